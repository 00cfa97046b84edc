"""A Cartesian stiffness at the tool on eq. 20's joint PD path (``reproduction.stiffness: spd``).

Eq. 20 gives joint j the stiffness K s_j (:mod:`hemg_drake.control.pd`); seen at the tool
point, with J the translational Jacobian of E (3 x n) and W = diag(s), that is the Cartesian
stiffness

    K_x^0 = K (J W^-1 J^T)^-1                       (N/m; eq. 20's, shaped by the arm)

Here the shape at the tool is the learnt one instead, S_hat (3 x 3, SPD, unit determinant:
:mod:`hemg_drake.learning.stiffness`), scaled by K and by the harmonic mean of K_x^0's
eigenvalues per unit of K:

    c   = 3 / trace(J W^-1 J^T)                     (N/m per unit of K)
    K_x = K c S_hat

so an isotropic S_hat = I has exactly the mean compliance of eq. 20 at the same K and q, and
any other unit-determinant shape is softer on average (AM-GM), never stiffer. The joint
stiffness keeps eq. 20's in the null space of the tool point:

    K_q = J^T K_x J + N^T (K W) N,   N = I - W^-1 J^T (J W^-1 J^T)^-1 J
        = K W + J^T (K_x - K_x^0) J                 (N^T W N = W - J^T (J W^-1 J^T)^-1 J)

N is the projector onto J's null space orthogonal in the metric W (the stiffness-weighted
pseudo-inverse), so a motion of the tool point meets K_x and a self-motion meets K W. K_q is
symmetric positive definite whenever S_hat is (both terms are positive semidefinite and no
non-zero dq is in both null spaces), and with K_x = K_x^0 it is eq. 20's K W exactly. The
damping keeps eq. 20's form on K_q's diagonal, d_j = 2 zeta sqrt(K_q,jj M_jj(q)), and the
torque is

    tau = clip(K_q (q_d - q) + diag(d) (v_d - v) + tau_ff, +-effort_limit).

Applied to the CLIK's joint reference (eq. 21), J (q_d - q) is to first order the tool's
position error, so the law is a Cartesian impedance at the tool on the existing PD path.
The scalar case (``reproduction.stiffness: scalar``) is eq. 20's own
:class:`~hemg_drake.control.pd.VariableGainPd`, untouched.
"""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.control.axis_task import inverse3
from hemg_drake.control.pd import VariableGainPd_, add_variable_gain_pd

SHAPE_SIZE = 9  # the 3 x 3 shape, row-major


def impedance_joint_stiffness(J, gain, scale, shape):
    """K_q = K W + J^T (K c S_hat - K_x^0) J of the module docstring, shape (n, n).

    Parameters
    ----------
    J : array, shape (3, n), the tool point's translational Jacobian (m/rad).
    gain : float, K (dimensionless).
    scale : array, shape (n,), s_j (N m/rad per unit of K).
    shape : array, shape (3, 3), S_hat (symmetric positive definite).

    Works on floats and on AutoDiffXd (object arrays): products and a 3 x 3 adjugate only.
    """
    C = (J / scale) @ J.T  # J W^-1 J^T, per unit of K
    C_inverse = np.array(inverse3(C.ravel().tolist(), 0.0)).reshape(3, 3)
    mean = 3.0 / (C[0, 0] + C[1, 1] + C[2, 2])
    correction = mean * np.asarray(shape) - C_inverse
    return gain * (np.diag(scale) + J.T @ correction @ J)


@TemplateSystem.define("CartesianImpedancePd_", T_list=[float, AutoDiffXd])
def CartesianImpedancePd_(T):
    class Impl(VariableGainPd_[T]):
        """Joint PD whose stiffness is a learnt Cartesian stiffness at the tool (eq. 20's
        scalar K times a shape), eq. 20's own stiffness in the null space.

        .. pydrake_system::

            name: CartesianImpedancePd
            input_ports:
            - q_desired
            - v_desired
            - state
            - gain
            - feedforward_torque
            - stiffness_shape
            output_ports:
            - torque

        Ports, parameters, timing and scalar types as
        :class:`~hemg_drake.control.pd.VariableGainPd` (``set_gains``/``get_gains`` too),
        plus ``stiffness_shape`` (9, S_hat row-major, dimensionless; the identity when not
        connected). Law: the module docstring, K_q = K W + J^T (K c S_hat - K_x^0) J, with
        M(q) and J(q) of the tool point ``arm.tool_frame`` computed on the controller
        plant's context kept in a cache entry that depends on ``state``.
        """

        def _construct(self, *, plant, arm, config=None, converter=None):
            """
            Parameters
            ----------
            plant : MultibodyPlant (double), finalized, containing ``arm``.
            arm : BaxterArm of ``plant`` (its ``tool_frame`` is the point E).
            config : PdConfig.
            """
            VariableGainPd_[T]._construct(
                self, plant=plant, arm=arm, config=config, converter=converter
            )
            frame_E = self._plant.get_frame(arm.tool_frame.index())
            world = self._plant.world_frame()
            self._jacobian_arguments = (
                JacobianWrtVariable.kV, frame_E, np.zeros(3), world, world
            )  # fmt: skip
            self._identity = np.eye(3).ravel().tolist()
            self.shape_input = self.DeclareVectorInputPort("stiffness_shape", SHAPE_SIZE)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._args, converter=converter)

        def _calc_torque(self, context, output):
            n = self._n
            x = self.state_input.Eval(context)
            v_desired = (
                self.v_desired_input.Eval(context)
                if self.v_desired_input.HasValue(context)
                else np.array(self._zeros)
            )
            feedforward = (
                self.feedforward_input.Eval(context)
                if self.feedforward_input.HasValue(context)
                else np.array(self._zeros)
            )
            shape = (
                self.shape_input.Eval(context).tolist()
                if self.shape_input.HasValue(context)
                else self._identity
            )
            law = context.get_numeric_parameter(self._parameter).CopyToVector()
            gain = (
                self.gain_input.Eval(context)[0] if self.gain_input.HasValue(context) else law[0]
            )
            if not (0.0 < gain < np.inf):
                raise ValueError(
                    f"CartesianImpedancePd: gain input must be a positive finite number, "
                    f"got {gain}"
                )
            q_desired = self.q_desired_input.Eval(context)
            total = sum(q_desired) + sum(v_desired) + sum(shape)  # NaN/inf spread to the sum
            if not (-np.inf < total < np.inf):
                raise ValueError(
                    "CartesianImpedancePd: q_desired/v_desired/stiffness_shape contain NaN or inf"
                )
            plant_context = self._plant_context.Eval(context)
            M = self._plant.CalcMassMatrix(plant_context)
            J = self._plant.CalcJacobianTranslationalVelocity(
                plant_context, *self._jacobian_arguments
            )[:, self._columns]
            scale, zeta, limit = law[1 : n + 1], law[n + 1], law[n + 2 :]
            K_q = impedance_joint_stiffness(J, gain, scale, np.reshape(shape, (3, 3)))
            mass = M.diagonal()[self._columns]
            damping = np.array(
                [2.0 * zeta * (K_q[j, j] * mass[j]) ** 0.5 for j in range(n)]
            )
            torque = (
                K_q @ (q_desired - x[:n]) + damping * (v_desired - x[n:]) + feedforward
            )
            output.SetFromVector(
                [min(max(tau, -high), high) for tau, high in zip(torque, limit, strict=True)]
            )

    return Impl


CartesianImpedancePd = CartesianImpedancePd_[None]


def add_cartesian_impedance_pd(builder, *, plant, arm, state_port, config=None, name="pd"):
    """Add a :class:`CartesianImpedancePd` as :func:`~hemg_drake.control.pd.
    add_variable_gain_pd` adds eq. 20's PD (same wiring, gravity compensation included);
    connect its ``stiffness_shape`` too."""
    system = CartesianImpedancePd(plant=plant, arm=arm, config=config)
    return add_variable_gain_pd(
        builder, plant=plant, arm=arm, state_port=state_port, config=config, name=name,
        system=system,
    )  # fmt: skip
