"""A human-like demonstrator's timing: per-phase tempo, pauses, overshoot then correction, and
an idle start (``operator.style: human``).

A person's takes of one task differ in length (2-5x), start time, pauses, hesitations and
corrections; the scripted operator's only in a 10 % log-normal stretch of each segment. The
human style rewrites the (already perturbed) plan from uniform draws, held in the operator's
Context by a Drake ``RandomSource`` like the rest of its variability
(:class:`~hemg_drake.teleop.operator.SimulatedOperator`):

- **idle start**: the whole plan starts ``idle_range`` later (uniform), the hand resting at
  its first point;
- **tempo**: each segment's speed is the take's tempo (log-uniform in ``tempo_range``) times
  the phase's own (log-uniform in [1 / phase_spread, phase_spread]), clipped to
  ``tempo_range``; its duration is divided by that speed;
- **pauses**: at each inner waypoint, with probability ``pause_probability``, a hold of
  ``pause_range`` seconds (uniform) in the kind, pen state and effort of the segment it ends;
- **overshoot then correction**: a free move in the air (not pen-down, not descending onto a
  pen-down segment) overshoots its end, with probability ``overshoot_probability``, by a
  fraction ``overshoot_range`` (uniform) of its displacement, at most ``max_overshoot`` m,
  then moves back in ``correction_time`` seconds.

Plans and numbers only (numpy); the draws' layout is :func:`human_draw_count`'s.
"""

import math

import numpy as np

from hemg_drake._validate import as_seed
from hemg_drake.tasks.plan import TaskPlan

# Each segment's draws: phase tempo, pause or not, pause length, overshoot or not, its size.
_PER_SEGMENT = 5
# The take's draws ahead of them: idle start, take tempo.
_PER_TAKE = 2
# The human draws' own stream of a seed (numpy's SeedSequence entropy [seed, this]): the
# scripted draws of the same seed are unchanged.
HUMAN_STREAM = 24


def human_draw_count(plan):
    """Number of uniform draws the human style takes for ``plan``: 2 + 5 per segment."""
    return _PER_TAKE + _PER_SEGMENT * len(plan.kinds)


def human_draws(plan, seed):
    """The uniform draws in [0, 1) of demonstration ``seed`` (numpy's ``default_rng`` on the
    entropy [seed, HUMAN_STREAM]): what :func:`set_operator_seed` puts in the Context."""
    rng = np.random.default_rng([as_seed(seed), HUMAN_STREAM])
    return rng.random(human_draw_count(plan))


def _overshoot_allowed(plan, i):
    """A free move in the air whose next segment does not put the pen down."""
    nxt = i + 1 < len(plan.kinds) and plan.pen_down[i + 1]
    return plan.kinds[i] == "free" and not plan.pen_down[i] and not nxt


def tempos(plan, uniforms, style):
    """Each segment's speed factor (the duration is divided by it), in ``style.tempo_range``."""
    low, high = (math.log(x) for x in style.tempo_range)
    per = np.asarray(uniforms, float)[_PER_TAKE:].reshape(-1, _PER_SEGMENT)
    take = low + (high - low) * float(uniforms[1])
    local = math.log(style.phase_spread) * (2.0 * per[:, 0] - 1.0)
    return np.exp(np.clip(take + local, low, high))


def humanised(plan, uniforms, style):
    """``plan`` as a person would take it, from uniform draws (see the module docstring).

    Parameters
    ----------
    plan : TaskPlan, the plan to rewrite (e.g. already perturbed).
    uniforms : array, shape (human_draw_count(plan),), draws in [0, 1).
    style : HumanStyleConfig

    Returns
    -------
    TaskPlan: the same waypoints in order, with holds and overshoot-correction waypoints
    inserted, later by the idle start.
    """
    uniforms = np.asarray(uniforms, float)
    n = len(plan.kinds)
    if uniforms.shape != (human_draw_count(plan),):
        raise ValueError(
            f"the human style takes {human_draw_count(plan)} uniform draws, got {uniforms.shape}"
        )
    per = uniforms[_PER_TAKE:].reshape(n, _PER_SEGMENT)
    durations = np.diff(plan.times) / tempos(plan, uniforms, style)
    idle_low, idle_high = style.idle_range
    pause_low, pause_high = style.pause_range
    over_low, over_high = style.overshoot_range
    t = plan.start_time + idle_low + (idle_high - idle_low) * uniforms[0]
    times, points, kinds, pen_down, effort = [t], [plan.points[0]], [], [], []

    def go(point, duration, kind, down, level):
        times.append(times[-1] + duration)
        points.append(np.asarray(point, float))
        kinds.append(kind)
        pen_down.append(down)
        effort.append(level)

    for i in range(n):
        kind, down, level = plan.kinds[i], plan.pen_down[i], float(plan.effort[i])
        end = plan.points[i + 1]
        if _overshoot_allowed(plan, i) and per[i, 3] < style.overshoot_probability:
            step = end - plan.points[i]
            over = step * (over_low + (over_high - over_low) * per[i, 4])
            norm = float(np.linalg.norm(over))
            if norm > style.max_overshoot:
                over *= style.max_overshoot / norm
            go(end + over, durations[i], kind, down, level)
            go(end, style.correction_time, kind, down, level)
        else:
            go(end, durations[i], kind, down, level)
        if i < n - 1 and per[i, 1] < style.pause_probability:
            go(end, pause_low + (pause_high - pause_low) * per[i, 2], kind, down, level)
    return TaskPlan(np.array(times), np.array(points), tuple(kinds), tuple(pen_down),
                    np.array(effort))  # fmt: skip
