"""An external push on the arm: a force at the tool point as joint torques, tau = J^T F.

Not one of the paper's equations: a disturbance for the stiffness study
(``docs/studies.md``), the same transpose that maps any force at the tool point E into the
joints (eq. 20's PD meets it as a torque it must resist). The force's time course comes from
Drake's ``TrajectorySource`` (:func:`push_trajectory`: a zero-order hold, 0 before and after
the push); :class:`ToolPointForce` turns it into the plant's ``applied_generalized_force``
(the station's free input).
"""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_, NumericParameterIndex
from pydrake.systems.scalar_conversion import TemplateSystem
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.control.pd import plant_for_scalar
from hemg_drake.robots.plant_context import declare_plant_context


def push_trajectory(f_W, start, duration):
    """The push's force over time (N, W): ``f_W`` during [start, start + duration), zero
    before and after; a ``PiecewisePolynomial`` zero-order hold for ``TrajectorySource``.

    Parameters
    ----------
    f_W : 3 floats, N, in W.
    start, duration : float, s (start >= 0, duration > 0).
    """
    f_W = as_vector("push force", f_W, 3)
    start = as_scalar("push start", start, strict=False)
    duration = as_scalar("push duration", duration)
    times = [0.0, start, start + duration, start + duration + 1.0] if start > 0 else [
        0.0, duration, duration + 1.0]  # fmt: skip
    zero = np.zeros(3)
    values = [zero, f_W, zero, zero] if start > 0 else [f_W, zero, zero]
    return PiecewisePolynomial.ZeroOrderHold(times, np.column_stack(values))


@TemplateSystem.define("ToolPointForce_", T_list=[float, AutoDiffXd])
def ToolPointForce_(T):
    class Impl(LeafSystem_[T]):
        """A force at the arm's tool point as generalized forces of the whole plant.

        .. pydrake_system::

            name: ToolPointForce
            input_ports:
            - arm_state
            - f_W
            output_ports:
            - generalized_force

        ``arm_state`` ([q; v], 14: the arm model instance's state), ``f_W`` (3, N, in W: the
        force applied at the tool point E). ``generalized_force`` (the plant's
        num_velocities, N m and N): tau = enabled * J_v^T f_W in the arm's columns, zero in
        the others (the cotter pin's slide), where J_v (3 x 7) is the translational
        Jacobian of E in W with respect to the arm's velocities, from ``controller_plant``
        (the arm alone) on a context cached per ``arm_state``. For the plant's
        ``applied_generalized_force`` input (the station's of that name).

        Parameters in the Context: [enabled] (1 by default; 0 switches the push off, as the
        reproduction's settling does, :func:`set_enabled`). Timing: stateless, direct
        feedthrough. Scalar types: double and AutoDiffXd.

        Parameters
        ----------
        controller_plant : MultibodyPlant of the arm alone (finalized).
        arm : BaxterArm of ``controller_plant`` (its ``tool_frame`` is E).
        columns : slice or array of int, the arm's velocities among the station plant's.
        num_velocities : int, the station plant's number of velocities.
        """

        def _construct(self, *, controller_plant, arm, columns, num_velocities,
                       converter=None):  # fmt: skip
            LeafSystem_[T].__init__(self, converter)
            self._args = dict(controller_plant=controller_plant, arm=arm, columns=columns,
                              num_velocities=num_velocities)  # fmt: skip
            self._plant = plant_for_scalar(controller_plant, T)
            self._n = len(arm.joint_names)
            self._columns = columns
            frame_E = self._plant.get_frame(arm.tool_frame.index())
            world = self._plant.world_frame()
            self._jacobian_arguments = (JacobianWrtVariable.kV, frame_E, np.zeros(3), world,
                                        world)  # fmt: skip
            self._zeros = [T(0.0)] * num_velocities
            self._enabled = self.DeclareNumericParameter(BasicVector_[T]([1.0]))
            self.arm_state_input = self.DeclareVectorInputPort("arm_state", 2 * self._n)
            self.f_W_input = self.DeclareVectorInputPort("f_W", 3)
            self._plant_context = declare_plant_context(
                self, self._plant, self.arm_state_input.ticket(), self._set_plant_state
            )
            self.generalized_force_output = self.DeclareVectorOutputPort(
                "generalized_force",
                num_velocities,
                self._calc_generalized_force,
                prerequisites_of_calc={
                    self.all_input_ports_ticket(),
                    self.numeric_parameter_ticket(NumericParameterIndex(self._enabled)),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._args, converter=converter)

        def set_enabled(self, context, enabled):
            """Switch the push on (True) or off (False) in this system's ``context``."""
            context.get_mutable_numeric_parameter(self._enabled).SetAtIndex(
                0, 1.0 if enabled else 0.0
            )

        def _set_plant_state(self, context, plant_context):
            x = self.arm_state_input.Eval(context)
            self._plant.SetPositions(plant_context, x[: self._n])
            self._plant.SetVelocities(plant_context, x[self._n :])

        def _calc_generalized_force(self, context, output):
            f_W = self.f_W_input.Eval(context)
            enabled = context.get_numeric_parameter(self._enabled).GetAtIndex(0)
            J = self._plant.CalcJacobianTranslationalVelocity(
                self._plant_context.Eval(context), *self._jacobian_arguments
            )
            tau = np.array(self._zeros)
            tau[self._columns] = enabled * (J.T @ f_W)
            output.SetFromVector(tau)

    return Impl


ToolPointForce = ToolPointForce_[None]
