"""The simulated work cell: models, frames, IK, hydroelastic insertion physics."""

from __future__ import annotations

import re

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from rlfd_drake.bench.sim import BuildHeldScene, p_FP, press_setup
from rlfd_drake.paths import models_dir
from rlfd_drake.scene import (
    FIXTURE_BODY,
    AddRlfdScene,
    CalcPartPose,
    CalcWristWrench,
    FixtureErrorTransform,
    FixturePoseInWorld,
    GoalPoseInWorld,
    PoseSpecToRigidTransform,
    SceneConfig,
    SetFixtureError,
    SolvePandaIK,
    TaskModelFiles,
)
from rlfd_drake.tasks import list_tasks, load_task, sample_fixture_error

TASKS = list_tasks()
MAX_JOINT_SPEED_RAD_S = 3.0  # a blow-up shows as hundreds of rad/s


_NUMBER = re.compile(r"(-?\d+(?:\.\d*)?(?:e[-+]?\d+)?)")


def _same_model_text(committed: str, generated: str, atol: float = 1e-12) -> bool:
    """The same model up to what differs between numeric libraries: numbers within
    ``atol`` (a centroid of 2e-19 against 0) and an OBJ face's vertex list starting at
    another vertex of the same cycle (same polygon, same orientation)."""

    def canonical(text: str) -> list[str]:
        lines = []
        for line in text.splitlines():
            if line.startswith("f "):
                corners = line.split()[1:]
                first = corners.index(min(corners, key=lambda c: int(c.split("/")[0])))
                line = "f " + " ".join(corners[first:] + corners[:first])
            lines.append(line)
        return lines

    a, b = canonical(committed), canonical(generated)
    if len(a) != len(b):
        return False
    for line_a, line_b in zip(a, b, strict=True):
        parts_a, parts_b = _NUMBER.split(line_a), _NUMBER.split(line_b)
        if len(parts_a) != len(parts_b) or parts_a[0::2] != parts_b[0::2]:
            return False
        numbers_a = np.array(parts_a[1::2], dtype=float)
        numbers_b = np.array(parts_b[1::2], dtype=float)
        if not np.allclose(numbers_a, numbers_b, rtol=1e-9, atol=atol):
            return False
    return True


def test_model_comparison_tolerates_only_numeric_noise_and_face_rotation():
    assert _same_model_text("<pose>2.46e-19 0 0.005</pose>", "<pose>0 0 0.005</pose>")
    assert _same_model_text("f 6 5 3 4\n", "f 5 3 4 6\n")
    assert not _same_model_text("f 6 5 3 4\n", "f 4 3 5 6\n")  # reversed: flipped normal
    assert not _same_model_text("<pose>0 0 0.005</pose>", "<pose>0 0 0.006</pose>")
    assert not _same_model_text("<mass>1</mass>", "<mass>1</mass>\n<mass>1</mass>")


@pytest.mark.parametrize("name", TASKS)
def test_committed_models_match_generated(name):
    for file, text in TaskModelFiles(load_task(name, check_demo=False)).items():
        path = models_dir() / "parts" / file
        assert path.exists(), f"{path} missing: run scene.WriteTaskModels"
        assert _same_model_text(path.read_text(), text), (
            f"{path} is stale: run scene.WriteTaskModels"
        )


@pytest.mark.parametrize("name", TASKS)
def test_builds_with_frames_and_ik(name):
    task = load_task(name, check_demo=False)
    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task)
    diagram = builder.Build()
    plant = scene.plant
    assert plant.num_positions() == 7 and plant.num_actuators() == 7
    context = plant.GetMyMutableContextFromRoot(diagram.CreateDefaultContext())
    X_WGoal = GoalPoseInWorld(scene, context)
    X_FG = FixturePoseInWorld(scene, context).inverse() @ X_WGoal
    assert X_FG.translation() == pytest.approx([0.0, 0.0, -task.fixture.depth_m])
    q = SolvePandaIK(scene, X_WGoal)
    plant.SetPositions(context, q)
    X_WP = CalcPartPose(plant, context, scene)
    assert np.linalg.norm(X_WP.translation() - X_WGoal.translation()) < 2e-5
    angle = X_WP.rotation().InvertAndCompose(X_WGoal.rotation()).ToAngleAxis().angle()
    assert angle < 2e-4
    X_WH = scene.hand_frame.CalcPoseInWorld(context)
    assert (X_WH @ scene.X_HP).IsNearlyEqualTo(X_WP, 1e-12)
    # Hand points down: its z axis is -z of the world.
    assert X_WH.rotation().col(2) == pytest.approx([0.0, 0.0, -1.0], abs=1e-3)


def test_fixture_error_is_applied():
    task = load_task("peg", check_demo=False)
    dp, dq = sample_fixture_error(task, np.random.default_rng(1))
    X_err = FixtureErrorTransform(dp, dq)
    scene = AddRlfdScene(DiagramBuilder(), task, SceneConfig(), X_err)
    context = scene.plant.CreateDefaultContext()
    X_WF = FixturePoseInWorld(scene, context)
    assert X_WF.IsNearlyEqualTo(scene.X_WFixture_nominal @ X_err, 1e-12)
    assert not X_WF.IsNearlyEqualTo(scene.X_WFixture_nominal, 1e-6)
    slope = RollPitchYaw(X_WF.rotation()).pitch_angle()
    assert abs(np.degrees(slope)) == pytest.approx(1.0, abs=1.0 + 1e-6)


def test_the_fixture_moves_with_its_context_parameter():
    """One built scene serves every fixture error: SetFixtureError moves the fixture
    body, its collision geometry as the scene graph sees it, and the goal frame."""
    task = load_task("peg", check_demo=False)
    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task)
    diagram = builder.Build()
    fixture_body = scene.plant.GetBodyByName(FIXTURE_BODY, scene.fixture)
    geometry = scene.plant.GetCollisionGeometriesForBody(fixture_body)[0]

    def geometry_pose(root):
        query = scene.scene_graph.get_query_output_port()
        return query.Eval(scene.scene_graph.GetMyContextFromRoot(root)).GetPoseInWorld(geometry)

    X_WGeometry_nominal = geometry_pose(diagram.CreateDefaultContext())
    root = diagram.CreateDefaultContext()
    context = scene.plant.GetMyMutableContextFromRoot(root)
    X_err = FixtureErrorTransform([0.002, -0.001, 0.0005], [0.9999, 0.0, 0.0, 0.0141])
    SetFixtureError(scene, context, X_err)
    X_WF = scene.X_WFixture_nominal @ X_err
    assert FixturePoseInWorld(scene, context).IsNearlyEqualTo(X_WF, 1e-15)
    X_FG = PoseSpecToRigidTransform(task.X_FP_goal)
    assert GoalPoseInWorld(scene, context).IsNearlyEqualTo(X_WF @ X_FG, 1e-15)
    X_FGeometry = scene.X_WFixture_nominal.inverse() @ X_WGeometry_nominal
    assert geometry_pose(root).IsNearlyEqualTo(X_WF @ X_FGeometry, 1e-12)
    assert not geometry_pose(root).IsNearlyEqualTo(X_WGeometry_nominal, 1e-4)
    SetFixtureError(scene, context, None)
    assert FixturePoseInWorld(scene, context).IsNearlyEqualTo(scene.X_WFixture_nominal, 1e-15)


def _press(name: str, lateral_m: float, yaw_deg: float = 0.0, duration_s: float = 1.5):
    """Pushes the part from 3 mm above the entrance toward the goal (joint PD); returns
    (held scene, context, lowest P height in F (m), peak joint speed (rad/s))."""
    held = BuildHeldScene(load_task(name, check_demo=False))
    context, _, _ = press_setup(held, lateral_m, yaw_deg=yaw_deg)
    simulator = Simulator(held.diagram, context)
    simulator.Initialize()
    lowest, speed = np.inf, 0.0
    for t in np.arange(1, int(round(duration_s / 0.05)) + 1) * 0.05:
        simulator.AdvanceTo(t)
        lowest = min(lowest, p_FP(held, context)[2])
        speed = max(
            speed, np.max(np.abs(held.scene.plant.GetVelocities(held.plant_context(context))))
        )
    return held, context, lowest, speed


def _contacts(held, context):
    plant = held.scene.plant
    return plant.get_contact_results_output_port().Eval(held.plant_context(context))


@pytest.mark.parametrize("name", TASKS)
def test_on_axis_slides_to_goal(name):
    held, context, _, speed = _press(name, lateral_m=0.0)
    task = held.scene.task
    p = p_FP(held, context)
    goal = np.array(task.X_FP_goal.position_m)
    assert np.linalg.norm(p - goal) < min(task.kappa_m, 0.001), p
    assert speed < MAX_JOINT_SPEED_RAD_S
    contacts = _contacts(held, context)
    assert contacts.num_hydroelastic_contacts() > 0
    assert contacts.num_point_pair_contacts() == 0


@pytest.mark.parametrize("name", TASKS)
def test_off_axis_rests_on_edge(name):
    held, context, lowest, speed = _press(name, lateral_m=0.003)
    # Pressed with 15-40 N onto the entrance edge: it stays on top (no tunnelling).
    assert lowest > -0.0005
    assert p_FP(held, context)[2] > -0.0003
    assert speed < MAX_JOINT_SPEED_RAD_S
    contacts = _contacts(held, context)
    assert contacts.num_hydroelastic_contacts() > 0
    assert contacts.num_point_pair_contacts() == 0
    # The wrist feels the push: the part pushes the hand up.
    wrench = CalcWristWrench(held.scene.plant, held.plant_context(context), held.scene)
    assert wrench.translational()[2] > 10.0


@pytest.mark.parametrize(("name", "yaw_deg"), [("gear", 3.0), ("rj45", 180.0)])
def test_orientation_must_match(name, yaw_deg):
    """The square shaft and the keyed RJ-45 socket reject a wrong yaw."""
    held, context, _, _ = _press(name, lateral_m=0.0, yaw_deg=yaw_deg, duration_s=1.0)
    depth = held.scene.task.fixture.depth_m
    assert p_FP(held, context)[2] > -0.5 * depth


def test_wrist_wrench_is_part_weight_at_rest():
    task = load_task("peg", check_demo=False)
    held = BuildHeldScene(task)
    scene = held.scene
    context = held.diagram.CreateDefaultContext()
    plant_context = held.plant_context(context)
    X_WP = RigidTransform(
        GoalPoseInWorld(scene, plant_context).rotation(),
        FixturePoseInWorld(scene, plant_context) @ [0.0, 0.0, 0.05],
    )
    q = SolvePandaIK(scene, X_WP)
    scene.plant.SetPositions(held.plant_context(context), q)
    held.set_target(context, q)
    simulator = Simulator(held.diagram, context)
    simulator.AdvanceTo(0.3)
    wrench = CalcWristWrench(scene.plant, held.plant_context(context), scene)
    weight = task.part.mass_kg * 9.81
    assert wrench.translational() == pytest.approx([0.0, 0.0, -weight], abs=0.02 * weight)
