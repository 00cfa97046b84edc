"""Closed-loop inverse kinematics (CLIK) of the slave's tool point, eq. 21.

The J^T law (the paper's) and its damped-least-squares variant are this project's own
system. Why the DLS variant is not Drake's ``DifferentialInverseKinematicsIntegrator``
(measured, Drake 1.51, ``benchmarks/bench_clik.py``, translation only, the same limits):
its law is another one (a QP for the velocity that closes the whole pose error within one
step, scaled to the velocity limits: eq. 21's rate K_sp and the DLS damping have no
counterpart; from home to a target 0.42 m away it reported "stuck" for 135 steps); it does
not convert to AutoDiffXd, which the loop's linearisation needs; and its step costs
73-112 us of CPU against 40-47 us for this system's DLS update in the same run.
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import sqrt as scalar_sqrt
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_, NumericParameterIndex
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.control.config import CLIK_METHODS, ClikConfig
from hemg_drake.robots.plant_context import declare_plant_context

# Damping mu of the tool-axis task's solve (dimensionless, as J_w). The task's two singular
# values are about 0.9 and 0.4 over a sheet within reach, so mu slows the axis there by 1-6 %.
# Where the arm cannot turn the axis further (the edge of its reach with the pen vertical, a
# wrist singularity) a singular value goes to 0 and mu bounds the joint rates: at 0.05 the
# arm swung out of that fold fast enough to lift the pen off the default sheet for 20 ms,
# at 0.1 it does not (benchmarks/bench_clik.py).
AXIS_DAMPING = 0.1
# Damping of the position Jacobian in the null-space projector (m): J J^T's eigenvalues are
# 0.1 to 2 m^2 over the workspace, so N leaks at most ~1e-7 of the axis task into the tool
# point's velocity, and N stays bounded at a singularity.
NULL_SPACE_DAMPING = 1e-4



@TemplateSystem.define("Clik_", T_list=[float, AutoDiffXd])
def Clik_(T):
    class Impl(LeafSystem_[T]):
        """Turns a desired tool-point position into a joint reference by CLIK (eq. 21).

        .. pydrake_system::

            name: Clik
            input_ports:
            - p_WE_desired
            - state
            output_ports:
            - q_desired
            - v_desired

        The reference ``q_d`` is integrated in discrete state, one step per
        ``period``::

            e      = p_WE_desired - p_WE(q_d)
            qdot_p = gain * J(q_d)^T e                                  (transpose)
            qdot_p = gain * J^T (J J^T + damping^2 I)^-1 e              (dls)
            qdot_d = qdot_p [+ the tool-axis task below]
            q_d   <- q_d + period * limited(qdot_d)

        with ``J`` the translational Jacobian of point E (the tool point, fixed in
        ``frame_E``) in the world frame W, from the plant. The transpose law is
        the paper's; damped least squares converges faster near singularities.
        The paper writes eq. 21 with the slave's measured ``q_s``; here the loop
        is closed on the reference ``q_d`` itself (the classic kinematic CLIK),
        so the reference does not inherit the arm's dynamics and tracking errors,
        and the measured ``state`` (the arm's ``[q; v]``) only initialises
        ``q_d`` at the start of a simulation.

        Limits (``limited``), per joint first: ``q_d`` stays ``limit_margin``
        inside each position limit, and a joint's rate is bounded by the room
        left to its own limits over the step, so a joint at a limit pushed
        further out stops while the others keep their rates. Then, if a joint
        still exceeds its velocity limit, every rate is scaled by one factor
        (the direction of motion kept).

        Tool-axis task (``orientation_gain > 0``; off by default, and then the
        step is exactly eq. 21's). The position law leaves the hand's
        orientation free: with the pen on the hand, its axis tilted 1 to 23 deg
        from vertical while drawing. With ``a = R_WE axis_E`` (the pen axis in
        W), ``d = axis_W_desired``, ``J_w`` the angular-velocity Jacobian of
        ``frame_E`` and ``P = I - a a^T``::

            e_a    = angle(a, d) * (a x d) / |a x d|        (turns a onto d)
            N      = I - J^T (J J^T + nu^2 I)^-1 J           (nu = 1e-4 m)
            A      = P J_w N
            qdot_d = qdot_p + A^T (A A^T + mu^2 I)^-1 (orientation_gain e_a - P J_w qdot_p)

        so the axis error decays as ``exp(-orientation_gain t)`` (to the damping
        ``mu`` below): the second term asks the angular rates across the axis for
        that decay, net of what the position law already turns. Why the null
        space of ``J``:
        ``J qdot_d = J qdot_p`` (to ``nu^2 / sigma_min(J)^2``), so the tool
        point moves exactly as eq. 21 says and the paper's position law is
        untouched; the arm's 7 joints leave 4 null-space directions, of which
        the axis needs 2 (``P`` leaves the roll about the axis itself free).
        ``mu`` (``AXIS_DAMPING``, 0.1) damps the solve where the arm loses those
        directions: at the edge of its reach with the axis held, the axis stays
        as close as the arm allows (measured: the default sheet's far line, 19.8
        deg, is out of a vertical pen's reach). The axis is undefined when
        ``a = -d`` exactly (then ``e_a = 0``). Measured while drawing the
        default plan on a sheet within reach (centre (0.60, -0.70, 0.09)) at
        ``orientation_gain`` 10 1/s: the pen within 0.6 deg of vertical whenever
        it touches, against 25 deg with the position law alone.

        Discrete stability of the transpose law needs
        ``period * gain * sigma_max(J J^T) < 2``; for the Baxter arm
        ``sigma_max`` is about 2 m^2, so the default gain suits a 1 ms period.
        The axis task needs ``period * orientation_gain <= 1`` (checked).

        Outputs ``q_desired`` and ``v_desired`` (``qdot_d``) match the inputs of
        :class:`~hemg_drake.control.pd.VariableGainPd`; they are the two discrete-state
        groups themselves (state output ports, no computation per evaluation).

        Parameters in the Context: one numeric parameter [gain, damping,
        orientation_gain, q_lower (n), q_upper (n), v_max (n)] (the limits as enforced:
        the plant's position limits moved ``limit_margin`` inwards, its velocity limits),
        so one built diagram runs several gains or limits: :meth:`set_gains`,
        :meth:`set_limits`, :meth:`get_parameters`. ``period``, ``method`` and whether
        the tool-axis task is on (``orientation_gain > 0`` in ``config``) are structural:
        they choose the events and the update.

        Scalar types: double and AutoDiffXd (the kinematics of ``plant`` converted). The
        kinematics at ``q_d`` come from a context of ``plant`` kept in a cache entry that
        depends on the discrete state.

        Parameters
        ----------
        plant : MultibodyPlant
            Finalised plant holding the arm: the arm alone
            (:func:`~hemg_drake.robots.baxter.make_arm_controller_plant`) or with a scene.
        model_instance : ModelInstanceIndex
            The arm's model instance; its joints are the controlled ones.
        frame_E : Frame
            Frame of ``plant`` that carries the tool point E.
        config : ClikConfig
            ``gain``, ``method``, ``damping``, ``period``, ``limit_margin``,
            ``orientation_gain``, ``axis_E``, ``axis_W_desired`` (see the config).
        p_EoE_E : array, shape (3,), optional
            Tool point in ``frame_E`` (m); default its origin.
        """

        def _construct(
            self, *, plant, model_instance, frame_E, config=None, p_EoE_E=None, converter=None
        ):
            LeafSystem_[T].__init__(self, converter)
            config = ClikConfig() if config is None else config
            self._args = dict(
                plant=plant,
                model_instance=model_instance,
                frame_E=frame_E,
                config=config,
                p_EoE_E=p_EoE_E,
            )
            if config.method not in CLIK_METHODS:
                raise ValueError(
                    f"Clik method must be one of {CLIK_METHODS}, got {config.method!r}"
                )
            self._method = config.method
            gain = as_scalar("Clik gain", config.gain)
            self._period = as_scalar("Clik period", config.period)
            damping = as_scalar("Clik damping", config.damping, strict=False)
            margin = as_scalar("Clik limit_margin", config.limit_margin, strict=False)
            p_EoE_E = np.zeros(3) if p_EoE_E is None else as_vector("Clik p_EoE_E", p_EoE_E, 3)
            self._axis_E = unit_direction("Clik axis_E", config.axis_E).tolist()
            self._axis_W = unit_direction("Clik axis_W_desired", config.axis_W_desired).tolist()
            orientation_gain = self._checked_orientation_gain(config.orientation_gain)
            self._axis_task = orientation_gain > 0.0
            nq = plant.num_positions(model_instance)
            if nq != plant.num_velocities(model_instance):
                raise ValueError("Clik needs a model instance with one velocity per position")
            self._n = n = nq
            self._plant = plant if T is float else plant.ToScalarType[T]()
            self._model = model_instance
            self._frame_E = self._plant.get_frame(frame_E.index())
            world = self._plant.world_frame()
            self._p_EoE_E = p_EoE_E.tolist()
            # The arguments after the context of the plant's Jacobian calls (point E in W).
            self._jacobian_arguments = (
                JacobianWrtVariable.kV, self._frame_E, p_EoE_E, world, world
            )
            self._point_arguments = (self._frame_E, p_EoE_E, world)
            self._columns = velocity_columns(plant, model_instance)
            lower = plant.GetPositionsFromArray(model_instance, plant.GetPositionLowerLimits())
            upper = plant.GetPositionsFromArray(model_instance, plant.GetPositionUpperLimits())
            v_max = plant.GetVelocityUpperLimits()[self._columns]
            self._sqrt = math.sqrt if T is float else scalar_sqrt
            self._double = T is float
            # [gain, damping, orientation_gain, q_lower, q_upper, v_max]: one read per step.
            law = [gain, damping, orientation_gain]
            law += (lower + margin).tolist() + (upper - margin).tolist() + v_max.tolist()
            self._parameter = self.DeclareNumericParameter(BasicVector_[T](law))

            self._p_desired = self.DeclareVectorInputPort("p_WE_desired", 3)
            self._state = self.DeclareVectorInputPort("state", 2 * n)
            # Discrete state q_d and qdot_d, two groups so that the outputs are the state.
            self._q_d_index = self.DeclareDiscreteState(n)
            self._v_d_index = self.DeclareDiscreteState(n)
            # The plant's context at q_d: forward kinematics and Jacobians on demand.
            self._plant_context = declare_plant_context(
                self, self._plant, self.discrete_state_ticket(self._q_d_index),
                self._set_plant_state,
            )  # fmt: skip
            self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period,
                offset_sec=0.0,
                update=self._update_axis if self._axis_task else self._update,
            )
            self.DeclareStateOutputPort("q_desired", self._q_d_index)
            self.DeclareStateOutputPort("v_desired", self._v_d_index)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._args, converter=converter)

        def _checked_orientation_gain(self, value):
            value = as_scalar("Clik orientation_gain", value, strict=False)
            if value * self._period > 1.0:
                raise ValueError(
                    f"Clik orientation_gain * period must be <= 1 (a stable step), got "
                    f"{value} * {self._period}"
                )
            return value

        def set_gains(self, context, *, gain=None, damping=None, orientation_gain=None):
            """Write the law's gains into ``context`` (this system's own context, e.g.
            ``clik.GetMyMutableContextFromRoot(root_context)``); None keeps a value.

            Parameters
            ----------
            gain : float, K_sp (positive; 1/(m^2 s) transpose, 1/s dls).
            damping : float, the DLS damping (m, >= 0).
            orientation_gain : float, the tool-axis rate (1/s); positive with
                ``period * orientation_gain <= 1`` where the task is on, and only there
                (whether it is on is structural: the config's ``orientation_gain > 0``).
            """
            values = context.get_mutable_numeric_parameter(self._parameter)
            if gain is not None:
                values.SetAtIndex(0, as_scalar("Clik gain", gain))
            if damping is not None:
                values.SetAtIndex(1, as_scalar("Clik damping", damping, strict=False))
            if orientation_gain is not None:
                value = self._checked_orientation_gain(orientation_gain)
                if (value > 0.0) != self._axis_task:
                    raise ValueError(
                        "Clik orientation_gain: the tool-axis task is "
                        f"{'on' if self._axis_task else 'off'} in this system (its config), "
                        f"so it must be {'> 0' if self._axis_task else '0'}, got {value}"
                    )
                values.SetAtIndex(2, value)

        def set_limits(self, context, *, q_lower=None, q_upper=None, v_max=None):
            """Write the enforced joint limits into ``context``; None keeps a value.

            Parameters
            ----------
            q_lower, q_upper : n finite floats (rad), the range ``q_d`` is kept in (any
                margin included), q_lower < q_upper.
            v_max : n positive floats (rad/s), the joint rate bounds.
            """
            n = self._n
            values = context.get_mutable_numeric_parameter(self._parameter)
            current = values.CopyToVector()
            lower = current[3 : 3 + n] if q_lower is None else as_vector("Clik q_lower", q_lower, n)
            upper = (
                current[3 + n : 3 + 2 * n] if q_upper is None
                else as_vector("Clik q_upper", q_upper, n)
            )  # fmt: skip
            if not np.all(np.asarray(lower, dtype=float) < np.asarray(upper, dtype=float)):
                raise ValueError(f"Clik q_lower must be below q_upper, got {lower}, {upper}")
            if v_max is not None:
                v_max = as_vector("Clik v_max", v_max, n)
                if not np.all(v_max > 0.0):
                    raise ValueError(f"Clik v_max must be positive, got {v_max}")
                for j in range(n):
                    values.SetAtIndex(3 + 2 * n + j, v_max[j])
            for j in range(n):
                values.SetAtIndex(3 + j, lower[j])
                values.SetAtIndex(3 + n + j, upper[j])

        def get_parameters(self, context):
            """The gains and limits in ``context``: a dict of ``gain``, ``damping``,
            ``orientation_gain``, ``q_lower``, ``q_upper``, ``v_max`` (arrays)."""
            n = self._n
            values = context.get_numeric_parameter(self._parameter).CopyToVector()
            return dict(
                gain=values[0], damping=values[1], orientation_gain=values[2],
                q_lower=values[3 : 3 + n], q_upper=values[3 + n : 3 + 2 * n],
                v_max=values[3 + 2 * n :],
            )  # fmt: skip

        def _law(self, context):
            """The numeric parameter as a list (a view's for doubles, a copy for
            AutoDiffXd)."""
            group = context.get_numeric_parameter(self._parameter)
            return (group.get_value() if self._double else group.CopyToVector()).tolist()

        def _set_plant_state(self, context, plant_context):
            self._plant.SetPositions(plant_context, self._model, self._q_d(context))

        def _set(self, discrete_state, q_d, v_d):
            if self._double:  # into the buffers' views: no array built
                discrete_state.get_mutable_value(self._q_d_index)[:] = q_d
                discrete_state.get_mutable_value(self._v_d_index)[:] = v_d
                return
            discrete_state.set_value(self._q_d_index, np.array(q_d))
            discrete_state.set_value(self._v_d_index, np.array(v_d))

        def _q_d(self, context):
            """The reference q_d: a view for doubles, a copy for AutoDiffXd (numpy cannot
            reference object arrays)."""
            if T is float:
                return context.get_discrete_state(self._q_d_index).value()
            return context.get_discrete_state(self._q_d_index).CopyToVector()

        def _initialize(self, context, discrete_state):
            n = self._n
            law = self._law(context)
            lower, upper = law[3 : 3 + n], law[3 + n : 3 + 2 * n]
            q = self._state.Eval(context)[:n].tolist()
            q = [min(max(q[j], lower[j]), upper[j]) for j in range(n)]
            self._set(discrete_state, q, [T(0.0)] * self._n)

        def _hold(self, context, discrete_state):
            """A NaN target: hold the reference rather than integrate a NaN into it."""
            q_d = self._q_d(context)
            self._set(discrete_state, q_d, [T(0.0)] * self._n)

        def _update(self, context, discrete_state):
            p_desired = self._p_desired.Eval(context).tolist()
            if not _finite(p_desired[0] + p_desired[1] + p_desired[2]):
                return self._hold(context, discrete_state)
            group = context.get_numeric_parameter(self._parameter)  # as _law, inline
            law = (group.get_value() if self._double else group.CopyToVector()).tolist()
            plant_context = self._plant_context.Eval(context)
            # The Jacobian reuses the forward kinematics of the point's position.
            p_WE = self._plant.CalcPointsPositions(plant_context, *self._point_arguments)
            J = self._plant.CalcJacobianTranslationalVelocity(
                plant_context, *self._jacobian_arguments
            )[:, self._columns]
            # Python floats from here (numpy scalars cost several times more per operation).
            p0, p1, p2 = p_WE.ravel().tolist()
            e0, e1, e2 = p_desired[0] - p0, p_desired[1] - p1, p_desired[2] - p2
            if self._method == "dls":
                G = (J @ J.T).ravel().tolist()
                damping = law[1]
                e0, e1, e2 = _mv(_inverse3(G, damping * damping), (e0, e1, e2))
            J0, J1, J2 = J.tolist()
            gain = law[0]
            qdot = [gain * (J0[j] * e0 + J1[j] * e1 + J2[j] * e2) for j in range(self._n)]
            q_d = self._q_d(context).tolist()
            self._set(discrete_state, *self._limited_step(q_d, qdot, law))

        def _update_axis(self, context, discrete_state):
            """The update with the tool-axis task (the class docstring's law)."""
            p_desired = self._p_desired.Eval(context).tolist()
            if not _finite(p_desired[0] + p_desired[1] + p_desired[2]):
                return self._hold(context, discrete_state)
            group = context.get_numeric_parameter(self._parameter)  # as _law, inline
            law = (group.get_value() if self._double else group.CopyToVector()).tolist()
            plant_context = self._plant_context.Eval(context)
            # One call for R_WE and p_WE (the pose's 4x4 matrix, row-major: 16 scalars).
            X_WE = self._frame_E.CalcPoseInWorld(plant_context).GetAsMatrix4().ravel().tolist()
            J = self._plant.CalcJacobianSpatialVelocity(
                plant_context, *self._jacobian_arguments
            )[:, self._columns]
            qdot = axis_task_rates(
                J,
                X_WE,
                p_desired,
                gain=law[0],
                dls_damping=law[1] if self._method == "dls" else None,
                axis_gain=law[2],
                p_EoE_E=self._p_EoE_E,
                axis_E=self._axis_E,
                axis_W=self._axis_W,
                sqrt=self._sqrt,
            )
            q_d = self._q_d(context).tolist()
            self._set(discrete_state, *self._limited_step(q_d, qdot, law))

        def _limited_step(self, q_d, qdot, law):
            """One integration step within the position and velocity limits: (q, v) lists.

            First each joint's rate is bounded by the room to its own position limits over
            the step: a joint at a limit that ``qdot`` pushes further out stops, and only it.
            Then, if a joint still exceeds ``v_max``, all rates are scaled by one factor
            (direction kept). Finally q = q_d + period * rate (clipped to the limits against
            rounding) and v = (q - q_d) / period.
            """
            n, period = self._n, self._period
            lower, upper, v_max = law[3 : 3 + n], law[3 + n : 3 + 2 * n], law[3 + 2 * n :]
            # Conditional expressions rather than min/max: a third of the cost at 1 kHz, and
            # the same lines run on floats and AutoDiffXd (indices beat zip here, measured).
            rates = []
            ratio = 0.0
            for j in range(n):
                rate, low, high = qdot[j], (lower[j] - q_d[j]) / period, (upper[j] - q_d[j]) / period
                rate = low if rate < low else high if rate > high else rate
                rates.append(rate)
                excess = abs(rate) / v_max[j]
                ratio = excess if excess > ratio else ratio
            q_next, v_next = [], []
            for j in range(n):
                rate = rates[j] / ratio if ratio > 1.0 else rates[j]
                q = q_d[j] + period * rate
                q = lower[j] if q < lower[j] else upper[j] if q > upper[j] else q
                q_next.append(q)
                v_next.append((q - q_d[j]) / period)
            return q_next, v_next

    return Impl


Clik = Clik_[None]


def axis_task_rates(
    J, X_WE, p_WE_desired, *, gain, dls_damping, axis_gain, p_EoE_E, axis_E, axis_W,
    sqrt=math.sqrt,
):
    """The CLIK rates with the tool-axis task in the position task's null space (``Clik``).

    With ``Jw``, ``Jv`` the angular and translational rows of ``J``, a = R_WE axis_E,
    d = axis_W::

        qdot_p = gain Jv^T y,  y = e  or  (Jv Jv^T + dls_damping^2 I)^-1 e   (dls)
        N      = I - Jv^T (Jv Jv^T + nu^2 I)^-1 Jv            (nu = NULL_SPACE_DAMPING)
        P      = I - a a^T,  e_a = angle(a, d) (a x d) / |a x d|
        A      = P Jw N
        qdot   = qdot_p + A^T (A A^T + mu^2 I)^-1 (axis_gain e_a - P Jw qdot_p)

    Computed in 3x3 blocks of J J^T, one product with the 6 x n Jacobian in and one out
    (n-vectors cost a numpy call each): with G = Jv Jv^T, K = Jw Jv^T,
    L = K (G + nu^2 I)^-1 and B = Jw N = Jw - L Jv,
    B B^T = Jw Jw^T - L K^T - nu^2 L L^T (as L G L^T = L K^T - nu^2 L L^T), A A^T = P B B^T P,
    and with w = P (A A^T + mu^2 I)^-1 (...), qdot = J^T [w; gain y - L^T w].
    3x3 matrices are row-major 9-tuples of scalars (floats or AutoDiffXd), written out
    term by term: at 1 kHz each Python call and loop counts.

    Parameters
    ----------
    J : array, shape (6, n), the spatial Jacobian of point E in W (angular rows first).
    X_WE : sequence of 16 scalars, frame E's pose in W as a row-major 4x4 matrix.
    p_WE_desired : sequence of 3 scalars.
    gain, axis_gain : scalars; dls_damping : scalar, or None for the transpose law.
    p_EoE_E, axis_E, axis_W : sequences of 3 (axis_E, axis_W unit).
    sqrt : the square root of the scalar type.

    Returns
    -------
    list of n scalars, rad/s, before the limits.
    """
    (s00, s01, s02, k00, k01, k02), (_, s11, s12, k10, k11, k12), (
        _, _, s22, k20, k21, k22), (_, _, _, g00, g01, g02), (_, _, _, _, g11, g12), (
        _, _, _, _, _, g22) = (J @ J.T).tolist()  # fmt: skip
    R = (*X_WE[0:3], *X_WE[4:7], *X_WE[8:11])
    p0, p1, p2 = _mv(R, p_EoE_E)
    q0, q1, q2 = X_WE[3], X_WE[7], X_WE[11]
    d0, d1, d2 = p_WE_desired
    y = (d0 - (q0 + p0), d1 - (q1 + p1), d2 - (q2 + p2))  # e
    a0, a1, a2 = _mv(R, axis_E)
    G = (g00, g01, g02, g01, g11, g12, g02, g12, g22)
    if dls_damping is not None:
        y = _mv(_inverse3(G, dls_damping * dls_damping), y)
    nu2 = NULL_SPACE_DAMPING * NULL_SPACE_DAMPING
    K = (k00, k01, k02, k10, k11, k12, k20, k21, k22)
    l00, l01, l02, l10, l11, l12, l20, l21, l22 = L = _mm(K, _inverse3(G, nu2))
    # X = B B^T = S_ww - L K^T - nu^2 L L^T (symmetric: six entries).
    x00 = s00 - (l00 * k00 + l01 * k01 + l02 * k02) - nu2 * (l00 * l00 + l01 * l01 + l02 * l02)
    x01 = s01 - (l00 * k10 + l01 * k11 + l02 * k12) - nu2 * (l00 * l10 + l01 * l11 + l02 * l12)
    x02 = s02 - (l00 * k20 + l01 * k21 + l02 * k22) - nu2 * (l00 * l20 + l01 * l21 + l02 * l22)
    x11 = s11 - (l10 * k10 + l11 * k11 + l12 * k12) - nu2 * (l10 * l10 + l11 * l11 + l12 * l12)
    x12 = s12 - (l10 * k20 + l11 * k21 + l12 * k22) - nu2 * (l10 * l20 + l11 * l21 + l12 * l22)
    x22 = s22 - (l20 * k20 + l21 * k21 + l22 * k22) - nu2 * (l20 * l20 + l21 * l21 + l22 * l22)
    # H = P X P with P = I - a a^T: X - a (X a)^T - (X a) a^T + (a^T X a) a a^T.
    xa0 = x00 * a0 + x01 * a1 + x02 * a2
    xa1 = x01 * a0 + x11 * a1 + x12 * a2
    xa2 = x02 * a0 + x12 * a1 + x22 * a2
    axa = a0 * xa0 + a1 * xa1 + a2 * xa2
    h00 = x00 - 2.0 * a0 * xa0 + axa * a0 * a0
    h01 = x01 - a0 * xa1 - xa0 * a1 + axa * a0 * a1
    h02 = x02 - a0 * xa2 - xa0 * a2 + axa * a0 * a2
    h11 = x11 - 2.0 * a1 * xa1 + axa * a1 * a1
    h12 = x12 - a1 * xa2 - xa1 * a2 + axa * a1 * a2
    h22 = x22 - 2.0 * a2 * xa2 + axa * a2 * a2
    H = (h00, h01, h02, h01, h11, h12, h02, h12, h22)
    # Axis error: the rotation vector that turns a onto d.
    d0, d1, d2 = axis_W
    c0, c1, c2 = a1 * d2 - a2 * d1, a2 * d0 - a0 * d2, a0 * d1 - a1 * d0
    s = sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    cosine = a0 * d0 + a1 * d1 + a2 * d2
    scale = axis_gain * _atan2(s, cosine) / s if s > 1e-12 else 0.0 * s
    # r = axis_gain e_a - P Jw qdot_p, with Jw qdot_p = gain K y and P v = v - a (a^T v).
    k0, k1, k2 = _mv(K, y)
    k0, k1, k2 = gain * k0, gain * k1, gain * k2
    ak = a0 * k0 + a1 * k1 + a2 * k2
    r = (scale * c0 - (k0 - a0 * ak), scale * c1 - (k1 - a1 * ak), scale * c2 - (k2 - a2 * ak))
    z0, z1, z2 = _mv(_inverse3(H, AXIS_DAMPING * AXIS_DAMPING), r)
    az = a0 * z0 + a1 * z1 + a2 * z2
    w0, w1, w2 = z0 - a0 * az, z1 - a1 * az, z2 - a2 * az
    # L^T w.
    m0 = l00 * w0 + l10 * w1 + l20 * w2
    m1 = l01 * w0 + l11 * w1 + l21 * w2
    m2 = l02 * w0 + l12 * w1 + l22 * w2
    u = np.array([w0, w1, w2, gain * y[0] - m0, gain * y[1] - m1, gain * y[2] - m2])
    return (u @ J).tolist()


def _mv(A, x):
    """A x for a row-major 3x3 9-tuple and a 3-sequence."""
    x0, x1, x2 = x
    return (
        A[0] * x0 + A[1] * x1 + A[2] * x2,
        A[3] * x0 + A[4] * x1 + A[5] * x2,
        A[6] * x0 + A[7] * x1 + A[8] * x2,
    )


def _mm(A, B):
    """A B for row-major 3x3 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (
        a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
    )  # fmt: skip


def _inverse3(G, damping_squared):
    """(G + damping_squared I)^-1 for a symmetric 3x3 G (row-major 9-tuple), by its adjugate.

    Written out: ``np.linalg.inv`` costs more than these sums at this size and takes no
    AutoDiffXd.
    """
    g00, g01, g02, _, g11, g12, _, _, g22 = G
    g00, g11, g22 = g00 + damping_squared, g11 + damping_squared, g22 + damping_squared
    c00 = g11 * g22 - g12 * g12
    c01 = g02 * g12 - g01 * g22
    c02 = g01 * g12 - g02 * g11
    c11 = g00 * g22 - g02 * g02
    c12 = g01 * g02 - g00 * g12
    c22 = g00 * g11 - g01 * g01
    inverse_det = 1.0 / (g00 * c00 + g01 * c01 + g02 * c02)
    c00, c01, c02 = c00 * inverse_det, c01 * inverse_det, c02 * inverse_det
    c11, c12, c22 = c11 * inverse_det, c12 * inverse_det, c22 * inverse_det
    return (c00, c01, c02, c01, c11, c12, c02, c12, c22)


def _atan2(y, x):
    if isinstance(y, float) and isinstance(x, float):
        return math.atan2(y, x)
    from pydrake.math import atan2

    return atan2(y, x)


def _finite(value):
    """True for a finite float or AutoDiffXd (NaN fails both comparisons)."""
    return -math.inf < value < math.inf


def unit_direction(name, value):
    """``value`` (3 finite numbers, not zero) scaled to unit length, or ValueError naming it."""
    vector = as_vector(name, value, 3)
    norm = float(np.linalg.norm(vector))
    if not norm > 1e-9:
        raise ValueError(f"{name} must be a nonzero direction, got {vector.tolist()}")
    return vector / norm


def velocity_columns(plant, model_instance):
    """Where the model instance's velocities sit among the plant's: a slice if contiguous.

    Index full-plant arrays (J, M, g) with it; a slice gives a view instead of the copy that
    an index array makes.

    Returns
    -------
    slice, or array of int, shape (nv,)
    """
    all_velocities = np.arange(plant.num_velocities(), dtype=float)
    columns = plant.GetVelocitiesFromArray(model_instance, all_velocities).astype(int)
    start = int(columns[0]) if len(columns) else 0
    if np.array_equal(columns, np.arange(start, start + len(columns))):
        return slice(start, start + len(columns))
    return columns
