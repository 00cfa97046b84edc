"""Synthetic, file and live sEMG sources, each run in a Drake diagram."""

import numpy as np
import pytest

from hemg_drake.emg.sources import (
    DEFAULT_CHANNEL_GAINS,
    DEFAULT_REST_STD,
    FileEmgSource,
    LiveEmgSource,
    SyntheticEmgSource,
    load_emg_recording,
    save_emg_recording,
    synthesize_emg,
)
from hemg_drake.fileio import save_npz_atomic, write_text_atomic


def _run_synthetic(builder, simulate, held_signal, activation, seed, **kwargs):
    source = builder.AddSystem(SyntheticEmgSource(seed=seed, **kwargs))
    signal = builder.AddSystem(held_signal(activation))
    builder.Connect(signal.get_output_port(), source.get_activation_input_port())
    return simulate(builder, {"emg": source.get_emg_output_port()}, len(activation))["emg"]


def test_synthetic_system_follows_its_documented_model(builder, simulate, held_signal):
    # The model of the docstring, written here: sample k is
    # clip(round((rest_std + g_i a_k^p) n_k), -128, 127), with n_k row k mod 200 of the
    # 200 x 8 normals of default_rng((seed, k // 200)). Exponent 2, so a^p matters;
    # 450 samples span three noise blocks, and full activation clips the widest channels.
    gains = np.array([40.0, 34.0, 26.0, 20.0, 20.0, 26.0, 34.0, 40.0])
    activation = np.concatenate([np.zeros(30), np.linspace(0.0, 1.0, 400), np.ones(20)])
    emg = _run_synthetic(builder, simulate, held_signal, activation, seed=11, exponent=2.0)
    expected = np.empty((len(activation), 8))
    for k, a in enumerate(activation):
        normals = np.random.default_rng((11, k // 200)).standard_normal((200, 8))[k % 200]
        expected[k] = np.clip(np.round((2.0 + gains * a**2) * normals), -128, 127)
    np.testing.assert_array_equal(emg, expected)
    assert np.any(np.abs(expected) == 127) or np.any(expected == -128)


def test_synthetic_system_has_the_documented_spread(builder, simulate, held_signal):
    # At a constant activation the samples are zero-mean with per-channel standard
    # deviation sqrt((rest_std + g_i a)^2 + 1/12) (rounding adds 1/12): 3000 samples.
    a = 0.6
    emg = _run_synthetic(builder, simulate, held_signal, np.full(3000, a), seed=4)
    spread = 2.0 + np.array(DEFAULT_CHANNEL_GAINS) * a
    np.testing.assert_allclose(emg.std(axis=0), np.sqrt(spread**2 + 1 / 12), rtol=0.05)
    assert np.all(np.abs(emg.mean(axis=0)) < 4 * spread / np.sqrt(3000))


def test_synthetic_system_equals_twin_sample_for_sample(builder, simulate, held_signal):
    # A wiring test: the twin shares the model (the two tests above check the model).
    # 450 samples cross two of the blocks in which the noise is drawn (NOISE_BLOCK = 200).
    activation = np.concatenate([np.full(40, 0.1), np.linspace(0.1, 1.0, 390), np.full(20, 0.8)])
    emg = _run_synthetic(builder, simulate, held_signal, activation, seed=11)
    np.testing.assert_array_equal(emg, synthesize_emg(activation, 11))
    assert np.all(emg == np.round(emg)) and emg.min() >= -128 and emg.max() <= 127


def test_sample_noise_is_a_function_of_seed_and_index():
    # Sample k's noise does not depend on which samples were drawn before it.
    activation = np.full(450, 0.5)
    whole = synthesize_emg(activation, 7)
    model = SyntheticEmgSource(seed=7)._model
    for k in (449, 3, 201, 199, 200, 0):
        np.testing.assert_array_equal(model.sample(0.5, k), whole[k])
    blocks = [model.noise(k) for k in (0, 200, 400)]
    assert not np.array_equal(blocks[0], blocks[1]) and not np.array_equal(blocks[1], blocks[2])


def test_same_seed_same_samples_different_seed_different():
    activation = np.full(200, 0.5)
    np.testing.assert_array_equal(synthesize_emg(activation, 3), synthesize_emg(activation, 3))
    assert np.mean(synthesize_emg(activation, 3) != synthesize_emg(activation, 4)) > 0.9


def test_noise_std_follows_documented_law():
    gains = np.asarray(DEFAULT_CHANNEL_GAINS)
    for a in (0.0, 0.5, 1.0):
        emg = synthesize_emg(np.full(4000, a), seed=5)
        assert np.all(np.abs(emg.mean(axis=0)) < 0.1 * (DEFAULT_REST_STD + gains * a) + 0.2)
        # Rounding adds variance 1/12; clipping at 127 is rare below 3 std.
        expected = np.sqrt((DEFAULT_REST_STD + gains * a) ** 2 + 1 / 12)
        np.testing.assert_allclose(emg.std(axis=0), expected, rtol=0.06)


def test_activation_is_clipped_and_nan_reads_as_rest(builder, simulate, held_signal):
    raw = np.array([1.7, -0.3, np.nan, 0.4])
    emg = _run_synthetic(builder, simulate, held_signal, raw, seed=2)
    np.testing.assert_array_equal(emg, synthesize_emg([1.0, 0.0, 0.0, 0.4], 2))


def test_strong_noise_is_clipped_to_int8():
    emg = synthesize_emg(np.ones(500), seed=1, channel_gains=np.full(8, 500.0))
    assert emg.max() == 127 and emg.min() == -128


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"seed": 0, "channel_gains": [1.0] * 7}, "channel_gains"),
        ({"seed": 0, "channel_gains": [np.nan] * 8}, "channel_gains"),
        ({"seed": 0, "rest_std": -1.0}, "rest_std"),
        ({"seed": 0, "exponent": 0.0}, "exponent"),
        ({"seed": 0, "period": 0.0}, "period"),
    ],
)
def test_synthetic_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SyntheticEmgSource(**kwargs)


def test_twin_rejects_bad_activation():
    with pytest.raises(ValueError, match="NaN"):
        synthesize_emg([0.1, np.nan], seed=0)
    with pytest.raises(ValueError, match="shape"):
        synthesize_emg(np.zeros((3, 2)), seed=0)


RECORDING = np.array([[k * 8 + i - 60 for i in range(8)] for k in range(5)], dtype=np.int64)


def _write_csv(path, rows):
    write_text_atomic(path, "".join(",".join(str(v) for v in row) + "\n" for row in rows))


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
@pytest.mark.parametrize("at_end", ["hold", "loop"])
def test_file_source_replays_recording(builder, simulate, tmp_path, suffix, at_end):
    path = tmp_path / f"rec{suffix}"
    if suffix == ".csv":
        _write_csv(path, RECORDING)
    else:
        save_npz_atomic(path, emg=RECORDING.astype(np.int8))
    source = builder.AddSystem(FileEmgSource(filename=path, at_end=at_end))
    emg = simulate(builder, {"emg": source.get_emg_output_port()}, 12)["emg"]
    rows = np.arange(12) % 5 if at_end == "loop" else np.minimum(np.arange(12), 4)
    np.testing.assert_array_equal(emg, RECORDING[rows])


def test_file_source_bad_option(tmp_path):
    _write_csv(tmp_path / "r.csv", RECORDING)
    with pytest.raises(ValueError, match="at_end"):
        FileEmgSource(filename=tmp_path / "r.csv", at_end="rewind")


@pytest.mark.parametrize(
    "text, message",
    [
        ("1,2,3,4,5,6,7,8\n1,2,3,4,5,6,7\n", r"line 2: expected 8 comma-separated columns"),
        ("1,2,3,4,5,6,7,8\n1,2,3,x,5,6,7,8\n", r"line 2: column 4: 'x' is not an integer"),
        ("1,2,3,4,5,6,7,8\n1,2,3,4.5,5,6,7,8\n", r"line 2: column 4: '4.5' is not an integer"),
        ("1,2,3,4,5,6,7,8\n1,2,3,4,5,6,7,128\n", r"line 2: column 8: value 128 is outside"),
        ("1,2,3,4,5,6,7,8\n-129,2,3,4,5,6,7,8\n", r"line 2: column 1: value -129 is outside"),
        ("", "holds no samples"),
        ("\n\n", "holds no samples"),
    ],
)
def test_malformed_csv_names_file_line_and_problem(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    write_text_atomic(path, text)
    with pytest.raises(ValueError, match=message) as error:
        FileEmgSource(filename=path)
    assert str(path) in str(error.value)


@pytest.mark.parametrize(
    "arrays, message",
    [
        ({"emg": np.array([[0.0] * 8, [1.0] * 7 + [np.nan]])}, r"row 2, column 8: NaN"),
        ({"emg": np.array([[0.0] * 8, [0.5] * 8])}, r"row 2, column 1: a non-integer"),
        ({"emg": np.array([[0] * 8, [300] * 8])}, r"row 2, column 1: a value outside"),
        ({"emg": np.zeros((4, 7))}, r"shape \(n_samples, 8\)"),
        ({"emg": np.zeros((0, 8))}, "holds no samples"),
        ({"data": np.zeros((4, 8))}, r"no array named 'emg'"),
    ],
)
def test_malformed_npz_names_file_row_and_problem(tmp_path, arrays, message):
    path = tmp_path / "bad.npz"
    save_npz_atomic(path, **arrays)
    with pytest.raises(ValueError, match=message) as error:
        load_emg_recording(path)
    assert str(path) in str(error.value)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.csv"):
        FileEmgSource(filename=tmp_path / "missing.csv")
    write_text_atomic(tmp_path / "junk.npz", "not a zip")
    with pytest.raises(ValueError, match="junk.npz: not a readable NPZ"):
        load_emg_recording(tmp_path / "junk.npz")


class FakeDevice:
    """Hands out a scripted sequence of samples (None: nothing new)."""

    def __init__(self, samples):
        self.samples = list(samples)

    def read_emg(self):
        return self.samples.pop(0) if self.samples else None


def test_live_source_outputs_newest_sample_and_holds(builder, simulate):
    a, b = [1, 2, 3, 4, 5, 6, 7, 8], [-8, -7, -6, -5, -4, -3, -2, 200]
    source = builder.AddSystem(LiveEmgSource(device=FakeDevice([None, a, None, b])))
    emg = simulate(builder, {"emg": source.get_emg_output_port()}, 5)["emg"]
    clipped_b = b[:7] + [127]
    np.testing.assert_array_equal(emg, [[0] * 8, a, a, clipped_b, clipped_b])


def test_live_source_rejects_bad_device_and_bad_samples(builder, simulate):
    with pytest.raises(ValueError, match="read_emg"):
        LiveEmgSource(device=object())
    source = builder.AddSystem(LiveEmgSource(device=FakeDevice([[1, 2, 3]])))
    with pytest.raises(ValueError, match="8 finite values"):
        simulate(builder, {"emg": source.get_emg_output_port()}, 2)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_saved_recording_reads_back_exactly(tmp_path, suffix):
    emg = synthesize_emg(np.linspace(0.0, 1.0, 50), 2)
    emg[0, :2] = (-128, 127)  # both ends of the int8 range survive
    path = tmp_path / f"recording{suffix}"
    save_emg_recording(path, emg)
    np.testing.assert_array_equal(load_emg_recording(path), emg)


@pytest.mark.parametrize(
    "emg, message",
    [
        (np.zeros((4, 7)), "shape"),
        (np.zeros((0, 8)), "shape"),
        (np.full((2, 8), np.nan), "finite.*row 1, column 1: NaN"),
        (np.full((2, 8), 0.5), "integers"),
        (np.full((2, 8), 128), "integers in -128..127"),
        (np.ones((2, 8), dtype=complex), "non-numeric dtype complex128"),
    ],
)
def test_save_recording_rejects_bad_samples(tmp_path, emg, message):
    path = tmp_path / "bad.csv"
    with pytest.raises(ValueError, match=message):
        save_emg_recording(path, emg)
    assert not path.exists()
