"""Master-to-slave workspace map: scale, rotation and offset, with an optional transport delay."""

import dataclasses as dc

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import AffineSystem, Demultiplexer, DiscreteTimeDelay, Multiplexer

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.teleop.config import MappingConfig

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

    def force_to_slave(self, f_M):
        """Stylus force in M (N) -> the slave force in W that maps onto it (N)."""
        return self.scale * self._rotate_to_world(f_M)


def _stateless_affine(D, y0):
    """Drake's AffineSystem y = D u + y0 without state (A, B, f0 and C empty)."""
    m, n = D.shape
    return AffineSystem(
        np.zeros((0, 0)), np.zeros((0, n)), np.zeros(0), np.zeros((m, 0)), D, y0
    )


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
    :class:`WorkspaceMapping` (``mapping``): [p_WE; v_WE] = D [p_MS; v_MS] + [p_WMo; 0],
    D = scale diag(R_WM, R_WM), a Drake ``AffineSystem`` without state.

    Timing: with ``config.delay_steps`` = 0 (default) the map is memoryless (direct
    feedthrough). With ``config.delay_steps`` = n > 0 it models a constant transport delay
    of the teleoperation channel with Drake's ``DiscreteTimeDelay`` (period ``period``,
    n - 1 steps: it samples and holds first, one more period on a signal held on the same
    grid). For an input held between sample instants on that grid (the
    :class:`~hemg_drake.teleop.master.HapticMaster`'s outputs), the output at time t is the
    mapped input at t - n * period; until the n-th sample (at t = (n - 1) period) it is the
    map of ``p_MS_initial`` at rest. Drake's delay starts at zero, so it carries the
    offset from that rest pose, u - [p_MS_initial; 0], which is added back before the map
    (exact for a zero ``p_MS_initial``, otherwise to one rounding).

    Structure (Drake's systems only, so it clones and converts to AutoDiffXd):
    ``Multiplexer`` -> [``AffineSystem`` (the offset) -> ``DiscreteTimeDelay`` ->
    ``AffineSystem`` (the rest pose back)] -> ``AffineSystem`` (the map) -> ``Demultiplexer``.

    Parameters
    ----------
    mapping : WorkspaceMapping
        Scale, R_WM and p_WMo (the scenario places it with the scene).
    period : float
        Sample period of the delay (s): the master's.
    p_MS_initial : array, shape (3,)
        The stylus's rest position in M before the start (m).
    config : MappingConfig
        Its ``delay_steps`` (the rest of the map is in ``mapping``).
    """

    def __init__(self, *, mapping, period, p_MS_initial=(0.0, 0.0, 0.0), config=MappingConfig()):
        Diagram.__init__(self)
        if not isinstance(mapping, WorkspaceMapping):
            raise ValueError(f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}")
        delay_steps = config.delay_steps
        try:
            steps = int(delay_steps)
        except (TypeError, ValueError, OverflowError):  # None, "two", NaN, inf
            steps = -1
        if steps != delay_steps or steps < 0 or isinstance(delay_steps, bool):
            raise ValueError(f"delay_steps must be a non-negative integer, got {delay_steps!r}")
        self.mapping = mapping
        self.delay_steps = steps
        R = mapping.scale * mapping.R_WM.matrix()
        D = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), R]])
        y0 = np.concatenate([mapping.p_WMo, np.zeros(3)])
        builder = DiagramBuilder()
        join = builder.AddNamedSystem("join", Multiplexer([3, 3]))
        signal = join.get_output_port()
        if steps > 0:
            rest = np.concatenate([as_vector("p_MS_initial", p_MS_initial, 3), np.zeros(3)])
            offset = builder.AddNamedSystem("offset", _stateless_affine(np.eye(6), -rest))
            delay = builder.AddNamedSystem(
                "delay", DiscreteTimeDelay(as_scalar("period", period), steps - 1, 6)
            )
            # The rest pose added back before the map (not folded into its constant), so
            # the map sees the same numbers as without a delay: bytes as before.
            restore = builder.AddNamedSystem("restore", _stateless_affine(np.eye(6), rest))
            builder.Connect(signal, offset.get_input_port())
            builder.Connect(offset.get_output_port(), delay.get_input_port())
            builder.Connect(delay.get_output_port(), restore.get_input_port())
            signal = restore.get_output_port()
        to_slave = builder.AddNamedSystem("map", _stateless_affine(D, y0))
        split = builder.AddNamedSystem("split", Demultiplexer([3, 3]))
        builder.Connect(signal, to_slave.get_input_port())
        builder.Connect(to_slave.get_output_port(), split.get_input_port())
        builder.ExportInput(join.get_input_port(0), "p_MS")
        builder.ExportInput(join.get_input_port(1), "v_MS")
        builder.ExportOutput(split.get_output_port(0), "p_WE_desired")
        builder.ExportOutput(split.get_output_port(1), "v_WE_desired")
        builder.BuildInto(self)
