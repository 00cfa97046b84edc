"""The arbitration law by hand values, its limits (weight 0 and 1) and the link watchdog."""

import dataclasses as dc

import numpy as np
import pytest

from hemg_drake.assist.arbitration import Arbitration, newest_command_age, target_weight
from hemg_drake.assist.config import AssistConfig

LAW = dict(scale=0.02, low=0.2, high=0.6)


def test_target_weight_by_hand():
    assert target_weight("none", weight=0.8, confidence=1, disagreement=0, activation=1, **LAW) == 0
    assert target_weight("fixed", weight=0.8, confidence=0, disagreement=9, activation=1, **LAW) == 0.8
    # confidence 0.5, d = delta: 0.8 * 0.5 * e^-1; the activation is not read.
    expected = 0.8 * 0.5 * np.exp(-1.0)
    for activation in (0.0, 1.0):
        got = target_weight(
            "confidence", weight=0.8, confidence=0.5, disagreement=0.02, activation=activation,
            **LAW,
        )  # fmt: skip
        assert got == pytest.approx(expected, rel=1e-15)
    # emg: below the band as confidence, mid-band half of it, above the band 0.
    for activation, factor in ((0.1, 1.0), (0.4, 0.5), (0.6, 0.0), (0.9, 0.0)):
        got = target_weight(
            "emg", weight=0.8, confidence=0.5, disagreement=0.02, activation=activation, **LAW
        )
        assert got == pytest.approx(expected * factor, rel=1e-12, abs=1e-15)


def test_delay_trust_floor_by_hand():
    tense = dict(confidence=0.5, disagreement=0.02, activation=0.9, **LAW)  # emg's law: 0
    for delay, expected in ((0.0, 0.0), (0.1, 0.16), (0.25, 0.4), (0.5, 0.8), (2.0, 0.8)):
        got = target_weight("emg", weight=0.5, delay=delay, trust_delay=0.5, trust_weight=0.8,
                            **tense)  # fmt: skip
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-15)
    # The floor's cap W_t defaults to 1 (the model may lead alone), whatever W is.
    got = target_weight("emg", weight=0.5, delay=0.75, trust_delay=0.5, **tense)
    assert got == 1.0
    # Above the floor the law stands; off (T_t = 0) or in the other modes there is none.
    law = 0.8 * 0.5 * np.exp(-1.0)  # 0.147
    got = target_weight("confidence", weight=0.8, delay=0.05, trust_delay=0.5, **tense)
    assert got == pytest.approx(law, rel=1e-12)
    assert target_weight("emg", weight=0.8, delay=0.5, trust_delay=0.0, **tense) == 0.0
    assert target_weight("fixed", weight=0.8, delay=0.5, trust_delay=0.1, **tense) == 0.8
    assert target_weight("none", weight=0.8, delay=0.5, trust_delay=0.1, **tense) == 0.0


def test_delay_trust_through_the_system():
    # A tense operator (activation above the band) over a 0.25 s link: the weight settles on
    # W_t * 0.25 / 0.5 = 0.3 (the first-order filter, tau 0.1 s, for 2 s: e^-20 left).
    config = AssistConfig(mode="emg", weight=0.5, trust_delay=0.5, trust_weight=0.6)
    arbitration = Harness(config, delay=0.25)
    arbitration.set(activation=1.0)
    arbitration.step(2000)
    assert arbitration.out("weight")[0] == pytest.approx(0.3, abs=1e-8)
    command, policy = np.array([0.1, 0.2, 0.3]), np.array([0.4, -0.5, 0.6])
    np.testing.assert_allclose(arbitration.out("p_WE_reference"), 0.7 * command + 0.3 * policy,
                               atol=1e-8)  # fmt: skip
    untrusting = Harness(dc.replace(config, trust_delay=0.0), delay=0.25)
    untrusting.set(activation=1.0)
    untrusting.step(2000)
    assert untrusting.out("weight")[0] == 0.0


def test_newest_command_age_by_hand():
    assert newest_command_age(2.0, 0.25, 0.0, 0.0) == 0.25  # no gap: the delay
    # Sent in [1.0, 1.5) is lost: at t = 1.45 with 0.25 delay, sent 1.2 is lost, the newest
    # arrived was sent at 1.0: age 0.45; at t = 1.8, sent 1.55 arrives: age 0.25.
    assert newest_command_age(1.45, 0.25, 1.0, 1.5) == pytest.approx(0.45)
    assert newest_command_age(1.8, 0.25, 1.0, 1.5) == pytest.approx(0.25)


class Harness:
    """An Arbitration with fixed inputs, stepped by hand (its periodic update)."""

    def __init__(self, config, *, delay=0.0, period=1e-3, n_states=3):
        self.system = Arbitration(
            config=config, period=period, delay=delay, p_WE_initial=[0.0, 0.0, 0.0],
            n_states=n_states,
        )  # fmt: skip
        self.context = self.system.CreateDefaultContext()
        self.period = period
        self.steps = 0
        self.set(command=[0.1, 0.2, 0.3], policy=[0.4, -0.5, 0.6], phase=0, confidence=1.0,
                 activation=0.0, enabled=1.0)  # fmt: skip

    def set(self, *, command=None, policy=None, phase=None, confidence=None, activation=None,
            enabled=None):  # fmt: skip
        fix = {
            "p_WE_command": command, "x_policy": policy, "confidence": confidence,
            "activation": activation, "enabled": enabled,
            "h_policy": None if phase is None else np.eye(3)[phase],
        }  # fmt: skip
        for name, value in fix.items():
            if value is not None:
                self.system.GetInputPort(name).FixValue(self.context, np.atleast_1d(value))

    def step(self, count=1):
        for _ in range(count):
            self.context.SetTime(self.steps * self.period)
            update = self.system.EvalUniquePeriodicDiscreteUpdate(self.context)
            self.context.SetDiscreteState(update)
            self.steps += 1
            self.context.SetTime(self.steps * self.period)

    def out(self, name):
        return self.system.GetOutputPort(name).Eval(self.context).copy()


def test_weight_zero_gives_the_command_bit_for_bit():
    arbitration = Harness(AssistConfig(mode="fixed", weight=0.0, guidance_stiffness=100.0))
    command = np.array([0.123456789, -0.987654321, 0.31415926535])
    arbitration.set(command=command, policy=[1e3, -1e3, 7.0])
    arbitration.step(50)
    assert arbitration.out("weight")[0] == 0.0
    assert np.array_equal(arbitration.out("p_WE_reference"), command)
    assert np.array_equal(arbitration.out("guidance_force"), np.zeros(3))


def test_weight_one_follows_the_policy():
    config = AssistConfig(mode="fixed", weight=1.0, weight_time_constant=1e-3,
                          guidance_stiffness=100.0)  # fmt: skip
    arbitration = Harness(config)
    arbitration.step()
    policy = np.array([0.4, -0.5, 0.6])
    assert arbitration.out("weight")[0] == 1.0
    assert np.array_equal(arbitration.out("p_WE_reference"), policy)
    # The guidance pulls toward the policy: K_g w (x_pol - p_cmd).
    np.testing.assert_allclose(
        arbitration.out("guidance_force"), 100.0 * (policy - [0.1, 0.2, 0.3]), rtol=1e-15
    )


def test_weight_filter_is_first_order():
    """w_k = 1 - (1 - T / tau)^k toward a fixed target of 1."""
    arbitration = Harness(AssistConfig(mode="fixed", weight=1.0, weight_time_constant=0.01))
    arbitration.step(7)
    assert arbitration.out("weight")[0] == pytest.approx(1.0 - 0.9**7, rel=1e-12)


def test_emg_mode_gives_way_to_a_tense_operator():
    config = AssistConfig(mode="emg", weight=1.0, weight_time_constant=1e-3)
    arbitration = Harness(config)
    arbitration.set(command=[0.1, 0.2, 0.3], policy=[0.1, 0.2, 0.3])  # no disagreement
    arbitration.step()
    assert arbitration.out("weight")[0] == pytest.approx(1.0)
    arbitration.set(activation=0.9)
    arbitration.step()
    assert arbitration.out("weight")[0] == 0.0


def test_link_loss_completes_the_phase_then_holds():
    """Commands sent from 0.1 s on are lost; after link_timeout the model takes over
    (w -> 1) and follows the policy while its phase lasts, then holds where it ended."""
    config = AssistConfig(mode="confidence", weight=0.3, weight_time_constant=1e-3,
                          link_timeout=0.05, gap_start=0.1, gap_duration=100.0)  # fmt: skip
    arbitration = Harness(config, delay=0.02)
    arbitration.set(confidence=0.0)  # w = 0 while the link is up
    arbitration.step(100)  # t = 0.1: the lost commands have not yet come due
    assert arbitration.out("link_lost")[0] == 0 and arbitration.out("weight")[0] == 0
    arbitration.step(30)  # t = 0.13: sent 0.11 lost, newest sent at 0.1: age 0.03, held
    arbitration.set(command=[9.0, 9.0, 9.0])  # what the operator sends is not in hand
    assert np.array_equal(arbitration.out("p_WE_reference"), [0.1, 0.2, 0.3])
    arbitration.step(30)  # t = 0.16: age 0.06 > 0.05: lost
    assert arbitration.out("link_lost")[0] == 1
    arbitration.step()
    assert arbitration.out("weight")[0] == 1.0
    arbitration.set(policy=[0.5, 0.5, 0.5])
    np.testing.assert_array_equal(arbitration.out("p_WE_reference"), [0.5, 0.5, 0.5])
    arbitration.set(phase=1, policy=[0.6, 0.6, 0.6])  # the phase ends: hold there
    arbitration.step()
    arbitration.set(policy=[0.9, 0.9, 0.9])
    arbitration.step(5)
    np.testing.assert_array_equal(arbitration.out("p_WE_reference"), [0.6, 0.6, 0.6])
    assert arbitration.out("link_lost")[0] == 1


def test_a_returning_link_clears_the_watchdog():
    config = AssistConfig(mode="fixed", weight=0.0, weight_time_constant=1e-3,
                          link_timeout=0.05, gap_start=0.0, gap_duration=0.1)  # fmt: skip
    arbitration = Harness(config)
    arbitration.step(80)
    assert arbitration.out("link_lost")[0] == 1 and arbitration.out("weight")[0] == 1.0
    arbitration.step(40)  # t = 0.12: commands arrive again
    assert arbitration.out("link_lost")[0] == 0 and arbitration.out("weight")[0] == 0.0
    assert np.array_equal(arbitration.out("p_WE_reference"), [0.1, 0.2, 0.3])


def test_config_checks():
    with pytest.raises(ValueError, match="activation_high"):
        dc.replace(AssistConfig(), activation_low=0.7).check("assist")


def test_mode_none_on_a_lost_link_holds_the_last_command():
    config = AssistConfig(mode="none", weight_time_constant=1e-3, link_timeout=0.05,
                          gap_start=0.02, gap_duration=1.0)  # fmt: skip
    arbitration = Harness(config)
    arbitration.step(100)
    arbitration.set(command=[5.0, 5.0, 5.0])
    assert arbitration.out("link_lost")[0] == 1 and arbitration.out("weight")[0] == 0.0
    assert np.array_equal(arbitration.out("p_WE_reference"), [0.1, 0.2, 0.3])


def test_switched_off_the_weight_decays_to_zero_and_back_on_it_rises():
    """The person's switch (enabled): off, w* = 0, so w falls by the first-order filter
    (w_k = w_0 (1 - T / tau)^k, by hand) and the reference returns to the command; on
    again, w rises towards W."""
    config = AssistConfig(mode="fixed", weight=0.8, weight_time_constant=0.01)
    h = Harness(config)
    h.step(200)
    w0 = h.out("weight")[0]
    assert w0 == pytest.approx(0.8, abs=1e-6)
    h.set(enabled=0.0)
    h.step(5)
    assert h.out("weight")[0] == pytest.approx(w0 * (1 - 0.1) ** 5, rel=1e-12)
    h.step(400)
    assert h.out("weight")[0] < 1e-12
    assert np.allclose(h.out("p_WE_reference"), [0.1, 0.2, 0.3], atol=1e-12)
    h.set(enabled=1.0)
    h.step(1)
    assert h.out("weight")[0] == pytest.approx(0.1 * 0.8, rel=1e-6)


def test_switched_off_a_lost_link_does_not_hand_over_to_the_model():
    config = AssistConfig(mode="fixed", weight=0.5, link_timeout=0.05, gap_start=0.0,
                          gap_duration=10.0, weight_time_constant=0.01)  # fmt: skip
    h = Harness(config)
    h.set(enabled=0.0)
    h.step(300)  # 0.3 s: the link lost for 0.25 s
    assert h.out("link_lost")[0] == 1.0
    assert h.out("weight")[0] == 0.0
