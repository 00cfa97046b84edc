"""Variable-gain joint PD with gravity compensation (eq. 20).

The paper's slave law is tau = K_p e + K_d edot with e = q_d - q, where K_p follows the
operator's muscle activation (eq. 22) and Table I puts the nominal gain at 50. One scalar K
cannot suit all seven joints: the shoulder carries about 3 kg m^2, the last wrist roll about
6e-4 kg m^2. So each joint gets

    k_j = K * s_j                       (stiffness, N m/rad; s_j: PdConfig.stiffness_scale)
    d_j = 2 * zeta * sqrt(k_j * M_jj)   (damping, N m s/rad; M_jj(q) from the plant)

The damping follows K at a fixed damping ratio zeta. Why this form: the torque is explicit
(the 1 ms discrete plant holds it over the step), and an explicit PD on one joint of inertia
M_jj is stable only while x = omega_j * dt, omega_j = sqrt(k_j / M_jj), satisfies
x^2 + 4 zeta x < 4 (x < 0.83 at zeta = 1). With the default scale, K = 500 keeps x below 0.35
on every joint over the whole joint range (2000 sampled configurations). That is the
one-joint picture; the off-diagonal terms of M lower the margin, and K = 1000 was measured to
end in a limit cycle. The tests check K from 5 to 500 (``GAIN_RANGE``).

Gravity compensation -g(q) is Drake's own ``InverseDynamics`` in ``kGravityCompensation``
mode on the controller's plant, fed to the PD's ``feedforward_torque`` input, which the PD
adds before the saturation (:func:`add_variable_gain_pd` wires both).

Why not the plant's implicit joint PD (``set_controller_gains``), which takes any gain: a
varying K would then mean rewriting plant parameters every step, and the torque would not be
an output that the rest of the diagram can log or saturate. Why not Drake's
``JointStiffnessController`` or ``PidController``: their gains are constructor constants,
not an input, and the damping here follows M_jj(q).
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import BasicVector_, LeafSystem_, NumericParameterIndex
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import as_scalar
from hemg_drake.control.clik import velocity_columns
from hemg_drake.control.config import GAIN_RANGE, MAX_TIME_STEP, PdConfig  # noqa: F401
from hemg_drake.robots.plant_context import declare_plant_context

# The default per-joint stiffness per unit of K, s_j (PdConfig's; figures label with it).
STIFFNESS_SCALE = np.array(PdConfig().stiffness_scale)


def plant_for_scalar(plant, T):
    """``plant`` itself for T = float, else its conversion to ``T`` (Drake's ToScalarType)."""
    return plant if T is float else plant.ToScalarType[T]()


@TemplateSystem.define("VariableGainPd_", T_list=[float, AutoDiffXd])
def VariableGainPd_(T):
    class Impl(LeafSystem_[T]):
        """Joint PD whose stiffness follows a scalar gain K, plus a feed-forward (eq. 20).

        .. pydrake_system::

            name: VariableGainPd
            input_ports:
            - q_desired
            - v_desired
            - state
            - gain
            - feedforward_torque
            output_ports:
            - torque

        Ports (n = 7 arm joints, order ``BaxterArm.joint_names``): ``q_desired`` (n, rad),
        ``v_desired`` (n, rad/s; zero when not connected), ``state`` ([q; v], 2n, the arm
        model instance's plant state), ``gain`` (1, K, dimensionless; ``config.gain`` when
        not connected), ``feedforward_torque`` (n, N m; zero when not connected: the
        gravity compensation -g(q) from ``InverseDynamics``, see
        :func:`add_variable_gain_pd`); ``torque`` (n, N m) for the plant's actuation input.

        Law (module docstring): k_j = K s_j, d_j = 2 zeta sqrt(k_j M_jj(q)),
        tau_j = clip(k_j (q_d - q)_j + d_j (v_d - v)_j + tau_ff_j, +-effort_limit_j).
        M(q) comes from ``plant`` (the arm alone, :func:`~hemg_drake.robots.baxter.
        make_arm_controller_plant`, or a plant holding it) on a context kept in a cache
        entry that depends on ``state``.

        Parameters in the Context: one numeric parameter [K, s_0..s_{n-1}, zeta,
        effort_limit_0..effort_limit_{n-1}] (K the gain used while ``gain`` is not
        connected; defaults ``config.gain``, ``config.stiffness_scale``,
        ``config.damping_ratio`` and ``arm.effort_limit``), so one built diagram runs
        several gains: :meth:`set_gains` writes them into a context, :meth:`get_gains`
        reads them.

        Timing: stateless and direct-feedthrough; a discrete plant samples it once per
        step. Table I's K = 50 lies inside the tested range ``GAIN_RANGE``. Scalar types:
        double and AutoDiffXd.
        """

        def _construct(self, *, plant, arm, config=None, converter=None):
            """
            Parameters
            ----------
            plant : MultibodyPlant (double), finalized, containing ``arm``.
            arm : BaxterArm, from ``add_baxter_arm``.
            config : PdConfig; ``gain``, ``stiffness_scale`` and ``damping_ratio`` are read
                here (``gravity_compensation`` by :func:`add_variable_gain_pd`).
            """
            LeafSystem_[T].__init__(self, converter)
            config = PdConfig() if config is None else config
            n = len(arm.joint_names)
            scale = _check_positive(config.stiffness_scale, n, "stiffness_scale")
            _check_gain(config.gain, "gain")
            damping_ratio = as_scalar("damping_ratio", config.damping_ratio)
            if not plant.is_finalized():
                raise ValueError("VariableGainPd needs a finalized plant")
            self._args = dict(plant=plant, arm=arm, config=config)
            self._plant = plant_for_scalar(plant, T)
            self._model = arm.model_instance
            self._n = n
            limit = np.asarray(arm.effort_limit, dtype=float)
            _check_positive(limit, n, "effort_limit")
            # [K, s (n), zeta, effort limit (n)]: one parameter, one read per call.
            values = np.concatenate([[float(config.gain)], scale, [damping_ratio], limit])
            self._parameter = self.DeclareNumericParameter(BasicVector_[T](values.tolist()))
            # The arm's joints among the plant's velocities (M is the plant's, full size): a
            # slice where contiguous (a view, cheaper than an index array's copy).
            self._columns = velocity_columns(plant, self._model)
            self._double = T is float
            self._zeros = [T(0.0)] * n

            self.q_desired_input = self.DeclareVectorInputPort("q_desired", n)
            self.v_desired_input = self.DeclareVectorInputPort("v_desired", n)
            self.state_input = self.DeclareVectorInputPort("state", 2 * n)
            self.gain_input = self.DeclareVectorInputPort("gain", 1)
            self.feedforward_input = self.DeclareVectorInputPort("feedforward_torque", n)
            # The controller plant's context at the arm's measured q: M(q) on demand.
            self._plant_context = declare_plant_context(
                self, self._plant, self.state_input.ticket(), self._set_plant_state
            )
            self.torque_output = self.DeclareVectorOutputPort(
                "torque",
                n,
                self._calc_torque,
                prerequisites_of_calc={
                    self.all_input_ports_ticket(),
                    self.numeric_parameter_ticket(NumericParameterIndex(self._parameter)),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._args, converter=converter)

        def set_gains(
            self, context, *, gain=None, stiffness_scale=None, damping_ratio=None,
            effort_limit=None,
        ):
            """Write the law's constants into ``context`` (this system's own context, e.g.
            ``pd.GetMyMutableContextFromRoot(root_context)``); None keeps a value.

            Parameters
            ----------
            gain : float, K while the ``gain`` input is not connected (positive).
            stiffness_scale : n positive floats, s_j (N m/rad per unit of K).
            damping_ratio : float, zeta (positive).
            effort_limit : n positive floats, the torque limits (N m).
            """
            n = self._n
            values = context.get_mutable_numeric_parameter(self._parameter)
            if gain is not None:
                _check_gain(gain, "gain")
                values.SetAtIndex(0, float(gain))
            if stiffness_scale is not None:
                for j, s_j in enumerate(_check_positive(stiffness_scale, n, "stiffness_scale")):
                    values.SetAtIndex(1 + j, s_j)
            if damping_ratio is not None:
                values.SetAtIndex(1 + n, as_scalar("damping_ratio", damping_ratio))
            if effort_limit is not None:
                for j, limit in enumerate(_check_positive(effort_limit, n, "effort_limit")):
                    values.SetAtIndex(2 + n + j, limit)

        def get_gains(self, context):
            """The law's constants in ``context``: a dict of ``gain``, ``stiffness_scale``
            (array), ``damping_ratio``, ``effort_limit`` (array), as ``set_gains`` takes."""
            n = self._n
            values = context.get_numeric_parameter(self._parameter).CopyToVector()
            return dict(
                gain=values[0], stiffness_scale=values[1 : 1 + n],
                damping_ratio=values[1 + n], effort_limit=values[2 + n :],
            )  # fmt: skip

        def _set_plant_state(self, context, plant_context):
            q = self.state_input.Eval(context)[: self._n]
            self._plant.SetPositions(plant_context, self._model, q)

        def _calc_torque(self, context, output):
            n = self._n
            x = self.state_input.Eval(context).tolist()
            q_desired = self.q_desired_input.Eval(context).tolist()
            v_desired = (
                self.v_desired_input.Eval(context).tolist()
                if self.v_desired_input.HasValue(context)
                else self._zeros
            )
            feedforward = (
                self.feedforward_input.Eval(context).tolist()
                if self.feedforward_input.HasValue(context)
                else self._zeros
            )
            group = context.get_numeric_parameter(self._parameter)
            # A view's list for doubles (a copy costs more); CopyToVector for AutoDiffXd.
            law = (
                group.get_value() if self._double else group.CopyToVector()
            ).tolist()
            gain = (
                self.gain_input.Eval(context).tolist()[0]
                if self.gain_input.HasValue(context)
                else law[0]
            )
            _check_gain(gain, "gain input")
            if not _finite(sum(q_desired) + sum(v_desired)):
                raise ValueError("VariableGainPd: q_desired/v_desired contain NaN or inf")
            M = self._plant.CalcMassMatrix(self._plant_context.Eval(context))
            mass = M.diagonal()[self._columns].tolist()
            torque = []
            scale, twice_zeta, limit = law[1 : n + 1], 2.0 * law[n + 1], law[n + 2 :]
            # Scalar arithmetic on 7 joints (numpy's per-call cost exceeds the sums here);
            # the same lines run on floats and on AutoDiffXd. The clip is written as
            # conditional expressions (what min(max(...)) returns, NaN kept, at less cost).
            for j in range(n):
                k = gain * scale[j]
                d = twice_zeta * (k * mass[j]) ** 0.5
                tau = k * (q_desired[j] - x[j]) + d * (v_desired[j] - x[n + j]) + feedforward[j]
                high = limit[j]
                low = -high
                torque.append(low if tau < low else high if tau > high else tau)
            output.SetFromVector(torque)

    return Impl


VariableGainPd = VariableGainPd_[None]


def add_variable_gain_pd(
    builder, *, plant, arm, state_port, config=None, name="pd", system=None
):
    """Add eq. 20 to ``builder``: a :class:`VariableGainPd` reading ``state_port`` and, if
    ``config.gravity_compensation``, Drake's ``InverseDynamics`` (``kGravityCompensation``,
    named ``<name>_gravity``) on ``plant`` reading it too and feeding the PD's
    ``feedforward_torque`` with -g(q).

    Parameters
    ----------
    builder : DiagramBuilder.
    plant : MultibodyPlant, finalized, of the arm alone (its state is the arm's [q; v]), e.g.
        from :func:`~hemg_drake.robots.baxter.make_arm_controller_plant`.
    arm : BaxterArm of ``plant``.
    state_port : OutputPort, the arm's [q; v] (the simulated plant's arm state).
    config : PdConfig.
    name : str, the PD's name in the builder.
    system : VariableGainPd (or a subclass: the Cartesian impedance of
        :mod:`hemg_drake.control.impedance`) to add; default ``VariableGainPd(plant=plant,
        arm=arm, config=config)``.

    Returns
    -------
    VariableGainPd; connect its ``q_desired`` (and ``v_desired``, ``gain``) and its
    ``torque`` output.
    """
    config = PdConfig() if config is None else config
    if plant.num_velocities() != len(arm.joint_names):
        raise ValueError("add_variable_gain_pd needs a plant of the arm alone")
    if system is None:
        system = VariableGainPd(plant=plant, arm=arm, config=config)
    pd = builder.AddNamedSystem(name, system)
    builder.Connect(state_port, pd.state_input)
    if config.gravity_compensation:
        gravity = builder.AddNamedSystem(
            f"{name}_gravity",
            InverseDynamics(plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation),
        )
        builder.Connect(state_port, gravity.get_input_port_estimated_state())
        builder.Connect(gravity.get_output_port_generalized_force(), pd.feedforward_input)
    return pd


def _finite(value):
    """True for a finite float or AutoDiffXd (NaN fails both comparisons)."""
    return -math.inf < value < math.inf


def _check_positive(values, n, name):
    """``values`` as an array of n positive finite floats, or ValueError naming it."""
    array = np.asarray(values, dtype=float)
    if array.shape != (n,) or not (np.isfinite(array) & (array > 0)).all():
        raise ValueError(f"{name} must be {n} positive finite numbers, got {array}")
    return array


def _check_gain(gain, name):
    if not (0.0 < gain < math.inf):
        raise ValueError(f"VariableGainPd: {name} must be a positive finite number, got {gain}")
