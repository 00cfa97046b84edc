"""Master-to-slave workspace map: scale, rotation and offset, with an optional transport delay."""

import dataclasses as dc

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import AffineSystem, DiscreteTimeDelay, Multiplexer

from hemg_drake._validate import all_finite, as_scalar, as_vector

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

    def velocity_to_slave_floats(self, v_MS):
        """:meth:`velocity_to_slave` on a list of 3 floats, returning one."""
        x, y, z = v_MS
        scale = self.scale
        return [scale * (r0 * x + r1 * y + r2 * z) for r0, r1, r2 in self._R_rows]

    def force_to_master_floats(self, f_W, gain=1.0):
        """``gain`` times :meth:`force_to_master` on a list of 3 floats, returning one."""
        x, y, z = f_W
        factor = gain / self.scale
        return [factor * (r0 * x + r1 * y + r2 * z) for r0, r1, r2 in self._RT_rows]

    def force_to_slave(self, f_M):
        """Stylus force in M (N) -> the slave force in W that maps onto it (N)."""
        return self.scale * self._rotate_to_world(f_M)


class _MasterToSlave(LeafSystem):
    """The map of one stylus sample, inside :class:`WorkspaceMap` (memoryless).

    .. pydrake_system::

        name: _MasterToSlave
        input_ports:
        - p_MS (no delay)
        - v_MS (no delay)
        - sample (delayed)
        output_ports:
        - p_WE_desired
        - v_WE_desired

    Inputs ``p_MS`` and ``v_MS`` (no delay), or ``sample``, the delayed 6-vector
    [p_MS - p_MS_rest; v_MS] (the delay's zero state is then the rest pose). Outputs by
    :class:`WorkspaceMapping`, direct feedthrough.
    """

    def __init__(self, mapping, p_MS_rest=None):
        LeafSystem.__init__(self)
        self.mapping = mapping
        if p_MS_rest is None:
            self._p_MS_rest = None
            self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
            self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
        else:
            self._p_MS_rest = [float(value) for value in p_MS_rest]
            self._sample_input = self.DeclareVectorInputPort("sample", 6)
        inputs = {self.all_input_ports_ticket()}
        self.DeclareVectorOutputPort(
            "p_WE_desired", 3, self._calc_p_WE, prerequisites_of_calc=inputs
        )
        self.DeclareVectorOutputPort(
            "v_WE_desired", 3, self._calc_v_WE, prerequisites_of_calc=inputs
        )

    def _floats(self, context, name):
        if self._p_MS_rest is None:
            port = self._p_MS_input if name == "p_MS" else self._v_MS_input
            values = port.Eval(context).tolist()
        elif name == "p_MS":
            offset = self._sample_input.Eval(context).tolist()[:3]
            values = [o + r for o, r in zip(offset, self._p_MS_rest)]
        else:
            values = self._sample_input.Eval(context).tolist()[3:]
        if not all_finite(values):
            raise ValueError(f"{name} must be finite, got {values}")
        return values

    def _calc_p_WE(self, context, output):
        output.SetFromVector(self.mapping.master_to_slave_floats(self._floats(context, "p_MS")))

    def _calc_v_WE(self, context, output):
        output.SetFromVector(self.mapping.velocity_to_slave_floats(self._floats(context, "v_MS")))


class WorkspaceMap(Diagram):
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
    :class:`WorkspaceMapping` (``mapping``). A NaN or infinite input raises ValueError when
    it reaches the map (after the delay, if any).

    Timing: with ``delay_steps`` = 0 (default) the map is memoryless (direct feedthrough).
    With ``delay_steps`` = n > 0 it models a constant transport delay of the teleoperation
    channel with Drake's ``DiscreteTimeDelay`` (period ``period``, n - 1 steps: it samples
    and holds first, one more period on a signal held on the same grid). For an input held
    between sample instants on that grid (the
    :class:`~hemg_drake.teleop.master.HapticMaster`'s outputs), the output at time t is the
    mapped input at t - n * period; until the n-th sample (at t = (n - 1) period) it is the
    map of ``p_MS_initial`` at rest. Drake's delay starts at zero, so it carries the
    offset from that rest pose, [p_MS - p_MS_initial; v_MS] (exact for a zero
    ``p_MS_initial``, otherwise to one rounding of the offset).

    Structure (a small Diagram): ``Multiplexer`` -> ``AffineSystem`` (the offset) ->
    ``DiscreteTimeDelay`` -> the map, a LeafSystem evaluated when its outputs are read;
    without delay, the map alone. Measured against the FIFO of Python discrete state that
    it replaced (``benchmarks/bench_teleop.py``): see ``docs/teleop.md``.
    """

    def __init__(self, *, mapping, delay_steps=0, period=1e-3, p_MS_initial=(0.0, 0.0, 0.0)):
        Diagram.__init__(self)
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
        builder = DiagramBuilder()
        if steps == 0:
            to_slave = builder.AddNamedSystem("map", _MasterToSlave(mapping))
            for name in ("p_MS", "v_MS"):
                builder.ExportInput(to_slave.GetInputPort(name), name)
        else:
            p_rest = as_vector("p_MS_initial", p_MS_initial, 3)
            join = builder.AddNamedSystem("join", Multiplexer([3, 3]))
            # y = u - [p_MS_initial; 0], without state (A, B, f0 and C are empty).
            no_state = (np.zeros((0, 0)), np.zeros((0, 6)), np.zeros(0), np.zeros((6, 0)))
            shift = np.concatenate([-p_rest, np.zeros(3)])
            offset = builder.AddNamedSystem("offset", AffineSystem(*no_state, np.eye(6), shift))
            delay = builder.AddNamedSystem(
                "delay", DiscreteTimeDelay(as_scalar("period", period), steps - 1, 6)
            )
            to_slave = builder.AddNamedSystem("map", _MasterToSlave(mapping, p_rest))
            builder.Connect(join.get_output_port(), offset.get_input_port())
            builder.Connect(offset.get_output_port(), delay.get_input_port())
            builder.Connect(delay.get_output_port(), to_slave.GetInputPort("sample"))
            builder.ExportInput(join.get_input_port(0), "p_MS")
            builder.ExportInput(join.get_input_port(1), "v_MS")
        for name in ("p_WE_desired", "v_WE_desired"):
            builder.ExportOutput(to_slave.GetOutputPort(name), name)
        builder.BuildInto(self)
