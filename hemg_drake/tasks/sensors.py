"""Force sensors of the task scenes: what the environment pushes on the slave's end-effector.

Both systems output ``f_WE`` (3, N): the force that the task exerts on the end-effector E,
expressed in the world frame W; the input that :class:`~hemg_drake.teleop.feedback.
ForceFeedback` sends back to the master, and what a demonstration logs.

- :class:`ContactForceSensor` sums the contact forces on one body from the plant's contact
  results (drawing: the pen on the paper).
- :class:`BushingForceSensor` reads the force of a ``LinearBushingRollPitchYaw`` on its frame
  C (cotter pin: the grasp that ties the tool to the pin's ring).
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import LeafSystem


class ContactForceSensor(LeafSystem):
    """Net contact force on one body of a ``MultibodyPlant``, from its contact results.

    .. pydrake_system::

        name: ContactForceSensor
        input_ports:
        - contact_results
        output_ports:
        - f_WE

    ``contact_results`` is the plant's ``ContactResults`` (connect
    ``plant.get_contact_results_output_port()``). ``f_WE`` (3, N, in W) is the sum of the
    forces that every contact exerts on the sensed body: point contacts (``contact_force()``
    acts on geometry B, so a pair whose geometry A is the body's counts with a minus sign) and
    hydroelastic contacts (``F_Ac_W`` acts on the body of geometry M). Moments are dropped:
    the force is what the operator feels at the end-effector point.

    Timing: stateless, direct feedthrough of the contact results. With a discrete plant's
    live output ports (``use_sampled_output_ports=False``, the scenarios' default) they are
    the contacts of the step about to be taken, computed once from the current state and
    inputs and reused by the step itself; with sampled ports (Drake's default) they are
    the last step's, so the force lags the state by one step.

    Parameters
    ----------
    plant : MultibodyPlant
        Finalized; its collision geometries are registered.
    body : Body
        The body whose contact force is sensed (it must have collision geometry).
    """

    def __init__(self, *, plant, body):
        LeafSystem.__init__(self)
        if not plant.is_finalized():
            raise ValueError("ContactForceSensor needs a finalized plant")
        self._geometries = frozenset(plant.GetCollisionGeometriesForBody(body))
        self._body_index = body.index()
        if not self._geometries:
            raise ValueError(f"ContactForceSensor: body {body.name()!r} has no collision geometry")
        self.contact_results_input = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self.f_WE_output = self.DeclareVectorOutputPort("f_WE", 3, self._calc_f_WE)

    def _calc_f_WE(self, context, output):
        results = self.contact_results_input.Eval(context)
        f_WE = np.zeros(3)
        for i in range(results.num_point_pair_contacts()):
            # By body index: the same test as geometry B (or A) being one of the body's,
            # without copying the point pair out of the results.
            info = results.point_pair_contact_info(i)
            if info.bodyB_index() == self._body_index:
                f_WE += info.contact_force()
            elif info.bodyA_index() == self._body_index:
                f_WE -= info.contact_force()
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            surface = info.contact_surface()
            if surface.id_M() in self._geometries:
                f_WE += info.F_Ac_W().translational()
            elif surface.id_N() in self._geometries:
                f_WE -= info.F_Ac_W().translational()
        output.SetFromVector(f_WE)


class BushingForceSensor(LeafSystem):
    """The force of a ``LinearBushingRollPitchYaw`` on its frame C, from the plant's state.

    .. pydrake_system::

        name: BushingForceSensor
        input_ports:
        - state
        output_ports:
        - f_WE

    ``state`` is the whole plant's [q; v] (connect ``plant.get_state_output_port()``).
    ``f_WE`` (3, N, in W) is the resultant of ``CalcBushingSpatialForceOnFrameC`` (Drake
    expresses it in C; here it is rotated into W): the force the bushing exerts on its frame C
    (the end-effector), minus its stiffness and damping times the displacement and rate of C
    from frame A. Evaluated on the sensor's own plant context with the bushing's default
    parameters.

    Timing: stateless, direct feedthrough of the state.

    Parameters
    ----------
    plant : MultibodyPlant
        Finalized, holding ``bushing``.
    bushing : LinearBushingRollPitchYaw
    """

    def __init__(self, *, plant, bushing):
        LeafSystem.__init__(self)
        if not plant.is_finalized():
            raise ValueError("BushingForceSensor needs a finalized plant")
        self._plant = plant
        self._bushing = bushing
        self._frame_C = bushing.frameC()
        self._plant_context = plant.CreateDefaultContext()
        self.state_input = self.DeclareVectorInputPort(
            "state", plant.num_positions() + plant.num_velocities()
        )
        self.f_WE_output = self.DeclareVectorOutputPort("f_WE", 3, self._calc_f_WE)

    def _calc_f_WE(self, context, output):
        self._plant.SetPositionsAndVelocities(self._plant_context, self.state_input.Eval(context))
        F_C_C = self._bushing.CalcBushingSpatialForceOnFrameC(self._plant_context)
        R_WC = self._frame_C.CalcRotationMatrixInWorld(self._plant_context)
        # F.Rotate(R): the same product as R @ f, without pydrake's shape-matching wrapper.
        output.SetFromVector(F_C_C.Rotate(R_WC).translational())
