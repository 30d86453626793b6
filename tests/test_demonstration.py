"""Demonstration type: validation errors, CSV/NPZ round trips, overwrite protection."""

import warnings

import numpy as np
import pytest

from rlfd_drake import dmp
from rlfd_drake.bench.dmp import synthetic_demonstration
from rlfd_drake.demonstration import (
    Demonstration,
    fit_dmp_from_demonstration,
    load_demonstration,
    save_demonstration,
)


@pytest.fixture
def demo():
    t, p, q = synthetic_demonstration(duration_s=2.0, rate_hz=50.0)  # 101 samples
    return Demonstration(times=t, positions=p, quats=q)


def test_valid_demo_passes(demo):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert demo.validate() is demo
    assert len(demo) == 101
    assert demo.duration == pytest.approx(2.0)


def test_wrong_columns(demo):
    demo.positions = demo.positions[:, :2]
    with pytest.raises(ValueError, match=r"positions must have shape \(N, 3\), got shape"):
        demo.validate()


def test_wrong_quat_columns(demo):
    demo.quats = demo.quats[:, :3]
    with pytest.raises(ValueError, match=r"quats must have shape \(N, 4\)"):
        demo.validate()


def test_row_mismatch(demo):
    demo.positions = demo.positions[:-1]
    with pytest.raises(ValueError, match="positions has 100 rows but times has 101"):
        demo.validate()


def test_nan_and_inf(demo):
    demo.positions[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions must be finite, got nan at index \(7, 1\)"):
        demo.validate()
    demo.positions[7, 1] = 0.0
    demo.times = demo.times.copy()
    demo.times[3] = np.inf
    with pytest.raises(ValueError, match="times must be finite, got inf"):
        demo.validate()


def test_non_increasing_time(demo):
    demo.times = demo.times.copy()
    demo.times[10] = demo.times[9]
    with pytest.raises(ValueError, match=r"strictly increasing, got times\[9\]=0.18"):
        demo.validate()


def test_too_few_samples(demo):
    short = Demonstration(demo.times[:50], demo.positions[:50], demo.quats[:50])
    with pytest.raises(ValueError, match="times has 50 samples, fewer than the minimum 70"):
        short.validate()
    short.validate(min_samples=10)


def test_quaternion_norms(demo):
    demo.quats = demo.quats * 1.005
    with pytest.warns(UserWarning, match="quats normalised: norm 1.005"):
        demo.validate()
    np.testing.assert_allclose(np.linalg.norm(demo.quats, axis=1), 1.0, atol=1e-15)
    demo.quats[4] *= 1.2
    with pytest.raises(ValueError, match="quats must be unit quaternions, got norm 1.2.* row 4"):
        demo.validate()


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip(tmp_path, demo, suffix):
    path = tmp_path / f"demo{suffix}"
    assert save_demonstration(demo, path) == path
    back = load_demonstration(path)
    np.testing.assert_array_equal(back.times, demo.times)
    np.testing.assert_array_equal(back.positions, demo.positions)
    np.testing.assert_allclose(back.quats, demo.quats, atol=1e-15)
    with pytest.raises(FileExistsError, match=f"{path.name} exists"):
        save_demonstration(demo, path)
    save_demonstration(demo, path, overwrite=True)


def test_csv_header(tmp_path, demo):
    path = tmp_path / "demo.csv"
    save_demonstration(demo, path)
    assert path.read_text().splitlines()[0] == "t,x,y,z,qw,qx,qy,qz"
    path.write_text("time,x,y,z,qw,qx,qy,qz\n" + "\n".join(path.read_text().splitlines()[1:]))
    with pytest.raises(ValueError, match="CSV header of .* must be t,x,y,z,qw,qx,qy,qz"):
        load_demonstration(path)


def test_npz_missing_key(tmp_path, demo):
    path = tmp_path / "demo.npz"
    np.savez(path, times=demo.times, positions=demo.positions)
    with pytest.raises(ValueError, match=r"lacks keys \['quats'\]"):
        load_demonstration(path)


def test_unknown_suffix_and_missing_file(tmp_path, demo):
    with pytest.raises(ValueError, match="unknown demonstration file suffix '.txt'"):
        save_demonstration(demo, tmp_path / "demo.txt")
    with pytest.raises(ValueError, match="unknown demonstration file suffix '.json'"):
        load_demonstration(tmp_path / "demo.json")
    with pytest.raises(FileNotFoundError, match="no demonstration file at"):
        load_demonstration(tmp_path / "absent.npz")


def test_load_rejects_bad_data(tmp_path, demo):
    path = tmp_path / "demo.npz"
    np.savez(path, times=demo.times[::-1], positions=demo.positions, quats=demo.quats)
    with pytest.raises(ValueError, match="strictly increasing"):
        load_demonstration(path)


def test_fit_dmp_from_demonstration(demo):
    model = fit_dmp_from_demonstration(demo)
    direct = dmp.fit_cartesian_dmp(demo.times, demo.positions, demo.quats)
    np.testing.assert_array_equal(model.weights_translation, direct.weights_translation)
    short = Demonstration(demo.times[:60], demo.positions[:60], demo.quats[:60])
    with pytest.raises(ValueError, match="fewer than the minimum 70"):
        fit_dmp_from_demonstration(short)
