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

Lifetime: the Meshcat server (a local port and one thread) lives as long as something holds
the ``Meshcat``: the recorder until ``stop_and_export``/``close``, and the diagram's
visualizer. pydrake objects form reference cycles, so the server stops once the diagram is
dropped and the garbage collector has run (``gc.collect()``, or at exit).
"""

import logging
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.math import RigidTransform

from hemg_drake.fileio import write_text_atomic

# Default view: the right arm's workspace from the robot's front right, slightly above.
CAMERA_IN_WORLD = (2.0, 0.5, 0.5)
TARGET_IN_WORLD = (0.4, -0.5, -0.15)


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
    floor_z : float, m
        Height of Meshcat's ground grid (e.g. ``baxter.FLOOR_Z`` under the pedestal).
    """

    def __init__(
        self,
        *,
        port=0,
        publish_period=1 / 32,
        camera_in_world=CAMERA_IN_WORLD,
        target_in_world=TARGET_IN_WORLD,
        floor_z=0.0,
    ):
        if not publish_period > 0:
            raise ValueError(f"publish_period must be positive, got {publish_period}")
        self._port = int(port)
        self._publish_period = float(publish_period)
        self._camera = (np.asarray(camera_in_world, float), np.asarray(target_in_world, float))
        if any(a.shape != (3,) or not np.all(np.isfinite(a)) for a in self._camera):
            raise ValueError("camera_in_world and target_in_world must be 3 finite numbers each")
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
        html = self._meshcat.StaticHtml()
        path = Path(path)
        write_text_atomic(path, html)
        self.close()
        return path

    def close(self):
        """Drop this recorder's references to Meshcat (idempotent)."""
        self._visualizer = None
        self._meshcat = None

    def _require_visualizer(self):
        if self._visualizer is None:
            raise ValueError("call ReplayRecorder.add_to_builder(builder, scene_graph) first")
