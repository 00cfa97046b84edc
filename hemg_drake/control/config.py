"""Settings of the slave's controllers: the CLIK (eq. 21) and the variable-gain PD (eq. 20).

Each dataclass owns its defaults; :class:`~hemg_drake.control.clik.Clik` and
:class:`~hemg_drake.control.pd.VariableGainPd` take one. Read from a scenario's ``clik`` and
``pd`` sections.
"""

import dataclasses as dc

from hemg_drake.config_fields import checked

CLIK_METHODS = ("transpose", "dls")
# Longest plant step the PD's gains are checked at (the explicit PD's stability, control/pd.py).
MAX_TIME_STEP = 1e-3
# Tested range of the PD's gain K at a 1 ms plant step.
GAIN_RANGE = (5.0, 500.0)


@dc.dataclass
class ClikConfig:
    """Closed-loop inverse kinematics (:class:`~hemg_drake.control.clik.Clik`, eq. 21)."""

    # K_sp: 1/(m^2 s) for "transpose", 1/s for "dls".
    gain: float = checked(300.0, positive=True)
    # "transpose" (the paper's J^T law) or "dls" (damped least squares).
    method: str = checked("transpose", choices=CLIK_METHODS)
    # Damping of the "dls" law (m).
    damping: float = checked(0.05)
    # Update period (s).
    period: float = checked(1e-3, positive=True)
    # Distance kept inside each joint's position limits (rad).
    limit_margin: float = checked(0.02)
    # Optional orientation task in the null space of eq. 21's position task: the tool
    # frame's axis axis_E (in E) is turned towards axis_W_desired (in W) at this rate
    # (1/s); 0 leaves the paper's position-only law. The drawing holds its pen down.
    orientation_gain: float = checked(0.0)
    axis_E: list[float] = checked([0.0, 0.0, 1.0], signed=True, size=3)
    axis_W_desired: list[float] = checked([0.0, 0.0, -1.0], signed=True, size=3)


@dc.dataclass
class PdConfig:
    """The joint PD of eq. 20 (:class:`~hemg_drake.control.pd.VariableGainPd`)."""

    # K while the gain input is not connected (Table I's nominal 50).
    gain: float = checked(50.0, positive=True)
    # Per-joint stiffness per unit of K, s_j (N m/rad), joints s0 s1 e0 e1 w0 w1 w2: at
    # K = 50 the shoulder holds 1000 N m/rad, the elbow 500, the wrist 100, the last roll 5.
    stiffness_scale: list[float] = checked([20.0, 20.0, 10.0, 10.0, 2.0, 2.0, 0.1], positive=True, size=7)
    # Damping ratio zeta of d_j = 2 zeta sqrt(k_j M_jj).
    damping_ratio: float = checked(1.0, positive=True)
    # Add -g(q), the torque that holds the arm against gravity.
    gravity_compensation: bool = True
