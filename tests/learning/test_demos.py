"""Datasets: Demonstration checks, NPZ round trip, damaged files, observations for learning."""

import json

import numpy as np
import pytest

from hemg_drake.learning.demos import (
    ALL_FIELDS,
    ARM_FIELD_SHAPES,
    FORMAT_VERSION,
    Demonstration,
    load_dataset,
    observations,
    save_dataset,
    tool_quaternions,
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
        for name in (*ALL_FIELDS, *ARM_FIELD_SHAPES):
            assert getattr(after, name).tobytes() == getattr(before, name).tobytes()
            assert getattr(after, name).shape == getattr(before, name).shape
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


def test_datasets_without_joints_load_with_none(tmp_path, make_demo):
    """A dataset recorded before q and R_WE were logged (format 3 or 2, no such arrays)."""
    old = [make_demo(3, 40, arm=False), make_demo(4, 55, arm=False)]
    assert old[0].q is None and old[0].R_WE is None
    path = tmp_path / "old.npz"
    save_dataset(path, old)
    arrays = dict(np.load(path))
    assert not [key for key in arrays if key.endswith((".q", ".R_WE"))]
    loaded, _ = load_dataset(path)
    assert [d.q for d in loaded] == [None, None] and [d.R_WE for d in loaded] == [None, None]
    assert tool_quaternions(loaded) is None
    record = json.loads(str(arrays["metadata"]))
    two = tmp_path / "format2.npz"
    np.savez(two, **{**arrays, "metadata": np.array(json.dumps({**record, "format_version": 2}))})
    assert load_dataset(two)[0][1].q is None
    with pytest.raises(ValueError, match="q and R_WE for every demonstration or for none"):
        save_dataset(tmp_path / "mixed.npz", [make_demo(3, 40), old[1]])


def test_demonstration_rejects_bad_joint_fields(make_demo):
    demo = make_demo(1, 10)
    fields = {name: getattr(demo, name) for name in demo.__dataclass_fields__}
    with pytest.raises(ValueError, match="'q' and 'R_WE' go together"):
        Demonstration(**{**fields, "R_WE": None})
    with pytest.raises(ValueError, match="'q'.*shape \\(10, 7\\)"):
        Demonstration(**{**fields, "q": np.zeros((10, 6))})
    with pytest.raises(ValueError, match="'R_WE'.*shape \\(10, 3, 3\\)"):
        Demonstration(**{**fields, "R_WE": np.zeros((10, 9))})
    with pytest.raises(ValueError, match="'q'.*NaN"):
        Demonstration(**{**fields, "q": np.full((10, 7), np.inf)})
    with pytest.raises(ValueError, match="'R_WE' must hold rotation matrices"):
        Demonstration(**{**fields, "R_WE": 1.01 * demo.R_WE})
    with pytest.raises(ValueError, match="'R_WE' must hold rotation matrices"):
        Demonstration(**{**fields, "R_WE": -demo.R_WE})  # det -1: a reflection


def _turn_about_x(angles):
    """Rotations about x by ``angles`` (rad), written out."""
    c, s = np.cos(angles), np.sin(angles)
    zero, one = np.zeros_like(c), np.ones_like(c)
    rows = [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    return np.moveaxis(np.array(rows), (0, 1), (1, 2))


def test_tool_quaternions_are_the_rotations_with_continuous_signs(make_demo, quaternion_rotation):
    # Random rotations: unit, and the closed-form matrix of each quaternion is R_WE.
    demos = [make_demo(3, 40), make_demo(4, 55)]
    for demo, quats in zip(demos, tool_quaternions(demos), strict=True):
        np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-14)
        np.testing.assert_allclose(quaternion_rotation(quats), demo.R_WE, atol=1e-14)
    # A tool turning through 180 deg about x (where a tool pointing down sits): Drake's
    # canonical w >= 0 would flip the sign at 180 deg; these stay on one path,
    # [cos(a/2), sin(a/2), 0, 0] up to one sign for the whole dataset.
    first = make_demo(5, 41)
    angles = np.linspace(np.radians(170), np.radians(190), 41)
    turning = Demonstration(**{**{n: getattr(first, n) for n in first.__dataclass_fields__},
                               "R_WE": _turn_about_x(angles)})  # fmt: skip
    back = Demonstration(**{**{n: getattr(first, n) for n in first.__dataclass_fields__},
                            "R_WE": _turn_about_x(angles[::-1])})  # fmt: skip
    quats = tool_quaternions([turning, back])
    path = np.column_stack([np.cos(angles / 2), np.sin(angles / 2), 0 * angles, 0 * angles])
    np.testing.assert_allclose(quats[0], path, atol=1e-12)  # w of the first sample >= 0
    np.testing.assert_allclose(quats[1], path[::-1], atol=1e-12)  # the same side
    assert np.abs(np.diff(quats[1], axis=0)).max() < 0.01
