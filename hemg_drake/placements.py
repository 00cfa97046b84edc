"""Demonstrations at many placements: scene poses drawn per seed, task frames, moved records.

A scenario's ``scene.placements`` gives ranges (a box of positions, an interval of yaws);
each demonstration's seed draws its scene pose from them (:func:`draw_pose`, deterministic
per seed, on a random stream of its own so the operator's draws are unchanged), and the
demonstration runs in the scenario placed there (:func:`demonstration_scenario`): the
scene, its plan and the master's workspace map all follow the scene frame T. A drawn pose
whose plan the arm cannot reach (inverse kinematics on every waypoint, with the pen's axis
when the CLIK holds one) is drawn again, up to ``MAX_DRAWS`` times, then refused with a
ValueError naming the range.

The task frames of a placement (:func:`task_frames`) are what the task-parameterised HSMM
(:mod:`hemg_drake.learning.tphsmm`) learns in: frame 1 the robot's base (the world at the
arm's mount: identity), frame 2 the scene frame T (the pin's fixture with its pull axis,
the sheet's centre with its orientation), as A (3 x 3 rotation) and b (3,).
:func:`moved_demonstration` carries a logged demonstration from its placement to another
(what a reproduction at a new placement is compared with).
"""

import dataclasses as dc

import numpy as np

# Stream of the placement draws: np.random.default_rng((seed, PLACEMENT_STREAM)).
PLACEMENT_STREAM = 16
MAX_DRAWS = 20


def has_placements(scenario):
    """True when ``scene.placements`` asks for a pose per demonstration."""
    placements = scenario.scene.placements
    return bool(placements.position_range or placements.yaw_range_deg)


def draw_pose(scenario, seed, attempt=0):
    """The scene pose (position (3,) list, yaw in deg) that ``seed`` draws; attempt k > 0
    gives the k-th redraw. Without placements: the scenario's own pose."""
    placements = scenario.scene.placements
    position = list(scenario.X_WT().translation())
    yaw = float(scenario.scene.yaw_deg)
    rng = np.random.default_rng((int(seed), PLACEMENT_STREAM, int(attempt)))
    if placements.position_range:
        low, high = np.array(placements.position_range, dtype=float)
        position = [float(v) for v in rng.uniform(low, high)]
    if placements.yaw_range_deg:
        yaw = float(rng.uniform(*placements.yaw_range_deg))
    return position, yaw


def placed(scenario, position, yaw_deg):
    """The scenario with its scene at ``position`` (m, W) and ``yaw_deg`` (exact round trip)."""
    values = ", ".join(repr(float(v)) for v in position)
    return scenario.replaced(
        [f"scene.position=[{values}]", f"scene.yaw_deg={float(yaw_deg)!r}"], source="placement"
    )


def unreachable_point(scenario):
    """The first plan waypoint (index, point in W) that the arm cannot reach, or None.

    Inverse kinematics of the tool point on each waypoint in turn (each from the previous
    solution), with the CLIK's tool axis when it holds one.
    """
    from pydrake.multibody.plant import MultibodyPlant

    from hemg_drake.control.ik import solve_tool_point_ik
    from hemg_drake.robots.baxter import add_baxter_arm

    plant = MultibodyPlant(0.0)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    axes = {}
    if scenario.clik.orientation_gain > 0:
        axes = dict(axis_E=scenario.clik.axis_E, axis_W=scenario.clik.axis_W_desired)
    q = None
    for index, point in enumerate(scenario.task_plan().points):
        try:
            q = solve_tool_point_ik(plant, arm, point, q_guess=q, **axes)
        except ValueError:
            return index, np.asarray(point)
    return None


def describe_placement(scenario):
    """'scene at [x, y, z] m, yaw Y deg': where a placed scenario's scene is, for progress."""
    origin = np.round(task_frames(scenario)[1][1], 3).tolist()
    return f"scene at {origin} m, yaw {scenario.scene.yaw_deg:.1f} deg"


def demonstration_scenario(scenario, seed):
    """The scenario placed where demonstration ``seed`` happens (itself without placements).

    Raises
    ------
    ValueError
        No reachable pose in ``MAX_DRAWS`` draws: the message names the range and the first
        unreachable waypoint.
    """
    if not has_placements(scenario):
        return scenario
    for attempt in range(MAX_DRAWS):
        position, yaw = draw_pose(scenario, seed, attempt)
        candidate = placed(scenario, position, yaw)
        failure = unreachable_point(candidate)
        if failure is None:
            return candidate
    index, point = failure
    placements = scenario.scene.placements
    raise ValueError(
        f"scene.placements: no placement the arm can reach in {MAX_DRAWS} draws for seed "
        f"{seed} (position_range {placements.position_range}, yaw_range_deg "
        f"{placements.yaw_range_deg}); e.g. at {np.round(position, 3).tolist()}, yaw "
        f"{yaw:.1f} deg, plan waypoint {index} {np.round(point, 3).tolist()} is out of reach: "
        f"narrow the ranges towards the arm"
    )


def task_frames(scenario):
    """The task frames of the scenario's placement: A (2, 3, 3), b (2, 3).

    Frame 1: the robot's base (the world frame at the arm's mount: identity, origin).
    Frame 2: the scene frame T, X_WT (its rotation and origin).
    """
    X_WT = scenario.X_WT()
    A = np.stack([np.eye(3), X_WT.rotation().matrix()])
    b = np.stack([np.zeros(3), X_WT.translation()])
    return A, b


# learning.task_frames: how many of the last task frames the TP-HSMM uses (base first).
FRAME_SETS = {"scene": 1, "base_and_scene": 2}


def last_frames(frames, count):
    """The last ``count`` frames of (A, b): 1 the scene frame alone, 2 the base and the scene."""
    A, b = frames
    return np.asarray(A)[-count:], np.asarray(b)[-count:]


def frames_vary(frames):
    """True when the demonstrations' frames (list of (A, b)) are not all the same."""
    A0, b0 = frames[0]
    return any(not (np.array_equal(A, A0) and np.array_equal(b, b0)) for A, b in frames[1:])


def scene_frame(A, b):
    """The scene frame (R, p) of a demonstration's task frames."""
    return np.asarray(A)[-1], np.asarray(b)[-1]


def moved_demonstration(demo, frame_from, frame_to):
    """``demo`` carried rigidly from the scene frame ``frame_from`` = (R, p) to ``frame_to``.

    Positions in W (p_WE, p_WE_desired) map by X_to X_from^-1, vectors (v_WE, f_WE) by its
    rotation; the master's record (p_MS, in the master frame, which follows the scene), the
    sEMG and the gain are unchanged. The same frame gives ``demo`` itself.
    """
    (R_from, p_from), (R_to, p_to) = frame_from, frame_to
    if np.array_equal(R_from, R_to) and np.array_equal(p_from, p_to):
        return demo
    R = np.asarray(R_to) @ np.asarray(R_from).T
    t = np.asarray(p_to) - R @ np.asarray(p_from)
    return dc.replace(
        demo,
        p_WE=demo.p_WE @ R.T + t,
        p_WE_desired=demo.p_WE_desired @ R.T + t,
        v_WE=demo.v_WE @ R.T,
        f_WE=demo.f_WE @ R.T,
    )


def scene_placements(frames):
    """The distinct scene placements of the demonstrations' task frames (list of (A, b)), as
    a model stores them (``learnt_at_``): JSON-ready ``{"position": [x, y, z], "rotation":
    R (3 x 3)}`` of the scene frame, in the demonstrations' order."""
    placements = []
    for A, b in frames:
        R, p = scene_frame(A, b)
        entry = {"position": np.asarray(p, float).tolist(),
                 "rotation": np.asarray(R, float).tolist()}  # fmt: skip
        if entry not in placements:
            placements.append(entry)
    return placements


def check_learnt_placement(model, scenario, frames=None, source="model"):
    """Warn (``UserWarning``, naming ``source``) when ``model`` is reproduced where it cannot
    do the task it learnt; returns the warning's text, or None.

    A world-frame model (a plain HSMM) reproduces its demonstrations where they were: at a
    scene placement that is none of those it was learnt at (its ``learnt_at_``, see
    :func:`scene_placements`; for a model file written without them, the placements of
    the demonstrations' ``frames``) it pulls the pin or draws the strokes where the scene
    was. A TP-HSMM (with ``at``) is placed by its frames; unknown placements say nothing.
    """
    import warnings

    learnt_at = getattr(model, "learnt_at_", None) or (frames and scene_placements(frames))
    if hasattr(model, "at") or not learnt_at:
        return None
    R, p = scene_frame(*task_frames(scenario))
    here = [(np.linalg.norm(p - e["position"]), np.abs(R - e["rotation"]).max()) for e in learnt_at]
    if any(distance <= 1e-6 and turn <= 1e-9 for distance, turn in here):
        return None
    nearest = learnt_at[int(np.argmin([distance for distance, _ in here]))]
    R0 = np.asarray(nearest["rotation"])
    yaw = np.degrees(np.arctan2(R0[1, 0], R0[0, 0]))
    message = (
        f"{source}: a world-frame HSMM learnt with the scene at "
        f"{np.round(nearest['position'], 3).tolist()} m, yaw {yaw:.1f} deg, reproduced with "
        f"the {describe_placement(scenario)}: it reproduces the task where it was learnt, and "
        f"is checked where the scene is now (demonstrate at several placements for a TP-HSMM)"
    )
    warnings.warn(message, stacklevel=3)
    return message
