"""Stability of the teleoperation loop by linearisation (the delay study without simulating).

The loop of a demonstration while the operator holds the stylus still: the Touch X master
(eq. 19), the operator's hand as a spring-damper holding the stylus where it started, the
workspace map with its transport delay, the slave station at a constant gain K (eqs. 20-21)
in the task's scene (the cotter pin held by its grasp), and the slave's force fed back
through the return delay. Every system of that loop converts to AutoDiffXd, so its periodic
discrete update x[n+1] = f(x[n]) (every update of the loop runs at the master's 1 ms sample)
can be differentiated about the hold: A = df/dx. The hold is asymptotically stable iff every
eigenvalue of A lies inside the unit circle. Sweeping the one-way delay finds, without
simulating, where the delay study (``docs/studies.md``) saw the force loop start to oscillate.

Why not Drake's ``Linearize``: it takes a discrete system with one state group, and a
diagram of several discrete systems has one group each; :func:`discrete_update_jacobian`
differentiates the diagram's update through its AutoDiffXd conversion instead.

The hold is found once, without delay: the loop is simulated for ``settle_time`` from the
task's start. Each delayed loop then starts from the same state with its delay lines filled
with the signals they carry (in a hold every sample in flight equals the present one).

Eigenvalues of exactly 1 are set aside and counted: a sample a system holds (the delay line's
validity flag) and the passivity observer's energy sum are not dynamics of the loop. What
linearisation cannot show: the time-domain passivity controller is an energy switch; about a
hold its observed energy stays positive, so it is inactive and its linearisation is the plain
loop's. It acts on the large motions only the simulation shows.
"""

import dataclasses as dc

import numpy as np
from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import AffineSystem, ConstantVectorSource, DiscreteTimeDelay

from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap
from hemg_drake.teleop.master import HapticMaster

# |lambda - 1| below this: a held sample or a running sum, set aside (not dynamics).
UNIT_TOLERANCE = 1e-9


@dc.dataclass(frozen=True)
class LoopSpectrum:
    """The linearised loop at one delay.

    Attributes
    ----------
    delay_ms : float, the one-way delay (each way), ms.
    spectral_radius : float, max |eig(A)| over the eigenvalues not set aside; < 1 is stable.
    frequency_hz : float, the frequency of that least stable eigenvalue (0 for a real one).
    num_states : int, the size of A.
    unit_eigenvalues : int, eigenvalues of exactly 1 set aside.
    equilibrium_residual : float, max |x[n+1] - x[n]| at the operating point.
    """

    delay_ms: float
    spectral_radius: float
    frequency_hz: float
    num_states: int
    unit_eigenvalues: int
    equilibrium_residual: float

    @property
    def stable(self):
        return self.spectral_radius < 1.0


def discrete_state(context):
    """Every discrete state group of ``context`` (a diagram's), concatenated."""
    values = context.get_discrete_state()
    return np.concatenate(
        [values.get_vector(i).CopyToVector() for i in range(values.num_groups())]
    )


def set_discrete_state(context, x):
    """Set every discrete state group of ``context`` from the concatenation ``x``."""
    values = context.get_mutable_discrete_state()
    start = 0
    for i in range(values.num_groups()):
        group = values.get_mutable_vector(i)
        group.SetFromVector(x[start : start + group.size()])
        start += group.size()


def discrete_update(diagram, context):
    """x[n+1] of a diagram whose periodic updates share one period, at ``context``."""
    values = diagram.EvalUniquePeriodicDiscreteUpdate(context)
    return np.concatenate(
        [values.get_vector(i).CopyToVector() for i in range(values.num_groups())]
    )


def discrete_update_jacobian(diagram, context):
    """A = d x[n+1] / d x[n] of a diagram's periodic discrete update at ``context``'s state.

    Converts the diagram to AutoDiffXd, seeds the concatenated discrete state with the
    identity and differentiates ``EvalUniquePeriodicDiscreteUpdate`` (all updates share one
    period). Inputs of the diagram, if any, must be fixed in ``context``; they are held.

    Returns
    -------
    array, shape (n, n), n the number of discrete states, in :func:`discrete_state`'s order.
    """
    loop = diagram.ToAutoDiffXd()
    ad_context = loop.CreateDefaultContext()
    ad_context.SetTimeStateAndParametersFrom(context)
    set_discrete_state(ad_context, InitializeAutoDiff(discrete_state(context)).ravel())
    values = loop.EvalUniquePeriodicDiscreteUpdate(ad_context)
    updated = np.concatenate(
        [values.get_vector(i).CopyToVector() for i in range(values.num_groups())]
    )
    return ExtractGradient(updated)


def spectrum(diagram, context, *, delay_ms, period):
    """The :class:`LoopSpectrum` of ``diagram`` linearised at ``context`` (period in s)."""
    x = discrete_state(context)
    residual = float(np.max(np.abs(discrete_update(diagram, context) - x)))
    A = discrete_update_jacobian(diagram, context)
    eigenvalues = np.linalg.eigvals(A)
    unit = np.abs(eigenvalues - 1.0) < UNIT_TOLERANCE
    dynamic = eigenvalues[~unit]
    worst = dynamic[np.argmax(np.abs(dynamic))]
    return LoopSpectrum(
        delay_ms=float(delay_ms),
        spectral_radius=float(abs(worst)),
        frequency_hz=float(abs(np.angle(worst)) / (2 * np.pi * period)),
        num_states=int(len(x)),
        unit_eigenvalues=int(unit.sum()),
        equilibrium_residual=residual,
    )


def build_hold_loop(scenario, *, gain):
    """The teleoperation loop of ``scenario`` with a hand holding the stylus and K = ``gain``.

    The scenario's master, mapping (``delay_steps``), feedback (mode, gain, passivity,
    ``delay_steps``), operator hand impedance, station and scene. The sEMG chain is left out:
    about a hold the gain is a constant.

    Returns
    -------
    Diagram named ``hold_loop``; subsystems ``master``, ``hand``, ``workspace_map``,
    ``station``, ``force_feedback``, ``gain``.
    """
    mapping = scenario.workspace_mapping()
    start = scenario.task_plan().points[0]
    p_MS_initial = mapping.slave_to_master(start)
    period = scenario.master.period
    builder = DiagramBuilder()
    station = builder.AddSystem(make_slave_station(scenario, start=start).diagram)

    def add(name, system):
        return builder.AddNamedSystem(name, system)

    master = add("master", HapticMaster(config=scenario.master, p_MS_initial=p_MS_initial))
    channel = add(
        "workspace_map",
        WorkspaceMap(
            mapping=mapping, period=period, p_MS_initial=p_MS_initial, config=scenario.mapping
        ),
    )
    feedback = add(
        "force_feedback", ForceFeedback(mapping=mapping, period=period, config=scenario.feedback)
    )
    # The hand: F = K_h (p0 - p_MS) - D_h v_MS, the operator's impedance holding the start.
    K_h, D_h = scenario.operator.hand_stiffness, scenario.operator.hand_damping
    hand = add(
        "hand",
        AffineSystem(
            D=np.hstack([-K_h * np.eye(3), -D_h * np.eye(3)]),
            y0=K_h * np.asarray(p_MS_initial, dtype=float),
        ),
    )
    constant_gain = add("gain", ConstantVectorSource([float(gain)]))
    connect = builder.Connect
    connect(master.GetOutputPort("state"), hand.get_input_port())
    connect(hand.get_output_port(), master.GetInputPort("hand_force"))
    for name in ("p_MS", "v_MS"):
        connect(master.GetOutputPort(name), channel.GetInputPort(name))
    connect(channel.GetOutputPort("p_WE_desired"), station.GetInputPort("p_WE_desired"))
    connect(constant_gain.get_output_port(), station.GetInputPort("gain"))
    if scenario.feedback.mode == "force":
        connect(station.GetOutputPort("f_WE"), feedback.GetInputPort("f_WE"))
        if feedback.HasInputPort("v_MS"):
            connect(master.GetOutputPort("v_MS"), feedback.GetInputPort("v_MS"))
    else:
        for name in ("p_WE", "v_WE"):
            connect(station.GetOutputPort(name), feedback.GetInputPort(name))
        for name in ("p_MS", "v_MS"):
            connect(master.GetOutputPort(name), feedback.GetInputPort(name))
    connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    diagram = builder.Build()
    diagram.set_name("hold_loop")
    return diagram


def _leaves(diagram):
    """Every leaf system of ``diagram``, recursively, by its path name."""
    systems = {}
    for system in diagram.GetSystems():
        if hasattr(system, "GetSystems"):
            systems.update(_leaves(system))
        else:
            systems[system.GetSystemPathname()] = system
    return systems


def carry_hold(source_diagram, source_context, diagram, context):
    """Set ``context`` to the hold held in ``source_context`` (a loop without delay).

    Each leaf's state where the two loops share the leaf (same path, same state size), and
    every delay line filled with the signal it delays: in a hold every sample in flight
    equals the present one.
    """
    sources = _leaves(source_diagram)
    delays = []
    for path, system in _leaves(diagram).items():
        if isinstance(system, DiscreteTimeDelay):
            delays.append(system)
            continue
        source = sources.get(path)
        if source is None:
            continue
        from_context = source.GetMyContextFromRoot(source_context)
        to_context = system.GetMyMutableContextFromRoot(context)
        if from_context.num_total_states() == to_context.num_total_states():
            to_context.SetStateAndParametersFrom(from_context)
    # A delay's input may come out of another delay: a second pass sees the first's fill.
    for _ in range(2):
        for delay in delays:
            delay_context = delay.GetMyMutableContextFromRoot(context)
            u = delay.get_input_port().Eval(delay_context)
            state = delay_context.get_mutable_discrete_state_vector()
            state.SetFromVector(np.tile(u, state.size() // len(u)))


def _with_delay(scenario, steps):
    return scenario.replaced([f"mapping.delay_steps={steps}", f"feedback.delay_steps={steps}"])


def hold(scenario, *, gain, settle_time=2.0):
    """The loop without delay settled for ``settle_time`` s: (diagram, context) of the hold."""
    diagram = build_hold_loop(_with_delay(scenario, 0), gain=gain)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(settle_time)
    return diagram, simulator.get_context()


def loop_stability(scenario, delays_ms, *, gain, settle_time=2.0):
    """The spectrum of the linearised hold loop at each one-way delay.

    Parameters
    ----------
    scenario : Scenario
        Its feedback mode, gain and passivity, mapping, master, operator hand, station and
        scene; each delay overrides ``mapping.delay_steps`` and ``feedback.delay_steps``.
    delays_ms : sequence of float
        One-way delays (ms, each way), whole multiples of the master's period.
    gain : float
        The PD's K, held constant.
    settle_time : float
        Simulated seconds to find the hold.

    Returns
    -------
    list of LoopSpectrum, one per delay, in the given order.
    """
    period = scenario.master.period
    steps = []
    for delay_ms in delays_ms:
        n = int(round(delay_ms * 1e-3 / period))
        if n < 0 or abs(n * period - delay_ms * 1e-3) > 1e-12:
            raise ValueError(
                f"delay {delay_ms} ms is not a whole number of the master's {period * 1e3:g} ms "
                "samples"
            )
        steps.append(n)
    source_diagram, source_context = hold(scenario, gain=gain, settle_time=settle_time)
    results = []
    for delay_ms, n in zip(delays_ms, steps):
        diagram = build_hold_loop(_with_delay(scenario, n), gain=gain)
        context = diagram.CreateDefaultContext()
        carry_hold(source_diagram, source_context, diagram, context)
        results.append(spectrum(diagram, context, delay_ms=delay_ms, period=period))
    return results


def onset_delay(results):
    """The first delay (ms) whose loop is unstable (spectral radius >= 1), or None."""
    for result in sorted(results, key=lambda r: r.delay_ms):
        if not result.stable:
            return result.delay_ms
    return None
