"""Master-to-slave workspace map: scale, rotation and offset, with an optional transport delay."""

import dataclasses as dc

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import as_scalar, as_vector

# The operator stands behind the robot and faces the way it faces, so the device's
# right (+x_M) is the robot's right (-y_W), up (+y_M) is up (+z_W), and towards the
# operator (+z_M) is backwards (-x_W). Roll-pitch-yaw (90, 0, -90) degrees, written exactly.
R_WM_BEHIND_ROBOT = RotationMatrix(np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))


@dc.dataclass(frozen=True, eq=False)
class WorkspaceMapping:
    """Map points, velocities and forces between the master frame M and the world W.

    A stylus-tip point p_MS maps to the slave's desired end-effector point
    p_WE = p_WMo + scale * R_WM p_MS (m), velocities by scale * R_WM. Forces go back the
    other way with the transpose rotation and the *inverse* scale, f_M = R_WM^T f_W / scale:
    a slave that moves ``scale`` times further than the hand has its forces felt ``scale``
    times smaller, which keeps slave forces of up to scale x 7.9 N within the Touch X's peak
    force. (This is not the power-preserving choice, which would multiply by ``scale``;
    :class:`~hemg_drake.teleop.feedback.ForceFeedback` adds its own gain on top.)

    Parameters
    ----------
    scale : float
        Slave metres per master metre, > 0.
    R_WM : RotationMatrix or array, shape (3, 3)
        Orientation of M in W. The default puts the operator behind the robot, facing the
        way it faces.
    p_WMo : array, shape (3,)
        Slave point (in W, m) when the stylus tip is at M's origin, the workspace centre.

    All methods take one vector, shape (3,), or a batch, shape (n, 3), and return the same
    shape.
    """

    scale: float = 1.0
    R_WM: RotationMatrix = R_WM_BEHIND_ROBOT
    p_WMo: np.ndarray = dc.field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        scale = as_scalar("scale", self.scale)
        R = self.R_WM.matrix() if isinstance(self.R_WM, RotationMatrix) else self.R_WM
        R = np.asarray(R, dtype=float)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(f"R_WM must be a finite 3x3 rotation, got shape {R.shape}")
        if not (np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0):
            raise ValueError(f"R_WM must be a rotation (orthonormal, det +1), got {R.tolist()}")
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "R_WM", RotationMatrix(R))
        object.__setattr__(self, "_R", R)  # numpy copy: the maps run at 1 kHz
        object.__setattr__(self, "p_WMo", as_vector("p_WMo", self.p_WMo, 3))
        # Plain-float copies for the *_floats maps, which run once per 1 kHz sample.
        object.__setattr__(self, "_R_rows", R.tolist())
        object.__setattr__(self, "_RT_rows", R.T.tolist())
        object.__setattr__(self, "_p_WMo_list", self.p_WMo.tolist())

    def _rotate_to_world(self, vectors_M):
        return np.asarray(vectors_M, dtype=float) @ self._R.T

    def _rotate_to_master(self, vectors_W):
        return np.asarray(vectors_W, dtype=float) @ self._R

    def master_to_slave(self, p_MS):
        """Stylus point in M (m) -> desired slave point in W (m)."""
        return self.p_WMo + self.scale * self._rotate_to_world(p_MS)

    def slave_to_master(self, p_WE):
        """Slave point in W (m) -> the stylus point in M that maps onto it (m)."""
        return self._rotate_to_master(np.asarray(p_WE, dtype=float) - self.p_WMo) / self.scale

    def velocity_to_slave(self, v_MS):
        """Stylus velocity in M (m/s) -> slave velocity in W (m/s)."""
        return self.scale * self._rotate_to_world(v_MS)

    def velocity_to_master(self, v_WE):
        """Slave velocity in W (m/s) -> stylus velocity in M (m/s)."""
        return self._rotate_to_master(v_WE) / self.scale

    def force_to_master(self, f_W):
        """Slave force in W (N) -> force felt on the stylus, in M (N): R_WM^T f_W / scale."""
        return self._rotate_to_master(f_W) / self.scale

    def master_to_slave_floats(self, p_MS):
        """:meth:`master_to_slave` on a list of 3 floats, returning one (equal to rounding).

        Plain floats: at 1 kHz numpy's per-call overhead on 3-vectors costs more than the
        arithmetic.
        """
        x, y, z = p_MS
        scale = self.scale
        return [
            o + scale * (r0 * x + r1 * y + r2 * z)
            for o, (r0, r1, r2) in zip(self._p_WMo_list, self._R_rows)
        ]

    def force_to_master_floats(self, f_W, gain=1.0):
        """``gain`` times :meth:`force_to_master` on a list of 3 floats, returning one."""
        x, y, z = f_W
        factor = gain / self.scale
        return [factor * (r0 * x + r1 * y + r2 * z) for r0, r1, r2 in self._RT_rows]

    def force_to_slave(self, f_M):
        """Stylus force in M (N) -> the slave force in W that maps onto it (N)."""
        return self.scale * self._rotate_to_world(f_M)


class WorkspaceMap(LeafSystem):
    """The master's stylus motion mapped into the slave's desired end-effector motion.

    .. pydrake_system::

        name: WorkspaceMap
        input_ports:
        - p_MS
        - v_MS
        output_ports:
        - p_WE_desired
        - v_WE_desired

    Ports: ``p_MS`` (3, m) and ``v_MS`` (3, m/s) the stylus tip in M; ``p_WE_desired``
    (3, m) and ``v_WE_desired`` (3, m/s) the slave end-effector target in W, by
    :class:`WorkspaceMapping` (``mapping``).

    Timing: with ``delay_steps`` = 0 (default) the map is memoryless (direct feedthrough).
    With ``delay_steps`` = n > 0 it models a constant transport delay of the teleoperation
    channel: a FIFO of n samples in discrete state, shifted by a periodic update every
    ``period`` (s). For an input held between sample instants on the same grid (the
    :class:`~hemg_drake.teleop.master.HapticMaster`'s outputs), the output at time t is
    exactly the mapped input at t - n * period; before the first n samples it is the map of
    ``p_MS_initial`` at rest. (Drake's ``DiscreteTimeDelay`` with n steps samples and holds
    its input first, so on such an input it delays by n + 1 periods.)
    """

    def __init__(self, *, mapping, delay_steps=0, period=1e-3, p_MS_initial=(0.0, 0.0, 0.0)):
        LeafSystem.__init__(self)
        if not isinstance(mapping, WorkspaceMapping):
            raise ValueError(f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}")
        try:
            steps = int(delay_steps)
        except (TypeError, ValueError, OverflowError):  # None, "two", NaN, inf
            steps = -1
        if steps != delay_steps or steps < 0:
            raise ValueError(f"delay_steps must be a non-negative integer, got {delay_steps!r}")
        self.mapping = mapping
        self.delay_steps = steps
        self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
        self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
        if self.delay_steps == 0:
            prerequisites = {self.all_input_ports_ticket()}
        else:
            p_initial = as_vector("p_MS_initial", p_MS_initial, 3)
            at_rest = np.concatenate([p_initial, np.zeros(3)])
            # The FIFO holds n master samples [p_MS; v_MS], oldest first; the oldest is output.
            self.DeclareDiscreteState(np.tile(at_rest, self.delay_steps))
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=as_scalar("period", period), offset_sec=0.0, update=self._update
            )
            prerequisites = {self.xd_ticket()}
        self._p_WE_desired_output = self.DeclareVectorOutputPort(
            "p_WE_desired", 3, self._calc_p_WE_desired, prerequisites_of_calc=prerequisites
        )
        self._v_WE_desired_output = self.DeclareVectorOutputPort(
            "v_WE_desired", 3, self._calc_v_WE_desired, prerequisites_of_calc=prerequisites
        )

    def _master_sample(self, context, port, rows):
        """``port``'s value on the output side: the current input, or the FIFO's oldest."""
        if self.delay_steps == 0:
            return port.Eval(context)
        return context.get_discrete_state_vector().value()[rows]

    def _update(self, context, discrete_state):
        fifo = context.get_discrete_state_vector().value()
        newest = np.concatenate(
            [
                as_vector("p_MS", self._p_MS_input.Eval(context), 3),
                as_vector("v_MS", self._v_MS_input.Eval(context), 3),
            ]
        )
        discrete_state.set_value(np.concatenate([fifo[6:], newest]))

    def _calc_p_WE_desired(self, context, output):
        p_MS = self._master_sample(context, self._p_MS_input, slice(0, 3))
        output.SetFromVector(self.mapping.master_to_slave_floats(p_MS.tolist()))

    def _calc_v_WE_desired(self, context, output):
        v_MS = self._master_sample(context, self._v_MS_input, slice(3, 6))
        output.SetFromVector(self.mapping.velocity_to_slave(v_MS))
