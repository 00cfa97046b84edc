"""HsmmGmrReproducer (eqs. 12-18) and TrackingForce (eq. 23) against references written here.

The HSMMs are built by hand so that GMR's output is known in closed form. A state whose
covariance is that of (x, A x + noise, c^T x + noise) regresses (eqs. 15-17)
xdot = mu^xdot + A (x - mu^x) and k = mu^k + c^T (x - mu^x); with one state, eq. 18
x_{t+1} = x_t + dt xdot_t is then a linear recursion with a closed-form solution. Two-state
models check the weights: eq. 14's Gaussian weighting (scipy's density), the forward
variable's first step (eq. 13), and the temporal weighting, whose state-0 weight for a
left-to-right model started in state 0 is the probability that its duration exceeds t.
None of these references calls the reproduction's own code (``reproduce``, the policy).
"""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource
from scipy.stats import multivariate_normal, norm

from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import STILL
from hemg_drake.learning.systems import HsmmGmrReproducer, TrackingForce

DT = 0.01


def linear_state(mu_x, b, A, mu_k, c, sigma_x):
    """Mean (7,) and covariance (7, 7) of a state that regresses xdot = b + A (x - mu_x)
    and k = mu_k + c . (x - mu_x): the covariance of (x, A x + e_v, c . x + e_k)."""
    A, c = np.asarray(A, float), np.asarray(c, float)
    S = np.diag(np.square(sigma_x))
    J = np.vstack([np.eye(3), A, c[None, :]])  # (7, 3): x -> (x, A x, c . x)
    covariance = J @ S @ J.T + np.diag([0.0] * 3 + [1e-4] * 3 + [1.0])
    return np.concatenate([mu_x, b, [mu_k]]), covariance


def hand_model(states, *, startprob, transmat, duration_means, duration_stds, max_duration,
               occupancy=None, k_range=(0.0, 1000.0)):
    """An HSMM with the given parameters, as if fitted (x, xdot in R^3, k in R)."""
    model = HSMM(len(states), max_duration=max_duration)
    model.means_ = np.array([mean for mean, _ in states])
    model.covariances_ = np.array([covariance for _, covariance in states])
    model.startprob_ = np.asarray(startprob, float)
    model.transmat_ = np.asarray(transmat, float)
    model.duration_means_ = np.asarray(duration_means, float)
    model.duration_stds_ = np.asarray(duration_stds, float)
    n = len(states)
    model.occupancy_ = np.full(n, 1.0 / n) if occupancy is None else np.asarray(occupancy)
    model.data_range_ = np.full((2, 7), [[-np.inf], [np.inf]])
    model.data_range_[:, 6] = k_range
    model.max_duration_ = max_duration
    model.log_likelihood_history_ = []
    return model


def run(reproducer, n_steps, p_WE=None):
    """Simulate; row k holds the outputs read at (k + 1/2) dt, after the update at k dt:
    x*_{k+1}, and step k's xdot*, k*, h. p_WE: a constant, or x* fed back when None."""
    builder = DiagramBuilder()
    builder.AddSystem(reproducer)
    if p_WE is None:
        builder.Connect(reproducer.GetOutputPort("x_star"), reproducer.GetInputPort("p_WE"))
    else:
        source = builder.AddSystem(ConstantVectorSource(np.asarray(p_WE, float)))
        builder.Connect(source.get_output_port(), reproducer.GetInputPort("p_WE"))
    simulator = Simulator(builder.Build())
    context = reproducer.GetMyContextFromRoot(simulator.get_context())
    names = ("x_star", "xdot_star", "k_star", "h")
    rows = {name: [] for name in names}
    for k in range(n_steps):
        simulator.AdvanceTo((k + 0.5) * DT)
        for name in names:
            rows[name].append(reproducer.GetOutputPort(name).Eval(context).copy())
    return {name: np.array(values) for name, values in rows.items()}


MU_X = np.array([0.5, -0.2, 0.3])
B = np.array([0.05, -0.02, 0.01])
A_DIAGONAL = np.array([-2.0, -1.0, -3.0])  # 1/s
MU_K, C = 80.0, np.array([1000.0, -500.0, 2000.0])  # N/m, N/m per m
SIGMA_X = [0.02, 0.03, 0.01]


def one_state_model(b=B, k_range=(0.0, 1000.0)):
    state = linear_state(MU_X, b, np.diag(A_DIAGONAL), MU_K, C, SIGMA_X)
    return hand_model(
        [state], startprob=[1.0], transmat=[[0.0]], duration_means=[50.0],
        duration_stds=[5.0], max_duration=100, k_range=k_range,
    )


@pytest.mark.parametrize("weighting", ["temporal", "spatial", "forward"])
def test_one_state_closed_loop_is_the_closed_form_recursion(weighting):
    # e_t = x*_t - mu: e_{t+1} = r e_t + dt b per axis, r = 1 + dt a, so
    # e_t = r^t e_0 + dt b (1 - r^t) / (1 - r).
    start = MU_X + np.array([0.03, 0.01, 0.01])
    n = 60
    log = run(HsmmGmrReproducer(model=one_state_model(), start=start, dt=DT,
                                weighting=weighting), n)
    r = 1.0 + DT * A_DIAGONAL
    t = np.arange(n + 1)[:, None]
    e = r**t * (start - MU_X) + DT * B * (1.0 - r**t) / (1.0 - r)
    np.testing.assert_allclose(log["x_star"], MU_X + e[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(log["xdot_star"], B + A_DIAGONAL * e[:-1], rtol=0, atol=1e-11)
    np.testing.assert_allclose(log["k_star"][:, 0], MU_K + e[:-1] @ C, rtol=1e-11)
    np.testing.assert_allclose(log["h"], 1.0, atol=1e-12)
    assert np.ptp(log["x_star"], axis=0).min() > 3e-3  # it really moved


def test_one_state_open_loop_integrates_the_velocity_at_the_measured_position():
    # p_WE held still: xdot* = b + A (p - mu) every step, so x*_n = x_0 + n dt xdot*.
    start, p_WE = MU_X + [0.03, 0.0, 0.0], MU_X + [-0.01, 0.02, 0.005]
    log = run(HsmmGmrReproducer(model=one_state_model(), start=start, dt=DT), 30, p_WE)
    xdot = B + A_DIAGONAL * (p_WE - MU_X)
    n = np.arange(1, 31)[:, None]
    np.testing.assert_allclose(log["x_star"], start + n * DT * xdot, rtol=0, atol=1e-13)
    np.testing.assert_allclose(log["xdot_star"], np.tile(xdot, (30, 1)), atol=1e-13)
    np.testing.assert_allclose(log["k_star"][:, 0], MU_K + (p_WE - MU_X) @ C, rtol=1e-12)


def test_stiffness_is_clipped_to_the_demonstrated_range_and_set_before_the_first_step():
    # k = 80 + c . (p - mu) = 80 + 1000 * 0.03 = 110 N/m, above the data's 90: clipped.
    start = p_WE = MU_X + [0.03, 0.0, 0.0]
    reproducer = HsmmGmrReproducer(model=one_state_model(k_range=(70.0, 90.0)), start=start)
    context = reproducer.CreateDefaultContext()
    # Before any update the outputs hold the step at the start.
    assert reproducer.GetOutputPort("k_star").Eval(context)[0] == 90.0
    np.testing.assert_allclose(
        reproducer.GetOutputPort("xdot_star").Eval(context), B + A_DIAGONAL * (start - MU_X),
        atol=1e-13,
    )
    log = run(reproducer, 3, p_WE)
    np.testing.assert_array_equal(log["k_star"][:, 0], 90.0)


def test_cross_track_attractor_decays_an_offset_across_the_path_only():
    # One state moving along x_W: u = e_x, and its projector I - w u u^T with
    # w = 1 / (1 + STILL) (the state is the fastest one). With kappa, per axis
    # e_{t+1} = (1 + dt (a - kappa P)) e_t + dt b, P = diag(1 - w, 1, 1).
    b = np.array([0.05, 0.0, 0.0])
    kappa = 5.0
    start = MU_X + np.array([0.01, 0.02, -0.01])
    log = run(HsmmGmrReproducer(model=one_state_model(b=b), start=start, dt=DT,
                                restoring_gain=kappa), 50)
    w = 1.0 / (1.0 + STILL)
    r = 1.0 + DT * (A_DIAGONAL - kappa * np.array([1.0 - w, 1.0, 1.0]))
    t = np.arange(51)[:, None]
    e = r**t * (start - MU_X) + DT * b * (1.0 - r**t) / (1.0 - r)
    np.testing.assert_allclose(log["x_star"], MU_X + e[1:], rtol=0, atol=1e-12)


def two_state_model(startprob=(0.4, 0.6), transmat=((0.0, 1.0), (1.0, 0.0)), durations=None):
    first = linear_state(MU_X, B, np.diag(A_DIAGONAL), MU_K, C, SIGMA_X)
    A2 = np.array([[-1.0, 0.2, 0.0], [0.1, -2.0, 0.3], [0.0, -0.4, -1.5]])
    second = linear_state(
        MU_X + [0.03, 0.01, -0.02], [-0.04, 0.03, 0.0], A2, 120.0, [-300.0, 800.0, 100.0],
        [0.015, 0.025, 0.02],
    )
    means, stds = durations or ((20.0, 30.0), (2.0, 3.0))
    return hand_model(
        [first, second], startprob=startprob, transmat=transmat, duration_means=means,
        duration_stds=stds, max_duration=80, occupancy=[0.3, 0.7],
    )


def gmr_by_hand(model, x):
    """Each state's [xdot; k] regression at x, by solving with S^xx (eq. 16), shape (2, 4)."""
    out = []
    for mean, S in zip(model.means_, model.covariances_):
        gain = np.linalg.solve(S[:3, :3], S[:3, 3:]).T  # S^OI (S^II)^-1
        out.append(mean[3:] + gain @ (x - mean[:3]))
    return np.array(out)


def test_spatial_weights_are_the_prior_weighted_gaussian_densities():
    # Eq. 14: h_i = pi_i N(p | mu_i^x, S_i^xx) / sum_j (...); eq. 15: [xdot; k] mixes the
    # states' regressions with h. Held p_WE: the same every step, x* a straight line.
    model = two_state_model()
    start, p_WE = MU_X, MU_X + [0.015, 0.005, -0.01]
    log = run(HsmmGmrReproducer(model=model, start=start, dt=DT, weighting="spatial"), 10, p_WE)
    density = [
        prior * multivariate_normal(mean[:3], S[:3, :3]).pdf(p_WE)
        for prior, mean, S in zip([0.3, 0.7], model.means_, model.covariances_)
    ]
    h = np.array(density) / sum(density)
    assert 0.05 < h[0] < 0.95  # both states count
    output = h @ gmr_by_hand(model, p_WE)
    np.testing.assert_allclose(log["h"], np.tile(h, (10, 1)), rtol=1e-10)
    np.testing.assert_allclose(log["xdot_star"], np.tile(output[:3], (10, 1)), rtol=1e-10)
    np.testing.assert_allclose(log["k_star"][:, 0], output[3], rtol=1e-10)
    n = np.arange(1, 11)[:, None]
    np.testing.assert_allclose(log["x_star"], start + n * DT * output[:3], atol=1e-13)


def test_forward_weights_start_as_the_start_probabilities_times_the_densities():
    # Eq. 13 at the first step: h_i is proportional to pi_i^start N(p | mu_i^x, S_i^xx).
    model = two_state_model(startprob=(0.4, 0.6))
    p_WE = MU_X + [0.015, 0.005, -0.01]
    log = run(HsmmGmrReproducer(model=model, start=MU_X, dt=DT, weighting="forward"), 1, p_WE)
    density = [
        start * multivariate_normal(mean[:3], S[:3, :3]).pdf(p_WE)
        for start, mean, S in zip([0.4, 0.6], model.means_, model.covariances_)
    ]
    h = np.array(density) / sum(density)
    np.testing.assert_allclose(log["h"][0], h, rtol=1e-10)
    np.testing.assert_allclose(log["xdot_star"][0], (h @ gmr_by_hand(model, p_WE))[:3], rtol=1e-10)


def test_temporal_weights_follow_the_first_duration_distribution():
    # Left to right, started in state 0, state 1 final (re-entered). State 0 is active at step
    # t while its duration D_0 > t: h_0(t) = sum_{d > t} p_0(d) / sum_{d >= 1} p_0(d), p_0 the
    # Gaussian N(20, 2^2) at integer d. (Exact while state 1's durations sum to 1, which for
    # N(30, 3^2) over 1..80 holds to 1e-15.) x* integrates the mix of the two regressions.
    model = two_state_model(startprob=(1.0, 0.0), transmat=((0.0, 1.0), (0.0, 0.0)))
    d = np.arange(1, 81)
    p0 = norm.pdf(d, 20.0, 2.0)
    assert abs(norm.pdf(d, 30.0, 3.0).sum() - 1.0) < 1e-12
    n = 40
    h0 = np.array([p0[d > t].sum() for t in range(n)]) / p0.sum()
    start, p_WE = MU_X, MU_X + [0.01, -0.01, 0.005]
    log = run(HsmmGmrReproducer(model=model, start=start, dt=DT, weighting="temporal"), n, p_WE)
    np.testing.assert_allclose(log["h"][:, 0], h0, rtol=0, atol=1e-12)
    assert h0[10] > 0.999 and h0[-1] < 1e-6  # the hand-over happens in the window
    mixed = h0[:, None] * gmr_by_hand(model, p_WE)[0] + (1 - h0[:, None]) * gmr_by_hand(
        model, p_WE
    )[1]
    np.testing.assert_allclose(log["xdot_star"], mixed[:, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        log["x_star"], start + DT * np.cumsum(mixed[:, :3], axis=0), rtol=0, atol=1e-12
    )


def test_tracking_force_in_a_simulator_is_eq_23_by_hand():
    # F_tr = K_ptr (x_g - x*) + K_dtr xdot*, per axis: [10 (0.4) + 2 (1), 20 (0.3) - 2, 0].
    builder = DiagramBuilder()
    force = builder.AddSystem(TrackingForce(kp=[10.0, 20.0, 30.0], kd=2.0))
    for name, value in (("x_star", [0.1, 0.2, 0.5]), ("xdot_star", [1.0, -1.0, 0.0]),
                        ("x_goal", [0.5, 0.5, 0.5])):
        source = builder.AddSystem(ConstantVectorSource(value))
        builder.Connect(source.get_output_port(), force.GetInputPort(name))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.01)
    F = force.GetOutputPort("F_tr").Eval(force.GetMyContextFromRoot(simulator.get_context()))
    np.testing.assert_allclose(F, [6.0, 4.0, 0.0], rtol=1e-14)
