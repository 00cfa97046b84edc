"""Where a diagram is shown: the scenario's ``VisualizationConfig`` applied in a Meshcat that
listens on the loopback interface only.

A builder takes ``visualization=`` (a :class:`Visualization`, or None for no visualiser at
all) and the station applies ``scenario.visualization`` inside its own builder::

    visualization = Visualization(port=0)        # localhost, a free port
    built = build_demonstration_diagram(scenario, visualization=visualization)
    print(visualization.web_url())

Why a handle and not a Meshcat or a port: Drake's ``ApplyVisualizationConfig`` creates its
own ``Meshcat()`` when given none (``enable_meshcat_creation``), and that one listens on every
interface: on a shared machine the station must never open one. The Meshcat therefore comes
from outside the config, and one made by :class:`Visualization` is one on ``localhost`` by
construction (the builders accept nothing else). It is made by the application and not by the
station because one page outlives the diagrams shown in it: ``hemg-drake teleop`` builds a
diagram per take into the one page the person keeps open, and the pipeline's replays of C
demonstrations need no server each. The diagram keeps the Meshcat alive through its
visualisers; the station's ``meshcat`` names it for recording (:mod:`hemg_drake.viz.recording`
starts and exports the recording on the visualiser found here by :func:`illustration_visualizer`).

LCM: the config's ``lcm_bus`` is Drake's null bus (``ApplyLcmBusConfig({bus: None})``), on
which ``ApplyVisualizationConfig`` adds no LCM publisher: nothing goes on the network.
"""

import logging

from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer
from pydrake.systems.lcm import ApplyLcmBusConfig
from pydrake.visualization import ApplyVisualizationConfig

# Drake names the illustration visualiser of ApplyVisualizationConfig so.
ILLUSTRATION = "meshcat_visualizer(illustration)"


class Visualization:
    """A Meshcat server on ``localhost:port`` that diagrams are shown (and recorded) in.

    Parameters
    ----------
    port : int, 0..65535; 0 picks a free one.

    Raises
    ------
    ValueError
        A port out of range, or one already in use (the message says to pick another).
    """

    def __init__(self, port=0):
        port = int(port)
        if not 0 <= port <= 65535:
            raise ValueError(f"--port must be in 0..65535, got {port}")
        drake_logger = logging.getLogger("drake")
        level = drake_logger.level
        drake_logger.setLevel(logging.WARNING)  # callers name the URL themselves
        try:
            self._meshcat = Meshcat(MeshcatParams(host="localhost", port=port))
        except RuntimeError as error:
            raise ValueError(
                f"cannot listen on localhost:{port} ({error}): the port is in use; give another "
                "--port, or --port 0 for a free one"
            ) from None
        finally:
            drake_logger.setLevel(level)

    @property
    def meshcat(self):
        """The ``Meshcat`` (its page: :meth:`web_url`)."""
        return self._meshcat

    def port(self):
        return self._meshcat.port()

    def web_url(self):
        return self._meshcat.web_url()


def apply_visualization(config, builder, *, plant, scene_graph, visualization):
    """``ApplyVisualizationConfig(config, ...)`` into ``builder`` with the Meshcat of
    ``visualization`` and LCM on Drake's null bus (no network).

    Parameters
    ----------
    config : VisualizationConfig (``enable_meshcat_creation`` false: the scenario checks it).
    builder : DiagramBuilder holding ``plant`` (finalized) and ``scene_graph``.
    visualization : Visualization
    """
    if not isinstance(visualization, Visualization):
        raise ValueError(
            f"visualization must be a Visualization (a loopback Meshcat), got {visualization!r}"
        )
    lcm_buses = ApplyLcmBusConfig({config.lcm_bus: None}, builder)
    ApplyVisualizationConfig(
        config, builder, lcm_buses=lcm_buses, plant=plant, scene_graph=scene_graph,
        meshcat=visualization.meshcat,
    )  # fmt: skip


def meshcat_visualizers(diagram):
    """Every ``MeshcatVisualizer`` in ``diagram`` and its sub-diagrams."""
    found = []
    for system in diagram.GetSystems():
        if isinstance(system, MeshcatVisualizer):
            found.append(system)
        elif hasattr(system, "GetSystems"):
            found.extend(meshcat_visualizers(system))
    return found


def illustration_visualizer(diagram):
    """The illustration ``MeshcatVisualizer`` that ``ApplyVisualizationConfig`` added to
    ``diagram`` (or a sub-diagram); its ``StartRecording`` records the whole Meshcat at its
    publish period. ValueError if the diagram has none (built without a Visualization)."""
    visualizers = meshcat_visualizers(diagram)
    named = [v for v in visualizers if v.get_name() == ILLUSTRATION]
    if not (named or visualizers):
        raise ValueError(
            f"diagram {diagram.get_name()!r} has no Meshcat visualiser: build it with "
            "visualization=Visualization()"
        )
    return (named or visualizers)[0]
