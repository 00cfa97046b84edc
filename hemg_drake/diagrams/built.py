"""What the built diagrams around a slave station share: their handles, the simulator they
run in and the replay they end with (demonstration, reproduction, plan follower)."""

import dataclasses as dc

from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

from hemg_drake._validate import as_scalar
from hemg_drake.viz.ink import add_ink_to_recording, in_contact


@dc.dataclass(frozen=True, eq=False)
class StationDiagram:
    """A built diagram and the :class:`~hemg_drake.diagrams.station.SlaveStation` in it.

    Attributes
    ----------
    diagram : Diagram
    station : SlaveStation
    """

    diagram: object
    station: object

    @property
    def plant(self):
        return self.station.plant

    @property
    def scene(self):
        return self.station.scene


def make_simulator(built, duration, replay_path):
    """The simulator of a built diagram, with the scenario's simulator settings.

    Parameters
    ----------
    built : StationDiagram with ``scenario`` and ``recorder`` attributes.
    duration : float or None
        Simulated seconds; None for ``scenario.duration``.
    replay_path : path-like or None
        Refused unless the diagram was built with a recorder.

    Returns
    -------
    (simulator, duration): a Simulator not yet initialised, and the duration (s).
    """
    scenario = built.scenario
    duration = scenario.duration if duration is None else as_scalar("duration", duration)
    if replay_path is not None and built.recorder is None:
        raise ValueError("replay_path needs a diagram built with a recorder")
    simulator = Simulator(built.diagram)
    ApplySimulatorConfig(scenario.simulator, simulator)
    return simulator, duration


def export_replay(built, replay_path, time, p_WE, f_WE):
    """Write the recorder's HTML replay to ``replay_path``; for the drawing, with the ink.

    Parameters
    ----------
    built : StationDiagram with ``scenario`` and ``recorder`` attributes.
    replay_path : path-like
    time : array, shape (T,), s; p_WE, f_WE : arrays, shape (T, 3)
        The logged tool point (m) and its force (N): the ink is drawn where it touches.
    """
    if built.scenario.task == "drawing" and built.scene is not None:
        # Just above the sheet: the tip's own heights are inside the compliant paper.
        height = built.scene.paper_height + 5e-4
        add_ink_to_recording(built.recorder.meshcat, time, p_WE, in_contact(f_WE), height=height)
    built.recorder.stop_and_export(replay_path)
