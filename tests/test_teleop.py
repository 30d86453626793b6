"""Teleoperated demonstrations: a scripted session (the sliders replaced by a function
of time) is recorded at 100 Hz, follows its commands, saves, loads and fits a DMP."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.geometry import Meshcat

from rlfd_drake.cli import main
from rlfd_drake.demonstration import load_demonstration, save_demonstration
from rlfd_drake.dmp import fit_cartesian_dmp, rollout
from rlfd_drake.geometry import quat_error
from rlfd_drake.tasks import load_task
from rlfd_drake.teleop import (
    SLIDER_NAMES,
    STOP_BUTTON,
    AddTeleopControls,
    MeshcatTeleopSource,
    TeleopConfig,
    offset_pose,
    record_teleop_demonstration,
    step_towards,
    teleop_start_pose,
)

#: The scripted offset reached after RAMP_S: 5 cm, -3 cm, -6 cm; roll 5 deg, yaw 15 deg.
TARGET_OFFSET = np.array([0.05, -0.03, -0.06, math.radians(5.0), 0.0, math.radians(15.0)])
RAMP_S = 2.0
SESSION_S = 3.0
#: The part follows a smooth command (peak speed 4.7 cm/s) through the impedance
#: controller within this, at every recorded sample (measured: 1.5 mm, 0.3 deg) ...
FOLLOW_TOL_M = 0.003
FOLLOW_TOL_DEG = 0.75
#: ... and settles on it once the command holds (measured: < 0.1 mm, < 0.01 deg).
SETTLED_TOL_M = 0.0005
SETTLED_TOL_DEG = 0.1
FAST = TeleopConfig(duration_s=SESSION_S, realtime_rate=0.0)


def scripted_command(t: float) -> np.ndarray:
    """Minimum-jerk from zero to TARGET_OFFSET over RAMP_S, then held."""
    s = min(t / RAMP_S, 1.0)
    return TARGET_OFFSET * (10 * s**3 - 15 * s**4 + 6 * s**5)


@pytest.fixture(scope="module")
def task():
    return load_task("peg_easy", check_demo=False)


@pytest.fixture(scope="module")
def session(task):
    return record_teleop_demonstration(task, scripted_command, config=FAST)


def _commanded(task, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    X = teleop_start_pose(task)
    p0, q0 = X.translation(), X.rotation().ToQuaternion().wxyz()
    poses = [offset_pose(p0, q0, scripted_command(t)) for t in times]
    return np.array([p for p, _ in poses]), np.array([q for _, q in poses])


def test_scripted_session_records_100_hz_for_its_duration(session):
    demo = session.demonstration
    assert session.stopped_by == "duration"
    assert len(demo) == round(SESSION_S / 0.01) + 1
    assert demo.times[0] == 0.0
    assert np.allclose(np.diff(demo.times), 0.01)
    assert session.setpoint_positions.shape == (len(demo), 3)


def test_recorded_poses_follow_the_scripted_commands(task, session):
    demo = session.demonstration
    p_cmd, q_cmd = _commanded(task, demo.times)
    position_error = np.linalg.norm(demo.positions - p_cmd, axis=1)
    angle_error = np.degrees(np.linalg.norm(quat_error(q_cmd, demo.quats), axis=1))
    assert position_error.max() < FOLLOW_TOL_M, position_error.max()
    assert angle_error.max() < FOLLOW_TOL_DEG, angle_error.max()
    assert position_error[-1] < SETTLED_TOL_M and angle_error[-1] < SETTLED_TOL_DEG
    # The motion really happened (the start is not the end).
    assert np.linalg.norm(demo.positions[-1] - demo.positions[0]) == pytest.approx(
        np.linalg.norm(TARGET_OFFSET[:3]), abs=SETTLED_TOL_M
    )


def test_same_script_same_recording(task, session):
    again = record_teleop_demonstration(task, scripted_command, config=FAST)
    assert np.array_equal(again.demonstration.positions, session.demonstration.positions)
    assert np.array_equal(again.demonstration.quats, session.demonstration.quats)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_recording_saves_loads_and_fits_a_dmp(session, tmp_path, suffix):
    demo = session.demonstration
    path = save_demonstration(demo, tmp_path / f"teleop{suffix}")
    loaded = load_demonstration(path)
    assert np.allclose(loaded.positions, demo.positions, atol=1e-12)
    with pytest.raises(FileExistsError, match="exists"):
        save_demonstration(demo, path)
    model = fit_cartesian_dmp(loaded.times, loaded.positions, loaded.quats)
    _, positions, _, quats, _ = rollout(model, dt=0.01)
    n = min(len(positions), len(loaded.positions))
    rmse_m = np.sqrt(np.mean(np.sum((positions[:n] - loaded.positions[:n]) ** 2, axis=1)))
    angles = np.linalg.norm(quat_error(loaded.quats[:n], quats[:n]), axis=1)
    assert rmse_m < 0.001
    assert np.degrees(np.sqrt(np.mean(angles**2))) < 0.5


def test_set_point_speed_is_limited_and_stop_ends_the_session(task):
    config = TeleopConfig(duration_s=5.0, realtime_rate=0.0, max_speed_m_s=0.1)
    jump = np.array([0.2, 0.0, 0.0, 0.0, 0.0, math.radians(40.0)])  # a slider yanked
    session = record_teleop_demonstration(
        task, lambda t: jump, stop_source=lambda t: t >= 0.8 - 1e-9, config=config
    )
    assert session.stopped_by == "button"
    assert len(session.demonstration) == 81
    steps = np.linalg.norm(np.diff(session.setpoint_positions, axis=0), axis=1)
    assert steps.max() <= config.max_speed_m_s * config.record_period_s + 1e-12
    turns = np.linalg.norm(
        quat_error(session.setpoint_quats[1:], session.setpoint_quats[:-1]), axis=1
    )
    assert turns.max() <= config.max_angular_speed_rad_s * config.record_period_s + 1e-9
    # Still moving at 0.1 m/s when stopped: 8 cm of the 20 cm.
    assert session.setpoint_positions[-1][0] - session.setpoint_positions[0][0] == pytest.approx(
        0.08, abs=1e-9
    )


def test_short_session_and_bad_commands_are_clear_errors(task):
    with pytest.raises(ValueError, match="recorded 11 samples"):
        record_teleop_demonstration(
            task, lambda t: np.zeros(6), lambda t: t >= 0.1 - 1e-9, config=FAST
        )
    with pytest.raises(ValueError, match=r"6 finite numbers .* got \[0.0, 0.0\]"):
        record_teleop_demonstration(task, lambda t: [0.0, 0.0], config=FAST)
    with pytest.raises(ValueError, match="needs a slider_source or a meshcat"):
        record_teleop_demonstration(task)
    with pytest.raises(ValueError, match="max_speed_m_s must be a positive number, got 0"):
        TeleopConfig(max_speed_m_s=0.0)


def test_pure_pose_maths():
    p0, q0 = np.array([0.4, 0.1, 0.3]), np.array([0.0, 1.0, 0.0, 0.0])
    p, q = offset_pose(p0, q0, np.zeros(6))
    assert np.array_equal(p, p0) and np.allclose(q, q0)
    p, q = offset_pose(p0, q0, [0.0, 0.0, 0.1, 0.0, 0.0, math.pi / 2])
    assert np.allclose(p, p0 + [0, 0, 0.1])
    assert np.degrees(np.linalg.norm(quat_error(q, q0))) == pytest.approx(90.0)
    p1, q1 = step_towards(p0, q0, p0 + [0.3, 0.4, 0.0], q, 0.05, math.radians(10))
    assert np.allclose(p1, p0 + [0.03, 0.04, 0.0])
    assert np.degrees(np.linalg.norm(quat_error(q1, q0))) == pytest.approx(10.0)
    p2, q2 = step_towards(p0, q0, p0 + [0.001, 0.0, 0.0], q0, 0.05, 0.1)
    assert np.allclose(p2, p0 + [0.001, 0, 0]) and np.allclose(q2, q0)


def test_meshcat_controls_are_read_as_an_offset():
    meshcat = Meshcat()
    with pytest.raises(ValueError, match="call AddTeleopControls"):
        MeshcatTeleopSource(meshcat)
    AddTeleopControls(meshcat)
    AddTeleopControls(meshcat)  # again: replaces, does not raise
    assert set(SLIDER_NAMES) <= set(meshcat.GetSliderNames())
    assert STOP_BUTTON in meshcat.GetButtonNames()
    meshcat.SetSliderValue("x (m)", 0.02)
    meshcat.SetSliderValue("yaw (deg)", 30.0)
    source = MeshcatTeleopSource(meshcat)
    assert np.allclose(source(0.0), [0.02, 0, 0, 0, 0, math.radians(30.0)])
    assert not source.stop_requested(0.0)


def test_cli_teleop_records_from_untouched_sliders_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "teleop.csv"
    args = ["demo", "teleop", "--task", "peg_easy", "--out", str(out), "--duration", "1"]
    assert main(args) == 0
    assert "recorded 101 poses over 1.00 s (stopped by the duration)" in capsys.readouterr().out
    demo = load_demonstration(out)
    # Nobody touched the sliders: the part held its start pose.
    start = teleop_start_pose(load_task("peg_easy"))
    assert np.linalg.norm(demo.positions - start.translation(), axis=1).max() < 0.001
    before = out.read_text()
    assert main(args) == 2
    assert f"{out} exists; pass --overwrite" in capsys.readouterr().err
    assert out.read_text() == before
    bad = ["demo", "teleop", "--task", "peg_easy", "--out", str(tmp_path / "x.txt")]
    assert main(bad) == 2
    assert "--out must end in .csv or .npz, got" in capsys.readouterr().err
