"""What the demonstration and reproduction diagrams share: the slave side, the log, viewers.

The slave side is the Baxter plant with the task's scene, the CLIK (eq. 21) and the
variable-gain PD (eq. 20) wired to the arm, and the tool point's kinematics. What drives it
differs: the operator through the master in a demonstration, the HSMM-GMR reproducer in a
reproduction.
"""

import dataclasses as dc

import numpy as np
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.geometry import MeshcatVisualizer
from pydrake.systems.framework import LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, Multiplexer

from hemg_drake.control.clik import Clik, velocity_columns
from hemg_drake.control.pd import VariableGainPd
from hemg_drake.robots.baxter import add_baxter_arm
from hemg_drake.tasks.cotter_pin import add_cotter_pin_scene
from hemg_drake.tasks.drawing import add_drawing_scene

# Each task's scene: added to the plant before Finalize, its handle has force_output_port.
SCENE_BUILDERS = {"cotter_pin": add_cotter_pin_scene, "drawing": add_drawing_scene}


class ToolPointKinematics(LeafSystem):
    """Position and velocity of the arm's tool point E in the world, from the arm's state.

    .. pydrake_system::

        name: ToolPointKinematics
        input_ports:
        - state
        output_ports:
        - p_WE
        - v_WE

    ``state`` is the arm's [q; v] (14: rad, rad/s); ``p_WE`` (3, m) and ``v_WE`` (3, m/s)
    are the origin of ``frame_E`` (the tool frame) measured and expressed in W, by forward
    kinematics on the controller's own plant context: v_WE = J_WE(q) v.

    Timing: stateless, direct feedthrough; computed only when a consumer (the logger every
    log period, or the force feedback in ``position_error`` mode) evaluates it.
    """

    def __init__(self, *, plant, arm, frame_E=None):
        LeafSystem.__init__(self)
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        self._model = arm.model_instance
        self._frame_E = arm.tool_frame if frame_E is None else frame_E
        self._columns = velocity_columns(plant, self._model)
        n = len(arm.joint_names)
        self._n = n
        self.state_input = self.DeclareVectorInputPort("state", 2 * n)
        self.p_WE_output = self.DeclareVectorOutputPort("p_WE", 3, self._calc_p_WE)
        self.v_WE_output = self.DeclareVectorOutputPort("v_WE", 3, self._calc_v_WE)

    def _set_positions(self, context):
        x = self.state_input.Eval(context)
        self._plant.SetPositions(self._context, self._model, x[: self._n])
        return x[self._n :]

    def _calc_p_WE(self, context, output):
        self._set_positions(context)
        output.SetFromVector(self._frame_E.CalcPoseInWorld(self._context).translation())

    def _calc_v_WE(self, context, output):
        v = self._set_positions(context)
        world = self._plant.world_frame()
        J_WE = self._plant.CalcJacobianTranslationalVelocity(
            self._context, JacobianWrtVariable.kV, self._frame_E, np.zeros(3), world, world
        )
        output.SetFromVector(J_WE[:, self._columns] @ v)


def solve_arm_positions(plant, arm, p_WE, *, iterations=200, damping=0.01):
    """Arm configuration that puts the tool point at ``p_WE``, from the home configuration.

    Damped Newton steps on the tool point's translational Jacobian, kept inside the joint
    limits. Used to start a demonstration at rest on the plan's first point.

    Returns
    -------
    q : array, shape (7,), rad.

    Raises
    ------
    ValueError
        The point is not reached within 1 mm.
    """
    context = plant.CreateDefaultContext()
    world = plant.world_frame()
    columns = velocity_columns(plant, arm.model_instance)
    q = arm.home_positions.copy()
    for _ in range(iterations):
        plant.SetPositions(context, arm.model_instance, q)
        error = p_WE - arm.tool_frame.CalcPoseInWorld(context).translation()
        if np.linalg.norm(error) < 1e-6:
            break
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
        )[:, columns]
        step = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(3), error)
        q = np.clip(q + step, arm.position_lower, arm.position_upper)
    if np.linalg.norm(error) > 1e-3:
        raise ValueError(f"the plan's first point {p_WE.tolist()} is out of the arm's reach")
    return q


@dc.dataclass(frozen=True)
class Slave:
    """Handles to the slave side added by :func:`add_slave`.

    Attributes
    ----------
    plant, scene_graph : MultibodyPlant, SceneGraph (subsystems ``plant``, ``scene_graph``).
    arm : BaxterArm
    scene : CotterPinScene, DrawingScene or None (free space).
    clik, pd, tool_point : the subsystems ``clik``, ``pd``, ``tool_point``.
    p_WE_desired_input : CLIK's input port, left for the caller to drive.
    gain_input : the PD's gain input port, left for the caller to drive.
    f_WE_output : output port of the scene's force on the tool point (N, W); in free
        space that of a zero source, the subsystem ``no_contact``.
    """

    plant: object
    scene_graph: object
    arm: object
    scene: object
    clik: object
    pd: object
    tool_point: object
    p_WE_desired_input: object
    gain_input: object
    f_WE_output: object


def add_slave(builder, scenario, *, start, positions=None, scene=True):
    """Add the slave side of a scenario to ``builder``.

    Parameters
    ----------
    builder : DiagramBuilder
    scenario : Scenario
        Its ``plant``, ``task`` and ``clik`` sections are used.
    start : array, shape (3,)
        Where the tool point starts, at rest (m, world frame).
    positions : array, shape (7,), optional
        The arm's configuration at the start (rad); default the one that puts the tool
        point on ``start`` (:func:`solve_arm_positions`).
    scene : bool
        False leaves out the task's scene (free space).

    Returns
    -------
    Slave
    """
    plant, scene_graph = AddMultibodyPlant(scenario.plant, builder)
    arm = add_baxter_arm(plant)
    task_scene = SCENE_BUILDERS[scenario.task](plant, arm) if scene else None
    plant.Finalize()
    if positions is None:
        positions = solve_arm_positions(plant, arm, np.asarray(start, dtype=float))
    plant.SetDefaultPositions(arm.model_instance, positions)
    clik = builder.AddNamedSystem(
        "clik",
        Clik(
            plant=plant,
            model_instance=arm.model_instance,
            frame_E=arm.tool_frame,
            **dc.asdict(scenario.clik),
        ),
    )
    pd = builder.AddNamedSystem("pd", VariableGainPd(plant=plant, arm=arm))
    tool_point = builder.AddNamedSystem("tool_point", ToolPointKinematics(plant=plant, arm=arm))
    arm_state = plant.get_state_output_port(arm.model_instance)
    builder.Connect(arm_state, clik.GetInputPort("state"))
    builder.Connect(arm_state, pd.state_input)
    builder.Connect(arm_state, tool_point.state_input)
    builder.Connect(clik.GetOutputPort("q_desired"), pd.q_desired_input)
    builder.Connect(clik.GetOutputPort("v_desired"), pd.v_desired_input)
    builder.Connect(pd.torque_output, plant.get_actuation_input_port(arm.model_instance))
    if task_scene is not None:
        # Wires the scene's own systems (the pin's detent) as well as its force sensor.
        f_WE = task_scene.force_output_port(builder)
    else:
        no_contact = builder.AddNamedSystem("no_contact", ConstantVectorSource(np.zeros(3)))
        f_WE = no_contact.get_output_port()
    return Slave(
        plant=plant,
        scene_graph=scene_graph,
        arm=arm,
        scene=task_scene,
        clik=clik,
        pd=pd,
        tool_point=tool_point,
        p_WE_desired_input=clik.GetInputPort("p_WE_desired"),
        gain_input=pd.gain_input,
        f_WE_output=f_WE,
    )


def add_logger(builder, sources, period):
    """Log the ``sources`` (name -> output port), stacked in their order, every ``period`` s.

    Returns the ``VectorLogSink`` (named ``logger``; its mux ``log_mux``).
    """
    ports = list(sources.values())
    mux = builder.AddNamedSystem("log_mux", Multiplexer([port.size() for port in ports]))
    for i, port in enumerate(ports):
        builder.Connect(port, mux.get_input_port(i))
    logger = LogVectorOutput(mux.get_output_port(), builder, period)
    logger.set_name("logger")
    return logger


def split_log(log, widths):
    """The columns of a ``VectorLog`` written by :func:`add_logger`, split by source.

    ``widths`` maps each source's name to its size, in the logger's order; returns name ->
    array of shape (T, size).
    """
    data, fields, row = log.data(), {}, 0
    for name, width in widths.items():
        fields[name] = data[row : row + width].T
        row += width
    return fields


def build_with_viewers(builder, scene_graph, name, *, meshcat=None, recorder=None):
    """Add a live Meshcat view and/or a replay recorder, then build the diagram ``name``."""
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    if recorder is not None:
        recorder.add_to_builder(builder, scene_graph)
    diagram = builder.Build()
    diagram.set_name(name)
    return diagram
