"""The delayed-spring loop of the force-feedback delay study (``docs/studies.md``).

The Touch X stylus (:class:`~hemg_drake.teleop.master.HapticMaster`) is held by a hand, a
spring-damper towards M's origin (the simulated operator's 300 N/m and 5 N s/m); the slave
follows it through a :class:`~hemg_drake.teleop.mapping.WorkspaceMap` delay of n samples
into a stiff environment (a spring in W, 500 N/m, at rest where the origin of M maps to); the
spring's force is fed back (:class:`~hemg_drake.teleop.feedback.ForceFeedback`, mode
"force", gain 1) through another n samples, optionally through the time-domain passivity
controller. ``tests/teleop/test_feedback.py`` checks its physics and
``benchmarks/bench_passivity.py`` sweeps the delay.
"""

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, MatrixGain

from hemg_drake.teleop.config import FeedbackConfig, MappingConfig, MasterConfig, OperatorConfig
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster


def build_delayed_spring_loop(
    delay_steps,
    passivity,
    *,
    environment_stiffness=500.0,
    hand_stiffness=OperatorConfig.hand_stiffness,
    hand_damping=OperatorConfig.hand_damping,
    scale=2.0,
    p_MS_initial=(0.005, 0.0, 0.0),
):
    """Build the loop: stylus, hand, delayed map, environment spring, delayed feedback.

    Parameters
    ----------
    delay_steps : int
        One-way delay n, in 1 ms samples, of both halves of the channel.
    passivity : {"none", "tdpa"}
        The force feedback's passivity controller.
    environment_stiffness : float
        The slave's spring in W (N/m).
    hand_stiffness, hand_damping : float
        The hand holding the stylus at M's origin (N/m, N s/m); by default the simulated
        operator's (OperatorConfig).
    scale : float
        The workspace map's scale (slave motion per master motion).
    p_MS_initial : 3 floats, m
        Where the stylus starts (off the spring's rest).

    Returns
    -------
    (diagram, master, feedback): the built Diagram, its HapticMaster and ForceFeedback.
    Drake's systems and scalar-convertible ones only: the diagram clones and converts to
    AutoDiffXd.
    """
    mapping = WorkspaceMapping(scale=scale)
    master_config = MasterConfig()
    period = master_config.period
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(config=master_config, p_MS_initial=p_MS_initial))
    channel = builder.AddSystem(
        WorkspaceMap(mapping=mapping, period=period, config=MappingConfig(delay_steps=delay_steps))
    )
    feedback_config = FeedbackConfig(delay_steps=delay_steps, passivity=passivity, peak_force=1e3)
    feedback = builder.AddSystem(
        ForceFeedback(mapping=mapping, period=period, config=feedback_config)
    )
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), channel.GetInputPort(name))
    # f_WE = -k (p_WE - p_rest), as -k p_WE + k p_rest.
    k_env = environment_stiffness
    spring = builder.AddSystem(MatrixGain(-k_env * np.eye(3)))
    rest = builder.AddSystem(ConstantVectorSource(k_env * mapping.master_to_slave(np.zeros(3))))
    total = builder.AddSystem(Adder(2, 3))
    builder.Connect(channel.GetOutputPort("p_WE_desired"), spring.get_input_port())
    builder.Connect(spring.get_output_port(), total.get_input_port(0))
    builder.Connect(rest.get_output_port(), total.get_input_port(1))
    builder.Connect(total.get_output_port(), feedback.GetInputPort("f_WE"))
    if passivity != "none":
        builder.Connect(master.GetOutputPort("v_MS"), feedback.GetInputPort("v_MS"))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    hand = builder.AddSystem(
        MatrixGain(np.hstack([-hand_stiffness * np.eye(3), -hand_damping * np.eye(3)]))
    )
    builder.Connect(master.GetOutputPort("state"), hand.get_input_port())
    builder.Connect(hand.get_output_port(), master.GetInputPort("hand_force"))
    return builder.Build(), master, feedback


def simulate_delayed_spring_loop(
    delay_steps, passivity, *, duration, sample_period=0.01, **loop_parameters
):
    """Simulate :func:`build_delayed_spring_loop` and sample the stylus and the observer.

    Parameters
    ----------
    delay_steps, passivity
        As :func:`build_delayed_spring_loop`, with any of its keyword ``loop_parameters``.
    duration : float
        Simulated seconds.
    sample_period : float
        Samples at sample_period, 2 sample_period, ... up to ``duration`` (s).

    Returns
    -------
    x : array, shape (K,), m
        |x| of the stylus tip (the axis it starts displaced along) at each sample.
    energy : array, shape (K,) or (0,), J
        The passivity observer's energy at each sample (empty when the feedback holds no
        state: no delay and no passivity controller).
    """
    diagram, master, feedback = build_delayed_spring_loop(
        delay_steps, passivity, **loop_parameters
    )
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    x, energy = [], []
    for t in np.arange(sample_period, duration + 1e-9, sample_period):
        simulator.AdvanceTo(t)
        p_MS = master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(context))
        x.append(abs(p_MS[0]))
        if feedback.stateful:
            energy.append(float(feedback.energy(feedback.GetMyContextFromRoot(context))))
    return np.array(x), np.array(energy)
