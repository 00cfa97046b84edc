"""Datasets: Demonstration checks, NPZ round trip, damaged files, observations for learning."""

import json

import numpy as np
import pytest

from hemg_drake.learning.demos import (
    ALL_FIELDS,
    FORMAT_VERSION,
    Demonstration,
    load_dataset,
    observations,
    save_dataset,
)


@pytest.fixture
def demos(make_demo):
    return [make_demo(3, 40), make_demo(4, 55)]


def test_round_trip_is_exact(tmp_path, demos):
    path = tmp_path / "dataset.npz"
    save_dataset(path, demos, {"scenario": "task: drawing\n"})
    loaded, metadata = load_dataset(path)
    assert len(loaded) == 2
    for before, after in zip(demos, loaded):
        assert after.seed == before.seed and len(after) == len(before)
        for name in ALL_FIELDS:
            assert getattr(after, name).tobytes() == getattr(before, name).tobytes()
    assert metadata["scenario"] == "task: drawing\n"
    assert metadata["seeds"] == [3, 4] and metadata["format_version"] == FORMAT_VERSION
    assert set(metadata["versions"]) == {"hemg_drake", "drake", "numpy"}


def test_observations_are_position_velocity_stiffness(demos):
    X = observations(demos)
    assert [x.shape for x in X] == [(40, 7), (55, 7)]
    np.testing.assert_array_equal(X[1][:, :3], demos[1].p_WE)
    np.testing.assert_array_equal(X[1][:, 3:6], demos[1].v_WE)
    np.testing.assert_array_equal(X[1][:, 6], demos[1].gain)
    assert observations(demos, ("p_WE",))[0].shape == (40, 3)
    with pytest.raises(ValueError, match="fields"):
        observations(demos, ("p_WE", "stiffness"))


def test_demonstration_rejects_bad_arrays(make_demo):
    demo = make_demo(1, 10)
    fields = {name: getattr(demo, name) for name in demo.__dataclass_fields__}
    with pytest.raises(ValueError, match="'p_WE'.*shape \\(10, 3\\)"):
        Demonstration(**{**fields, "p_WE": np.zeros((10, 2))})
    with pytest.raises(ValueError, match="'gain'.*NaN"):
        Demonstration(**{**fields, "gain": np.full(10, np.nan)})
    # The 200 Hz fields share their own length, not the log's.
    with pytest.raises(ValueError, match="'muscle_activation'.*shape \\(20,\\)"):
        Demonstration(**{**fields, "muscle_activation": np.zeros(19)})
    with pytest.raises(ValueError, match="'emg'.*shape \\(20, 8\\)"):
        Demonstration(**{**fields, "emg": np.zeros((20, 4))})


def test_save_replaces_atomically_and_failure_keeps_the_old_file(tmp_path, demos):
    path = tmp_path / "dataset.npz"
    save_dataset(path, demos[:1])
    before = path.read_bytes()
    with pytest.raises(ValueError, match="JSON"):
        save_dataset(path, demos, {"scenario": object()})
    assert path.read_bytes() == before
    with pytest.raises(ValueError, match="non-empty"):
        save_dataset(path, [])
    save_dataset(path, demos)
    assert len(load_dataset(path)[0]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dataset.npz"]


def _write_npz(path, **arrays):
    np.savez(path, **arrays)
    return path


def _metadata(**changes):
    record = {"format_version": FORMAT_VERSION, "num_demonstrations": 1, "seeds": [3]}
    record.update(changes)
    return np.array(json.dumps(record))


def test_damaged_files_give_clear_errors(tmp_path, demos):
    good = tmp_path / "good.npz"
    save_dataset(good, demos[:1])
    arrays = dict(np.load(good))

    with pytest.raises(FileNotFoundError, match="missing.npz"):
        load_dataset(tmp_path / "missing.npz")
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(ValueError, match="truncated.npz.*not a readable"):
        load_dataset(truncated)
    text = tmp_path / "text.npz"
    text.write_text("time,x\n0,1\n")
    with pytest.raises(ValueError, match="not a readable") as error:
        load_dataset(text)
    assert "pickle" not in str(error.value)  # never advise allow_pickle
    no_metadata = _write_npz(tmp_path / "a.npz", **{"demo0.time": arrays["demo0.time"]})
    with pytest.raises(ValueError, match="no 'metadata'"):
        load_dataset(no_metadata)
    bad_json = _write_npz(tmp_path / "b.npz", **{**arrays, "metadata": np.array("{oops")})
    with pytest.raises(ValueError, match="JSON"):
        load_dataset(bad_json)
    future = _write_npz(tmp_path / "c.npz", **{**arrays, "metadata": _metadata(format_version=99)})
    with pytest.raises(ValueError, match="format 99, this hemg_drake reads format 2"):
        load_dataset(future)
    old = _write_npz(tmp_path / "old.npz", **{**arrays, "metadata": _metadata(format_version=1)})
    with pytest.raises(ValueError, match="format 1.*record it again with hemg-drake demonstrate"):
        load_dataset(old)
    model_like = _write_npz(tmp_path / "m.npz", means=np.zeros(3), metadata=np.array("{}"))
    with pytest.raises(ValueError, match="no format_version; not a hemg_drake dataset"):
        load_dataset(model_like)
    missing = {k: v for k, v in arrays.items() if k != "demo0.gain"}
    with pytest.raises(ValueError, match="missing array 'demo0.gain'"):
        load_dataset(_write_npz(tmp_path / "d.npz", **missing))
    wrong = {**arrays, "demo0.p_WE": arrays["demo0.p_WE"][:, :2]}
    with pytest.raises(ValueError, match="demonstration 1: .*p_WE"):
        load_dataset(_write_npz(tmp_path / "e.npz", **wrong))
    seeds = {**arrays, "metadata": _metadata(seeds=[1, 2])}
    with pytest.raises(ValueError, match="one seed each"):
        load_dataset(_write_npz(tmp_path / "f.npz", **seeds))
