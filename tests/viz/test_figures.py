"""Figures: each plot shows the data it is given, and saves as a real image."""

import numpy as np
import pytest

from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.sources import synthesize_emg
from hemg_drake.viz.figures import plot_emg_envelopes, save_figure


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
