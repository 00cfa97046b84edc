"""Closed-loop inverse kinematics (CLIK) of the slave's tool point, eq. 21."""

import math

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.control import _kernels
from hemg_drake.control._kernels import (
    axis_step_into,
    limited_step_into,
    transpose_point_step_into,
)

CLIK_METHODS = ("transpose", "dls")
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


class Clik(LeafSystem):
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

    Parameters
    ----------
    plant : MultibodyPlant
        Finalised plant holding the arm (and possibly a scene).
    model_instance : ModelInstanceIndex
        The arm's model instance; its joints are the controlled ones.
    frame_E : Frame
        Frame that carries the tool point E.
    p_EoE_E : array, shape (3,), optional
        Tool point in ``frame_E`` (m); default its origin.
    gain : float
        CLIK gain ``K_sp``: 1/(m^2 s) for the transpose law, 1/s for dls.
    method : {"transpose", "dls"}
    damping : float
        DLS damping (m); used with ``method="dls"``.
    period : float
        Update period (s).
    limit_margin : float
        Distance kept inside each position limit (rad).
    axis_E : array, shape (3,)
        Direction fixed in ``frame_E``, the tool's axis (default its z, the pen's axis
        from the hand toward the tip); normalised here.
    axis_W_desired : array, shape (3,)
        Direction in W that ``axis_E`` is turned onto (default world -z, pen down);
        normalised here.
    orientation_gain : float
        Rate of the tool-axis task (1/s); 0 (default) turns it off.
    """

    def __init__(
        self,
        *,
        plant,
        model_instance,
        frame_E,
        p_EoE_E=None,
        gain=300.0,
        method="transpose",
        damping=0.05,
        period=1e-3,
        limit_margin=0.02,
        axis_E=(0.0, 0.0, 1.0),
        axis_W_desired=(0.0, 0.0, -1.0),
        orientation_gain=0.0,
    ):
        LeafSystem.__init__(self)
        if method not in CLIK_METHODS:
            raise ValueError(f"Clik method must be one of {CLIK_METHODS}, got {method!r}")
        self._gain = as_scalar("Clik gain", gain)
        self._period = as_scalar("Clik period", period)
        self._damping = as_scalar("Clik damping", damping, strict=False)
        limit_margin = as_scalar("Clik limit_margin", limit_margin, strict=False)
        self._p_EoE_E = np.zeros(3) if p_EoE_E is None else as_vector("Clik p_EoE_E", p_EoE_E, 3)
        self._axis_E = unit_direction("Clik axis_E", axis_E)
        self._axis_W_desired = unit_direction("Clik axis_W_desired", axis_W_desired)
        self._orientation_gain = as_scalar(
            "Clik orientation_gain", orientation_gain, strict=False
        )
        if self._orientation_gain * self._period > 1.0:
            raise ValueError(
                f"Clik orientation_gain * period must be <= 1 (a stable step), got "
                f"{self._orientation_gain} * {self._period}"
            )
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._model = model_instance
        self._frame_E = frame_E
        self._world = plant.world_frame()
        self._method = method
        # The arguments after the context of the plant's Jacobian calls (point E in W).
        self._jacobian_arguments = (
            JacobianWrtVariable.kV,
            frame_E,
            self._p_EoE_E,
            self._world,
            self._world,
        )

        nq = plant.num_positions(model_instance)
        nv = plant.num_velocities(model_instance)
        if nq != nv:
            raise ValueError("Clik needs a model instance with one velocity per position")
        self._n = nq
        # Columns of the full-plant Jacobian that belong to the arm.
        self._v_columns = velocity_columns(plant, model_instance)
        lower = plant.GetPositionsFromArray(model_instance, plant.GetPositionLowerLimits())
        upper = plant.GetPositionsFromArray(model_instance, plant.GetPositionUpperLimits())
        self._q_lower = lower + limit_margin
        self._q_upper = upper - limit_margin
        self._v_max = plant.GetVelocityUpperLimits()[self._v_columns]
        self._zeros = np.zeros(self._n)
        # For the compiled steps, made once: column indices, the limits in their argument
        # orders, and one (2, n) output buffer whose rows are q_next and v_next.
        self._columns = np.arange(plant.num_velocities())[self._v_columns]
        self._limits = (self._v_max, self._q_lower, self._q_upper, self._period)
        self._next = np.zeros((2, self._n))
        self._q_next, self._v_next = self._next
        # The axis step's constants, packed in one array (see _kernels.TASK_*).
        self._task = np.zeros(_kernels.TASK_SIZE)
        self._task[_kernels.TASK_GAIN] = self._gain
        self._task[_kernels.TASK_DLS] = float(method == "dls")
        self._task[_kernels.TASK_DAMPING] = self._damping
        self._task[_kernels.TASK_AXIS_GAIN] = self._orientation_gain
        self._task[_kernels.TASK_AXIS_DAMPING] = AXIS_DAMPING
        self._task[_kernels.TASK_NULL_DAMPING] = NULL_SPACE_DAMPING
        self._task[_kernels.TASK_PERIOD] = self._period
        self._task[_kernels.TASK_P_EOE_E] = self._p_EoE_E
        self._task[_kernels.TASK_AXIS_E] = self._axis_E
        self._task[_kernels.TASK_AXIS_W] = self._axis_W_desired
        self._limit_rows = np.array([self._v_max, self._q_lower, self._q_upper])
        self._transpose_arguments = (self._columns, self._gain, self._limit_rows, self._period)

        self._p_desired = self.DeclareVectorInputPort("p_WE_desired", 3)
        self._state = self.DeclareVectorInputPort("state", 2 * self._n)
        # Discrete state q_d and qdot_d, two groups so that the outputs are the state itself.
        self._q_d_index = self.DeclareDiscreteState(self._n)
        self._v_d_index = self.DeclareDiscreteState(self._n)
        self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=self._period,
            offset_sec=0.0,
            update=self._update_axis if self._orientation_gain > 0.0 else self._update,
        )
        self.DeclareStateOutputPort("q_desired", self._q_d_index)
        self.DeclareStateOutputPort("v_desired", self._v_d_index)

    def _set(self, discrete_state, q_d, v_d):
        discrete_state.set_value(self._q_d_index, q_d)
        discrete_state.set_value(self._v_d_index, v_d)

    def _initialize(self, context, discrete_state):
        q = np.clip(self._state.Eval(context)[: self._n], self._q_lower, self._q_upper)
        self._set(discrete_state, q, self._zeros)

    def p_WE(self, q):
        """Tool-point position for arm configuration ``q`` (m), by forward kinematics."""
        self._plant.SetPositions(self._plant_context, self._model, q)
        return self._plant.CalcPointsPositions(
            self._plant_context, self._frame_E, self._p_EoE_E, self._world
        ).ravel()

    def _jacobian(self):
        """The plant's (3, nv) translational Jacobian of E in W, at the last p_WE() positions."""
        return self._plant.CalcJacobianTranslationalVelocity(
            self._plant_context, *self._jacobian_arguments
        )

    def qdot(self, q, p_WE_desired):
        """The CLIK joint velocity of eq. 21 at ``q`` (rad/s), before limits.

        The position law alone: the tool-axis task, when on, is added in the compiled step.
        """
        # The Jacobian reuses the forward kinematics that p_WE cached in the plant context.
        e = np.asarray(p_WE_desired, float) - self.p_WE(q)
        J = self._jacobian()[:, self._v_columns]
        if self._method == "transpose":
            return self._gain * J.T @ e
        JJt = J @ J.T + self._damping**2 * np.eye(3)
        return self._gain * J.T @ np.linalg.solve(JJt, e)

    def _update(self, context, discrete_state):
        q_d = context.get_discrete_state(self._q_d_index).value()
        p_desired = self._p_desired.Eval(context)
        if self._method == "transpose":
            # The sums of qdot() and of the limits, and the NaN check, in one compiled call
            # (tests compare them); the Jacobian reuses the kinematics of the point's position.
            plant, plant_context = self._plant, self._plant_context
            plant.SetPositions(plant_context, self._model, q_d)
            p_WE = plant.CalcPointsPositions(
                plant_context, self._frame_E, self._p_EoE_E, self._world
            )
            J = plant.CalcJacobianTranslationalVelocity(plant_context, *self._jacobian_arguments)
            if transpose_point_step_into(
                self._next, q_d, J, p_WE, p_desired, *self._transpose_arguments
            ):
                discrete_state.set_value(self._q_d_index, self._q_next)
                discrete_state.set_value(self._v_d_index, self._v_next)
                return
        elif all(map(math.isfinite, p_desired.tolist())):
            limited_step_into(
                self._q_next, self._v_next, q_d, self.qdot(q_d, p_desired), *self._limits
            )
            self._set(discrete_state, self._q_next, self._v_next)
            return
        # Hold the reference rather than integrate a NaN into it.
        self._set(discrete_state, q_d, self._zeros)

    def _update_axis(self, context, discrete_state):
        """The update with the tool-axis task: one forward kinematics (SetPositions, then the
        pose) that the Jacobian reuses, then the NaN check, both tasks and the limits in one
        compiled call. Written out rather than shared with _update: at 1 kHz each Python call
        and lookup counts."""
        q_d = context.get_discrete_state(self._q_d_index).value()
        p_desired = self._p_desired.Eval(context)
        plant, plant_context = self._plant, self._plant_context
        plant.SetPositions(plant_context, self._model, q_d)
        X_WE = self._frame_E.CalcPoseInWorld(plant_context).GetAsMatrix4()
        J = plant.CalcJacobianSpatialVelocity(plant_context, *self._jacobian_arguments)
        if axis_step_into(
            self._next, q_d, J, X_WE, p_desired, self._columns, self._task, self._limit_rows
        ):
            discrete_state.set_value(self._q_d_index, self._q_next)
            discrete_state.set_value(self._v_d_index, self._v_next)
        else:  # a NaN target: hold the reference, as _update does
            self._set(discrete_state, q_d, self._zeros)


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
    an index array makes, which counts in the 1 kHz controllers.

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
