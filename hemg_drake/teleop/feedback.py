"""Force feedback: what the slave feels (or how far it lags) sent back to the master's motors."""

from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import all_finite, as_scalar
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import TOUCH_X_PEAK_FORCE, saturate_norm

MODES = ("force", "position_error")


class ForceFeedback(LeafSystem):
    """The Touch X motor force that lets the operator feel the slave, saturated at its peak.

    .. pydrake_system::

        name: ForceFeedback
        input_ports:
        - f_WE (mode "force")
        - p_WE (mode "position_error")
        - v_WE (mode "position_error")
        - p_MS (mode "position_error")
        - v_MS (mode "position_error")
        output_ports:
        - motor_force

    Two modes, chosen by ``mode``; only that mode's input ports exist.

    - ``"force"`` (default): ``f_WE`` (3, N) is the force the environment exerts on the
      slave end-effector E, in W (a contact force, or the tracking force of eq. 23). The
      operator feels it rotated into M and scaled back by the workspace map,
      F_m = gain * R_WM^T f_WE / scale (see :class:`WorkspaceMapping`).
    - ``"position_error"``: the paper's master PD, F_m = K_pm e + K_dm edot (Table I:
      K_pm = K_dm = 50), with e = p_MSdes - p_MS the gap between the slave's position
      mapped into M and the stylus, edot the same for velocities. Inputs: ``p_WE`` (3, m) and
      ``v_WE`` (3, m/s) the slave end-effector in W, ``p_MS`` and ``v_MS`` the stylus in M.
      The stylus is pulled towards where the slave is, so a blocked slave is felt as a
      spring. Sampled with the 1 kHz master, K_dm * period / mass must stay below 2 (it is
      1.1 with Table I's 50 N s/m on the 45 g tip).

    ``motor_force`` (3, N, in M) is saturated in norm at ``peak_force`` (7.9 N, Touch X), as
    the device driver would. The output is a direct feedthrough of the inputs, without
    state; the HapticMaster samples it at its own rate. NaN inputs raise ValueError.

    Parameters
    ----------
    mapping : WorkspaceMapping
    mode : {"force", "position_error"}
    gain : float
        Extra force scale in mode "force" (dimensionless, >= 0).
    stiffness, damping : float
        K_pm (N/m) and K_dm (N s/m) in mode "position_error".
    peak_force : float
        Saturation of the output's norm (N).
    """

    def __init__(
        self,
        *,
        mapping,
        mode="force",
        gain=1.0,
        stiffness=50.0,
        damping=50.0,
        peak_force=TOUCH_X_PEAK_FORCE,
    ):
        LeafSystem.__init__(self)
        if not isinstance(mapping, WorkspaceMapping):
            raise ValueError(f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.mapping = mapping
        self.mode = mode
        self.gain = as_scalar("gain", gain, strict=False)
        self.stiffness = as_scalar("stiffness", stiffness, strict=False)
        self.damping = as_scalar("damping", damping, strict=False)
        self.peak_force = as_scalar("peak_force", peak_force, strict=False)
        names = ("f_WE",) if mode == "force" else ("p_WE", "v_WE", "p_MS", "v_MS")
        self._inputs = {name: self.DeclareVectorInputPort(name, 3) for name in names}
        self._motor_force_output = self.DeclareVectorOutputPort(
            "motor_force",
            3,
            self._calc_motor_force,
            prerequisites_of_calc={self.all_input_ports_ticket()},
        )

    def _input(self, context, name):
        value = self._inputs[name].Eval(context)
        if not all_finite(value.tolist()):
            raise ValueError(f"{name} must be finite, got {value.tolist()}")
        return value

    def _calc_motor_force(self, context, output):
        if self.mode == "force":
            force = self.mapping.force_to_master_floats(
                self._input(context, "f_WE").tolist(), self.gain
            )
        else:
            error = self.mapping.slave_to_master(self._input(context, "p_WE")) - self._input(
                context, "p_MS"
            )
            error_rate = self.mapping.velocity_to_master(
                self._input(context, "v_WE")
            ) - self._input(context, "v_MS")
            force = (self.stiffness * error + self.damping * error_rate).tolist()
        output.SetFromVector(saturate_norm(force, self.peak_force))
