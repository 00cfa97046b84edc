"""The slave station: the Baxter arm, its task scene and its controllers as one sub-diagram.

In the spirit of Drake's ``MakeHardwareStation``: one builder turns a scenario into a
``Diagram`` with named exported ports, and every diagram of this package (demonstration,
reproduction, plan follower, arm tour) drives the slave through them::

    station = make_slave_station(scenario)
    builder.AddSystem(station.diagram)
    builder.Connect(reference, station.diagram.GetInputPort("p_WE_desired"))

Inside: the ``MultibodyPlant`` and ``SceneGraph`` (``scenario.plant``), the arm
(:func:`~hemg_drake.robots.baxter.add_baxter_arm`), the task's scene placed at
``scenario.X_WT()`` with its own systems (the cotter pin's detent on the pin's actuator, the
force sensors), the CLIK (eq. 21) and the variable-gain PD (eq. 20), and the tool point's
kinematics. The plant's ``applied_generalized_force`` input is exported untouched, free for
the user's own forces. With ``visualization=`` (a loopback Meshcat,
:class:`~hemg_drake.diagrams.visualization.Visualization`), ``scenario.visualization`` is
applied inside the station's builder (``ApplyVisualizationConfig``); without, it has no
visualiser.
"""

import dataclasses as dc

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform_
from pydrake.multibody.math import SpatialVelocity_
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.framework import DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import ConstantVectorSource, SharedPointerSystem
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.control.clik import Clik
from hemg_drake.control.ik import solve_tool_point_ik
from hemg_drake.control.impedance import add_cartesian_impedance_pd
from hemg_drake.control.pd import add_variable_gain_pd
from hemg_drake.diagrams.visualization import apply_visualization
from hemg_drake.robots.baxter import add_baxter_arm, make_arm_controller_plant
from hemg_drake.tasks.block import add_block
from hemg_drake.tasks.cotter_pin import add_cotter_pin_scene
from hemg_drake.tasks.drawing import add_drawing_scene

# Each task's scene: added to the plant before Finalize, its handle has force_output_port.
SCENE_BUILDERS = {"cotter_pin": add_cotter_pin_scene, "drawing": add_drawing_scene}
# How the station is driven: a tool-point reference through the CLIK, or joint references.
REFERENCES = ("tool_point", "joints")
# The PD's stiffness: eq. 20's scalar K, or a Cartesian stiffness at the tool.
STIFFNESSES = ("scalar", "spd")


@TemplateSystem.define("ToolPointKinematics_", T_list=[float, AutoDiffXd])
def ToolPointKinematics_(T):
    class Impl(LeafSystem_[T]):
        """Position, velocity and orientation of the tool frame E in the world, from the
        plant's body kinematics.

        .. pydrake_system::

            name: ToolPointKinematics
            input_ports:
            - body_poses
            - body_spatial_velocities
            output_ports:
            - p_WE
            - v_WE
            - R_WE

        ``body_poses`` and ``body_spatial_velocities`` are the plant's output ports of the
        same names (the poses X_WB and spatial velocities V_WB of every body, which the
        plant computes for its own step). ``p_WE`` (3, m) and ``v_WE`` (3, m/s) are the
        origin E of ``frame_E`` (the tool frame, fixed on body B at X_BE) measured and
        expressed in W: p_WE = X_WB p_BE, v_WE = v_WB + w_WB x (R_WB p_BE). ``R_WE`` (9)
        is the frame's orientation R_WE = R_WB R_BE, its rows one after another
        (``R_WE.reshape(3, 3)`` gives the matrix back).

        Timing: stateless, direct feedthrough; computed only when a consumer (a logger, the
        force feedback in ``position_error`` mode, a reproducer observing the tool)
        evaluates it. Scalar types: double and AutoDiffXd.

        Parameters
        ----------
        frame_E : Frame of a finalized plant, fixed to a body (the tool frame).
        """

        def _construct(self, *, frame_E, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._frame_E = frame_E
            self._body = int(frame_E.body().index())
            X_BE = frame_E.GetFixedPoseInBodyFrame()
            p_BE = X_BE.translation()
            self._p_BE = p_BE if T is float else np.array([T(x) for x in p_BE])
            self._R_BE = X_BE.rotation().cast[T]()
            self.body_poses_input = self.DeclareAbstractInputPort(
                "body_poses", AbstractValue.Make([RigidTransform_[T]()])
            )
            self.body_spatial_velocities_input = self.DeclareAbstractInputPort(
                "body_spatial_velocities", AbstractValue.Make([SpatialVelocity_[T]()])
            )
            self.p_WE_output = self.DeclareVectorOutputPort(
                "p_WE",
                3,
                self._calc_p_WE,
                prerequisites_of_calc={self.body_poses_input.ticket()},
            )
            self.v_WE_output = self.DeclareVectorOutputPort(
                "v_WE",
                3,
                self._calc_v_WE,
                prerequisites_of_calc={
                    self.body_poses_input.ticket(),
                    self.body_spatial_velocities_input.ticket(),
                },
            )

            self.R_WE_output = self.DeclareVectorOutputPort(
                "R_WE",
                9,
                self._calc_R_WE,
                prerequisites_of_calc={self.body_poses_input.ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, frame_E=other._frame_E, converter=converter)

        def _calc_p_WE(self, context, output):
            X_WB = self.body_poses_input.Eval(context)[self._body]
            output.SetFromVector(X_WB.multiply(self._p_BE))

        def _calc_R_WE(self, context, output):
            R_WB = self.body_poses_input.Eval(context)[self._body].rotation()
            output.SetFromVector(R_WB.multiply(self._R_BE).matrix().reshape(9))

        def _calc_v_WE(self, context, output):
            R_WB = self.body_poses_input.Eval(context)[self._body].rotation()
            V_WB = self.body_spatial_velocities_input.Eval(context)[self._body]
            output.SetFromVector(V_WB.Shift(R_WB.multiply(self._p_BE)).translational())

    return Impl


ToolPointKinematics = ToolPointKinematics_[None]


@dc.dataclass(frozen=True, eq=False)
class SlaveStation:
    """The station's diagram and handles into it, from :func:`make_slave_station`.

    Attributes
    ----------
    diagram : Diagram, named ``station``. Input ports: ``p_WE_desired`` (3, m, W) or, with
        ``reference="joints"``, ``q_desired`` and ``v_desired`` (7 each, rad, rad/s);
        ``gain`` (1, the PD's K); ``applied_generalized_force`` (the plant's, free; may
        stay unconnected); with ``stiffness="spd"`` also ``stiffness_shape`` (9, the
        Cartesian stiffness' shape, :class:`~hemg_drake.control.impedance.
        CartesianImpedancePd`; the identity when unconnected). Output ports: ``p_WE``, ``v_WE`` (3, m and m/s, W), ``f_WE``
        (3, N: the scene's force on the tool point, zero in free space), ``arm_state``
        (14: [q; v]), ``tau`` (7, N m: the PD's joint torques), ``f_block`` (3, N: the
        contact force on ``scene.block``, only when there is one), ``q_desired`` (7, the
        CLIK's joint reference; absent with joint references), ``R_WE`` (9: the tool frame's
        rotation in W, row after row), ``contact_results``, ``query_object``. Subsystems: ``plant``,
        ``scene_graph``, ``clik``, ``pd``, ``pd_gravity`` (gravity compensation), ``tool_point``
        and the scene's own. The controllers use a plant of the arm alone.
    plant : MultibodyPlant
    arm : BaxterArm
    scene : CotterPinScene, DrawingScene or None (free space).
    q0 : array, shape (7,), the arm's configuration at the start (rad), at rest.
    meshcat : Meshcat or None
        Where the station is shown (the ``Visualization``'s), None without visualisation.
    """

    diagram: object
    plant: object
    arm: object
    scene: object
    q0: np.ndarray
    meshcat: object = None

    def plant_context(self, root_context):
        """The plant's context inside the context of the diagram holding the station."""
        return self.plant.GetMyContextFromRoot(root_context)

    def set_start(self, root_context, diagram=None):
        """Put the plant of ``diagram`` (default this station's; a clone or an AutoDiffXd
        conversion of it) at the start, at rest: the arm at ``q0``, the scene at its
        defaults, in ``root_context`` (of the diagram holding it).

        A new context of this station's own diagram already starts there; a converted one
        does not: Drake 1.51's scalar conversion of a MultibodyPlant (Clone,
        ToAutoDiffXd) drops the joints' default positions (drake#14344 once fixed this).
        """
        diagram = self.diagram if diagram is None else diagram
        plant = diagram.GetSubsystemByName(self.plant.get_name())
        plant_context = plant.GetMyMutableContextFromRoot(root_context)
        positions = self.plant.GetPositions(self.plant.CreateDefaultContext())
        plant.SetPositions(plant_context, positions)
        plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))


def start_configuration(scenario, plant, arm, start=None):
    """The arm's configuration with the tool point on ``start`` (default the task plan's
    first point), its axis where the CLIK's orientation task holds it.

    Inverse kinematics from the arm's home. SNOPT can stop infeasible from there at a start
    in reach (5 cm above the drawing's first point it ran into the joint limits), so a start
    off the plan's first point that fails is solved again from (and near) the solution at
    that first point, as :func:`hemg_drake.placements.unreachable_point` walks the plan.

    Raises
    ------
    ValueError
        The start (with its axis) is out of the arm's reach.
    """
    first = np.asarray(scenario.task_plan().points[0], dtype=float)
    start = first if start is None else np.asarray(start, dtype=float)
    axes = {}
    if scenario.clik.orientation_gain > 0:
        axes = dict(axis_E=scenario.clik.axis_E, axis_W=scenario.clik.axis_W_desired)
    try:
        return solve_tool_point_ik(plant, arm, start, **axes)
    except ValueError as error:
        failure = error
    if start.shape == first.shape and not np.array_equal(start, first):
        try:
            q_first = solve_tool_point_ik(plant, arm, first, **axes)
            return solve_tool_point_ik(plant, arm, start, q_guess=q_first, **axes)
        except ValueError:
            pass
    raise ValueError(
        f"the task's start {np.round(start, 4).tolist()} m (the plan's first point, "
        f"placed by scene.position and scene.yaw_deg) is out of the arm's reach: {failure}"
    ) from None


def make_slave_station(
    scenario,
    *,
    start=None,
    q0=None,
    reference="tool_point",
    scene=True,
    visualization=None,
    name="station",
    stiffness="scalar",
):
    """Build the slave station of a scenario.

    Parameters
    ----------
    scenario : Scenario
        Its ``plant``, ``task``, ``scene``, ``clik`` and ``pd`` sections are used.
    start : array, shape (3,), optional
        Where the tool point starts, at rest (m, W); default the task plan's first point.
    q0 : array, shape (7,), optional
        The arm's configuration at the start (rad); default the one that puts the tool
        point on ``start`` (:func:`~hemg_drake.control.ik.solve_tool_point_ik`).
    reference : {"tool_point", "joints"}
        Drive the station by a tool-point reference through the CLIK, or by joint
        references straight into the PD.
    scene : bool
        False leaves out the task's scene (free space).
    visualization : Visualization, optional
        Show the station in its Meshcat: ``scenario.visualization`` is applied
        (``ApplyVisualizationConfig``); to record it, see :mod:`hemg_drake.viz.recording`.
    name : str
        The diagram's name.
    stiffness : {"scalar", "spd"}
        The PD: eq. 20's :class:`~hemg_drake.control.pd.VariableGainPd` (the joints'
        stiffness scaled by K), or :class:`~hemg_drake.control.impedance.
        CartesianImpedancePd` (K times a shape at the tool, eq. 20's in the null space).

    Returns
    -------
    SlaveStation

    Raises
    ------
    ValueError
        An unknown ``reference``, a start out of the arm's reach or of the wrong shape.
    """
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    if stiffness not in STIFFNESSES:
        raise ValueError(f"stiffness must be one of {STIFFNESSES}, got {stiffness!r}")
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(scenario.plant, builder)
    arm = add_baxter_arm(plant)
    task_scene = block = None
    if scene:
        task_scene = SCENE_BUILDERS[scenario.task](
            plant, arm, params=scenario.scene_params(), X_WT=scenario.X_WT()
        )
        block = add_block(plant, scenario.scene.block, scenario.X_WT())
    plant.Finalize()
    if q0 is None:
        q0 = start_configuration(scenario, plant, arm, start)
    q0 = np.array(q0, dtype=float)
    plant.SetDefaultPositions(arm.model_instance, q0)

    # The controllers' own plant of the arm alone (manipulation's station does the same),
    # owned by the diagram through a SharedPointerSystem.
    controller_plant, controller_arm = make_arm_controller_plant()
    SharedPointerSystem.AddToBuilder(builder, controller_plant)
    arm_state = plant.get_state_output_port(arm.model_instance)
    add_pd = add_variable_gain_pd if stiffness == "scalar" else add_cartesian_impedance_pd
    pd = add_pd(
        builder, plant=controller_plant, arm=controller_arm, state_port=arm_state,
        config=scenario.pd,
    )  # fmt: skip
    tool_point = builder.AddNamedSystem("tool_point", ToolPointKinematics(frame_E=arm.tool_frame))
    builder.Connect(plant.get_body_poses_output_port(), tool_point.body_poses_input)
    builder.Connect(
        plant.get_body_spatial_velocities_output_port(), tool_point.body_spatial_velocities_input
    )
    builder.Connect(pd.torque_output, plant.get_actuation_input_port(arm.model_instance))
    if reference == "tool_point":
        clik = builder.AddNamedSystem(
            "clik",
            Clik(
                plant=controller_plant,
                model_instance=controller_arm.model_instance,
                frame_E=controller_arm.tool_frame,
                config=scenario.clik,
            ),
        )
        builder.Connect(arm_state, clik.GetInputPort("state"))
        builder.Connect(clik.GetOutputPort("q_desired"), pd.q_desired_input)
        builder.Connect(clik.GetOutputPort("v_desired"), pd.v_desired_input)
        builder.ExportInput(clik.GetInputPort("p_WE_desired"), "p_WE_desired")
    else:
        builder.ExportInput(pd.q_desired_input, "q_desired")
        builder.ExportInput(pd.v_desired_input, "v_desired")
    builder.ExportInput(pd.gain_input, "gain")
    if stiffness == "spd":
        builder.ExportInput(pd.shape_input, "stiffness_shape")
    builder.ExportInput(plant.get_applied_generalized_force_input_port(), "applied_generalized_force")

    if task_scene is not None:
        # Wires the scene's own systems (the pin's detent) as well as its force sensor.
        f_WE = task_scene.force_output_port(builder)
    else:
        f_WE = builder.AddNamedSystem("no_contact", ConstantVectorSource(np.zeros(3)))
        f_WE = f_WE.get_output_port()
    builder.ExportOutput(tool_point.p_WE_output, "p_WE")
    builder.ExportOutput(tool_point.v_WE_output, "v_WE")
    builder.ExportOutput(tool_point.R_WE_output, "R_WE")
    builder.ExportOutput(f_WE, "f_WE")
    builder.ExportOutput(arm_state, "arm_state")
    builder.ExportOutput(pd.torque_output, "tau")
    if block is not None:
        builder.ExportOutput(block.force_output_port(builder), "f_block")
    if reference == "tool_point":
        builder.ExportOutput(clik.GetOutputPort("q_desired"), "q_desired")
    builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")
    builder.ExportOutput(scene_graph.get_query_output_port(), "query_object")
    meshcat = None
    if visualization is not None:
        apply_visualization(scenario.visualization, builder, plant=plant,
                            scene_graph=scene_graph, visualization=visualization)  # fmt: skip
        meshcat = visualization.meshcat
    diagram = builder.Build()
    diagram.set_name(name)
    return SlaveStation(
        diagram=diagram, plant=plant, arm=arm, scene=task_scene, q0=q0, meshcat=meshcat
    )

