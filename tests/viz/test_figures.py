"""Figures: each plot shows the data it is given, and saves as a real image."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.sources import synthesize_emg
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import Reproduction
from hemg_drake.control.pd import STIFFNESS_SCALE
from hemg_drake.viz.figures import (
    plot_demonstrations,
    plot_drawing_reproduction,
    plot_emg_envelopes,
    plot_gain_law,
    plot_gmr_field,
    plot_pin_reproduction,
    plot_reproductions,
    plot_state_activations,
    plot_strokes,
    plot_time_series,
    save_figure,
    state_activations_title,
    steps_from_contact,
)

# K's unit as the figures must name it: joint j's stiffness is K * s_j N·m/rad.
K_UNIT = "N·m/rad per unit s_j"


@pytest.fixture(scope="module")
def samples():
    return synthesize_emg(np.linspace(0.0, 1.0, 400), seed=3)


def test_emg_envelopes_plot_the_summed_signal_and_each_window(samples):
    figure = plot_emg_envelopes(samples, windows=(10, 30), rate=200.0)
    raw_axes, envelope_axes = figure.axes
    (raw_line,) = raw_axes.get_lines()
    np.testing.assert_array_equal(raw_line.get_ydata(), samples.sum(axis=1))
    np.testing.assert_allclose(raw_line.get_xdata()[[0, -1]], [0.0, 399 / 200.0])
    lines = envelope_axes.get_lines()
    assert [line.get_label() for line in lines] == ["L_win = 10", "L_win = 30"]
    for line, window in zip(lines, (10, 30), strict=True):
        np.testing.assert_array_equal(line.get_ydata(), moving_rms(samples, window))


def test_per_channel_option_plots_the_per_channel_envelope(samples):
    figure = plot_emg_envelopes(samples, windows=(20,), per_channel=True)
    (line,) = figure.axes[1].get_lines()
    np.testing.assert_array_equal(line.get_ydata(), moving_rms(samples, 20, per_channel=True))


@pytest.mark.parametrize(
    "kwargs, message",
    [({"windows": ()}, "at least one"), ({"windows": (0,)}, "window"), ({"rate": 0.0}, "rate")],
)
def test_emg_envelopes_bad_input(samples, kwargs, message):
    with pytest.raises(ValueError, match=message):
        plot_emg_envelopes(samples, **kwargs)


def test_save_figure_writes_png_and_svg(tmp_path, samples):
    figure = plot_emg_envelopes(samples[:50], windows=(10,))
    save_figure(figure, tmp_path / "f.png")
    save_figure(figure, tmp_path / "f.svg")
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (tmp_path / "f.svg").read_bytes()[:1000]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.png", "f.svg"]


def test_gain_law_plots_eq_22_per_shape_factor():
    figure = plot_gain_law((-0.6981, 2.0), k_min=10.0, k_max=100.0)
    activation_axes, gain_axes = figure.axes
    for line, A_emg in zip(activation_axes.get_lines(), (-0.6981, 2.0), strict=True):
        u = line.get_xdata()
        np.testing.assert_allclose(line.get_ydata(), np.expm1(A_emg * u) / np.expm1(A_emg))
    for line in gain_axes.get_lines():
        gain = line.get_ydata()
        assert gain[0] == pytest.approx(10.0) and gain[-1] == pytest.approx(100.0)
        assert np.all(np.diff(gain) > 0)  # stronger contraction, stiffer slave
    assert K_UNIT in gain_axes.get_ylabel()
    # Concave for A_emg < 0: at u = 0.5 the paper's curve lies above the straight line.
    assert activation_axes.get_lines()[0].get_ydata()[50] == pytest.approx(0.586, abs=1e-3)


def test_time_series_draws_one_axis_per_signal_and_a_line_per_column():
    time = np.linspace(0.0, 1.0, 11)
    figure = plot_time_series(time, {"gain": 2 * time, "p_WE (m)": np.outer(time, [1, 2, 3]),
                                     "k*": 4 * time[:, None]})
    gain_axes, position_axes, k_axes = figure.axes
    np.testing.assert_array_equal(gain_axes.get_lines()[0].get_ydata(), 2 * time)
    (k_line,) = k_axes.get_lines()  # a one-column signal is one unlabelled line
    np.testing.assert_array_equal(k_line.get_ydata(), 4 * time)
    assert k_axes.get_legend() is None
    lines = position_axes.get_lines()
    assert [line.get_label() for line in lines] == ["x", "y", "z"]
    np.testing.assert_array_equal(lines[2].get_ydata(), 3 * time)
    assert position_axes.get_ylabel() == "p_WE (m)"


@pytest.mark.parametrize(
    "time, series, message",
    [
        (np.zeros((2, 2)), {"a": np.zeros(2)}, "time must have shape"),
        (np.zeros(3), {}, "at least one"),
        (np.zeros(3), {"a": np.zeros(4)}, "signal 'a'"),
    ],
)
def test_time_series_bad_input(time, series, message):
    with pytest.raises(ValueError, match=message):
        plot_time_series(time, series)


def test_gain_law_needs_a_shape_factor():
    with pytest.raises(ValueError, match="at least one"):
        plot_gain_law(())


def _demo(seed, n=40):
    """A demonstration moving up along z at 0.1 m/s with a stiffness ramp (the fields of
    ``Demonstration`` the figures read)."""
    time = np.arange(n) * 0.01
    p_WE = np.column_stack([np.full(n, 0.6 + 0.001 * seed), np.full(n, -0.8), 0.1 + 0.1 * time])
    v_WE = np.tile([0.0, 0.0, 0.1], (n, 1))
    zeros = np.zeros(n)
    return SimpleNamespace(seed=seed, time=time, p_WE=p_WE, v_WE=v_WE, p_MS=np.zeros((n, 3)),
                           envelope=zeros, activation=zeros, gain=50 + 100 * time, f_WE=v_WE)


def _two_state_model():
    """A hand-set 7-D HSMM (x, xdot, k) with velocity coupled to x (non-zero GMR gains)."""
    rng = np.random.default_rng(4)
    model = HSMM(2)
    model.means_ = np.array([[0.6, -0.8, 0.12, 0.0, 0.0, 0.1, 60.0],
                             [0.6, -0.8, 0.14, 0.01, 0.0, 0.05, 90.0]])
    factors = 0.01 * rng.standard_normal((2, 7, 7))
    model.covariances_ = factors @ factors.transpose(0, 2, 1) + 1e-4 * np.eye(7)
    model.startprob_ = np.array([1.0, 0.0])
    model.transmat_ = np.array([[0.0, 1.0], [1.0, 0.0]])
    model.duration_means_ = np.array([20.0, 20.0])
    model.duration_stds_ = np.array([2.0, 2.0])
    model.occupancy_ = np.array([0.4, 0.6])
    model.data_range_ = np.outer([-np.inf, np.inf], np.ones(7))  # k* left unclipped
    model.max_duration_ = 40
    model.log_likelihood_history_ = []
    return model


def test_reproductions_plot_demos_in_grey_and_each_reproduction():
    demos = [_demo(0), _demo(1)]
    t = np.arange(30) * 0.01
    reproduction = Reproduction(t=t, x=np.outer(t, [1, 2, 3]), xdot=np.tile([1, 2, 3], (30, 1)),
                                k=np.full((30, 1), 70.0), h=np.ones((30, 1)))
    figure = plot_reproductions(demos, {"forward": reproduction})
    z_axes, vz_axes, k_axes = figure.axes[2], figure.axes[5], figure.axes[6]
    demo_line, _, reproduced = z_axes.get_lines()
    np.testing.assert_array_equal(demo_line.get_ydata(), demos[0].p_WE[:, 2])
    np.testing.assert_array_equal(reproduced.get_ydata(), 3 * t)
    np.testing.assert_array_equal(vz_axes.get_lines()[-1].get_ydata(), np.full(30, 3.0))
    np.testing.assert_array_equal(k_axes.get_lines()[-1].get_ydata(), np.full(30, 70.0))
    assert reproduced.get_label() == "forward"
    assert K_UNIT in k_axes.get_ylabel()


def test_state_activations_one_line_per_state():
    h = np.column_stack([np.linspace(1, 0, 5), np.linspace(0, 1, 5)])
    figure = plot_state_activations(np.arange(5) * 0.1, h)
    lines = figure.axes[0].get_lines()
    assert [line.get_label() for line in lines] == ["state 1", "state 2"]
    np.testing.assert_array_equal(lines[1].get_ydata(), h[:, 1])
    assert figure.axes[0].get_legend() is not None


def test_many_state_activations_are_a_heat_map_with_a_colour_bar():
    rng = np.random.default_rng(7)
    h = rng.dirichlet(np.ones(18), size=50)  # T = 50, N = 18
    time = 0.01 * np.arange(50)
    figure = plot_state_activations(time, h, task="drawing", along="demonstration 1")
    axes, colorbar_axes = figure.axes
    assert axes.get_lines() == []  # no ten-colour cycle repeating over 18 lines
    (mesh,) = axes.collections
    np.testing.assert_array_equal(np.asarray(mesh.get_array()).reshape(18, 50), h.T)
    assert mesh.get_clim() == (0.0, 1.0)
    assert colorbar_axes.get_ylabel() == "h_i"
    # Cells centred on the samples' times and on the state numbers 1..18.
    np.testing.assert_allclose(axes.get_xlim(), [-0.005, 0.495])
    np.testing.assert_allclose(axes.get_ylim(), [0.5, 18.5])
    assert "Fig. 8" not in axes.get_title() and "drawing" in axes.get_title()


def test_state_activation_titles_name_fig_8c_only_for_the_pin():
    assert state_activations_title("cotter_pin", "demonstration 1") == (
        "HSMM state activations h, cotter pin, on demonstration 1 (Fig. 8 (c))")
    assert "Fig. 8" not in state_activations_title("drawing")
    assert state_activations_title("drawing", 2) == (
        "HSMM state activations h, drawing, on demonstration 2 (eq. 12)")
    h = np.full((3, 2), 0.5)
    figure = plot_state_activations(np.arange(3.0), h, task="cotter_pin", title="mine")
    assert figure.axes[0].get_title() == "mine"  # an explicit title wins
    with pytest.raises(ValueError, match="task"):
        state_activations_title("pin")
    for along in (0, True):
        with pytest.raises(ValueError, match="along"):
            state_activations_title("drawing", along)


def _gmr_reference(model, x, radius=3.0):
    """Eq. 14 weights and eq. 16 conditional means, by hand (scipy's Gaussian density); each
    state's eq. 16 conditions on x pulled onto its ``radius``-sigma ellipsoid (the policy's
    support: it does not extrapolate)."""
    weights, velocities = [], []
    for prior, mean, covariance in zip(model.occupancy_, model.means_, model.covariances_):
        S_xx, S_vx = covariance[:3, :3], covariance[3:6, :3]
        weights.append(prior * multivariate_normal(mean[:3], S_xx).pdf(x))
        d = x - mean[:3]
        sigmas = np.sqrt(d @ np.linalg.solve(S_xx, d))
        x_i = mean[:3] + d * min(1.0, radius / sigmas) if sigmas > 0 else x
        velocities.append(mean[3:6] + S_vx @ np.linalg.solve(S_xx, x_i - mean[:3]))
    return np.average(velocities, axis=0, weights=weights)


def test_gmr_field_arrows_follow_eqs_14_to_17():
    model = _two_state_model()
    figure = plot_gmr_field(model, [_demo(0)], plane=(0, 2), grid=5)
    axes = figure.axes[0]
    (quiver,) = axes.collections
    centre = model.occupancy_ @ model.means_[:, :3]
    spacing = np.diff(np.unique(quiver.get_offsets()[:, 1]))[0]
    longest = 1.2 * spacing * quiver.scale  # no arrow is longer than 1.2 grid spacings
    unclipped = 0
    for (x_axis, z_axis), U, V in zip(quiver.get_offsets(), quiver.U, quiver.V, strict=True):
        expected = _gmr_reference(model, np.array([x_axis, centre[1], z_axis]))[[0, 2]]
        if np.hypot(*expected) < longest:
            np.testing.assert_allclose([U, V], expected, rtol=1e-6, atol=1e-12)
            unclipped += 1
        else:
            assert np.hypot(U, V) == pytest.approx(longest)
            np.testing.assert_allclose(np.arctan2(V, U), np.arctan2(*expected[::-1]))
    assert unclipped >= len(quiver.U) // 2
    assert len(axes.patches) == 2  # one ellipse per state


def test_gmr_field_of_a_thin_path_keeps_one_scale_on_both_axes():
    # The demonstrations move 0.4 m up and 1 mm sideways, like the pin: equal axes, and
    # the narrow side widened to 0.3 of the long one rather than magnified 400 times.
    model = _two_state_model()
    narrow = np.diag([0.02, 1, 1, 1, 1, 1, 1])  # x's spread down 50 times, still positive
    model.covariances_ = narrow @ model.covariances_ @ narrow
    figure = plot_gmr_field(model, [_demo(0, n=400), _demo(1, n=400)], plane=(0, 2))
    axes = figure.axes[0]
    assert axes.get_aspect() == 1.0
    width, height = np.ptp(axes.get_xlim()), np.ptp(axes.get_ylim())
    assert 0.3 <= width / height <= 0.5  # 0.3, rounded up to whole grid cells
    assert "m/s" in axes.get_xlabel()  # the arrows' scale is stated
    # A middle column of arrows runs through the data's middle.
    columns = np.unique(np.round(axes.collections[0].get_offsets()[:, 0], 12))
    assert np.min(np.abs(columns - np.mean(axes.get_xlim()))) < 1e-9
    loose = plot_gmr_field(model, [_demo(0)], plane=(0, 2), equal_aspect=False).axes[0]
    assert loose.get_aspect() == "auto"


@pytest.mark.parametrize(
    "kwargs, message",
    [({"plane": (0, 0)}, "plane"), ({"plane": (0, 3)}, "plane"), ({"grid": 1}, "grid")],
)
def test_gmr_field_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        plot_gmr_field(_two_state_model(), **kwargs)


def test_learning_plots_bad_input():
    with pytest.raises(ValueError, match="at least one reproduction"):
        plot_reproductions([_demo(0)], {})
    with pytest.raises(ValueError, match=r"h \(T, N\)"):
        plot_state_activations(np.zeros(3), np.zeros((4, 2)))


def _log(n=30):
    """A reproduction log: the tool point rising along z at 0.2 m/s, k* and F_tr ramps."""
    time = np.arange(n) * 0.01
    return SimpleNamespace(
        time=time, p_WE=np.outer(time, [0.0, 0.0, 0.2]) + [0.6, -0.8, 0.1],
        v_WE=np.tile([0.0, 0.0, 0.2], (n, 1)), k_star=80 + 10 * time,
        F_tr=np.outer(time, [1.0, 2.0, 3.0]),
    )


def test_pin_reproduction_shows_demos_log_and_tracking_force():
    demos, log = [_demo(0), _demo(1)], _log()
    axes = plot_pin_reproduction(demos, log).axes
    grid = np.reshape(axes[:9], (3, 3))
    *demo_lines, reproduced = grid[0, 2].get_lines()
    np.testing.assert_array_equal(demo_lines[1].get_ydata(), demos[1].p_WE[:, 2])
    np.testing.assert_array_equal(reproduced.get_ydata(), log.p_WE[:, 2])
    assert reproduced.get_label() == "reproduction"
    np.testing.assert_array_equal(grid[1, 2].get_lines()[-1].get_ydata(), log.v_WE[:, 2])
    np.testing.assert_array_equal(grid[2, 1].get_lines()[0].get_ydata(), log.F_tr[:, 1])


def test_pin_reproduction_has_a_stiffness_panel_with_its_unit():
    demos, log = [_demo(0), _demo(1)], _log()
    stiffness = plot_pin_reproduction(demos, log).axes[9]
    *demo_gains, k_star = stiffness.get_lines()
    for line, demo in zip(demo_gains, demos, strict=True):
        np.testing.assert_array_equal(line.get_xdata(), demo.time)
        np.testing.assert_array_equal(line.get_ydata(), demo.gain)
    np.testing.assert_array_equal(k_star.get_xdata(), log.time)
    np.testing.assert_array_equal(k_star.get_ydata(), log.k_star)
    assert K_UNIT in stiffness.get_ylabel()
    # The note beside the axis gives the joint stiffnesses K sets (pd.STIFFNESS_SCALE).
    assert ", ".join(f"{s:g}" for s in STIFFNESS_SCALE) in stiffness.get_xlabel()


def _pen_force(time, strokes):
    """A pen force of 3 N (down, -z) inside each (start, end) stroke, zero elsewhere."""
    f = np.zeros((len(time), 3))
    for start, end in strokes:
        f[(time >= start) & (time <= end), 2] = -3.0
    return f


def _drawing_log(strokes=((1.0, 2.0), (3.0, 4.5), (5.5, 7.0))):
    time = np.round(np.arange(801) * 0.01, 10)  # 0 ... 8 s
    p_WE = np.column_stack([0.6 + 0.01 * time, -0.8 + 0.02 * time, 0.1 + 0.0 * time])
    return SimpleNamespace(time=time, p_WE=p_WE, v_WE=np.zeros_like(p_WE),
                           k_star=60 + 10 * time, f_WE=_pen_force(time, strokes))


def test_drawing_reproduction_shows_positions_and_stiffness():
    demos, log = [_demo(0)], _log()
    axes = plot_drawing_reproduction(demos, log).axes
    demo_line, reproduced = axes[1].get_lines()
    np.testing.assert_array_equal(demo_line.get_ydata(), demos[0].p_WE[:, 1])
    np.testing.assert_array_equal(reproduced.get_ydata(), log.p_WE[:, 1])
    demo_gain, k_star = axes[3].get_lines()
    np.testing.assert_array_equal(demo_gain.get_ydata(), demos[0].gain)
    np.testing.assert_array_equal(k_star.get_ydata(), log.k_star)
    assert K_UNIT in axes[3].get_ylabel()
    # Neither log shows three strokes: no marks, and the title says so.
    assert [t.get_text() for t in axes[0].texts] == []
    assert "not marked" in axes[0].figure.get_suptitle()


def _marks(axes):
    """x of the vertical dashed lines on an axis (axvline: two equal x values)."""
    return [line.get_xdata()[0] for line in axes.get_lines() if line.get_linestyle() == "--"]


def test_drawing_reproduction_marks_steps_I_to_VI_from_the_pen_force():
    log = _drawing_log()
    axes = plot_drawing_reproduction([_demo(0)], log).axes
    # Boundaries by hand: end of stroke 1, start and end of 2, start and end of 3.
    boundaries = [2.0, 3.0, 4.5, 5.5, 7.0]
    for each in axes:
        np.testing.assert_allclose(_marks(each), boundaries)
    texts = axes[0].texts
    assert [t.get_text() for t in texts] == ["I", "II", "III", "IV", "V", "VI"]
    centres = [t.get_position()[0] for t in texts]
    np.testing.assert_allclose(centres, np.diff([0.0, *boundaries, 8.0]) / 2
                               + np.array([0.0, *boundaries]))


def test_drawing_steps_given_or_switched_off():
    log = _drawing_log()
    steps = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])  # e.g. drawing_steps(plan)
    axes = plot_drawing_reproduction([_demo(0)], log, steps=steps).axes
    np.testing.assert_allclose(_marks(axes[2]), steps[1:-1])
    axes = plot_drawing_reproduction([_demo(0)], log, steps=False).axes
    assert _marks(axes[2]) == [] and len(axes[0].texts) == 0
    with pytest.raises(ValueError, match="7 increasing times"):
        plot_drawing_reproduction([_demo(0)], log, steps=[0.0, 1.0])


def test_steps_from_contact_joins_a_bounce_and_needs_three_strokes():
    time = np.round(np.arange(801) * 0.01, 10)
    bounced = _pen_force(time, [(1.0, 1.5), (1.6, 2.0), (3.0, 4.5), (5.5, 7.0)])
    np.testing.assert_allclose(steps_from_contact(time, bounced),
                               [0.0, 2.0, 3.0, 4.5, 5.5, 7.0, 8.0])
    # A pen lift of 0.5 s is a stroke boundary: four strokes, no steps.
    assert steps_from_contact(time, _pen_force(time, [(1, 1.5), (2, 2.5), (3, 4), (5, 6)])) is None
    assert steps_from_contact(time, np.zeros((801, 3))) is None


def test_stiffness_has_its_unit_on_the_drawing_demonstrations():
    axes = plot_demonstrations([_demo(0)], task="drawing").axes
    assert K_UNIT in axes[3].get_ylabel()
    np.testing.assert_array_equal(axes[3].get_lines()[0].get_ydata(), _demo(0).gain)


def test_strokes_are_drawn_from_above_over_the_demonstrations():
    line = np.array([[0.0, 0.1, 0.05], [0.1, 0.1, 0.05], [0.2, 0.15, 0.05]])
    figure = plot_strokes([line, line[:, :2] + 0.01], demonstrated=[line])
    axes = figure.axes[0]
    demonstrated, first, second = axes.get_lines()
    assert [each.get_label() for each in (demonstrated, first, second)] == [
        "demonstrations", "stroke 1", "stroke 2"]
    np.testing.assert_array_equal(first.get_xydata(), line[:, :2])
    np.testing.assert_array_equal(second.get_xydata(), line[:, :2] + 0.01)
    assert axes.get_aspect() == 1.0  # equal axes: the shapes are not distorted


@pytest.mark.parametrize("stroke", [np.zeros(3), np.zeros((4, 1))])
def test_strokes_bad_shape(stroke):
    with pytest.raises(ValueError, match=r"a stroke must have shape \(k, 2 or 3\)"):
        plot_strokes([stroke])
