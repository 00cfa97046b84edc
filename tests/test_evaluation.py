"""The reproduction's record: Table II measured three ways, and success checked on the physics."""

import numpy as np
import pytest

from hemg_drake import evaluation
from hemg_drake.diagrams.reproduction import ReproductionLog, ReproductionResult
from hemg_drake.learning.demos import Demonstration


def _pull(t, rise, z0=0.12, end_time=3.0):
    """A tool point rising by ``rise`` over ``end_time`` s (minimum-jerk), at rest after."""
    tau = np.clip(t / end_time, 0.0, 1.0)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    p = np.column_stack([np.full_like(t, 0.64), np.full_like(t, -0.84), z0 + rise * s])
    return p, np.gradient(p, t, axis=0)


def _demo(seed, rise):
    t = np.arange(0, 4.0, 0.01)
    p, v = _pull(t, rise)
    n, zeros = len(t), np.zeros((len(t), 3))
    force = zeros.copy()
    force[:, 2] = -20.0 * np.exp(-((t - 1.0) ** 2) / 0.05)  # a 20 N pull at t = 1 s
    return Demonstration(
        seed=seed, time=t, p_WE=p, v_WE=v, p_MS=zeros, p_WE_desired=p, envelope=np.zeros(n),
        activation=np.zeros(n), gain=np.full(n, 100.0), f_WE=force,
        emg_time=np.arange(2 * n) * 0.005, emg=np.zeros((2 * n, 8)),
        muscle_activation=np.zeros(2 * n),
    )  # fmt: skip


def _result(rise, *, force=20.0, pin_out=True, dip=0.0, back_down=0.0, tilt_deg=0.0):
    """A pull that rises by ``rise``; ``back_down``: then rises that much more over the last
    second and comes back down; ``tilt_deg``: tool and x* pull that far off the axis (in x)."""
    t = np.arange(0, 4.0, 0.01)
    p, v = _pull(t, rise)
    p[50:60, 2] -= dip
    last = t >= 3.0
    p[last, 2] += back_down * np.sin(np.pi * (t[last] - 3.0))
    tilt = np.radians(tilt_deg)
    z = p[:, 2] - p[0, 2]
    p[:, 0] += z * np.sin(tilt)
    p[:, 2] = p[0, 2] + z * np.cos(tilt)
    v = np.gradient(p, t, axis=0)
    n = len(t)
    f_WE = np.zeros((n, 3))
    f_WE[100, 2] = -force
    log = ReproductionLog(
        time=t, x_star=p, xdot_star=v, k_star=np.full(n, 100.0), h=np.ones((n, 1)),
        p_WE=p, v_WE=v, f_WE=f_WE, F_tr=np.zeros((n, 3)),
    )  # fmt: skip
    return ReproductionResult(log=log, q0=np.zeros(7), pin_displacement=0.06, pin_out=pin_out)


@pytest.fixture
def demos():
    return [_demo(c, rise) for c, rise in enumerate((0.095, 0.10, 0.105))]


def test_a_reproduction_like_the_demonstrations_succeeds_and_its_floor_is_reported(demos):
    record = evaluation.task_metrics("cotter_pin", demos, _result(0.10))
    assert record["success"] and all(record["success_checks"].values())
    # The reproduction is the middle demonstration itself: the lead figure is its offset
    # from the mean of all three (zero), each demonstration's own against the others' mean.
    assert record["position_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    floor = record["table_ii"]["demonstrations_leave_one_out"]["position_rmse_m"]
    assert len(floor) == 3 and max(floor) > 0.004
    assert record["success_limits"]["peak_force_n"] == pytest.approx(1.5 * 20.0, rel=1e-3)
    assert record["table_ii"]["paper"]["position_rmse_m"] == 0.0022
    assert record["pull_direction_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert record["overshoot_m"] == pytest.approx(-0.005, abs=1e-9)  # the peaks: 0.22, 0.225


@pytest.mark.parametrize(
    "result, failed",
    [
        (dict(rise=0.13), "no overshoot"),  # 2.5 cm above the highest demonstration
        # Rises 2 cm above the demonstrations and comes back down to where they end: the
        # old check (the final height) passed it.
        (dict(rise=0.10, back_down=0.02), "no overshoot"),
        # The pin out, but pulled 13 degrees off its axis (a world-frame model at a moved
        # scene): the old checks passed it.
        (dict(rise=0.10, tilt_deg=13.0), "pulled along the axis"),
        (dict(rise=0.10, force=206.0), "force within limit"),
        (dict(rise=0.10, dip=0.04), "not pushed into the fixture"),
        (dict(rise=0.10, pin_out=False), "pin out"),
    ],
)
def test_success_checks_the_physics(demos, result, failed):
    record = evaluation.task_metrics("cotter_pin", demos, _result(**result))
    assert record["success"] is False
    if "back_down" in result:
        assert record["overshoot_m"] == pytest.approx(0.015, abs=1e-4)  # 0.24 m against 0.225
        assert record["final_height_m"] == pytest.approx(0.22, abs=1e-3)  # back down
    if "tilt_deg" in result:
        assert record["pull_direction_error_deg"] == pytest.approx(13.0, abs=1e-6)
    assert record["success_checks"][failed] is False
    assert sum(not ok for ok in record["success_checks"].values()) == 1


# --- checks that see what happened (issue 23): cases that fooled the old checks -----------

DT = 0.01


def _shapes():
    """Three strokes on the sheet (x, y, m): a line, a half circle, a zig-zag."""
    line = np.column_stack([np.linspace(-0.05, 0.06, 12), np.full(12, -0.09)])
    angle = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 15)
    arc = np.column_stack([0.005 + 0.045 * np.cos(angle), -0.01 + 0.045 * np.sin(angle)])
    zigzag = np.column_stack([[-0.02, 0.02, -0.02, 0.02, -0.02], np.linspace(0.05, 0.11, 5)])
    return [line, arc, zigzag]


def _along(corners, n):
    """``n`` points evenly spaced by arc length along the polyline ``corners``."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(corners, axis=0), axis=1))])
    return np.column_stack([np.interp(np.linspace(0, s[-1], n), s, c) for c in corners.T])


def _drawing(order=(0, 1, 2), shift=((0, 0), (0, 0), (0, 0)), lift=None):
    """A drawing's log: 1 s of travel 1 cm above the sheet before each stroke, then the
    stroke pressed with 2 N over 1.5 s (in ``order``, stroke k moved by ``shift[k]``, m), and
    1 s in the air at the end. ``lift`` = (stroke, samples): the pen off the paper for that
    many samples half way through the stroke drawn ``stroke``-th.

    Returns (time, p_WE, f_WE)."""
    points, touching, here = [], [], np.array([0.0, 0.0, 0.01])
    for drawn, k in enumerate(order):
        xy = _along(_shapes()[k], 150) + shift[k]
        stroke = np.column_stack([xy, np.zeros(150)])
        air = np.linspace(here, stroke[0] + [0, 0, 0.01], 100)
        down = np.ones(150, dtype=bool)
        if lift is not None and lift[0] == drawn:
            down[75 : 75 + lift[1]] = False
        points += [air, stroke]
        touching += [np.zeros(100, dtype=bool), down]
        here = stroke[-1] + [0, 0, 0.01]
    points.append(np.linspace(here, [0.0, 0.0, 0.01], 100))
    touching.append(np.zeros(100, dtype=bool))
    p_WE, touching = np.vstack(points), np.concatenate(touching)
    f_WE = np.zeros_like(p_WE)
    f_WE[touching, 2] = 2.0
    return np.arange(len(p_WE)) * DT, p_WE, f_WE


def _demo_of(t, p, f, seed=1):
    n, zeros = len(t), np.zeros((len(t), 3))
    return Demonstration(
        seed=seed, time=t, p_WE=p, v_WE=np.gradient(p, t, axis=0), p_MS=zeros, p_WE_desired=p,
        envelope=np.zeros(n), activation=np.zeros(n), gain=np.full(n, 100.0), f_WE=f,
        emg_time=np.arange(2 * n) * 0.005, emg=np.zeros((2 * n, 8)),
        muscle_activation=np.zeros(2 * n),
    )  # fmt: skip


def _drawing_demo(seed, jitter):
    return _demo_of(*_drawing(shift=[np.array(jitter) * (k + 1) for k in range(3)]), seed=seed)


def _drawn(**kwargs):
    t, p, f = _drawing(**kwargs)
    n, v = len(t), np.gradient(p, t, axis=0)
    log = ReproductionLog(
        time=t, x_star=p, xdot_star=v, k_star=np.full(n, 100.0), h=np.ones((n, 1)),
        p_WE=p, v_WE=v, f_WE=f, F_tr=np.zeros((n, 3)),
    )  # fmt: skip
    return ReproductionResult(log=log, q0=np.zeros(7), pin_displacement=None, pin_out=None)


@pytest.fixture
def drawing_demos():
    # Three demonstrations, demonstration c's stroke k moved (c - 1) (k + 1) mm along y:
    # apart, and their mean is the plain drawing.
    return [_drawing_demo(101 + c, (0.0, 0.001 * (c - 1))) for c in range(3)]


def _drawing_record(demos, **kwargs):
    return evaluation.task_metrics("drawing", demos, _drawn(**kwargs))


def test_the_plain_drawing_succeeds_with_its_strokes_in_shape_and_in_place(drawing_demos):
    record = _drawing_record(drawing_demos)
    assert record["success"] and all(record["success_checks"].values())
    assert record["strokes"] == 3 and record["stroke_order"] == [0, 1, 2]
    assert record["stroke_breaks"] == 0 and record["demonstrated_stroke_breaks"] == [0, 0, 0]
    # The demonstrations' mean stroke k is the drawn one moved by (k + 1) * 0 mm across:
    # the jitters -1, 0, +1 mm average to zero.
    np.testing.assert_allclose(record["stroke_placement_error_m"], 0.0, atol=1e-9)
    np.testing.assert_allclose(record["stroke_shape_error_m"], 0.0, atol=1e-9)


def test_a_40_ms_pen_bounce_mid_stroke_does_not_cut_the_stroke(drawing_demos):
    # Old check: any contact of 0.1 s was a stroke, so the bounce made four strokes and the
    # strokes after it were compared with the wrong ones (by index).
    record = _drawing_record(drawing_demos, lift=(0, 4))
    assert record["strokes"] == 3 and record["stroke_breaks"] == 1
    assert record["success"], record["success_checks"]
    assert max(record["stroke_shape_error_m"]) < 1e-3
    # 50 ms off the paper is a lift: four strokes, and the drawing fails.
    lifted = _drawing_record(drawing_demos, lift=(0, 5))
    assert lifted["strokes"] == 4 and lifted["stroke_breaks"] == 0
    assert lifted["success_checks"]["three strokes"] is False


def test_strokes_drawn_in_another_order_are_matched_by_position(drawing_demos):
    # Drawn zig-zag, line, arc: demonstrated stroke 0 (the line) is drawn second, etc.
    record = _drawing_record(drawing_demos, order=(2, 0, 1))
    assert record["stroke_order"] == [1, 2, 0]
    assert record["success"], record["success_checks"]
    np.testing.assert_allclose(record["stroke_shape_error_m"], 0.0, atol=1e-9)


def test_a_stroke_in_the_wrong_place_fails_in_place_only(drawing_demos):
    # The arc drawn 15 mm to the side (in shape): its placement error is the shift itself.
    shift = ((0, 0), (0.012, 0.009), (0, 0))
    record = _drawing_record(drawing_demos, shift=shift)
    assert record["stroke_placement_error_m"][1] == pytest.approx(0.015, abs=1e-9)
    assert record["success"] is False
    assert [name for name, ok in record["success_checks"].items() if not ok] == ["strokes in place"]
    assert record["success_limits"]["stroke_placement_error_m"] == evaluation.STROKE_PLACEMENT_M
    # Within the bound (8 mm off) it is in place.
    near = _drawing_record(drawing_demos, shift=((0, 0), (0.0, 0.008), (0, 0)))
    assert near["success"], near["success_checks"]


def test_stroke_runs_merge_only_breaks_shorter_than_50_ms():
    t = np.arange(60) * DT
    f = np.zeros((60, 3))
    # Contacts at samples 0-14, 18-29 (3 off: 30 ms), 34-45 (4 off: 40 ms) and 51-59 (5 off:
    # 50 ms, a lift; 9 samples, too short to be a stroke alone).
    for a, b in ((0, 15), (18, 30), (34, 46), (51, 60)):
        f[a:b, 2] = 1.0
    runs, breaks = evaluation.stroke_runs(t, f)
    assert runs == [(0, 46)] and breaks == [2]


# --- a take's ink against the page's template (template_errors) ----------------------------


def test_a_take_is_scored_against_the_template_by_shape_hand_values():
    shapes = [np.column_stack([s, np.zeros(len(s))]) for s in _shapes()]
    a = 0.002  # the template's line tilted: its ends a above and a below the drawn line
    tilted = shapes[0][[0, -1]] + [[0.0, a, 0.0], [0.0, -a, 0.0]]
    # Both resampled to 50 points evenly along x: the gaps a (1 - 2u), u = i / 49, whose mean
    # square is (n + 1) / (3 (n - 1)) a^2 for n = 50 points.
    expected = a * np.sqrt(51 / 147)
    drawn, errors = evaluation.template_errors(_demo_of(*_drawing(order=(2, 0, 1))),
                                               [shapes[1], tilted, shapes[2]])  # fmt: skip
    assert drawn == 3
    # The arc and the zig-zag drawn as sampled (150 points, cutting the template's vertices
    # by up to 0.3 mm at the zig-zag's corners): next to nothing.
    assert errors[0] < 1e-4 and errors[2] < 3e-4
    assert errors[1] == pytest.approx(expected, rel=1e-9)
    # Where the template stands does not count (shape only), nor which way a stroke was drawn.
    t, p, f = _drawing(shift=((0.004, -0.003), (0, 0), (0, 0)))
    p_back = p.copy()
    down = f[:, 2] > 0
    first = np.flatnonzero(down)[:150]
    p_back[first] = p[first][::-1]
    drawn, errors = evaluation.template_errors(_demo_of(t, p_back, f), [tilted])
    assert drawn == 3 and errors == [pytest.approx(expected, rel=1e-9)]


def _inked(xy_strokes):
    """A take inking ``xy_strokes`` (m) in turn, 2 N on the pen, 0.3 s in the air between."""
    points, force = [], []
    for xy in xy_strokes:
        stroke = np.column_stack([xy, np.zeros(len(xy))])
        points += [np.repeat(stroke[:1] + [0.0, 0.0, 0.01], 30, axis=0), stroke]
        force += [np.zeros((30, 3)), np.tile([0.0, 0.0, 2.0], (len(xy), 1))]
    p = np.vstack(points)
    return _demo_of(np.arange(len(p)) * DT, p, np.vstack(force))


def test_a_stroke_drawn_backwards_is_matched_to_its_template_stroke():
    # The line drawn from its far end, and a stray 2 cm touch 8 mm from its near end: the
    # line is matched whichever way it went (by its forward distance alone the stray won it).
    line, arc, zigzag = (_along(s, 150) for s in _shapes())
    stray = _along(line[0] + np.array([[0.0, 0.008], [0.02, 0.008]]), 20)
    template = [np.column_stack([s, np.zeros(len(s))]) for s in _shapes()]
    drawn, errors = evaluation.template_errors(_inked([line[::-1], stray, arc, zigzag]), template)
    assert drawn == 4
    assert errors[0] < 1e-9 and errors[1] < 1e-4 and errors[2] < 3e-4


def test_ink_that_never_moved_counts_but_is_not_matched():
    dot = np.tile([0.0, -0.09], (20, 1))  # the pen pressed and lifted where it came down
    template = [np.column_stack([s, np.zeros(len(s))]) for s in _shapes()]
    drawn, errors = evaluation.template_errors(_inked([dot]), template)
    assert drawn == 1 and errors == [None, None, None]


def test_a_template_stroke_left_undrawn_has_no_error():
    t, p, f = _drawing()
    f[250:500, 2] = 0.0  # the second stroke (the arc) drawn in the air
    template = [np.column_stack([s, np.zeros(len(s))]) for s in _shapes()]
    drawn, errors = evaluation.template_errors(_demo_of(t, p, f), template)
    assert drawn == 2 and errors[1] is None
    assert errors[0] < 1e-9 and errors[2] < 3e-4
