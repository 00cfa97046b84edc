"""Variable-gain joint PD with gravity compensation (eq. 20), and its numpy twin.

The paper's slave law is tau = K_p e + K_d edot with e = q_d - q, where K_p follows the
operator's muscle activation (eq. 22) and Table I puts the nominal gain at 50. One scalar K
cannot suit all seven joints: the shoulder carries about 3 kg m^2, the last wrist roll about
6e-4 kg m^2. So each joint gets

    k_j = K * s_j                       (stiffness, N m/rad; s_j in STIFFNESS_SCALE)
    d_j = 2 * zeta * sqrt(k_j * M_jj)   (damping, N m s/rad; M_jj(q) from the plant)

The damping follows K at a fixed damping ratio zeta. Why this form: the torque is explicit
(the 1 ms discrete plant holds it over the step), and an explicit PD on one joint of inertia
M_jj is stable only while x = omega_j * dt, omega_j = sqrt(k_j / M_jj), satisfies
x^2 + 4 zeta x < 4 (x < 0.83 at zeta = 1). With STIFFNESS_SCALE, K = 500 keeps x below 0.35
on every joint over the whole joint range (2000 sampled configurations). That is the
one-joint picture; the off-diagonal terms of M lower the margin, and K = 1000 was measured to
end in a limit cycle. The tests check K from 5 to 500 (``GAIN_RANGE``).

Why not the plant's implicit joint PD (``set_controller_gains``), which takes any gain: a
varying K would then mean rewriting plant parameters every step, and the torque would not be
an output that the rest of the diagram can log or saturate.
"""

import math

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from hemg_drake.control._kernels import pd_torque_into
from hemg_drake.control.clik import velocity_columns
from hemg_drake._validate import as_scalar

# Per-joint stiffness per unit of K (N m/rad per unit gain), s0 s1 e0 e1 w0 w1 w2. At
# Table I's K = 50 the shoulder holds 1000 N m/rad (1 cm at 1 m reach under 10 N m), the
# elbow 500, the wrist pitch/roll 100, the last wrist roll 5 (it carries almost no load and
# has the least inertia).
STIFFNESS_SCALE = np.array([20.0, 20.0, 10.0, 10.0, 2.0, 2.0, 0.1])
# Tested range of K at a 1 ms plant step.
GAIN_RANGE = (5.0, 500.0)
# Longest plant step the gains are checked at (the explicit PD's stability, module docstring).
MAX_TIME_STEP = 1e-3


def pd_gains(gain, stiffness_scale, mass_diagonal, damping_ratio):
    """Joint stiffness and damping for a scalar gain.

    Parameters
    ----------
    gain : float, K (> 0).
    stiffness_scale : array, shape (n,), s_j.
    mass_diagonal : array, shape (n,), M_jj(q), kg m^2.
    damping_ratio : float, zeta.

    Returns
    -------
    kp, kd : arrays, shape (n,): k_j = K s_j (N m/rad), d_j = 2 zeta sqrt(k_j M_jj) (N m s/rad).
    """
    kp = gain * np.asarray(stiffness_scale)
    kd = 2.0 * damping_ratio * np.sqrt(kp * np.asarray(mass_diagonal))
    return kp, kd


def pd_torque(q, v, q_desired, v_desired, kp, kd, effort_limit, gravity_torque=0.0):
    """Eq. 20 plus a feed-forward, saturated: clip(kp (q_d - q) + kd (v_d - v) + tau_ff).

    Parameters
    ----------
    q, v, q_desired, v_desired, kp, kd, effort_limit : arrays, shape (n,).
    gravity_torque : array, shape (n,), or 0.0. The torque that holds the arm against gravity
        (``-CalcGravityGeneralizedForces``).

    Returns
    -------
    tau : array, shape (n,), N m, within [-effort_limit, effort_limit].
    """
    tau = kp * (q_desired - q) + kd * (v_desired - v) + gravity_torque
    # np.minimum/np.maximum rather than np.clip: the same numbers, at half the cost.
    return np.minimum(np.maximum(tau, -effort_limit), effort_limit)


class VariableGainPd(LeafSystem):
    """Joint PD whose stiffness follows a scalar gain K, plus gravity compensation (eq. 20).

    .. pydrake_system::

        name: VariableGainPd
        input_ports:
        - q_desired
        - v_desired
        - state
        - gain
        output_ports:
        - torque

    Ports (n = 7 arm joints, order ``BaxterArm.joint_names``): ``q_desired`` (n, rad),
    ``v_desired`` (n, rad/s; zero when not connected), ``state`` ([q; v], 2n, the arm model
    instance's plant state), ``gain`` (1, K, dimensionless; the constructor's ``gain`` when not
    connected); ``torque`` (n, N m) for the plant's actuation input of the arm.

    Law: see the module docstring, k_j = K s_j and d_j = 2 zeta sqrt(k_j M_jj(q)), torque
    ``pd_torque``; gravity compensation -g(q) from ``CalcGravityGeneralizedForces`` on the
    controller's own plant context; then saturation at the actuators' effort limits.

    Timing: stateless and direct-feedthrough; a discrete plant samples it once per step.
    Table I's K = 50 lies inside the tested range ``GAIN_RANGE``.
    """

    def __init__(
        self,
        *,
        plant,
        arm,
        gain=50.0,
        stiffness_scale=STIFFNESS_SCALE,
        damping_ratio=1.0,
        gravity_compensation=True,
    ):
        """
        Parameters
        ----------
        plant : MultibodyPlant, finalized, containing ``arm`` (the simulated plant will do).
        arm : BaxterArm, from ``add_baxter_arm``.
        gain : float, K used while the ``gain`` port is not connected.
        stiffness_scale : array, shape (7,), s_j > 0.
        damping_ratio : float, zeta > 0.
        gravity_compensation : bool, add -g(q) to the torque.
        """
        LeafSystem.__init__(self)
        n = len(arm.joint_names)
        stiffness_scale = np.asarray(stiffness_scale, dtype=float)
        positive = np.isfinite(stiffness_scale) & (stiffness_scale > 0)
        if stiffness_scale.shape != (n,) or not positive.all():
            raise ValueError(
                f"stiffness_scale must be {n} positive finite numbers, got {stiffness_scale}"
            )
        _check_gain(gain, "gain")
        damping_ratio = as_scalar("damping_ratio", damping_ratio)
        if not plant.is_finalized():
            raise ValueError("VariableGainPd needs a finalized plant")
        self._plant = plant
        self._model = arm.model_instance
        self._plant_context = plant.CreateDefaultContext()
        self._default_gain = float(gain)
        self._stiffness_scale = stiffness_scale
        self._damping_ratio = damping_ratio
        self._gravity_compensation = bool(gravity_compensation)
        self._effort_limit = np.asarray(arm.effort_limit, dtype=float)
        # The arm's joints among all the plant's velocities (M and g are full size).
        self._columns = np.arange(plant.num_velocities())[velocity_columns(plant, self._model)]
        self._n = n
        self._zeros = np.zeros(n)
        self._no_gravity = np.zeros(0)
        self._torque = np.zeros(n)

        self.q_desired_input = self.DeclareVectorInputPort("q_desired", n)
        self.v_desired_input = self.DeclareVectorInputPort("v_desired", n)
        self.state_input = self.DeclareVectorInputPort("state", 2 * n)
        self.gain_input = self.DeclareVectorInputPort("gain", 1)
        self.torque_output = self.DeclareVectorOutputPort(
            "torque",
            BasicVector(n),
            self._calc_torque,
            prerequisites_of_calc={self.all_input_ports_ticket()},
        )

    def _calc_torque(self, context, output):
        x = self.state_input.Eval(context)
        q_desired = self.q_desired_input.Eval(context)
        v_desired = (
            self.v_desired_input.Eval(context)
            if self.v_desired_input.HasValue(context)
            else self._zeros
        )
        gain = (
            self.gain_input.Eval(context)[0]
            if self.gain_input.HasValue(context)
            else self._default_gain
        )
        _check_gain(gain, "gain input")
        # M and g from one position update of the controller's plant context.
        self._plant.SetPositions(self._plant_context, self._model, x[: self._n])
        M = self._plant.CalcMassMatrix(self._plant_context)
        g = (
            self._plant.CalcGravityGeneralizedForces(self._plant_context)
            if self._gravity_compensation
            else self._no_gravity
        )
        # pd_gains and pd_torque in one compiled call (the same sums; tests compare them).
        finite = pd_torque_into(
            self._torque,
            x,
            q_desired,
            v_desired,
            float(gain),
            self._stiffness_scale,
            self._damping_ratio,
            M,
            g,
            self._columns,
            self._effort_limit,
        )
        if not finite:
            raise ValueError("VariableGainPd: q_desired/v_desired contain NaN or inf")
        output.SetFromVector(self._torque)


def _check_gain(gain, name):
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f"VariableGainPd: {name} must be a positive finite number, got {gain}")
