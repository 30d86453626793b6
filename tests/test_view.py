"""Meshcat drawing (view.py, SetpointTriad) and `rlfd view`: a standalone HTML replay
that holds the robot's meshes, the DMP's plan and the animated set-point triads."""

from __future__ import annotations

import contextlib
import io
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from rlfd_drake import view
from rlfd_drake.cli import main
from rlfd_drake.episode import demo_start_pose, load_task_dmp
from rlfd_drake.systems.setpoint_triad import SetpointTriad
from rlfd_drake.tasks import load_task

PANDA_LINKS = [f"panda_link{i}" for i in range(8)] + ["panda_hand"]
#: A mesh sent with set_object weighs at least this (the Panda's weigh 50 kB - 2 MB);
#: a triad axis or a transform weighs under 1 kB.
MIN_MESH_BYTES = 10_000


@pytest.fixture(scope="module")
def meshcat() -> Meshcat:
    return Meshcat()


@pytest.fixture(scope="module")
def replay(tmp_path_factory) -> tuple[str, str, Path]:
    """`rlfd view` of the DMP alone on peg_easy saved as HTML (about 3 s): the page, the
    command's stdout and the file."""
    path = tmp_path_factory.mktemp("view") / "x.html"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["view", "--task", "peg_easy", "--policy", "dmp", "--html", str(path)])
    assert code == 0, out.getvalue()
    return path.read_text(), out.getvalue(), path


def test_view_html_is_a_standalone_replay_of_the_robot(replay):
    html, stdout, path = replay
    assert "success" in stdout and str(path) in stdout
    objects = view.static_html_objects(html)
    for link in PANDA_LINKS:
        mesh = f"/drake/illustration/panda/panda/{link}/panda/panda/Mesh"
        assert objects.get(mesh, 0) >= MIN_MESH_BYTES, f"no mesh for {link} in the replay"
    assert any(p.startswith("/drake/illustration/part/") for p in objects)
    assert any(p.startswith("/drake/illustration/fixture/") for p in objects)
    # The episode's own drawing: plan, triads, goals.
    assert objects["/drake/" + view.DMP_PLAN_PATH] > 0
    for path_prefix in (view.SETPOINT_PATH, view.BASE_SETPOINT_PATH, view.TRUE_GOAL_PATH):
        assert "/drake/" + path_prefix + "/x-axis" in objects
    animated = view.static_html_animated_paths(html)
    assert "/drake/illustration/panda/panda/panda_link7" in animated
    assert "/drake/" + view.SETPOINT_PATH in animated
    assert "/drake/" + view.BASE_SETPOINT_PATH in animated
    # The part touched the fixture: a hydroelastic contact surface was recorded.
    assert any("/contact_forces/hydroelastic/" in p for p in animated)
    # Standalone: no script from elsewhere, no connection to the Meshcat server that
    # recorded it, and everything fetched is inline data.
    assert "<script src" not in html and "viewer.connect(" not in html
    fetched = re.findall(r'fetch\("([^"]*)"', html)
    assert fetched and all(url.startswith("data:") for url in fetched)


def test_view_refuses_to_overwrite_the_html(replay, capsys):
    _, _, path = replay
    before = path.stat().st_mtime_ns
    assert main(["view", "--task", "peg_easy", "--policy", "dmp", "--html", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path} exists; pass --overwrite" in err
    assert path.stat().st_mtime_ns == before


def test_view_bad_task_or_policy_is_a_clear_error(tmp_path, capsys):
    html = tmp_path / "x.html"
    assert main(["view", "--task", "peg_huge", "--html", str(html)]) == 2
    assert "unknown task 'peg_huge'" in capsys.readouterr().err
    missing = str(tmp_path / "no_policy.zip")
    assert main(["view", "--task", "peg_easy", "--policy", missing, "--html", str(html)]) == 2
    assert f"got {missing!r}" in capsys.readouterr().err
    assert main(["view", "--task", "peg_easy", "--html", str(tmp_path / "x.txt")]) == 2
    assert "--html must end in .html" in capsys.readouterr().err
    assert main(["view", "--realtime-rate", "-1"]) == 2
    assert "--realtime-rate must be >= 0, got -1" in capsys.readouterr().err
    assert not html.exists()


def test_setpoint_triad_follows_its_input_into_the_recording(meshcat):
    X_WE = RigidTransform(RollPitchYaw(0.1, -0.2, 0.3), [0.4, -0.1, 0.3])
    pose = np.concatenate([X_WE.translation(), X_WE.rotation().ToQuaternion().wxyz()])
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(pose))
    triad = builder.AddSystem(SetpointTriad(meshcat, "test/triad", period_s=0.05))
    builder.Connect(source.get_output_port(), triad.GetInputPort("X_WE"))
    simulator = Simulator(builder.Build())
    meshcat.DeleteRecording()
    meshcat.StartRecording(set_visualizations_while_recording=False)
    simulator.AdvanceTo(0.5)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    html = meshcat.StaticHtml()
    assert {"/drake/test/triad/x-axis", "/drake/test/triad/z-axis"} <= set(
        view.static_html_objects(html)
    )
    assert "/drake/test/triad" in view.static_html_animated_paths(html)
    meshcat.DeleteRecording()
    meshcat.Delete("test")


def test_setpoint_triad_validates(meshcat):
    with pytest.raises(ValueError, match="period_s must be a positive number of seconds, got 0"):
        SetpointTriad(meshcat, "test/bad", period_s=0.0)
    with pytest.raises(ValueError, match="path must be a non-empty Meshcat path"):
        SetpointTriad(meshcat, "")
    with pytest.raises(ValueError, match="opacity must be in"):
        view.TriadStyle(opacity=0.0)


def test_pose_vector_to_rigid_transform_normalises_and_validates():
    X = view.pose_vector_to_rigid_transform([1.0, 2.0, 3.0, 2.0, 0.0, 0.0, 0.0])
    assert np.allclose(X.translation(), [1, 2, 3])
    assert np.allclose(X.rotation().matrix(), np.eye(3))
    with pytest.raises(ValueError, match="7 finite numbers"):
        view.pose_vector_to_rigid_transform([0.0] * 6)
    with pytest.raises(ValueError, match="must be non-zero"):
        view.pose_vector_to_rigid_transform([0.0] * 7)


def test_dmp_plan_runs_from_the_start_to_the_demonstrated_goal():
    task = load_task("peg_easy")
    dmp_model = load_task_dmp(task)
    X_start = demo_start_pose(dmp_model)
    X_start.set_translation(X_start.translation() + [0.05, -0.03, 0.02])
    positions = view.dmp_plan_positions(dmp_model, X_start, duration_s=task.episode_time_s)
    assert positions.shape == (round(task.episode_time_s / 0.02) + 1, 3)
    assert np.array_equal(positions[0], X_start.translation())
    # The DMP is still settling at the episode's end (3.6 mm above the goal at 10 s);
    # given time, it reaches the demonstrated goal.
    assert np.linalg.norm(positions[-1] - dmp_model.g) < task.kappa_m
    settled = view.dmp_plan_positions(dmp_model, X_start, duration_s=20.0)
    assert np.linalg.norm(settled[-1] - dmp_model.g) < 5e-5


def test_draw_polyline_validates(meshcat):
    with pytest.raises(ValueError, match=r"shape \(N >= 2, 3\), got \(1, 3\)"):
        view.DrawPolyline(meshcat, "test/line", np.zeros((1, 3)))


def test_diagram_svg_renders_only_with_graphviz():
    svg = view.diagram_svg("digraph { a -> b }")
    if shutil.which("dot") is None:
        assert svg is None
    else:
        assert svg is not None and "<svg" in svg
    assert view.diagram_svg("this is not dot {") is None
