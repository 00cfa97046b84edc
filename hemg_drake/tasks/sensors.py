"""Force sensors of the task scenes: what the environment pushes on the slave's end-effector.

Both systems output ``f_WE`` (3, N): the force that the task exerts on the end-effector E,
expressed in the world frame W; the input that :class:`~hemg_drake.teleop.feedback.
ForceFeedback` sends back to the master, and what a demonstration logs.

- :class:`ContactForceSensor` sums the contact forces on one body from the plant's contact
  results (drawing: the pen on the paper).
- :class:`BushingForceSensor` reads the force of a ``LinearBushingRollPitchYaw`` on its frame
  C (cotter pin: the grasp that ties the tool to the pin's ring).
"""

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.robots.plant_context import declare_plant_context


@TemplateSystem.define("ContactForceSensor_", T_list=[float])
def ContactForceSensor_(T):
    class Impl(LeafSystem_[T]):
        """Net contact force on one body of a ``MultibodyPlant``, from its contact results.

        .. pydrake_system::

            name: ContactForceSensor
            input_ports:
            - contact_results
            output_ports:
            - f_WE

        ``contact_results`` is the plant's ``ContactResults`` (connect
        ``plant.get_contact_results_output_port()``). ``f_WE`` (3, N, in W) is the sum of
        the forces that every contact exerts on the sensed body: point contacts
        (``contact_force()`` acts on geometry B, so a pair whose geometry A is the body's
        counts with a minus sign) and hydroelastic contacts (``F_Ac_W`` acts on the body of
        geometry M). Moments are dropped: the force is what the operator feels at the
        end-effector point.

        Timing: stateless, direct feedthrough of the contact results. With a discrete
        plant's live output ports (``use_sampled_output_ports=False``, the scenarios'
        default) they are the contacts of the step about to be taken, computed once from
        the current state and inputs and reused by the step itself; with sampled ports
        (Drake's default) they are the last step's, so the force lags the state by one step.

        Scalar types: double only (Clone works). Under AutoDiffXd a plant reports no
        hydroelastic contact and point contact for few shape pairs, so the sensor would
        read zero where the double plant feels the pen; the AutoDiffXd loop
        (``make_slave_station(..., scene=False)``) holds no contact scene.

        Parameters
        ----------
        plant : MultibodyPlant
            Finalized; its collision geometries are registered.
        body : Body
            The body whose contact force is sensed (it must have collision geometry).
        """

        def _construct(self, *, plant, body, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if not plant.is_finalized():
                raise ValueError("ContactForceSensor needs a finalized plant")
            self._args = dict(plant=plant, body=body)
            self._geometries = frozenset(plant.GetCollisionGeometriesForBody(body))
            self._body_index = body.index()
            if not self._geometries:
                raise ValueError(
                    f"ContactForceSensor: body {body.name()!r} has no collision geometry"
                )
            self.contact_results_input = self.DeclareAbstractInputPort(
                "contact_results", AbstractValue.Make(ContactResults_[T]())
            )
            self.f_WE_output = self.DeclareVectorOutputPort(
                "f_WE",
                3,
                self._calc_f_WE,
                prerequisites_of_calc={self.contact_results_input.ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._args, converter=converter)

        def _calc_f_WE(self, context, output):
            results = self.contact_results_input.Eval(context)
            f_WE = [0.0, 0.0, 0.0]
            for i in range(results.num_point_pair_contacts()):
                # By body index: the same test as geometry B (or A) being one of the body's,
                # without copying the point pair out of the results.
                info = results.point_pair_contact_info(i)
                if info.bodyB_index() == self._body_index:
                    f_WE = [f + g for f, g in zip(f_WE, info.contact_force().tolist())]
                elif info.bodyA_index() == self._body_index:
                    f_WE = [f - g for f, g in zip(f_WE, info.contact_force().tolist())]
            for i in range(results.num_hydroelastic_contacts()):
                info = results.hydroelastic_contact_info(i)
                surface = info.contact_surface()
                force = info.F_Ac_W().translational().tolist()
                if surface.id_M() in self._geometries:
                    f_WE = [f + g for f, g in zip(f_WE, force)]
                elif surface.id_N() in self._geometries:
                    f_WE = [f - g for f, g in zip(f_WE, force)]
            output.SetFromVector(f_WE)

    return Impl


ContactForceSensor = ContactForceSensor_[None]


@TemplateSystem.define("BushingForceSensor_", T_list=[float, AutoDiffXd])
def BushingForceSensor_(T):
    class Impl(LeafSystem_[T]):
        """The force of a ``LinearBushingRollPitchYaw`` on its frame C, from the plant's state.

        .. pydrake_system::

            name: BushingForceSensor
            input_ports:
            - state
            output_ports:
            - f_WE

        ``state`` is the whole plant's [q; v] (connect ``plant.get_state_output_port()``).
        ``f_WE`` (3, N, in W) is the resultant of Drake's
        ``CalcBushingSpatialForceOnFrameC`` (Drake expresses it in C; here it is rotated
        into W): the force the bushing exerts on its frame C (the end-effector), minus its
        stiffness and damping times the displacement and rate of C from frame A. Evaluated
        on a context of the plant kept in a cache entry that depends on ``state``, with the
        bushing's default parameters.

        Timing: stateless, direct feedthrough of the state. Scalar types: double and
        AutoDiffXd (the plant converted).

        Parameters
        ----------
        plant : MultibodyPlant
            Finalized, holding ``bushing``.
        bushing : LinearBushingRollPitchYaw
        """

        def _construct(self, *, plant, bushing, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if not plant.is_finalized():
                raise ValueError("BushingForceSensor needs a finalized plant")
            self._args = dict(plant=plant, bushing=bushing)
            self._plant = plant if T is float else plant.ToScalarType[T]()
            self._bushing = self._plant.get_force_element(bushing.index())
            self._frame_C = self._bushing.frameC()
            self.state_input = self.DeclareVectorInputPort(
                "state", plant.num_positions() + plant.num_velocities()
            )
            self._plant_context = declare_plant_context(
                self, self._plant, self.state_input.ticket(), self._set_plant_state
            )
            self.f_WE_output = self.DeclareVectorOutputPort(
                "f_WE", 3, self._calc_f_WE, prerequisites_of_calc={self.state_input.ticket()}
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._args, converter=converter)

        def _set_plant_state(self, context, plant_context):
            self._plant.SetPositionsAndVelocities(plant_context, self.state_input.Eval(context))

        def _calc_f_WE(self, context, output):
            plant_context = self._plant_context.Eval(context)
            F_C_C = self._bushing.CalcBushingSpatialForceOnFrameC(plant_context)
            R_WC = self._frame_C.CalcRotationMatrixInWorld(plant_context)
            output.SetFromVector(F_C_C.Rotate(R_WC).translational())

    return Impl


BushingForceSensor = BushingForceSensor_[None]
