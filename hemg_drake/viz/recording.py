"""Record a simulation in Drake's Meshcat and export it as one self-contained HTML replay.

Usage, for any diagram with a ``SceneGraph``::

    recorder = ReplayRecorder()
    recorder.add_to_builder(builder, scene_graph)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    recorder.start()
    simulator.AdvanceTo(duration)
    recorder.stop_and_export(out_dir / "replay.html")

Extra animated objects (ink traces) go through ``recorder.meshcat`` while recording, e.g.
``SetLineSegments`` at time 0 and ``SetProperty(path, "visible", True,
time_in_recording=t)`` (Meshcat cannot record ``SetObject`` mid-animation).

Each replay has its own page title (``title``, e.g. "cotter pin: demonstration 2") and
opens framed on its task: ``ReplayRecorder(view=frame_task(plan.points))`` puts the camera
where the arm's shoulder and the plan's points fill the view (``camera_framing`` for any
points). Both are
written into the exported HTML (the camera as Meshcat's recorded camera commands).

Lifetime: the Meshcat server (a local port and one thread) lives as long as something holds
the ``Meshcat``: the recorder until ``stop_and_export``/``close``, and the diagram's
visualizer. pydrake objects form reference cycles, so the server stops once the diagram is
dropped and the garbage collector has run (``gc.collect()``, or at exit).
"""

import html as html_text
import logging
import re
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.math import RigidTransform

from hemg_drake.fileio import write_text_atomic

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
    """Attach a localhost-only ``Meshcat`` + ``MeshcatVisualizer`` and record one replay.

    Parameters
    ----------
    port : int
        Local port for the Meshcat server; 0 picks a free one (nothing needs to connect:
        the replay is read from the recording, not from a browser session).
    publish_period : float
        Seconds between recorded frames.
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
        port=0,
        publish_period=1 / 32,
        camera_in_world=None,
        target_in_world=None,
        view=None,
        floor_z=0.0,
        title=DEFAULT_TITLE,
    ):
        if not publish_period > 0:
            raise ValueError(f"publish_period must be positive, got {publish_period}")
        if view is not None:
            if camera_in_world is not None or target_in_world is not None:
                raise ValueError("give either view or camera_in_world/target_in_world, not both")
            if len(view) != 2:
                raise ValueError("view must be a pair (camera_in_world, target_in_world)")
            camera_in_world, target_in_world = view
        camera_in_world = CAMERA_IN_WORLD if camera_in_world is None else camera_in_world
        target_in_world = TARGET_IN_WORLD if target_in_world is None else target_in_world
        self._port = int(port)
        self._publish_period = float(publish_period)
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
        """The ``Meshcat`` being recorded into (after ``add_to_builder``)."""
        self._require_visualizer()
        return self._meshcat

    def add_to_builder(self, builder, scene_graph):
        """Start a Meshcat server on localhost and add a visualizer of ``scene_graph``.

        Returns
        -------
        MeshcatVisualizer
        """
        if self._visualizer is not None:
            raise ValueError("this ReplayRecorder is already attached to a diagram")
        # Only localhost: the machine is shared, and nothing remote needs to connect. Its
        # "listening at http://..." notice would invite users to a page nobody serves later.
        drake_logger = logging.getLogger("drake")
        level = drake_logger.level
        drake_logger.setLevel(logging.WARNING)
        try:
            self._meshcat = Meshcat(MeshcatParams(host="localhost", port=self._port))
        finally:
            drake_logger.setLevel(level)
        self._meshcat.SetCameraPose(*self._camera)
        self._meshcat.SetTransform("/Grid", RigidTransform([0.0, 0.0, self._floor_z]))
        params = MeshcatVisualizerParams(publish_period=self._publish_period)
        self._visualizer = MeshcatVisualizer.AddToBuilder(
            builder, scene_graph, self._meshcat, params
        )
        return self._visualizer

    def start(self):
        """Begin recording frames (call before advancing the simulator)."""
        self._require_visualizer()
        # Frames go to the recording only; no browser watches the live scene.
        self._visualizer.StartRecording(set_transforms_while_recording=False)

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
            raise ValueError("call ReplayRecorder.add_to_builder(builder, scene_graph) first")


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
