"""The slave station's visualisation: the scenario's VisualizationConfig in a loopback Meshcat,
its keys checked and overridden, and nothing listening beyond loopback."""

import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.scenario import Scenario, load_scenario, shipped_scenario


# --- visualisation: the scenario's VisualizationConfig in a loopback Meshcat -------------


def _systems(diagram):
    """Every leaf system of ``diagram``, sub-diagrams opened."""
    for system in diagram.GetSystems():
        if hasattr(system, "GetSystems"):
            yield from _systems(system)
        else:
            yield system


def _sockets_of_this_process():
    """(protocol, local address, port, state) of the sockets this process holds, read from
    /proc: its file descriptors' socket inodes matched in /proc/net/{tcp,tcp6,udp,udp6}."""
    import os
    import re
    from pathlib import Path

    inodes = set()
    for fd in Path("/proc/self/fd").iterdir():
        try:
            match = re.fullmatch(r"socket:\[(\d+)\]", os.readlink(fd))
        except OSError:
            continue
        if match:
            inodes.add(match.group(1))
    found = []
    for protocol in ("tcp", "tcp6", "udp", "udp6"):
        for line in Path(f"/proc/net/{protocol}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[9] in inodes:
                address, port = fields[1].split(":")
                found.append((protocol, address, int(port, 16), fields[3]))
    return found


LOOPBACK = {"0100007F", "00000000000000000000000001000000"}  # 127.0.0.1, ::1 in /proc's hex
LISTEN = "0A"


def test_a_station_built_without_visualisation_has_no_visualiser(pin_scenario):
    from pydrake.geometry import MeshcatVisualizer

    from hemg_drake.diagrams.demonstration import build_demonstration_diagram

    station = make_slave_station(pin_scenario)
    assert station.meshcat is None
    names = [type(s).__name__ for s in _systems(station.diagram)]
    assert not any("Visualizer" in n or "Lcm" in n for n in names), names
    built = build_demonstration_diagram(pin_scenario, scene=False)
    assert built.meshcat is None
    assert not [s for s in _systems(built.diagram) if isinstance(s, MeshcatVisualizer)]


def test_the_station_applies_the_scenarios_visualization(pin_scenario):
    from pydrake.geometry import MeshcatVisualizer

    from hemg_drake.diagrams.visualization import ILLUSTRATION, Visualization, meshcat_visualizers

    visualization = Visualization()
    station = make_slave_station(pin_scenario, visualization=visualization)
    assert station.meshcat is visualization.meshcat
    # The project's defaults: the illustration alone, and no LCM publisher of any kind.
    assert [v.get_name() for v in meshcat_visualizers(station.diagram)] == [ILLUSTRATION]
    names = [type(s).__name__ for s in _systems(station.diagram)]
    assert not any(n in ("DrakeVisualizer", "LcmPublisherSystem", "ContactVisualizer")
                   for n in names), names  # fmt: skip
    # A --set override reaches Drake: the collision geometry gets its own visualiser, and
    # the recorded frame rate is 1 / publish_period.
    shown = pin_scenario.replaced(
        ["visualization.publish_period=0.02", "visualization.publish_proximity=true"]
    )
    station = make_slave_station(shown, visualization=visualization)
    visualizers = {v.get_name(): v for v in meshcat_visualizers(station.diagram)}
    assert set(visualizers) == {ILLUSTRATION, "meshcat_visualizer(proximity)"}
    assert all(isinstance(v, MeshcatVisualizer) for v in visualizers.values())
    recording = visualizers[ILLUSTRATION].StartRecording()
    assert recording.frames_per_second() == pytest.approx(50.0)
    visualizers[ILLUSTRATION].StopRecording()


@pytest.mark.parametrize(
    "override, message",
    [("visualization.publish_period=0", "key 'visualization.publish_period' must be positive"),
     ("visualization.enable_meshcat_creation=true", "every interface"),
     ("visualization.publish_period=fast", "must be a number"),
     ("visualization.default_illustration_color={rgba: [1, 0, x]}",
      "visualization.default_illustration_color.rgba[2]")],
)
def test_bad_visualization_keys_name_the_key(override, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_scenario(shipped_scenario("drawing"), overrides=[override])


def test_visualization_keys_load_override_and_round_trip():
    from hemg_drake.scenario import parse_scenario

    default = Scenario().visualization
    assert (default.publish_period, default.publish_illustration) == (1 / 32, True)
    assert not (default.publish_proximity or default.publish_contacts or default.publish_inertia
                or default.enable_meshcat_creation)  # fmt: skip
    scenario = load_scenario(
        shipped_scenario("cotter_pin"),
        overrides=["visualization.publish_period=0.02",
                   "visualization.default_illustration_color={rgba: [0.2, 0.4, 0.6, 1.0]}"],
    )  # fmt: skip
    assert scenario.visualization.publish_period == 0.02
    color = scenario.visualization.default_illustration_color
    assert (color.r(), color.g(), color.b(), color.a()) == (0.2, 0.4, 0.6, 1.0)
    again = parse_scenario(scenario.to_yaml())
    assert again.to_yaml() == scenario.to_yaml()
    assert again.visualization.publish_period == 0.02


def test_nothing_listens_beyond_loopback_and_nothing_goes_out_on_udp(pin_scenario):
    from hemg_drake.diagrams.visualization import Visualization

    before = set(_sockets_of_this_process())
    visualization = Visualization()
    station = make_slave_station(pin_scenario, visualization=visualization)
    simulator = Simulator(station.diagram)
    context = simulator.get_mutable_context()
    station.diagram.GetInputPort("p_WE_desired").FixValue(
        context, pin_scenario.task_plan().points[0]
    )
    station.diagram.GetInputPort("gain").FixValue(context, [50.0])
    simulator.AdvanceTo(0.1)  # a few frames published
    new = set(_sockets_of_this_process()) - before
    listening = [s for s in new if s[3] == LISTEN]
    assert [port for _, _, port, _ in listening] == [visualization.port()]
    assert all(address in LOOPBACK for _, address, _, _ in listening), listening
    assert not [s for s in new if s[0].startswith("udp")]  # no LCM socket
    with pytest.raises(ValueError, match="in use"):
        Visualization(visualization.port())
    with pytest.raises(ValueError, match="0..65535"):
        Visualization(70000)
