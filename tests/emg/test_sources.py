"""Synthetic, file and live sEMG sources, each run in a Drake diagram."""

import numpy as np
import pytest
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.emg.config import MYO_PERIOD, SyntheticEmgConfig
from hemg_drake.emg.sources import (
    LiveEmgSource,
    SyntheticEmgLaw,
    load_emg_recording,
    make_file_emg_source,
    make_synthetic_emg_source,
    save_emg_recording,
    synthesize_emg,
)
from hemg_drake.fileio import save_npz_atomic, write_text_atomic

GAINS = np.array([40.0, 34.0, 26.0, 20.0, 20.0, 26.0, 34.0, 40.0])  # SyntheticEmgConfig's


def _run_synthetic(builder, simulate, held_signal, activation, seed, config=SyntheticEmgConfig()):
    source = builder.AddSystem(make_synthetic_emg_source(config=config))
    signal = builder.AddSystem(held_signal(activation))
    builder.Connect(signal.get_output_port(), source.GetInputPort("activation"))
    return simulate(builder, {"emg": source.GetOutputPort("emg")}, len(activation), seed)["emg"]


@pytest.mark.parametrize(
    "activation, noise, expected",
    [
        # std_i = 2 + g_i * 0.5 = 22, 19, 15, 12, 12, 15, 19, 22; times the noise, rounded
        # half to even, clipped to -128..127.
        (0.5, [1.0, -1.0, 0.1, 0.125, -0.0625, 10.0, -10.0, 0.0],
         [22, -19, 2, 2, -1, 127, -128, 0]),  # 1.5 -> 2, 1.5 -> 2, -0.75 -> -1
        (1.7, [0.5] * 8, [21, 18, 14, 11, 11, 14, 18, 21]),  # clipped to a = 1: (2 + g) / 2
        (np.nan, [0.25] * 8, [0.0] * 8),  # NaN reads as rest: std 2, 0.5 rounds to 0
        (-1.0, [0.75] * 8, [2.0] * 8),  # below 0 reads as 0: 1.5 rounds to 2
    ],
)  # fmt: skip
def test_synthetic_law_by_hand(activation, noise, expected):
    np.testing.assert_array_equal(_law_sample(SyntheticEmgLaw(), activation, noise), expected)


def _law_sample(law, activation, noise, k=0):
    """The law's sample k, with ``noise`` in row k mod 200 of the noise block (zeros else)."""
    context = law.CreateDefaultContext()
    context.SetTime(k * MYO_PERIOD)
    block = np.zeros((200, 8))
    block[k % 200] = noise
    law.GetInputPort("activation").FixValue(context, [activation])
    law.GetInputPort("noise").FixValue(context, block.ravel())
    return law.GetOutputPort("emg").Eval(context)


def test_synthetic_law_reads_row_k_of_the_block():
    for k in (0, 1, 199, 200, 437):
        np.testing.assert_array_equal(_law_sample(SyntheticEmgLaw(), 1.0, np.ones(8), k), 2 + GAINS)


def test_synthetic_law_exponent_by_hand():
    # p = 2, a = 0.5: std_i = 2 + g_i / 4 = 12, 10.5, 8.5, 7, 7, 8.5, 10.5, 12 (unit noise),
    # rounded half to even.
    law = SyntheticEmgLaw(config=SyntheticEmgConfig(exponent=2.0))
    np.testing.assert_array_equal(_law_sample(law, 0.5, np.ones(8)), [12, 10, 8, 7, 7, 8, 10, 12])


def test_synthetic_source_takes_sample_k_at_t_k(builder, simulate, held_signal):
    # No noise at rest (rest_std 0): silent while the activation is 0, noisy from the first
    # sample whose activation is 1, and zero before the first sample.
    activation = np.concatenate([np.zeros(10), np.ones(10)])
    config = SyntheticEmgConfig(rest_std=0.0)
    emg = _run_synthetic(builder, simulate, held_signal, activation, seed=1, config=config)
    assert np.all(emg[:10] == 0) and np.all(np.abs(emg[10:]).sum(axis=1) > 0)


def test_synthetic_source_has_the_documented_spread(builder, simulate, held_signal):
    # At a constant activation the samples are zero-mean with per-channel standard deviation
    # sqrt((rest_std + g_i a)^2 + 1/12) (rounding adds 1/12), independent from sample to
    # sample and from channel to channel: 3000 samples.
    a = 0.6
    emg = _run_synthetic(builder, simulate, held_signal, np.full(3000, a), seed=4)
    spread = 2.0 + GAINS * a
    np.testing.assert_allclose(emg.std(axis=0), np.sqrt(spread**2 + 1 / 12), rtol=0.05)
    assert np.all(np.abs(emg.mean(axis=0)) < 4 * spread / np.sqrt(3000))
    lag1 = [np.corrcoef(emg[1:, i], emg[:-1, i])[0, 1] for i in range(8)]
    assert np.max(np.abs(lag1)) < 4 / np.sqrt(3000)
    cross = np.corrcoef(emg.T)[np.triu_indices(8, 1)]
    assert np.max(np.abs(cross)) < 4 / np.sqrt(3000)
    assert np.all(emg == np.round(emg)) and emg.min() >= -128 and emg.max() <= 127
    # The noise is drawn 200 samples at a time: no block repeats another.
    blocks = emg.reshape(15, 200, 8)
    assert all(np.mean(blocks[i] != blocks[j]) > 0.9 for i in range(15) for j in range(i))


def test_one_built_diagram_runs_many_seeds_same_seed_same_bytes():
    builder = DiagramBuilder()
    source = builder.AddSystem(make_synthetic_emg_source())
    builder.ExportInput(source.GetInputPort("activation"))
    logger = LogVectorOutput(source.GetOutputPort("emg"), builder, publish_period=MYO_PERIOD)
    diagram = builder.Build()

    def run(system, seed):
        simulator = Simulator(system)
        context = simulator.get_mutable_context()
        system.get_input_port(0).FixValue(context, [0.5])
        system.SetRandomContext(context, RandomGenerator(seed))
        simulator.AdvanceTo(0.5)
        sink = system.GetSubsystemByName(logger.get_name())
        return sink.FindLog(context).data().tobytes()

    first = run(diagram, 3)
    assert run(diagram, 3) == first
    assert run(diagram, 4) != first
    assert run(diagram.Clone(), 3) == first  # a clone, seeded alike, gives the same bytes
    activation = np.full(100, 0.5)
    np.testing.assert_array_equal(synthesize_emg(activation, 3), synthesize_emg(activation, 3))
    assert np.mean(synthesize_emg(activation, 3) != synthesize_emg(activation, 4)) > 0.9


def test_synthesize_emg_is_the_seeded_source(builder, simulate, held_signal):
    activation = np.linspace(0.0, 1.0, 60)
    emg = _run_synthetic(builder, simulate, held_signal, activation, seed=9)
    np.testing.assert_array_equal(synthesize_emg(activation, 9), emg)


def test_strong_noise_is_clipped_to_int8():
    config = SyntheticEmgConfig(channel_gains=[500.0] * 8)
    emg = synthesize_emg(np.ones(500), seed=1, config=config)
    assert emg.max() == 127 and emg.min() == -128


@pytest.mark.parametrize(
    "config, message",
    [
        (SyntheticEmgConfig(channel_gains=[1.0] * 7), "channel_gains"),
        (SyntheticEmgConfig(channel_gains=[np.nan] * 8), "channel_gains"),
        (SyntheticEmgConfig(rest_std=-1.0), "rest_std"),
        (SyntheticEmgConfig(exponent=0.0), "exponent"),
    ],
)
def test_synthetic_bad_parameters(config, message):
    with pytest.raises(ValueError, match=message):
        make_synthetic_emg_source(config=config)
    with pytest.raises(ValueError, match="period"):
        make_synthetic_emg_source(period=0.0)
    with pytest.raises(ValueError, match="200 periods do not add up"):
        make_synthetic_emg_source(period=1 / 3)


def test_synthesize_emg_rejects_bad_input():
    with pytest.raises(ValueError, match="NaN"):
        synthesize_emg([0.1, np.nan], seed=0)
    with pytest.raises(ValueError, match="shape"):
        synthesize_emg(np.zeros((3, 2)), seed=0)
    with pytest.raises(ValueError, match="seed"):
        synthesize_emg(np.zeros(3), seed=-1)


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
    source = builder.AddSystem(make_file_emg_source(filename=path, at_end=at_end, duration=0.1))
    emg = simulate(builder, {"emg": source.GetOutputPort("emg")}, 12)["emg"]
    # Row k at sample k, by hand: 0 1 2 3 4 then 4 4 ... (hold) or 0 1 2 ... (loop).
    rows = [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 0, 1] if at_end == "loop" else [0, 1, 2, 3, 4] + [4] * 7
    np.testing.assert_array_equal(emg, RECORDING[rows])


def test_file_source_is_zero_before_the_first_sample(tmp_path):
    path = tmp_path / "rec.csv"
    _write_csv(path, RECORDING)
    source = make_file_emg_source(filename=path)
    context = source.CreateDefaultContext()
    np.testing.assert_array_equal(source.GetOutputPort("emg").Eval(context), np.zeros(8))
    simulator = Simulator(source.Clone())
    simulator.AdvanceTo(2.5 * MYO_PERIOD)  # after the updates at 0, T, 2T
    np.testing.assert_array_equal(
        simulator.get_system().GetOutputPort("emg").Eval(simulator.get_context()), RECORDING[2]
    )


def test_file_source_bad_option(tmp_path):
    _write_csv(tmp_path / "r.csv", RECORDING)
    with pytest.raises(ValueError, match="at_end"):
        make_file_emg_source(filename=tmp_path / "r.csv", at_end="rewind")
    with pytest.raises(ValueError, match="duration"):
        make_file_emg_source(filename=tmp_path / "r.csv", at_end="loop")


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
        make_file_emg_source(filename=path)
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
        make_file_emg_source(filename=tmp_path / "missing.csv")
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
    emg = np.random.default_rng(2).integers(-128, 128, size=(50, 8))
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
