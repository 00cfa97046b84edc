"""The cotter-pin task (the paper's Fig. 7-8): a pin held by a detent, pulled out by the slave.

Scene (``models/cotter_pin.sdf``, primitives only): a fixture block on a stand in front of
the robot and a pin with a pull ring on a prismatic joint ``pin_slide`` along the **pull
axis, world +z** (up). Joint position x = withdrawal: 0 = in, ``pin_length`` (0.05 m) = out
(success), a stop 0.10 m further so the pulled pin can be lifted clear on its rail.

What holds the pin (all along the joint, nothing collides):

- a **detent**, in :class:`PinResistance`: a spring of ``detent_stiffness`` towards x = 0
  saturated at ``hold_force``, acting while x < ``detent_length`` (3 mm); past it the pin is free of the detent. A pull below
  ``hold_force`` only moves the pin by pull / ``detent_stiffness`` (about 1 mm); a pull above
  it pops the pin out. A position-only force: no stiction threshold to regularise, so it is
  deterministic and stable at a 1 ms step.
- **sliding friction**, viscous: -``sliding_damping`` * xdot, in the same system. It is
  explicit (sampled once per step, like the grasp bushing's damper) rather than the joint's own damping: Drake's SAP solver then has no
  implicit term to solve for and the scene's plant steps about 1.6x faster, while the
  explicit term stays far inside its stability limit (see ``_STABILITY_MARGIN``). (A
  Coulomb term would need a velocity regularisation stiff enough to chatter at 1 ms on a
  0.1 kg pin.)

The **grasp** is a ``LinearBushingRollPitchYaw`` from the pin's ``ring`` frame (A) to the
arm's tool frame (C), attached from the start: translational stiffness ``grasp_stiffness``
and damping ``grasp_damping`` on all three axes, no torsional stiffness or damping (a ring
on a hook turns freely). Why a bushing: it is Drake's own force element, needs no port of
the plant, and its force is read back exactly (:class:`~hemg_drake.tasks.sensors.
BushingForceSensor`); the task never releases the ring, so a switchable spring would add a
port and a mode for nothing. The interaction force ``f_WE`` is the bushing's force on the
tool in W: pointing down (-z) while the slave pulls on a pin that holds.

Tuning with :class:`~hemg_drake.control.pd.VariableGainPd` (default per-joint scale), CLIK
following :func:`~hemg_drake.tasks.plans.default_cotter_pin_plan` (0.10 m of travel): the measured peak pulls on
the tool, 18 N at K = 5, 34 N at K = 10 and 48 N at K = 15, leave the pin in
(``hold_force`` = 50 N), while K = 20 and above pull it out (the EMG chain's defaults give
K = 10 at rest and 100 at full contraction); ``docs/tasks.md`` lists the runs.
"""

import copy
import dataclasses as dc

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import RigidTransform
from pydrake.multibody.tree import LinearBushingRollPitchYaw
from pydrake.systems.framework import BasicVector_, LeafSystem_, NumericParameterIndex
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.robots.baxter import make_parser
from hemg_drake.tasks.config import CotterPinParams
from hemg_drake.tasks.placement import DEFAULT_POSITIONS, checked_scene_pose
from hemg_drake.tasks.plans import COTTER_PIN_MODEL, PULL_AXIS_W, pin_geometry, pin_length
from hemg_drake.tasks.sensors import BushingForceSensor

# Where the ring waits by default (the scene frame T's origin, ``scene.position`` in a
# scenario): the tool point p_WE at BaxterArm.home_positions, to the millimetre.
DEFAULT_POSITION = DEFAULT_POSITIONS["cotter_pin"]
# The pin's explicit forces (detent and grasp springs k, friction and grasp dampers c, all
# sampled once per step) on its mass m are stable at the plant's step dt while
# (omega dt)^2 + 2 c dt / m < 4 (omega^2 = k / m; the discrete plant's semi-implicit Euler
# step of a spring-damper). Keep that sum below half its limit.
_STABILITY_MARGIN = 2.0




# double and AutoDiffXd: the law branches on x, which a symbolic x cannot.
@TemplateSystem.define("PinResistance_", T_list=(float, AutoDiffXd))
def PinResistance_(T):
    class Impl(LeafSystem_[T]):
        """The detent and the sliding friction that hold the cotter pin, as a generalized force.

        .. pydrake_system::

            name: PinResistance
            input_ports:
            - pin_state
            output_ports:
            - generalized_force

        ``pin_state`` is the pin model instance's [x; xdot] (m, m/s; connect
        ``plant.get_state_output_port(pin_model)``). ``generalized_force`` (1, N along the
        pull axis) is the detent's spring minus the sliding friction::

            tau = -clip(detent_stiffness * x, -hold_force, hold_force) * [x < detent_length]
                  - sliding_damping * xdot

        a spring back to x = 0 that gives at most ``hold_force`` and lets go past the detent
        (a position-only law: no stiction threshold), and viscous friction. This system is
        the law's one implementation. It drives the pin's own joint actuator
        (``pin_resistance``, added by :func:`add_cotter_pin_scene`) through
        ``plant.get_actuation_input_port(pin_model)``, so the plant's
        ``applied_generalized_force`` input stays free for users.

        Parameters (a numeric parameter of the Context, defaults from ``config``):
        [hold_force (N), detent_length (m), detent_stiffness (N/m), sliding_damping (N s/m)].
        Scalar-convertible between double and AutoDiffXd.

        Timing: stateless, direct feedthrough of the state; the discrete plant samples it
        once per step, so the detent spring and the friction are explicit
        (``add_cotter_pin_scene`` checks their stability at the plant's step).
        """

        def _construct(self, *, config, converter=None):
            """
            Parameters
            ----------
            config : CotterPinParams, the law's defaults (its other fields are the grasp's).
            """
            LeafSystem_[T].__init__(self, converter)
            config = copy.deepcopy(config).check()
            self._config = config  # construction only, for scalar conversion
            self._law = self.DeclareNumericParameter(
                BasicVector_[T](
                    [config.hold_force, config.detent_length, config.detent_stiffness,
                     config.sliding_damping]  # fmt: skip
                )
            )
            self.pin_state_input = self.DeclareVectorInputPort("pin_state", 2)
            self.generalized_force_output = self.DeclareVectorOutputPort(
                "generalized_force",
                1,
                self._calc_generalized_force,
                prerequisites_of_calc={
                    self.pin_state_input.ticket(),
                    self.numeric_parameter_ticket(NumericParameterIndex(self._law)),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, config=other._config, converter=converter)

        def _calc_generalized_force(self, context, output):
            # Plain floats (or AutoDiffXd objects): numpy scalars cost more than the arithmetic.
            x, xdot = self.pin_state_input.Eval(context).tolist()
            law = context.get_numeric_parameter(self._law).CopyToVector()
            hold, length, stiffness, damping = law.tolist()
            spring = -min(max(stiffness * x, -hold), hold)
            detent = spring if x < length else 0.0 * x
            output.SetAtIndex(0, detent - damping * xdot)

    return Impl


PinResistance = PinResistance_[None]


@dc.dataclass(frozen=True, eq=False)
class CotterPinScene:
    """Handles to the cotter-pin scene in a plant, from :func:`add_cotter_pin_scene`.

    Attributes
    ----------
    plant : MultibodyPlant
    model_instance : ModelInstanceIndex, the fixture and pin.
    pin_joint : PrismaticJoint, ``pin_slide``: position = withdrawal (m) along the pull axis.
    ring_frame : Frame, the ring's centre on the pin (the grasp point).
    bushing : LinearBushingRollPitchYaw, the grasp (frame A = ring, frame C = tool).
    pin_length : float, m; the pin is out once withdrawn this far.
    params : CotterPinParams, the scene's own copy.
    X_WT : RigidTransform, the scene frame: the ring's centre (pin in) at its origin.
    """

    plant: object
    model_instance: object
    pin_joint: object
    ring_frame: object
    bushing: object
    pin_length: float
    params: CotterPinParams
    X_WT: RigidTransform

    @property
    def pull_axis_W(self):
        """The pin's pull axis in W, shape (3,): world +z."""
        return PULL_AXIS_W.copy()

    @property
    def hold_force(self):
        """The detent's largest holding force (N): ``params.hold_force``."""
        return self.params.hold_force

    def pin_displacement(self, plant_context):
        """Withdrawal of the pin (m) in a context of the plant."""
        return float(self.pin_joint.get_translation(plant_context))

    def pin_out(self, plant_context):
        """Success: the pin has been withdrawn by at least its length."""
        return self.pin_displacement(plant_context) >= self.pin_length

    def add_systems(self, builder):
        """Add the detent and the force sensor to ``builder`` (once; later calls reuse them).

        Connects :class:`PinResistance` to the actuation input of the pin's own model
        instance (its joint actuator ``pin_resistance``). Call after ``plant.Finalize()``.

        Returns
        -------
        (PinResistance, BushingForceSensor), named ``cotter_pin_detent`` and
        ``cotter_pin_force`` in the builder.
        """
        names = ("cotter_pin_detent", "cotter_pin_force")
        if builder.HasSubsystemNamed(names[0]):
            return tuple(builder.GetSubsystemByName(name) for name in names)
        plant = self.plant
        detent = builder.AddNamedSystem(names[0], PinResistance(config=self.params))
        builder.Connect(plant.get_state_output_port(self.model_instance), detent.pin_state_input)
        builder.Connect(
            detent.generalized_force_output, plant.get_actuation_input_port(self.model_instance)
        )
        sensor = builder.AddNamedSystem(
            names[1], BushingForceSensor(plant=plant, bushing=self.bushing)
        )
        builder.Connect(plant.get_state_output_port(), sensor.state_input)
        return detent, sensor

    def force_output_port(self, builder):
        """The interaction force ``f_WE`` (3, N, in W) on the tool; adds the systems if needed."""
        return self.add_systems(builder)[1].f_WE_output


def add_cotter_pin_scene(plant, arm, *, params=None, X_WT=None):
    """Add the fixture, the pin and the grasp of its ring by the arm's tool to ``plant``.

    Call before ``plant.Finalize()``; after it, :meth:`CotterPinScene.add_systems` (or
    :meth:`~CotterPinScene.force_output_port`) wires the detent and the force sensor.

    Parameters
    ----------
    plant : MultibodyPlant, not finalized, discrete (the detent is checked against its step).
    arm : BaxterArm, from ``add_baxter_arm``; its ``tool_frame`` grasps the ring.
    params : CotterPinParams, optional (default ``CotterPinParams()``).
    X_WT : RigidTransform, optional
        The scene frame (:func:`~hemg_drake.tasks.placement.scene_pose`): the ring's centre
        with the pin in at its origin, the fixture turned by its yaw about world z (the pull
        axis stays world +z); default at ``DEFAULT_POSITION``, unturned.

    Returns
    -------
    CotterPinScene

    Raises
    ------
    ValueError
        Bad parameters (naming the field), a finalized or continuous plant, or springs too
        stiff for the plant's time step.
    """
    params = (CotterPinParams() if params is None else params).check()
    if params.detent_length >= pin_length():
        raise ValueError(
            f"CotterPinParams.detent_length must be shorter than the pin ({pin_length()} m), "
            f"got {params.detent_length}"
        )
    X_WT = checked_scene_pose(X_WT, "cotter_pin")
    if plant.is_finalized():
        raise ValueError("add_cotter_pin_scene must be called before plant.Finalize()")
    dt = plant.time_step()
    if not dt > 0:
        raise ValueError("the cotter-pin scene needs a discrete plant (time_step > 0)")
    (model,) = make_parser(plant).AddModels(str(COTTER_PIN_MODEL))
    pin_joint = plant.GetJointByName("pin_slide", model)
    # The detent and friction act through the pin's own actuator (see PinResistance).
    plant.AddJointActuator("pin_resistance", pin_joint)
    ring_frame = plant.GetFrameByName("ring", model)
    pin_mass = plant.GetBodyByName("pin", model).default_mass()
    stiffness = params.detent_stiffness + params.grasp_stiffness
    damping = params.sliding_damping + params.grasp_damping
    stability = stiffness * dt**2 / pin_mass + 2.0 * damping * dt / pin_mass
    if stability > _STABILITY_MARGIN:
        raise ValueError(
            f"CotterPinParams: springs of {stiffness} N/m (detent_stiffness + "
            f"grasp_stiffness) and dampers of {damping} N s/m (sliding_damping + "
            f"grasp_damping) are too stiff for the {pin_mass} kg pin at time_step {dt} s: "
            f"(omega dt)^2 + 2 c dt / m = {stability:.2f} > {_STABILITY_MARGIN}"
        )
    # The ring's offset above the fixture frame (the hole's mouth) is the model's.
    # fixture_offset moves the physical fixture (and the pin) off the scene frame.
    p_FR = pin_geometry()[1]
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName("fixture", model),
        X_WT @ RigidTransform(np.asarray(params.fixture_offset, dtype=float) - p_FR),
    )
    bushing = plant.AddForceElement(
        LinearBushingRollPitchYaw(
            ring_frame,
            arm.tool_frame,
            np.zeros(3),
            np.zeros(3),
            np.full(3, params.grasp_stiffness),
            np.full(3, params.grasp_damping),
        )
    )
    return CotterPinScene(
        plant=plant,
        model_instance=model,
        pin_joint=pin_joint,
        ring_frame=ring_frame,
        bushing=bushing,
        pin_length=pin_length(),
        params=copy.deepcopy(params),  # the scene's own: later edits cannot change it
        X_WT=RigidTransform(X_WT),
    )
