"""What the built diagrams around a slave station share: their handles and the simulator they
run in (demonstration, reproduction, plan follower). Their replays are recorded by the
application (:mod:`hemg_drake.viz.recording`) on the visualiser the station's
``visualization`` added."""

import dataclasses as dc

from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

from hemg_drake._validate import as_scalar


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

    @property
    def meshcat(self):
        """The Meshcat the diagram is shown in (its ``visualization``'s), or None."""
        return self.station.meshcat


def make_simulator(built, duration):
    """The simulator of a built diagram, with the scenario's simulator settings.

    Parameters
    ----------
    built : StationDiagram with a ``scenario`` attribute.
    duration : float or None
        Simulated seconds; None for ``scenario.duration``.

    Returns
    -------
    (simulator, duration): a Simulator not yet initialised, and the duration (s).
    """
    scenario = built.scenario
    duration = scenario.duration if duration is None else as_scalar("duration", duration)
    simulator = Simulator(built.diagram)
    ApplySimulatorConfig(scenario.simulator, simulator)
    return simulator, duration
