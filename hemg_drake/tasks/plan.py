"""Task plans: timed waypoints in the slave's task space, with seeded human variability."""

import bisect
import dataclasses as dc
import math

import numpy as np

from hemg_drake._validate import as_scalar, as_seed

SEGMENT_KINDS = ("free", "forceful")
_FIELDS = ("times", "points", "kinds", "pen_down", "effort")


@dc.dataclass(frozen=True)
class Segment:
    """What the plan asks for between two waypoints.

    Attributes
    ----------
    index : int
        Segment number, 0 .. n_segments - 1 (segment i runs from waypoint i to i + 1).
    kind : str
        ``"free"`` motion or ``"forceful"`` work against the environment.
    pen_down : bool
        For drawing: the pen should touch the paper.
    effort : float
        How hard the operator works in this segment, relative to nominal (1.0).
    """

    index: int
    kind: str
    pen_down: bool
    effort: float


def _field_array(name, value, dtype=float):
    try:
        return np.array(value, dtype=dtype)
    except (TypeError, ValueError) as error:
        raise ValueError(f"TaskPlan field '{name}' must hold numbers: {error}") from None


def _minimum_jerk(tau):
    """Minimum-jerk profile s(tau) and its derivative ds/dtau, tau in [0, 1]."""
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    return s, ds


def _per_point(value):
    """A float as is; an array of values gains an axis to scale (..., 3) points."""
    return value if isinstance(value, float) else value[..., None]


@dc.dataclass(frozen=True, eq=False)
class TaskPlan:
    """Timed waypoints of the slave end-effector, each segment free or forceful.

    Between waypoints the plan follows a minimum-jerk profile (Flash and Hogan's model of
    human point-to-point reaching), so position, velocity and acceleration are continuous
    and the velocity is zero at every waypoint. Before the first time and after the last
    the plan holds the end points.

    Parameters
    ----------
    times : array, shape (n,)
        Waypoint times (s), strictly increasing, n >= 2.
    points : array, shape (n, 3)
        Waypoints p_WE in the world frame (m).
    kinds : sequence of str, length n - 1
        ``"free"`` or ``"forceful"`` for each segment.
    pen_down : sequence of bool, length n - 1, optional
        Whether the pen should touch the paper in each segment (default all False).
    effort : array, shape (n - 1,), optional
        Effort scale per segment, > 0 (default all 1).

    Raises
    ------
    ValueError
        Naming the field at fault: wrong size, NaN, non-increasing times, unknown kind.
    """

    times: np.ndarray
    points: np.ndarray
    kinds: tuple
    pen_down: tuple = None
    effort: np.ndarray = None

    def __post_init__(self):
        times = _field_array("times", self.times)
        if times.ndim != 1 or times.size < 2:
            raise ValueError(
                f"TaskPlan field 'times' must be a list of at least 2 numbers, "
                f"got shape {times.shape}"
            )
        n = times.size
        points = _field_array("points", self.points)
        if points.shape != (n, 3):
            raise ValueError(
                f"TaskPlan field 'points' must have shape ({n}, 3) (one [x, y, z] per "
                f"time), got {points.shape}"
            )
        for name, array in (("times", times), ("points", points)):
            bad = np.argwhere(~np.isfinite(array))
            if bad.size:
                index = bad[0].tolist()
                raise ValueError(f"TaskPlan field '{name}' is not finite at index {index}")
        steps = np.diff(times)
        if np.any(steps <= 0):
            i = int(np.argmax(steps <= 0)) + 1
            raise ValueError(
                f"TaskPlan field 'times' must be strictly increasing: times[{i}] = "
                f"{times[i]} follows times[{i - 1}] = {times[i - 1]}"
            )
        kinds = tuple(self.kinds) if not isinstance(self.kinds, str) else (self.kinds,)
        if len(kinds) != n - 1:
            raise ValueError(
                f"TaskPlan field 'kinds' must have {n - 1} entries (one per segment), "
                f"got {len(kinds)}"
            )
        for i, kind in enumerate(kinds):
            if kind not in SEGMENT_KINDS:
                raise ValueError(
                    f"TaskPlan field 'kinds'[{i}] = {kind!r} is not one of {SEGMENT_KINDS}"
                )
        pen_down = (False,) * (n - 1) if self.pen_down is None else tuple(self.pen_down)
        if len(pen_down) != n - 1 or not all(isinstance(f, (bool, np.bool_)) for f in pen_down):
            raise ValueError(
                f"TaskPlan field 'pen_down' must be {n - 1} booleans (one per segment), "
                f"got {list(pen_down)}"
            )
        effort = np.ones(n - 1) if self.effort is None else _field_array("effort", self.effort)
        if effort.shape != (n - 1,) or not np.all(np.isfinite(effort) & (effort > 0)):
            raise ValueError(
                f"TaskPlan field 'effort' must be {n - 1} positive numbers (one per "
                f"segment), got {effort.tolist()}"
            )
        times.flags.writeable = points.flags.writeable = effort.flags.writeable = False
        values = (times, points, kinds, tuple(map(bool, pen_down)), effort)
        for name, value in zip(_FIELDS, values, strict=True):
            object.__setattr__(self, name, value)
        # Cached for the 1 kHz path: times for bisect, each segment's displacement (also as
        # lists of floats, for position_velocity_floats).
        object.__setattr__(self, "_times", times.tolist())
        object.__setattr__(self, "_steps", np.diff(points, axis=0))
        object.__setattr__(self, "_point_lists", points.tolist())
        object.__setattr__(self, "_step_lists", self._steps.tolist())

    @classmethod
    def from_dict(cls, data):
        """Build a plan from plain data (as read from YAML): a mapping of the fields.

        Parameters
        ----------
        data : dict
            Keys ``times``, ``points``, ``kinds`` and optionally ``pen_down``, ``effort``,
            each a list (of floats, [x, y, z] lists, strings, booleans).
        """
        if not isinstance(data, dict):
            raise ValueError(
                f"TaskPlan data must be a mapping of {_FIELDS}, got {type(data).__name__}"
            )
        unknown = sorted(set(data) - set(_FIELDS))
        if unknown:
            raise ValueError(f"TaskPlan has unknown field(s) {unknown}; expected {_FIELDS}")
        missing = [name for name in _FIELDS[:3] if name not in data]
        if missing:
            raise ValueError(f"TaskPlan is missing field(s) {missing}")
        return cls(**data)

    def to_dict(self):
        """Plain data (lists) that :meth:`from_dict` reads back to the same plan."""
        return dict(
            times=self.times.tolist(),
            points=self.points.tolist(),
            kinds=list(self.kinds),
            pen_down=list(self.pen_down),
            effort=self.effort.tolist(),
        )

    @property
    def start_time(self):
        return float(self.times[0])

    @property
    def end_time(self):
        return float(self.times[-1])

    def _locate(self, t):
        """Segment index, phase tau in [0, 1] and segment duration for times t (any shape).

        Scalars take a plain-float path: it runs at the 1 kHz haptic rate, where numpy's
        per-call overhead on 0-d arrays would dominate.
        """
        last = len(self.kinds) - 1
        if isinstance(t, (float, int)):
            if not math.isfinite(t):
                raise ValueError(f"TaskPlan time must be finite, got {t}")
            index = min(max(bisect.bisect_right(self._times, t) - 1, 0), last)
            start, end = self._times[index], self._times[index + 1]
            return index, min(max((t - start) / (end - start), 0.0), 1.0), end - start
        t = np.asarray(t, dtype=float)
        if not np.isfinite(t).all():
            raise ValueError(f"TaskPlan time must be finite, got {t}")
        index = np.minimum(np.maximum(np.searchsorted(self.times, t, side="right") - 1, 0), last)
        duration = self.times[index + 1] - self.times[index]
        tau = np.minimum(np.maximum((t - self.times[index]) / duration, 0.0), 1.0)
        return index, tau, duration

    def position(self, t):
        """Planned p_WE at time t (s): shape (3,) for a scalar t, (..., 3) for an array."""
        index, tau, _ = self._locate(t)
        s, _ = _minimum_jerk(tau)
        return self.points[index] + self._steps[index] * _per_point(s)

    def velocity(self, t):
        """Planned v_WE at time t (m/s), shaped like :meth:`position`; zero outside the plan."""
        index, tau, duration = self._locate(t)
        _, ds = _minimum_jerk(tau)
        return self._steps[index] * _per_point(ds / duration)

    def position_velocity_floats(self, t):
        """:meth:`position` and :meth:`velocity` at scalar time t, as two lists of 3 floats.

        One segment lookup for both, on plain floats (the 1 kHz operator's path); the same
        arithmetic as the two methods, so the same numbers to the bit.
        """
        index, tau, duration = self._locate(float(t))
        s, ds = _minimum_jerk(tau)
        rate = ds / duration
        step = self._step_lists[index]
        position = [p + d * s for p, d in zip(self._point_lists[index], step)]
        return position, [d * rate for d in step]

    def in_frame(self, points):
        """This plan with its waypoints replaced by ``points`` (n, 3), e.g. mapped to a frame.

        Minimum-jerk interpolation commutes with an affine map, so mapping the waypoints
        maps the whole plan: ``plan.in_frame(f(plan.points)).position(t) == f(plan.position(t))``
        for affine f, to rounding.
        """
        return dc.replace(self, points=points)

    def segment(self, t):
        """The :class:`Segment` in force at scalar time t (the first/last outside the plan)."""
        index = int(self._locate(float(t))[0])
        return Segment(index, self.kinds[index], self.pen_down[index], float(self.effort[index]))

    def perturbed(self, seed, *, timing_std=0.1, path_std=0.003, effort_std=0.1):
        """A plausible human variation of this plan; the same seed gives the same plan.

        Parameters
        ----------
        seed : int
            Seed of ``np.random.default_rng``.
        timing_std : float
            Each segment's duration is stretched by exp(timing_std * N(0, 1)) (the start
            time is kept).
        path_std : float or array, shape (3,)
            Standard deviation (m) of a smooth spatial offset, per world axis (give 0 for an
            axis that must not move, e.g. the pen's height on the paper). The offset of a
            waypoint at normalised time u in [0, 1] is a constant plus two slow sines,
            path_std * (c0 + c1 sin(pi u + phi1) + c2 sin(2 pi u + phi2)) / sqrt(2), with
            c ~ N(0, 1) and phi ~ U(0, 2 pi) per axis: a shift and a gentle bend of the whole
            path.
        effort_std : float
            Each segment's effort is scaled by exp(effort_std * N(0, 1)).

        Returns
        -------
        TaskPlan
        """
        return self.perturbed_by(
            *self.perturbation_draws(seed),
            timing_std=timing_std, path_std=path_std, effort_std=effort_std,
        )  # fmt: skip

    def perturbation_draws(self, seed):
        """The draws (normals, uniforms) of :meth:`perturbed_by` that :meth:`perturbed` makes
        from ``seed`` (``np.random.default_rng``), in the order it has always drawn them."""
        rng = np.random.default_rng(as_seed(seed))
        n_segments = len(self.kinds)
        timing = rng.standard_normal(n_segments)
        c = rng.standard_normal((3, 3))
        phase = rng.random((2, 3))
        effort = rng.standard_normal(n_segments)
        return np.concatenate([timing, c.ravel(), effort]), phase.ravel()

    def perturbation_sizes(self):
        """(number of standard normal draws, number of uniform draws) of :meth:`perturbed_by`."""
        return 2 * len(self.kinds) + 9, 6

    def perturbed_by(self, normals, uniforms, *, timing_std, path_std, effort_std):
        """:meth:`perturbed` from given draws (e.g. a Drake ``RandomSource``'s), not a seed.

        Parameters
        ----------
        normals : array, shape (2 n_segments + 9,)
            Standard normal draws: n_segments for the timing, 9 for the path's c (3 x 3,
            row-major), n_segments for the effort.
        uniforms : array, shape (6,)
            Uniform draws in [0, 1): the two phases of each axis (2 x 3, row-major), as
            fractions of 2 pi.
        timing_std, path_std, effort_std
            As :meth:`perturbed`. All draws zero: this plan unchanged.
        """
        timing_std = as_scalar("timing_std", timing_std, strict=False)
        effort_std = as_scalar("effort_std", effort_std, strict=False)
        path_std = np.broadcast_to(_field_array("path_std", path_std), (3,))
        if not np.all(np.isfinite(path_std) & (path_std >= 0)):
            raise ValueError(
                f"path_std must be finite and >= 0 (a number or 3 numbers), got {path_std.tolist()}"
            )
        n_segments = len(self.kinds)
        sizes = self.perturbation_sizes()
        normals, uniforms = np.asarray(normals, float), np.asarray(uniforms, float)
        if normals.shape != (sizes[0],) or uniforms.shape != (sizes[1],):
            raise ValueError(
                f"perturbed_by takes {sizes[0]} normal and {sizes[1]} uniform draws, got "
                f"{normals.shape} and {uniforms.shape}"
            )
        durations = np.diff(self.times) * np.exp(timing_std * normals[:n_segments])
        times = self.times[0] + np.concatenate([[0.0], np.cumsum(durations)])
        u = ((self.times - self.times[0]) / (self.times[-1] - self.times[0]))[:, None]
        c = normals[n_segments : n_segments + 9].reshape(3, 3)
        phase = 0.0 + 2.0 * np.pi * uniforms.reshape(2, 3)
        bend = c[0] + c[1] * np.sin(np.pi * u + phase[0]) + c[2] * np.sin(2 * np.pi * u + phase[1])
        points = self.points + path_std * bend / np.sqrt(2.0)
        effort = self.effort * np.exp(effort_std * normals[n_segments + 9 :])
        return TaskPlan(times, points, self.kinds, self.pen_down, effort)
