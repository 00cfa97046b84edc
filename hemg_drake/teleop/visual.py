"""An operator who acts on what it sees (``operator.visual``): the laws, in plain numbers.

The scripted operator follows its plan in time whatever it sees, so a transport delay only
lags the slave. A person under delay sees the slave late (the channel's slave-to-master
delay plus a visuomotor reaction time of ~0.2 s), waits to see a move completed before the
next one (move and wait, Ferrell 1965), corrects the error it sees, and gives up when the
tool does not get where it should. The law here, one update every ``period`` seconds:

- **plan clock** s: advances with time, except at an inner waypoint t_i of the plan, where
  it holds until the operator has seen the tool within ``tolerance`` of that waypoint for
  ``dwell`` seconds (the seen position, p_seen = the tool point ``reaction_time`` + the
  channel's delay ago, mapped into M);
- **correction** c (m, in M), the integral of the seen error beyond the tolerance (a dead
  zone: what the operator cannot see it does not correct),
  c' = w_c e (1 - tol / |e|)+,  e = p_plan(s) - p_seen, |c| <= ``max_correction``;
  with the crossover model's gain w_c and the reaction time alone the loop
  w_c e^{-s tau} / s keeps a phase margin of 90 - w_c tau (rad -> deg) ~ 44 deg; the
  channel's round trip adds to tau, and beyond w_c (tau + 2T) = pi / 2 the correction
  oscillates (bounded by ``max_correction``);
- **patience**: held at one waypoint longer than ``patience`` seconds, the operator lets go
  for good (no hand force, muscles at rest);
- **tremor**: A sin(2 pi f t + phi_k) on each axis of the hand's target, f and phi_k from
  seeded uniform draws (:func:`visual_draws`);
- **efference copy** (``efference_copy``, a Smith predictor): the operator keeps what it
  sent, (s, c), for the loop's whole latency L (command delay + video delay + reaction
  time) and compares the tool it sees with the command (s_L, c_L) sent L ago, counting the
  corrections sent since as under way: e = p_plan(s_L) - p_seen - (c - c_L). A move seen
  late is then no error, and with the slave following, c' = w_c (m - c) for a steady miss m
  (a contact, the tracker's offset): first order, no delay left in the loop;
- **on the paper** (pen-down segments, given the sheet's normal n in M): the operator sees
  where the pen is on the sheet, not how deep it presses (that it feels), so the error it
  sees is e - (e . n) n: the correction ignores the depth (and drops what it had of it when
  the pen goes down), and a waypoint between two pen-down
  segments counts as reached where the pen is seen on the sheet (without it the plan's
  press 3 mm under the paper, where the pen cannot go, is an error the operator never
  closes, pushing deeper until it gives up).

The hand then pulls the stylus toward p_plan(s) + c + tremor with its impedance
(:func:`~hemg_drake.teleop.operator.hand_impedance_force`).
"""

import math

import numpy as np

from hemg_drake._validate import as_seed

# The visual state: plan clock s, correction c (3), time held at the waypoint, time seen
# settled there, given up (0 or 1).
STATE_SIZE = 7
S, C, WAIT, SETTLED, GAVE_UP = 0, slice(1, 4), 4, 5, 6
# Draws: tremor frequency, phase per axis.
DRAW_COUNT = 4
# The visual draws' own stream of a seed (numpy's SeedSequence entropy [seed, this]).
VISUAL_STREAM = 26


def visual_draws(seed):
    """The uniform draws in [0, 1) of demonstration ``seed`` for the tremor."""
    return np.random.default_rng([as_seed(seed), VISUAL_STREAM]).random(DRAW_COUNT)


def delay_samples(config, video_delay, period):
    """Samples of the seen tool point's delay: (video delay + reaction time) / period, >= 1."""
    return max(1, int(round((video_delay + config.reaction_time) / period)))


def loop_samples(config, command_delay, video_delay, period):
    """Samples of the loop's latency kept by the efference copy: the command delay plus the
    seen tool point's delay (:func:`delay_samples`)."""
    return int(round(command_delay / period)) + delay_samples(config, video_delay, period)


def initial_state(start_time=0.0):
    """The plan clock at ``start_time``, no correction, not waiting, not given up."""
    state = np.zeros(STATE_SIZE)
    state[S] = start_time
    return state


def tremor(t, draws, config):
    """The tremor's offset (m, 3) at time ``t`` from the draws (see the module docstring)."""
    amplitude = config.tremor_amplitude
    if amplitude == 0:
        return [0.0, 0.0, 0.0]
    low, high = config.tremor_frequency
    frequency = low + (high - low) * float(draws[0])
    return [amplitude * math.sin(2.0 * math.pi * (frequency * t + float(phase)))
            for phase in draws[1:4]]  # fmt: skip


def next_gate(times, s):
    """The first inner waypoint time at or after s (None past the last)."""
    for t_i in times[1:-1]:
        if t_i >= s - 1e-12:
            return float(t_i)
    return None


def on_sheet(vector, normal=None):
    """``vector`` (3) without its component along the unit ``normal`` (unchanged if None)."""
    vector = np.asarray(vector, dtype=float)
    return vector if normal is None else vector - float(vector @ normal) * normal


def visual_step(state, seen_M, plan_M, config, dt, normal_M=None, sent=None):
    """The visual state one period ``dt`` later (see the module docstring).

    Parameters
    ----------
    state : array (STATE_SIZE,)
    seen_M : 3 floats, the tool point the operator sees now, in M (m).
    plan_M : TaskPlan in M, the operator's (perturbed) plan.
    config : VisualConfig
    normal_M : unit 3-vector in M, optional; the sheet's normal (pen-down segments are
        seen on the sheet).
    sent : 4 floats, optional; with ``config.efference_copy`` (required then): the plan
        clock and the correction (3) sent the loop's latency ago.

    Returns
    -------
    array (STATE_SIZE,), a new array.
    """
    new = np.array(state, dtype=float)
    if new[GAVE_UP]:
        return new
    seen = np.asarray(seen_M, dtype=float)
    s = new[S]
    gate = next_gate(plan_M.times, s)
    if gate is not None and s + dt > gate + 1e-12:  # at (or arriving at) a waypoint
        point, _ = plan_M.position_velocity_floats(gate)
        # On the paper only between two pen-down segments: a pen put down or lifted is seen.
        both_down = plan_M.segment(gate - 1e-12).pen_down and plan_M.segment(gate).pen_down
        error = on_sheet(np.asarray(point) - seen, normal_M if both_down else None)
        reached = float(np.linalg.norm(error)) <= config.tolerance
        new[SETTLED] = new[SETTLED] + dt if reached else 0.0
        if new[SETTLED] >= config.dwell - 1e-12:
            new[S], new[WAIT], new[SETTLED] = max(s, gate) + dt, 0.0, 0.0
        else:
            new[S] = gate
            new[WAIT] += dt
            if new[WAIT] > config.patience:
                new[GAVE_UP] = 1.0
    else:
        new[S] = s + dt
    # The segment that leads to the clock: held at a stroke's end the pen is still down.
    if normal_M is not None and plan_M.segment(s - 1e-12).pen_down:
        new[C] = on_sheet(new[C], normal_M)  # the depth goes by feel: aimed deeper is dropped
    under_way = 0.0
    if config.efference_copy:
        if sent is None:
            raise ValueError("visual_step: efference_copy needs what was sent")
        s, under_way = float(sent[0]), new[C] - np.asarray(sent[1:4], dtype=float)
    target, _ = plan_M.position_velocity_floats(s)
    on_paper = normal_M if plan_M.segment(s - 1e-12).pen_down else None
    error = on_sheet(np.asarray(target) - seen - under_way, on_paper)
    norm = float(np.linalg.norm(error))
    if norm > config.tolerance:
        correction = new[C] + dt * config.gain * error * (1.0 - config.tolerance / norm)
        size = float(np.linalg.norm(correction))
        if size > config.max_correction:
            correction *= config.max_correction / size
        new[C] = correction
    return new


def visual_target(state, t, plan_M, draws, config):
    """(p_target, v_target) of the hand in M at time ``t``: the plan at the clock s, plus
    the correction and the tremor; the plan's velocity only while the clock runs. None
    once the operator has given up."""
    if state[GAVE_UP]:
        return None
    s = float(state[S])
    point, velocity = plan_M.position_velocity_floats(s)
    if state[WAIT] > 0:
        velocity = [0.0, 0.0, 0.0]
    shake = tremor(t, draws, config)
    target = [p + float(c) + d for p, c, d in zip(point, state[C], shake)]
    return target, list(velocity)
