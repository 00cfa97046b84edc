"""What a logged run did to its environment and how it met a push: forces, impulse, energy,
joint torques, tracking, and the return after a push (the stiffness study,
``docs/studies.md``).

Every figure is computed from samples logged together (every 0.01 s by the reproduction's
logger); integrals use the trapezoidal rule over the logged times.
"""

import numpy as np

from hemg_drake.analysis.contact import in_contact

# A push is answered when the tool is back within PUSH_RETURN_M of the demonstrated path
# within PUSH_RETURN_S after the push ends (issue 23's goal), and stays there for the
# PUSH_WATCH_S after the release that are looked at.
PUSH_RETURN_M = 0.005
PUSH_RETURN_S = 0.5
PUSH_WATCH_S = 1.5
# How far in time (s) from a sample the demonstrated path is searched for its nearest point:
# the reproduction's timing drifts from the demonstrations' by a few tenths of a second.
PATH_WINDOW_S = 1.0


def _norms(vectors):
    return np.linalg.norm(np.asarray(vectors, dtype=float), axis=1)


def interaction_metrics(time, p_WE, v_WE, f_WE, x_star, tau=None, f_block=None):
    """Forces on the environment, energy, joint torque and tracking of one logged run.

    Parameters
    ----------
    time : array, shape (T,), s.
    p_WE, v_WE : arrays, shape (T, 3), the tool point (m, m/s, W).
    f_WE : array, shape (T, 3), the environment's force on the tool point (N, W).
    x_star : array, shape (T, 3), the reference the station tracked (m, W).
    tau : array, shape (T, n), optional, joint torques (N m).
    f_block : array, shape (T, 3), optional, the contact force on an extra block (N, W).

    Returns
    -------
    dict: ``contact_force_peak_n`` (max |f_WE|), ``contact_force_mean_n`` (mean |f_WE|
    over the samples in contact, |f| > ``CONTACT_THRESHOLD``; 0 if none),
    ``impulse_n_s`` (the integral of |f_WE|), ``energy_j`` (the work the tool did on the
    environment, the integral of -f_WE . v_WE; negative when the environment gave energy
    back), ``tracking_error_rms_m`` and ``tracking_error_max_m`` (|p_WE - x*|),
    ``joint_torque_peak_nm`` (max |tau_j|; None without ``tau``), ``block_force_peak_n`` and
    ``block_impulse_n_s`` (None without ``f_block``), ``environment_force_peak_n`` (the
    larger of the tool's and the block's peaks).
    """
    time = np.asarray(time, dtype=float)
    force = _norms(f_WE)
    touching = in_contact(f_WE)
    power = -np.sum(np.asarray(f_WE) * np.asarray(v_WE), axis=1)
    error = _norms(np.asarray(p_WE) - np.asarray(x_star))
    record = {
        "contact_force_peak_n": float(force.max()),
        "contact_force_mean_n": float(force[touching].mean()) if touching.any() else 0.0,
        "impulse_n_s": float(np.trapezoid(force, time)),
        "energy_j": float(np.trapezoid(power, time)),
        "tracking_error_rms_m": float(np.sqrt(np.mean(error**2))),
        "tracking_error_max_m": float(error.max()),
        "joint_torque_peak_nm": None if tau is None else float(np.abs(tau).max()),
        "block_force_peak_n": None,
        "block_impulse_n_s": None,
    }
    peak = record["contact_force_peak_n"]
    if f_block is not None:
        block = _norms(f_block)
        record["block_force_peak_n"] = float(block.max())
        record["block_impulse_n_s"] = float(np.trapezoid(block, time))
        peak = max(peak, record["block_force_peak_n"])
    record["environment_force_peak_n"] = peak
    return record


def demonstrated_path(demos, duration, period=0.005):
    """The demonstrations' mean tool path on a common clock: each demonstration's p_WE
    resampled at the same fractions of its length, averaged, on times [0, duration] every
    ``period`` (s; at the tasks' speeds, under 0.3 mm between points).

    Returns
    -------
    (times (n,), points (n, 3))
    """
    fractions = np.linspace(0.0, 1.0, int(round(duration / period)) + 1)
    paths = []
    for demo in demos:
        t = (demo.time - demo.time[0]) / (demo.time[-1] - demo.time[0])
        paths.append(np.column_stack([np.interp(fractions, t, demo.p_WE[:, i]) for i in range(3)]))
    return fractions * duration, np.mean(paths, axis=0)


def path_deviation(time, p_WE, path_time, path, window=PATH_WINDOW_S):
    """Distance (m) of each sample from the nearest point of ``path`` no further than
    ``window`` seconds from it in time, shape (T,)."""
    time = np.asarray(time, dtype=float)
    p_WE = np.asarray(p_WE, dtype=float)
    deviation = np.empty(len(time))
    for i, (t, p) in enumerate(zip(time, p_WE, strict=True)):
        near = np.abs(path_time - t) <= window
        deviation[i] = _norms(path[near] - p).min() if near.any() else np.inf
    return deviation


def push_response(time, p_WE, f_push, path_time, path):
    """How the tool met a push and came back: against the demonstrated ``path``.

    The push is on while |f_push| > 0; it is released at the first sample after it.
    ``deviation_before_m`` is the largest deviation in the 0.5 s before the push (what the
    run showed unpushed), ``deviation_peak_m`` the largest from the push's start to
    ``PUSH_WATCH_S`` after its release, ``return_time_s`` the time after the release from
    which the deviation stays within ``PUSH_RETURN_M`` for the rest of that watch (0 if it
    never left; None if it never came back), and ``returned`` whether that is within
    ``PUSH_RETURN_S``.

    Returns
    -------
    dict, or None when the log shows no push.
    """
    time = np.asarray(time, dtype=float)
    on = _norms(f_push) > 0
    if not on.any():
        return None
    start, end = time[on][0], time[on][-1]
    released = time > end
    release = float(time[released][0]) if released.any() else float(end)
    deviation = path_deviation(time, p_WE, path_time, path)
    before = (time >= start - 0.5) & (time < start)
    during = (time >= start) & (time <= release + PUSH_WATCH_S)
    watch = (time >= release) & (time <= release + PUSH_WATCH_S)
    outside = np.flatnonzero(watch & (deviation > PUSH_RETURN_M))
    if outside.size == 0:
        back = 0.0
    elif outside[-1] + 1 < len(time) and watch[outside[-1] + 1]:
        back = float(time[outside[-1] + 1] - release)
    else:
        back = None
    return {
        "start_s": float(start),
        "release_s": release,
        "deviation_before_m": float(deviation[before].max()) if before.any() else None,
        "deviation_peak_m": float(deviation[during].max()),
        "return_time_s": back,
        "returned": back is not None and back <= PUSH_RETURN_S,
        "limits": {"return_m": PUSH_RETURN_M, "return_s": PUSH_RETURN_S},
    }
