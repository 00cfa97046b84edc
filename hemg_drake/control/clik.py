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
from hemg_drake.control.axis_task import (  # noqa: F401 (the dampings: Clik's API)
    AXIS_DAMPING,
    NULL_SPACE_DAMPING,
    axis_task_rates,
    inverse3,
    mv3,
)
from hemg_drake.control.config import CLIK_METHODS, ClikConfig
from hemg_drake.robots.plant_context import declare_plant_context




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
            law = self._law(context)
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
                e0, e1, e2 = mv3(inverse3(G, damping * damping), (e0, e1, e2))
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
            law = self._law(context)
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
