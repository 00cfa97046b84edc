"""Figures: each plot shows the data it is given, and saves as a real image."""

import numpy as np
import pytest

from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.sources import synthesize_emg
from hemg_drake.viz.figures import (
    plot_emg_envelopes,
    plot_gain_law,
    plot_time_series,
    save_figure,
)


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
    # Concave for A_emg < 0: at u = 0.5 the paper's curve lies above the straight line.
    assert activation_axes.get_lines()[0].get_ydata()[50] == pytest.approx(0.586, abs=1e-3)


def test_time_series_draws_one_axis_per_signal_and_a_line_per_column():
    time = np.linspace(0.0, 1.0, 11)
    figure = plot_time_series(time, {"gain": 2 * time, "p_WE (m)": np.outer(time, [1, 2, 3])})
    gain_axes, position_axes = figure.axes
    np.testing.assert_array_equal(gain_axes.get_lines()[0].get_ydata(), 2 * time)
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
