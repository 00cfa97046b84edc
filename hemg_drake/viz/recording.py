"""Record a simulation in the Meshcat its visualisation draws in, and export it as one
self-contained HTML replay.

Usage, for a diagram built with a ``Visualization`` (the station applies the scenario's
``VisualizationConfig``; :mod:`hemg_drake.diagrams.visualization`)::

    visualization = Visualization()
    built = build_demonstration_diagram(scenario, visualization=visualization)
    recorder = ReplayRecorder(title="cotter pin: demonstration 1", view=frame_task(points))
    recorder.start(built.diagram, visualization.meshcat)
    demo = run_demonstration(built, seed=1)
    recorder.stop_and_export(out_dir / "replay.html")

The recording is the one of the illustration ``MeshcatVisualizer`` that
``ApplyVisualizationConfig`` added (found in the diagram by name): its frames come at the
config's ``publish_period``. :func:`export_station_replay` adds the drawing's ink first.
Extra animated objects (ink traces) go through ``recorder.meshcat`` while recording, e.g.
``SetLineSegments`` at time 0 and ``SetProperty(path, "visible", True,
time_in_recording=t)`` (Meshcat cannot record ``SetObject`` mid-animation).

Each replay has its own page title (``title``, e.g. "cotter pin: demonstration 2") and
opens framed on its task: ``ReplayRecorder(view=frame_task(plan.points))`` puts the camera
where the arm's shoulder and the plan's points fill the view (``camera_framing`` for any
points). Both are written into the exported HTML (the camera as Meshcat's recorded camera
commands).

Lifetime: the Meshcat server (a local port and one thread) lives as long as something holds
the ``Meshcat``: the ``Visualization``, the recorder until ``stop_and_export``/``close``, and
the diagram's visualisers. pydrake objects form reference cycles, so the server stops once
they are dropped and the garbage collector has run (``gc.collect()``, or at exit).
"""

import html as html_text
import re
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform

from hemg_drake.diagrams.visualization import illustration_visualizer
from hemg_drake.fileio import write_text_atomic
from hemg_drake.viz.ink import INK_PATH, add_ink_to_recording, in_contact

# Default view: the right arm's workspace from the robot's front right, slightly above.
CAMERA_IN_WORLD = (2.0, 0.5, 0.5)
TARGET_IN_WORLD = (0.4, -0.5, -0.15)
DEFAULT_TITLE = "hemg-drake replay"
# Vertical field of view of Meshcat's default perspective camera (three.js), degrees.
FOV_DEG = 75.0
# From where camera_framing looks by default: in front of the robot (+x), to its left (+y)
# and above, so the right arm and a task at its front right are seen from the side.
VIEW_FROM = (1.6, 1.0, 0.9)
# The right arm's shoulder (joint s0's origin) in the world, with add_baxter_arm's base at the
# world's origin: right_arm_mount (0.024645, -0.219645, 0.118588), yawed -45 deg, and s0
# 0.055695 m along the mount's x and 0.011038 m up (docs/facts.md).
RIGHT_SHOULDER_W = (0.064027, -0.259027, 0.129626)
# How far above the shoulder the framed view reaches: the elbow rises about 0.4 m above it
# in the tasks' poses (at the home pose its links reach z = 0.53 m, the shoulder is at 0.13).
ELBOW_RISE = 0.45


def camera_framing(points_W, *, view_from=VIEW_FROM, fov_deg=FOV_DEG, margin=1.5):
    """A camera position and target that frame ``points_W`` in Meshcat's view.

    The target is the centre of the points' bounding box; the camera looks at it from the
    direction ``view_from``, far enough that the box's circumscribed sphere (radius r) fits
    the vertical field of view with ``margin``: distance = margin r / sin(fov / 2). Browser
    windows are wider than tall, so the horizontal view has more room.

    Parameters
    ----------
    points_W : array-like, shape (n, 3), m
        What must be seen, e.g. the arm's shoulder and the task plan's points.
    view_from : 3 floats
        Direction from the target to the camera (any length, not zero).
    fov_deg : float
        Vertical field of view of the camera, degrees (Meshcat's default 75).
    margin : float
        >= 1; 1 puts the sphere on the view's edge.

    Returns
    -------
    (camera_in_world, target_in_world) : two arrays, shape (3,), m; pass as
        ``ReplayRecorder(view=...)``.
    """
    points = np.asarray(points_W, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"points_W must have shape (n, 3) with n >= 1, got {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError("points_W contains NaN or inf")
    direction = np.asarray(view_from, dtype=float)
    if direction.shape != (3,) or not np.all(np.isfinite(direction)) or not direction.any():
        raise ValueError(f"view_from must be 3 finite numbers, not all zero, got {view_from!r}")
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg!r}")
    if not margin >= 1.0:
        raise ValueError(f"margin must be >= 1, got {margin!r}")
    low, high = points.min(axis=0), points.max(axis=0)
    target = (low + high) / 2
    # At least 10 cm, so a single point is seen with some room around it.
    radius = max(np.linalg.norm(high - low) / 2, 0.1)
    distance = margin * radius / np.sin(np.radians(fov_deg) / 2)
    return target + distance * direction / np.linalg.norm(direction), target


def frame_task(points_W, **options):
    """:func:`camera_framing` of the right arm and ``points_W`` (the task's plan points, say),
    so the arm and its task fill the view. The arm is its shoulder and a point ``ELBOW_RISE``
    above it, where the elbow reaches. Options as camera_framing's.
    """
    points = np.asarray(points_W, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_W must have shape (n, 3), got {points.shape}")
    shoulder = np.asarray(RIGHT_SHOULDER_W)
    arm = [shoulder, shoulder + [0.0, 0.0, ELBOW_RISE]]
    return camera_framing(np.vstack([arm, points]), **options)


class ReplayRecorder:
    """Record one run of a visualised diagram and export it as an HTML replay.

    Parameters
    ----------
    camera_in_world, target_in_world : 3 floats, m
        Initial camera position and the point it looks at.
    view : (camera_in_world, target_in_world), optional
        The same two points as one pair, e.g. from :func:`camera_framing`; give either
        ``view`` or the two arguments.
    floor_z : float, m
        Height of Meshcat's ground grid (e.g. ``baxter.FLOOR_Z`` under the pedestal).
    title : str
        The replay page's title (the browser's tab), e.g. "drawing: reproduction".
    """

    def __init__(
        self,
        *,
        camera_in_world=None,
        target_in_world=None,
        view=None,
        floor_z=0.0,
        title=DEFAULT_TITLE,
    ):
        if view is not None:
            if camera_in_world is not None or target_in_world is not None:
                raise ValueError("give either view or camera_in_world/target_in_world, not both")
            if len(view) != 2:
                raise ValueError("view must be a pair (camera_in_world, target_in_world)")
            camera_in_world, target_in_world = view
        camera_in_world = CAMERA_IN_WORLD if camera_in_world is None else camera_in_world
        target_in_world = TARGET_IN_WORLD if target_in_world is None else target_in_world
        self._camera = (np.asarray(camera_in_world, float), np.asarray(target_in_world, float))
        if any(a.shape != (3,) or not np.all(np.isfinite(a)) for a in self._camera):
            raise ValueError("camera_in_world and target_in_world must be 3 finite numbers each")
        if np.allclose(*self._camera):
            raise ValueError("camera_in_world and target_in_world must differ")
        if not isinstance(title, str) or not title.strip() or "\n" in title:
            raise ValueError(f"title must be a non-empty one-line string, got {title!r}")
        self._title = title
        self._floor_z = float(floor_z)
        self._meshcat = None
        self._visualizer = None

    @property
    def meshcat(self):
        """The ``Meshcat`` being recorded into (after ``start``)."""
        self._require_visualizer()
        return self._meshcat

    def start(self, diagram, meshcat):
        """Begin recording ``diagram`` (built with a Visualization whose Meshcat is
        ``meshcat``): call before advancing its simulator, before or after ``Initialize``.

        Frames go to the recording and to the live scene as well (a page watching the
        Meshcat keeps moving; the replay's scene starts where the arm is). Ink of an earlier
        recording in the same Meshcat is removed.

        Returns
        -------
        MeshcatVisualizer, the illustration visualiser recorded through.
        """
        if self._visualizer is not None:
            raise ValueError("this ReplayRecorder is already recording")
        visualizer = illustration_visualizer(diagram)  # ValueError without one
        self._meshcat, self._visualizer = meshcat, visualizer
        meshcat.Delete(INK_PATH)
        meshcat.SetCameraPose(*self._camera)
        meshcat.SetTransform("/Grid", RigidTransform([0.0, 0.0, self._floor_z]))
        visualizer.StartRecording(set_transforms_while_recording=True)
        return visualizer

    def stop_and_export(self, path):
        """Stop recording, write the replay to ``path`` atomically, release the recorder.

        Returns
        -------
        Path, the HTML file written (one file; scripts inlined; no network needed).
        """
        self._require_visualizer()
        self._visualizer.StopRecording()
        self._visualizer.PublishRecording()
        html = _with_title(self._meshcat.StaticHtml(), self._title)
        path = Path(path)
        write_text_atomic(path, html)
        self.close()
        return path

    @property
    def title(self):
        """The title the exported page gets."""
        return self._title

    def close(self):
        """Drop this recorder's references to Meshcat (idempotent)."""
        self._visualizer = None
        self._meshcat = None

    def _require_visualizer(self):
        if self._visualizer is None:
            raise ValueError("call ReplayRecorder.start(diagram, meshcat) first")


def export_station_replay(recorder, built, path, time, p_WE, f_WE):
    """Write the replay of a recorded station diagram; for the drawing, with the ink.

    Parameters
    ----------
    recorder : ReplayRecorder, started on ``built.diagram``.
    built : StationDiagram with a ``scenario`` (demonstration, reproduction).
    path : path-like
    time : array, shape (T,), s; p_WE, f_WE : arrays, shape (T, 3)
        The logged tool point (m) and its force (N): the ink is drawn where it touches.

    Returns
    -------
    Path
    """
    if built.scenario.task == "drawing" and built.scene is not None:
        # Just above the sheet: the tip's own heights are inside the compliant paper.
        height = built.scene.paper_height + 5e-4
        add_ink_to_recording(recorder.meshcat, time, p_WE, in_contact(f_WE), height=height)
    return recorder.stop_and_export(path)


def record_run(built, run, path, *, title):
    """``run(built)`` with the station's Meshcat recorded, and its replay written to ``path``
    (the drawing's ink included), framed on the scenario's task and titled ``title``.

    Parameters
    ----------
    built : DemonstrationDiagram or ReproductionDiagram, built with a Visualization.
    run : callable, ``run(built)`` -> a Demonstration, or a result with a ``log`` (a
        ReproductionLog): its ``time``, ``p_WE`` and ``f_WE`` place the ink. Every
        simulation of the diagram that ``run`` makes is recorded: a reproduction's settling
        run (``reproduction.settle_time``) goes first, and its frames are overwritten by the
        reproduction's own when that lasts longer (as a demonstration's length does).
    path : path-like
    title : str, the page's title.

    Returns
    -------
    What ``run`` returned.
    """
    from hemg_drake.robots.baxter import FLOOR_Z

    if built.meshcat is None:
        raise ValueError("record_run needs a diagram built with visualization=Visualization()")
    view = frame_task(built.scenario.task_plan().points)
    recorder = ReplayRecorder(floor_z=FLOOR_Z, title=title, view=view)
    recorder.start(built.diagram, built.meshcat)
    result = run(built)
    log = getattr(result, "log", result)
    export_station_replay(recorder, built, path, log.time, log.p_WE, log.f_WE)
    return result


def record_arm_demo(out_dir, *, duration=6.0, time_step=None):
    """Simulate the arm's waypoint tour (:mod:`hemg_drake.diagrams.arm_demo`) and write
    ``out_dir/replay.html``.

    Parameters
    ----------
    out_dir : path-like, created if missing.
    duration : float, s, simulated time.
    time_step : float, s, plant step; default the arm demo's.

    Returns
    -------
    Path of the replay (one self-contained HTML file).
    """
    from pydrake.systems.analysis import Simulator

    from hemg_drake.diagrams.arm_demo import build_arm_demo
    from hemg_drake.diagrams.visualization import Visualization
    from hemg_drake.robots.baxter import FLOOR_Z

    visualization = Visualization()
    steps = {} if time_step is None else dict(time_step=time_step)
    diagram, _, _, _ = build_arm_demo(duration=duration, visualization=visualization, **steps)
    recorder = ReplayRecorder(floor_z=FLOOR_Z)
    recorder.start(diagram, visualization.meshcat)
    Simulator(diagram).AdvanceTo(duration)
    return recorder.stop_and_export(Path(out_dir) / "replay.html")


def _with_title(page, title):
    """``page`` with its <title> (Meshcat's "Drake MeshCat") replaced by ``title``, escaped."""
    escaped = html_text.escape(title, quote=False)
    page, count = re.subn(r"<title>.*?</title>", lambda _: f"<title>{escaped}</title>", page,
                          count=1, flags=re.IGNORECASE | re.DOTALL)
    if count == 0:  # a Meshcat without a title: give the head one
        page, count = re.subn(r"<head[^>]*>", lambda m: f"{m.group(0)}<title>{escaped}</title>",
                              page, count=1, flags=re.IGNORECASE)
    if count == 0:
        raise ValueError("Meshcat's page has neither a <title> nor a <head> to put one in")
    return page
