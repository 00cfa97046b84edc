"""The task plans in force: each task's default plan, and a scenario's own plan, placed.

Plans and poses only (numpy, ``pydrake.math``): a scenario builds its plan without a plant
or a system. The cotter pin's default plan needs the pin's length, read from its model file
as XML (:func:`pin_geometry`; ``tests/tasks/test_cotter_pin.py`` checks it against the
plant's).
"""

import functools
import xml.etree.ElementTree as ET

import numpy as np

from hemg_drake._validate import as_scalar
from hemg_drake.model_files import MODELS_DIR
from hemg_drake.tasks.config import DrawingParams
from hemg_drake.tasks.placement import checked_scene_pose, task_scene_pose, to_world
from hemg_drake.tasks.plan import TaskPlan

COTTER_PIN_MODEL = MODELS_DIR / "cotter_pin.sdf"
# The pin slides out along world +z (the model's z; the scene only turns about z).
PULL_AXIS_W = np.array([0.0, 0.0, 1.0])


def task_plan(task, scene, plan=None):
    """The plan in force, in W: ``plan`` (a ``PlanConfig``, in the scene frame T) if given,
    else the task's default; placed by the scene (a ``SceneConfig``).

    Raises
    ------
    ValueError
        A ``plan`` that is no valid :class:`TaskPlan` (naming its field).
    """
    X_WT = task_scene_pose(task, scene)
    if plan is not None:
        plan_T = plan.task_plan()
        return plan_T.in_frame(to_world(X_WT, plan_T.points))
    if task == "cotter_pin":
        return default_cotter_pin_plan(X_WT=X_WT)
    return default_drawing_plan(scene.drawing, X_WT=X_WT)


# --- the cotter pin ----------------------------------------------------------------------


def _frame_offset(model, name):
    """Translation (m) of the SDF ``<frame name=...>`` attached to the link ``pin``, in it."""
    frame = model.find(f"frame[@name='{name}']")
    pose = None if frame is None else frame.find("pose")
    if (
        pose is None
        or frame.get("attached_to") != "pin"
        or pose.get("relative_to", "pin") != "pin"
    ):
        raise ValueError(f"{COTTER_PIN_MODEL}: no frame '{name}' posed on the link 'pin'")
    return np.array(pose.text.split()[:3], dtype=float)


@functools.cache
def pin_geometry():
    """(pin length, ring offset p_FR (3,)) of the cotter pin's model file (m).

    The pin's frame sits at the hole's mouth when the pin is in (the model's frame, as the
    link ``pin`` has no pose of its own); the length is the depth of the frame ``pin_tip``
    below it, the ring offset the frame ``ring``'s position.
    """
    model = ET.parse(COTTER_PIN_MODEL).getroot().find("model")
    if model.find("link[@name='pin']/pose") is not None:
        raise ValueError(f"{COTTER_PIN_MODEL}: the link 'pin' must sit at the model's frame")
    tip, ring = _frame_offset(model, "pin_tip"), _frame_offset(model, "ring")
    ring.flags.writeable = False  # cached: shared by every caller
    return float(-tip[2]), ring


def pin_length():
    """Depth (m) the pin must rise to be out: its frame (at the hole's mouth) to ``pin_tip``."""
    return pin_geometry()[0]


def default_cotter_pin_plan(*, X_WT=None, margin=0.015, carry=0.035):
    """The pulling task in the paper's N = 4 phases, as timed tool-point waypoints in W.

    1. hold (0-0.5 s, free): the tool waits at the ring;
    2. pull (0.5-2.0 s, forceful): up the pull axis by ``pin_length + margin``;
    3. carry away (2.0-3.0 s, free): a further ``carry`` along the axis, clear of the fixture;
    4. settle (3.0-3.5 s, free): hold still.

    The whole travel (0.10 m by default) stays inside the master's mapped workspace.

    Parameters
    ----------
    X_WT : RigidTransform, optional
        The scene frame: its origin, the ring, is the first waypoint (default as
        :func:`~hemg_drake.tasks.cotter_pin.add_cotter_pin_scene`).
    margin, carry : float, m, >= 0.

    Returns
    -------
    TaskPlan
    """
    X_WT = checked_scene_pose(X_WT, "cotter_pin")
    margin = as_scalar("margin", margin, strict=False)
    carry = as_scalar("carry", carry, strict=False)
    pulled = pin_length() + margin
    p_WR = X_WT.translation()
    rises = np.array([0.0, 0.0, pulled, pulled + carry, pulled + carry])
    return TaskPlan(
        times=np.array([0.0, 0.5, 2.0, 3.0, 3.5]),
        points=p_WR + rises[:, None] * PULL_AXIS_W,
        kinds=("free", "forceful", "free", "free"),
    )


# --- the drawing -------------------------------------------------------------------------


def _stroke_shapes():
    """The three strokes as (k, 2) arrays of sheet coordinates (m) from the sheet's centre."""
    line = np.array([[-0.05, -0.09], [0.06, -0.09]])
    angle = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 7)
    arc = np.column_stack([0.005 + 0.045 * np.cos(angle), -0.01 + 0.045 * np.sin(angle)])
    zigzag = np.column_stack([[-0.02, 0.02, -0.02, 0.02, -0.02], np.linspace(0.05, 0.11, 5)])
    return line, arc, zigzag
# Timing (s) of the moves around the strokes: brisk, as a person lifts and moves a pen.
_PRESS_TIME = 0.2
_LIFT_TIME = 0.3
_TRAVEL_TIME = 0.5
# A pen-down chord takes length / _DRAW_SPEED plus _TURN_TIME per half turn (pi rad) of the
# corner that ends it: people slow down before sharp turns (the corners of the zig-zag get
# the most time, the arc's gentle bends little). Chosen so that the line takes 1.2 s and an
# arc chord 0.3 s.
_DRAW_SPEED = 0.13
_TURN_TIME = 0.75
# Pen-down segments start and end this high above the paper (m): the arm's lag and
# overshoot at the end of a free move stay clear of the paper.
_CLEARANCE = 0.005


def _chord_times(xy):
    """Duration (s) of each chord of a stroke's corners ``xy`` (k, 2), by its length and turn.

    The last chord turns by 90 degrees into the pen's lift.
    """
    chords = np.diff(xy, axis=0)
    lengths = np.linalg.norm(chords, axis=1)
    directions = chords / lengths[:, None]
    cosines = np.sum(directions[:-1] * directions[1:], axis=1)
    turns = np.append(np.arccos(np.clip(cosines, -1.0, 1.0)), 0.5 * np.pi)
    return lengths / _DRAW_SPEED + _TURN_TIME * turns / np.pi


def default_drawing_plan(params=None, *, X_WT=None):
    """Three strokes with pen lifts between them: the paper's six steps I-VI (Fig. 10).

    I stroke 1, a 11 cm line; II lift and move; III stroke 2, a 14 cm half circle (six
    chords); IV lift and move; V stroke 3, a 17 cm zig-zag; VI lift and back. The plan
    starts and ends ``hover_height`` above the sheet's centre (by default where the tool
    point is at the arm's home pose). Around each stroke: descend (free) to 5 mm above the
    paper, press (pen down) to ``press_depth`` below it, draw (pen down, one segment per
    chord), release (pen down) to 5 mm above, lift (free) to ``hover_height``. Pen-down
    segments are forceful, the others free. 11.7 s in all; chord durations by length and
    turn (people slow down before sharp corners), brisk pen lifts.

    Parameters
    ----------
    params : DrawingParams, optional; the plan's heights.
    X_WT : RigidTransform, optional
        The sheet's frame (as :func:`~hemg_drake.tasks.drawing.add_drawing_scene`); the
        plan is written in it and mapped to W, so the strokes turn with the sheet.

    Returns
    -------
    TaskPlan, waypoints in W.
    """
    params = (DrawingParams() if params is None else params).check()
    X_WT = checked_scene_pose(X_WT, "drawing", what="sheet")
    center = np.zeros(3)
    hover = params.hover_height
    touch = _CLEARANCE
    press = -params.press_depth
    above_center = np.array([*center[:2], hover])
    points, durations, pen_down = [above_center], [], []

    def go(point, duration, down):
        points.append(np.asarray(point, dtype=float))
        durations.append(duration)
        pen_down.append(down)

    for shape in _stroke_shapes():
        xy = center[:2] + shape
        go([*xy[0], hover], _TRAVEL_TIME, False)
        go([*xy[0], touch], _LIFT_TIME, False)
        go([*xy[0], press], _PRESS_TIME, True)
        for corner, chord_time in zip(xy[1:], _chord_times(xy)):
            go([*corner, press], chord_time, True)
        go([*xy[-1], touch], _PRESS_TIME, True)
        go([*xy[-1], hover], _LIFT_TIME, False)
    go(above_center, _TRAVEL_TIME, False)
    times = np.concatenate([[0.0], np.cumsum(durations)])
    kinds = tuple("forceful" if down else "free" for down in pen_down)
    points_W = to_world(X_WT, np.array(points))
    return TaskPlan(times=times, points=points_W, kinds=kinds, pen_down=tuple(pen_down))


def drawing_steps(plan):
    """Boundaries of the six steps I-VI of a drawing plan (s), shape (7,).

    Step I runs from the plan's start to the end of the first pen-down stretch (stroke 1),
    II from there to the start of the second stretch, and so on; VI from the end of the third
    stroke to the plan's end. Works on perturbed plans (it reads ``pen_down``).

    Raises
    ------
    ValueError
        The plan does not have exactly three pen-down stretches.
    """
    down = np.asarray(plan.pen_down, dtype=int)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], down, [0]])))
    if edges.size != 6:
        raise ValueError(
            f"a drawing plan needs exactly 3 pen-down stretches, got {edges.size // 2}"
        )
    starts, ends = plan.times[edges[0::2]], plan.times[edges[1::2]]
    return np.array(
        [plan.start_time, ends[0], starts[1], ends[1], starts[2], ends[2], plan.end_time]
    )
