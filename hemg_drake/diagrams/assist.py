"""The shared control added to the demonstration diagram (``assist:``; docs/shared_control.md).

Signal flow, on the slave's side of the channel::

    workspace_map --p_WE_desired (the command as it arrives)--> intent, arbitration
    station --p_WE (measured)--> assist_policy (LQR tracker) --x_star, h--> arbitration
    intent --confidence--> arbitration;  variable_gain --activation--> arbitration
    arbitration --p_WE_reference--> station
    station f_WE + arbitration guidance_force --> force_feedback (delay, passivity) --> master

With ``assist.mode`` none nothing of this is built.
"""

from pydrake.systems.primitives import Adder, ConstantVectorSource

from hemg_drake.assist.arbitration import Arbitration
from hemg_drake.assist.intent import IntentEstimator
from hemg_drake.learning.systems import HsmmLqrReproducer

ASSIST_LOGGED = {"weight": 1, "confidence": 1, "phase": 1, "link_lost": 1, "guidance_force": 3,
                 "x_policy": 3}


def assist_model(scenario):
    """The fitted HSMM of ``assist.model`` at the scenario's placement (a TP-HSMM's product in
    its task frames), checked to be a [x, xdot, k] model; ValueError naming the key."""
    from hemg_drake.diagrams.reproduction import check_model
    from hemg_drake.learning.tphsmm import load_model
    from hemg_drake.placements import last_frames, task_frames

    path = scenario.assist.model
    try:
        model = load_model(path)
    except (OSError, ValueError, KeyError) as error:
        raise ValueError(f"key 'assist.model' = {path!r}: {error}") from None
    if hasattr(model, "at"):
        model = model.at(*last_frames(task_frames(scenario), model.n_frames_))
    try:
        check_model(model)
    except ValueError as error:
        raise ValueError(f"key 'assist.model' = {path!r}: {error}") from None
    return model


def add_assist(builder, scenario, *, model, start, command, p_WE, f_WE, activation,
               enabled=None):  # fmt: skip
    """Add the intent estimator, the policy and the arbitration to ``builder``.

    Parameters
    ----------
    builder : DiagramBuilder
    scenario : Scenario
        Its ``assist``, ``reproduction`` (the tracker's horizon, costs and lead), the master's
        period and the channel's delay.
    model : HSMM
        Fitted (:func:`assist_model`).
    start : 3 floats
        Where the arm starts (m, W).
    command, p_WE, f_WE, activation : OutputPort
        The operator's command as the slave receives it, the measured tool point, the
        interaction force and the EMG chain's activation.
    enabled : OutputPort, optional
        The person's on/off switch (1 on; the teleop page's A key, the browser master's
        ``assist_on``); without one the assist is always on.

    Returns
    -------
    (reference, fed_back, sources): the slave's reference port, the force to feed back
    (``f_WE`` plus the guidance when ``assist.guidance_stiffness`` > 0), and the assist's
    ports to log by name (:data:`ASSIST_LOGGED`).
    """
    settings, fresh = scenario.assist, scenario.reproduction
    dt = scenario.log_period
    intent = builder.AddNamedSystem(
        "intent",
        IntentEstimator(
            model=model, dt=dt, likelihood_time_constant=settings.likelihood_time_constant,
            command_noise=settings.command_noise,
        ),
    )
    policy = builder.AddNamedSystem(
        "assist_policy",
        HsmmLqrReproducer(
            model=model, start=start, dt=dt, weighting="forward", horizon=fresh.horizon,
            control_cost=fresh.control_cost, max_lead=fresh.max_lead,
            state_cost=fresh.state_cost,
        ),  # fmt: skip
    )
    period = scenario.master.period
    arbitration = builder.AddNamedSystem(
        "arbitration",
        Arbitration(
            config=settings, period=period, delay=scenario.mapping.delay_steps * period,
            p_WE_initial=start, n_states=model.n_states,
        ),  # fmt: skip
    )
    connect = builder.Connect
    connect(command, intent.GetInputPort("p_WE_command"))
    connect(command, arbitration.GetInputPort("p_WE_command"))
    connect(p_WE, policy.GetInputPort("p_WE"))
    connect(policy.GetOutputPort("x_star"), arbitration.GetInputPort("x_policy"))
    connect(policy.GetOutputPort("h"), arbitration.GetInputPort("h_policy"))
    connect(intent.GetOutputPort("confidence"), arbitration.GetInputPort("confidence"))
    connect(activation, arbitration.GetInputPort("activation"))
    if enabled is None:
        enabled = builder.AddNamedSystem("assist_always_on", ConstantVectorSource([1.0]))
        enabled = enabled.get_output_port()
    connect(enabled, arbitration.GetInputPort("enabled"))
    fed_back = f_WE
    if settings.guidance_stiffness > 0:
        total = builder.AddNamedSystem("f_WE_and_guidance", Adder(2, 3))
        connect(f_WE, total.get_input_port(0))
        connect(arbitration.GetOutputPort("guidance_force"), total.get_input_port(1))
        fed_back = total.get_output_port()
    sources = {
        "weight": arbitration.GetOutputPort("weight"),
        "confidence": intent.GetOutputPort("confidence"),
        "phase": intent.GetOutputPort("phase"),
        "link_lost": arbitration.GetOutputPort("link_lost"),
        "guidance_force": arbitration.GetOutputPort("guidance_force"),
        "x_policy": policy.GetOutputPort("x_star"),
    }
    return arbitration.GetOutputPort("p_WE_reference"), fed_back, sources
