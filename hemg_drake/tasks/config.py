"""Settings of the task scenes: where the scene stands, its physics, its placements, a plan.

Besides the standard library and the field helper, this module imports the argument checks
(``hemg_drake._validate``) and :class:`~hemg_drake.tasks.plan.TaskPlan` (numpy only), whose
checks a written-out plan must pass.
"""

import dataclasses as dc

import numpy as np

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.config_fields import checked, key_path
from hemg_drake.tasks.plan import TaskPlan


def _field_name(config, key, field):
    """How a check names a field: its key path under ``key``, else ``Class.field``."""
    return f"key '{key_path(key, field)}'" if key else f"{type(config).__name__}.{field}"


@dc.dataclass
class CotterPinParams:
    """Physics of the cotter-pin scene (SI units); loadable from YAML (``scene.cotter_pin``).

    The placement is not a parameter: the scene frame T (:func:`scene_pose`) puts the ring's
    centre, with the pin fully in, at T's origin. Every field is checked by :meth:`check`
    (also called by :func:`~hemg_drake.tasks.cotter_pin.add_cotter_pin_scene`), which raises
    ValueError naming the field; the detent against the pin's length (read from its model,
    :func:`~hemg_drake.tasks.plans.pin_length`) by the scene and by ``Scenario.check``.
    """

    # Largest force (N) with which the detent holds the pin in.
    hold_force: float = 50.0
    # Withdrawal (m) over which the detent acts; beyond it only sliding friction remains.
    detent_length: float = 0.003
    # Stiffness (N/m) of the detent spring until it saturates at hold_force.
    detent_stiffness: float = 3.0e4
    # Viscous sliding friction of the pin (N s/m).
    sliding_damping: float = 20.0
    # Grasp bushing, translational stiffness (N/m) and damping (N s/m) on each axis.
    grasp_stiffness: float = 5000.0
    grasp_damping: float = 40.0
    # Where the fixture (and the pin in it) actually stands, relative to where the plan and
    # the operator expect it: an offset (m, in the scene frame T) of the physical fixture
    # only; the scene frame, the plan and the map stay put. A world that differs from the
    # demonstrations' (the stiffness study, docs/studies.md): the grasp starts stretched.
    fixture_offset: list[float] = checked([0.0, 0.0, 0.0], signed=True, size=3)

    def __post_init__(self):
        self.check()

    def check(self, key=""):
        """Raise ValueError naming the first bad field (its key path under ``key`` if given,
        else ``CotterPinParams.field``); return self."""
        for field in ("hold_force", "detent_length", "detent_stiffness", "grasp_stiffness"):
            as_scalar(_field_name(self, key, field), getattr(self, field))
        for field in ("sliding_damping", "grasp_damping"):
            as_scalar(_field_name(self, key, field), getattr(self, field), strict=False)
        as_vector(_field_name(self, key, "fixture_offset"), self.fixture_offset, 3)
        return self


@dc.dataclass
class DrawingParams:
    """The pen, its contact and the plan's heights (SI units); loadable from YAML
    (``scene.drawing``).

    The placement is not a parameter: the scene frame T puts the sheet's top-surface centre
    at its origin. Every field is checked by :meth:`check` (also called by
    :func:`add_drawing_scene` and :func:`default_drawing_plan`), which raises ValueError
    naming the field.
    """

    # Radius of the pen's spherical tip (m).
    pen_radius: float = 0.003
    # Point-contact stiffness (N/m), Hunt-Crossley dissipation (s/m), friction of the tip.
    pen_stiffness: float = 1.0e4
    pen_dissipation: float = 10.0
    pen_friction: float = 0.2
    # Plan: depth of the planned tip below the paper while drawing (m), and height of the
    # pen lifts above it (m).
    press_depth: float = 0.003
    hover_height: float = 0.03
    # How much higher (m, along T's z; negative: lower) the sheet actually stands than the
    # plan and the operator expect it: the physical sheet only moves. A world that differs
    # from the demonstrations' (the stiffness study, docs/studies.md).
    sheet_offset: float = checked(0.0, signed=True)

    def __post_init__(self):
        self.check()

    def check(self, key=""):
        """Raise ValueError naming the first bad field (its key path under ``key`` if given,
        else ``DrawingParams.field``); return self."""
        for field in ("pen_radius", "pen_stiffness", "press_depth", "hover_height"):
            as_scalar(_field_name(self, key, field), getattr(self, field))
        for field in ("pen_dissipation", "pen_friction"):
            as_scalar(_field_name(self, key, field), getattr(self, field), strict=False)
        as_scalar(_field_name(self, key, "sheet_offset"), self.sheet_offset, minimum=-np.inf,
                  strict=False)  # fmt: skip
        if self.press_depth >= self.hover_height:
            raise ValueError(
                f"{_field_name(self, key, 'press_depth')} ({self.press_depth}) must be less "
                f"than {_field_name(self, key, 'hover_height')} ({self.hover_height})"
            )
        return self


@dc.dataclass
class PlacementsConfig:
    """A scene placement per demonstration (``hemg_drake.placements``): each demonstration's
    seed draws its scene pose uniformly from these ranges; empty: ``scene.position`` /
    ``scene.yaw_deg`` for every demonstration."""

    # Box of scene positions (m, in W): [[xmin, ymin, zmin], [xmax, ymax, zmax]].
    position_range: list[list[float]] = checked([], signed=True)
    # Range of scene yaws (deg): [smallest, largest].
    yaw_range_deg: list[float] = checked([], signed=True, size=(0, 2))

    def check(self, key=""):
        """The ranges' order: each min <= max. Raises ValueError naming the key."""
        box = self.position_range
        rows = np.array(box, dtype=float) if all(len(row) == 3 for row in box) else None
        if box and (rows is None or rows.shape != (2, 3) or np.any(rows[0] > rows[1])):
            raise ValueError(
                f"key '{key_path(key, 'position_range')}' must be [[xmin, ymin, zmin], [xmax, "
                f"ymax, zmax]] with each min <= max, got {box}"
            )
        yaws = self.yaw_range_deg
        if yaws and yaws[0] > yaws[1]:
            raise ValueError(
                f"key '{key_path(key, 'yaw_range_deg')}' must be [smallest, largest], got {yaws}"
            )


@dc.dataclass
class BlockConfig:
    """An unexpected rigid box in the scene (``scene.block``): welded to the world, it
    collides with every collision geometry of the arm (the pen's tip, the links), and the
    force the arm puts on it is measured (``tasks.block``). Not in the plan, nor known to
    the operator: a world that differs from the demonstrations' (docs/studies.md)."""

    # Edge lengths (m) along the scene frame T's axes; empty: no block.
    size: list[float] = checked([], positive=True, size=(0, 3))
    # Centre of the box (m, in T).
    position: list[float] = checked([0.0, 0.0, 0.0], signed=True, size=3)
    # Point-contact stiffness (N/m) and Hunt-Crossley dissipation (s/m) of its surface:
    # nearly rigid, as the drawing's sheet.
    stiffness: float = checked(1.0e6, positive=True)
    dissipation: float = checked(10.0)


@dc.dataclass
class SceneConfig:
    """Where the task's object stands, and its physics (the scene frame T)."""

    # Position of the scene frame T in the world (m): the cotter pin's ring centre with the
    # pin in; the sheet's top-surface centre. Empty: the task's default
    # (tasks.placement.DEFAULT_POSITIONS).
    # The operator's plan and the workspace map move with it.
    position: list[float] = checked([], signed=True, size=(0, 3))
    # Turn of the scene about world +z (deg): the fixture, the sheet and its strokes, the
    # plan and the master's frame turn with it (the pin's pull axis stays world +z).
    yaw_deg: float = checked(0.0, signed=True)
    # The cotter pin's detent, friction and grasp (used when task is cotter_pin).
    cotter_pin: CotterPinParams = dc.field(default_factory=CotterPinParams)
    # The pen, its contact and the plan's heights (used when task is drawing).
    drawing: DrawingParams = dc.field(default_factory=DrawingParams)
    # Demonstrations at many placements: ranges each demonstration's seed draws its pose from.
    placements: PlacementsConfig = dc.field(default_factory=PlacementsConfig)
    # An extra rigid box, not in the plan (default: none).
    block: BlockConfig = dc.field(default_factory=BlockConfig)


@dc.dataclass
class PlanConfig:
    """A task plan written out in the scenario (see :class:`~hemg_drake.tasks.plan.TaskPlan`)."""

    # Waypoint times (s), strictly increasing, at least two.
    times: list[float] = dc.field(default_factory=list)
    # Waypoints of the tool point in the scene frame T (m), one [x, y, z] per time; the
    # scene's pose maps them to the world.
    points: list[list[float]] = checked([], signed=True)
    # "free" or "forceful", one per segment (between consecutive waypoints).
    kinds: list[str] = dc.field(default_factory=list)
    # Drawing: the pen touches the paper, one flag per segment (empty: all False).
    pen_down: list[bool] = dc.field(default_factory=list)
    # Operator's effort per segment relative to nominal, > 0 (empty: all 1).
    effort: list[float] = dc.field(default_factory=list)

    def task_plan(self):
        """The :class:`TaskPlan` written out here, in the scene frame T (empty optional lists
        take TaskPlan's defaults). Raises ValueError naming the plan's field at fault."""
        data = dc.asdict(self)
        for name in ("pen_down", "effort"):
            if not data[name]:
                del data[name]
        return TaskPlan.from_dict(data)

    def check(self, key=""):
        """Raise ValueError (naming ``key``) if the fields make no valid :class:`TaskPlan`."""
        try:
            self.task_plan()
        except ValueError as error:
            where = f"key '{key}'" if key else type(self).__name__
            raise ValueError(f"{where}: {error}") from None
