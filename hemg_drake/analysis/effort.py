"""The shared-control study's measures from a demonstration's interaction log
(:func:`~hemg_drake.diagrams.demonstration.interaction_signals`): the operator's effort,
the operator-policy disagreement, how early the online phase is right, the passivity
observer's energy and whether the visual operator gave up."""

import numpy as np


def _integral(time, values):
    """Trapezoidal integral of ``values`` (T,) over ``time`` (T,)."""
    time, values = np.asarray(time, float), np.asarray(values, float)
    if len(time) < 2:
        return 0.0
    return float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(time)))


def hand_impulse(time, hand_force):
    """The integral of |F_h| over time (N s): the hand's effort on the stylus."""
    return _integral(time, np.linalg.norm(hand_force, axis=1))


def hand_work(time, hand_force, v_MS):
    """The hand's positive work on the stylus, the integral of max(F_h . v_MS, 0) (J): what
    the operator puts into the master (work the device does on the hand is not effort
    returned)."""
    power = np.sum(np.asarray(hand_force) * np.asarray(v_MS), axis=1)
    return _integral(time, np.maximum(power, 0.0))


def disagreement(command, policy):
    """Mean over time of |p_command - x_policy| (m): how far the operator's command (as the
    slave receives it) and the learnt policy's point lie apart."""
    return float(np.mean(np.linalg.norm(np.asarray(command) - np.asarray(policy), axis=1)))


def phase_lags(time, online, offline):
    """For each change of the offline state to s at t_off: t_on - t_off, t_on when the
    online phase first became s after the previous offline change (s; negative: the
    estimate was right early; NaN: never before the next change)."""
    online, offline = np.asarray(online), np.asarray(offline)
    lags = []
    changes = np.flatnonzero(np.diff(offline)) + 1
    for k, start in enumerate(changes):
        since = changes[k - 1] if k else 0
        end = changes[k + 1] if k + 1 < len(changes) else len(offline)
        hits = np.flatnonzero(online[since:end] == offline[start])
        lags.append(time[since + hits[0]] - time[start] if len(hits) else np.nan)
    return np.array(lags, dtype=float)


def viterbi_free_durations(log_emission, log_start, log_transitions):
    """The most likely state path with the transitions' probabilities between states and a
    free stay in a state (log self-transition 0, whatever the matrix says).

    Parameters
    ----------
    log_emission : (T, N); log_start : (N,); log_transitions : (N, N), row i to column j.

    Returns
    -------
    array of int (T,)
    """
    log_emission = np.asarray(log_emission, float)
    moves = np.array(log_transitions, float)
    np.fill_diagonal(moves, 0.0)
    T, N = log_emission.shape
    score = np.asarray(log_start, float) + log_emission[0]
    back = np.zeros((T, N), dtype=int)
    for t in range(1, T):
        candidates = score[:, None] + moves  # from i (rows) to j (columns)
        back[t] = np.argmax(candidates, axis=0)
        score = candidates[back[t], np.arange(N)] + log_emission[t]
    path = np.zeros(T, dtype=int)
    path[-1] = int(np.argmax(score))
    for t in range(T - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


def offline_states(model, observations):
    """The model's state sequence of a recorded motion (its ``[x, xdot, k]`` observations),
    with the operator's own durations: :func:`viterbi_free_durations` on the model's
    emissions, start and transition probabilities. (The HSMM's smoothed posterior cannot
    explain an operator who waits longer than the demonstrations it learnt from.)"""
    from hemg_drake.learning.gmr import gaussian_log_pdf

    with np.errstate(divide="ignore"):
        return viterbi_free_durations(
            gaussian_log_pdf(np.asarray(observations), model.means_, model.covariances_),
            np.log(model.startprob_), np.log(model.transmat_),
        )


def interaction_metrics(signals, demo, model=None):
    """The study's measures of one demonstration.

    Parameters
    ----------
    signals : dict name -> array (T, width), :func:`interaction_signals`'s (``time``,
        ``hand_force``, ``v_MS``, optionally ``passivity_energy``, ``visual_state``,
        ``assist.phase``, ``assist.x_policy``).
    demo : Demonstration (its ``p_WE_desired``, the command as the slave received it, on
        the same log grid).
    model : HSMM or None, the assist's model, for the offline state sequence.

    Returns
    -------
    dict: ``hand_impulse_n_s``, ``hand_work_j``, and when logged ``passivity_energy_min_j``,
    ``gave_up`` (0/1), ``held_s`` (time the plan clock stood still), ``disagreement_m``,
    ``phase_lag_s`` (mean over the model's transitions, negative: early) and
    ``phase_missed`` (fraction of transitions the online phase never matched).
    """
    time = np.asarray(signals["time"], float).reshape(-1)
    result = {
        "hand_impulse_n_s": hand_impulse(time, signals["hand_force"]),
        "hand_work_j": hand_work(time, signals["hand_force"], signals["v_MS"]),
    }
    if "passivity_energy" in signals:
        result["passivity_energy_min_j"] = float(np.min(signals["passivity_energy"]))
    if "visual_state" in signals:
        from hemg_drake.teleop.visual import GAVE_UP, S

        last = signals["visual_state"][-1]
        result["gave_up"] = float(last[GAVE_UP] > 0)
        result["held_s"] = float(time[-1] - last[S])
    if "assist.x_policy" in signals:
        n = min(len(demo.time), len(signals["assist.x_policy"]))
        result["disagreement_m"] = disagreement(
            demo.p_WE_desired[:n], signals["assist.x_policy"][:n]
        )
    if "assist.phase" in signals and model is not None:
        from hemg_drake.learning.demos import observations

        offline = offline_states(model, observations([demo])[0])
        online = signals["assist.phase"][:, 0].astype(int)[: len(offline)]
        lags = phase_lags(demo.time, online, offline[: len(online)])
        if len(lags):
            found = lags[np.isfinite(lags)]
            result["phase_lag_s"] = float(found.mean()) if len(found) else float("nan")
            result["phase_missed"] = float(np.mean(~np.isfinite(lags)))
    return result
