"""A plant's Context kept in a system's cache: the Drake-native home of the kinematics a
controller or a sensor computes on its own plant (manipulation's station does the same)."""

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer


def declare_plant_context(system, plant, ticket, set_state):
    """Declare on ``system`` a cache entry holding a Context of ``plant``.

    Parameters
    ----------
    system : LeafSystem being constructed (any scalar type matching ``plant``'s).
    plant : MultibodyPlant, finalized (e.g. a controller plant of the arm alone).
    ticket : DependencyTicket, what the entry depends on (an input port, a state group).
    set_state : callable ``set_state(context, plant_context)``, writes the system's
        ``context`` into the cached ``plant_context`` (positions, velocities).

    Returns
    -------
    CacheEntry; ``entry.Eval(context)`` is the plant's context, updated when ``ticket``
    changes and held by each of the system's contexts (clones and copies included).
    """
    return system.DeclareCacheEntry(
        "plant_context",
        ValueProducer(
            allocate=lambda: AbstractValue.Make(plant.CreateDefaultContext()),
            calc=lambda context, value: set_state(context, value.get_mutable_value()),
        ),
        {ticket},
    )
