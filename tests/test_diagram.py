"""System tests of the built rLfD diagram (rates, insertion, torques, tracking, residual).

One zero-residual 10 s episode of the ``peg`` task from the demonstration's start is
simulated once per module (about 5 s wall); a short episode with a policy inside the
diagram checks the 10 Hz residual path.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.common.eigen_geometry import AngleAxis, Quaternion
from pydrake.math import RigidTransform
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator

from rlfd_drake.control_math import cartesian_impedance_torque
from rlfd_drake.demonstration import load_demonstration
from rlfd_drake.diagram import (
    LOGGED_OUTPUTS,
    BuildRlfdDiagram,
    ResumeFromSnapshot,
    RlfdDiagramConfig,
    SetEpisodeStart,
    SnapshotDiagramState,
)
from rlfd_drake.dmp import fit_cartesian_dmp
from rlfd_drake.episode import EPISODE_LOGS, demo_start_pose
from rlfd_drake.geometry import quat_conjugate, quat_multiply
from rlfd_drake.panda import PANDA_TORQUE_LIMITS_NM
from rlfd_drake.tasks import load_task

EPISODE_S = 10.0
#: Position tracking of the DMP set-point by the impedance controller in free space
#: (the part's actual position against the extrapolated base set-point), m.
FREE_SPACE_TRACKING_TOL_M = 0.004
#: Joint speeds stay below the Panda's rated limits (2.17-2.61 rad/s): a blow-up of the
#: sampled controller shows as hundreds of rad/s.
MAX_JOINT_SPEED_RAD_S = 1.0


@pytest.fixture(scope="module")
def peg():
    task = load_task("peg")
    demo = load_demonstration(task.demo_path())
    model = fit_cartesian_dmp(demo.times, demo.positions, demo.quats)
    X_WP_start = demo_start_pose(model)
    return task, model, X_WP_start


@pytest.fixture(scope="module")
def episode(peg):
    """A zero-residual 10 s episode; torques and joint speeds recorded at every step."""
    task, model, X_WP_start = peg
    rlfd = BuildRlfdDiagram(task, model)
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.zeros(6))
    SetEpisodeStart(rlfd, context, X_WP_start)
    torque_port = rlfd.controller.GetOutputPort("panda_torque")
    controller_context = rlfd.controller.GetMyContextFromRoot(context)
    plant = rlfd.scene.plant
    plant_context = plant.GetMyContextFromRoot(context)
    torques, speeds = [], []

    def monitor(root_context):
        torques.append(np.array(torque_port.Eval(controller_context)))
        speeds.append(plant.GetVelocities(plant_context, rlfd.scene.panda))

    simulator.set_monitor(monitor)
    simulator.Initialize()
    simulator.AdvanceTo(EPISODE_S)
    simulator.clear_monitor()
    return rlfd, context, np.array(torques), np.array(speeds)


def _log(rlfd, context, name):
    log = rlfd.logs[name].FindLog(context)
    return log.sample_times(), log.data()


def test_periods_of_the_four_systems(peg):
    task, model, _ = peg
    rlfd = BuildRlfdDiagram(task, model, policy=lambda obs: np.zeros(6))

    def period(system):
        attribute = system.GetUniquePeriodicDiscreteUpdateAttribute()
        assert attribute is not None, system.get_name()
        assert attribute.offset_sec() == 0.0
        return attribute.period_sec()

    assert period(rlfd.dmp) == pytest.approx(0.01)
    assert period(rlfd.residual_policy) == pytest.approx(0.1)
    assert period(rlfd.controller) == pytest.approx(0.002)
    assert rlfd.scene.plant.time_step() == pytest.approx(0.002)
    # The extrapolator samples its 100 Hz source at the source's rate; its outputs are
    # polynomials of time (time is a prerequisite), so the 500 Hz controller reads a
    # fresh value at every one of its own updates (see test_base_is_extrapolated...).
    assert period(rlfd.extrapolator) == pytest.approx(rlfd.dmp.period_s)
    assert rlfd.extrapolator.config.source_period_s == pytest.approx(0.01)


def test_zero_residual_inserts_the_peg(episode):
    rlfd, context, _, _ = episode
    diagram = rlfd.diagram
    distance = diagram.GetOutputPort("distance_to_goal").Eval(context)[0]
    assert diagram.GetOutputPort("success").Eval(context)[0] == 1.0
    assert distance < rlfd.task.kappa_m
    assert diagram.GetOutputPort("reward").Eval(context)[0] == 1.0


def test_torques_within_limits_and_joint_speeds_sane(episode):
    _, _, torques, speeds = episode
    assert torques.shape[0] >= int(EPISODE_S / 0.002)
    assert np.all(np.isfinite(torques))
    assert np.all(np.abs(torques) <= PANDA_TORQUE_LIMITS_NM + 1e-9)
    assert np.max(np.abs(speeds)) < MAX_JOINT_SPEED_RAD_S


def test_first_torque_holds_the_start(episode):
    """The controller's initialisation reads the DMP start (the extrapolator passes its
    source through before its first sample): the arm starts without a kick."""
    _, _, torques, speeds = episode
    assert np.all(np.abs(torques[0]) < 0.5 * PANDA_TORQUE_LIMITS_NM)
    assert np.max(np.abs(speeds[:50])) < 0.05  # first 0.1 s, rad/s


def test_controller_tracks_the_dmp_in_free_space(episode):
    rlfd, context, _, _ = episode
    t, X_base = _log(rlfd, context, "X_WE_base")
    _, obs = _log(rlfd, context, "observation")
    scale = rlfd.observer.config.position_scale_m
    p_WP = obs[0:3] * scale + rlfd.X_WGoal_nominal.translation()[:, None]
    approach = (t >= 0.1) & (t <= 4.0)  # the part is well above the fixture
    error = np.linalg.norm(X_base[:3, approach] - p_WP[:, approach], axis=0)
    assert np.max(error) < FREE_SPACE_TRACKING_TOL_M
    _, forces = _log(rlfd, context, "force_metrics")
    assert np.all(forces[0, approach] == 0.0)  # no contact during the approach


def test_composer_leaves_the_base_untouched_with_zero_residual(episode):
    rlfd, context, _, _ = episode
    _, X_base = _log(rlfd, context, "X_WE_base")
    _, X_desired = _log(rlfd, context, "X_WE_desired")
    np.testing.assert_array_equal(X_desired, X_base)


def test_controller_law_matches_the_reference_maths(episode):
    """The controller's scalar fast path equals control_math's impedance law."""
    rlfd, _, _, _ = episode
    controller = rlfd.controller
    plant = controller._plant
    ctx = plant.CreateDefaultContext()
    rng = np.random.default_rng(3)
    frame_E = plant.GetFrameByName("controlled_frame_E")
    for _ in range(5):
        x = np.concatenate([controller._q_nominal + rng.normal(0, 0.2, 7), rng.normal(0, 0.3, 7)])
        plant.SetPositionsAndVelocities(ctx, x)
        X_WE = frame_E.CalcPoseInWorld(ctx)
        dq = rng.normal(0, 0.3, 3)
        Q_d = AngleAxis(np.linalg.norm(dq), dq / np.linalg.norm(dq)).quaternion()
        Q_d = Q_d.multiply(X_WE.rotation().ToQuaternion())
        X_d = np.concatenate([X_WE.translation() + rng.normal(0, 0.01, 3), -Q_d.wxyz()])
        V_d = rng.normal(0, 0.05, 6)
        J = plant.CalcJacobianSpatialVelocity(
            ctx, JacobianWrtVariable.kV, frame_E, np.zeros(3), plant.world_frame(),
            plant.world_frame(),
        )  # fmt: skip
        aa = AngleAxis(Quaternion(X_d[3:]).multiply(X_WE.rotation().ToQuaternion().conjugate()))
        e = np.concatenate([aa.angle() * aa.axis(), X_d[:3] - X_WE.translation()])
        config = controller.config
        tau_posture = (
            config.nullspace_stiffness_Nm_per_rad * (controller._q_nominal - x[:7])
            - config.nullspace_damping_Nms_per_rad * x[7:]
        )
        expected = cartesian_impedance_torque(
            J, e, V_d - J @ x[7:], controller._K, controller.nominal_damping, tau_posture,
            plant.CalcGravityGeneralizedForces(ctx), PANDA_TORQUE_LIMITS_NM,
        )  # fmt: skip
        np.testing.assert_allclose(controller.CalcTorque(x, X_d, V_d), expected, atol=1e-9)


@pytest.mark.parametrize("from_activation", [True, False])
def test_policy_inside_the_diagram_acts_at_10_hz(peg, from_activation):
    """The policy is first called at the residual's activation, as a training episode
    first asks for an action there (or, as evaluations before 2026-12-06 did, from the
    start, its actions held but not applied until then), then every 0.1 s."""
    task, model, X_WP_start = peg
    calls = []

    def policy(obs: np.ndarray) -> np.ndarray:
        # Normalised time obs[19]: a different action at every policy update.
        calls.append(float(obs[19]))
        return np.full(6, 5.0 * obs[19])

    config = RlfdDiagramConfig(
        residual_activation_s=0.5, residual_policy_from_activation=from_activation
    )
    rlfd = BuildRlfdDiagram(task, model, config, policy=policy)
    assert not any(
        rlfd.diagram.get_input_port(i).get_name() == "residual"
        for i in range(rlfd.diagram.num_input_ports())
    )
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.Initialize()
    simulator.AdvanceTo(1.0)
    t, residual = _log(rlfd, context, "residual")
    # Piecewise constant, equal to the action of the last update strictly before the
    # sample (a log at t_k records what the diagram saw just before its update at t_k),
    # the policy's action at the update t_j being 5 * t_j / 10 s (float32 obs).
    t_update = np.maximum(np.ceil(t / 0.1 - 1e-9) - 1.0, 0.0) * 0.1
    first_call_s = 0.5 if from_activation else 0.0
    expected = np.where(t_update > first_call_s - 1e-9, 0.5 * t_update, 0.0)
    np.testing.assert_allclose(residual, np.tile(expected, (6, 1)), atol=1e-6)
    if from_activation:  # updates at 0.5, ..., 0.9 s, the first at the activation
        assert len(calls) == 5 and calls[0] == pytest.approx(0.05)
    else:  # initialisation + updates at 0, 0.1, ..., 0.9 s
        assert len(calls) == 1 + 10 and np.unique(np.round(residual[0], 6)).size == 10
    # The composer applies it after activation: translation max_translation_m * a.
    _, X_base = _log(rlfd, context, "X_WE_base")
    _, X_desired = _log(rlfd, context, "X_WE_desired")
    before, after = t < 0.5, t >= 0.5
    np.testing.assert_array_equal(X_desired[:, before], X_base[:, before])
    dp = X_desired[:3, after] - X_base[:3, after]
    np.testing.assert_allclose(
        dp, config.residual_bounds(task)[0] * residual[:3, after], atol=1e-12
    )


def test_the_task_sets_the_wrist_stiffness(peg):
    """A task's rotational stiffness reaches the controller; the translational gains and
    the config's own default stay as they were."""
    task, model, _ = peg
    config = RlfdDiagramConfig()
    soft = dataclasses.replace(task, rotational_stiffness_Nm_per_rad=20.0)
    gains = BuildRlfdDiagram(soft, model, config).controller.config
    assert gains.rotational_stiffness_Nm_per_rad == (20.0, 20.0, 20.0)
    assert gains.translational_stiffness_N_per_m == config.impedance.translational_stiffness_N_per_m
    assert config.impedance.rotational_stiffness_Nm_per_rad == (150.0, 150.0, 150.0)
    assert config.impedance_for(task) is config.impedance


def test_the_task_sets_the_translational_stiffness(peg):
    """A task's translational stiffness reaches the controller alongside its rotational
    one; each leaves the other at the config's value."""
    task, model, _ = peg
    config = RlfdDiagramConfig()
    soft_z = dataclasses.replace(task, translational_stiffness_N_per_m=1000.0)
    gains = config.impedance_for(soft_z)
    assert gains.translational_stiffness_N_per_m == (1000.0, 1000.0, 1000.0)
    assert gains.rotational_stiffness_Nm_per_rad == config.impedance.rotational_stiffness_Nm_per_rad
    both = dataclasses.replace(soft_z, rotational_stiffness_Nm_per_rad=20.0)
    controller = BuildRlfdDiagram(both, model, config).controller.config
    assert controller.translational_stiffness_N_per_m == (1000.0, 1000.0, 1000.0)
    assert controller.rotational_stiffness_Nm_per_rad == (20.0, 20.0, 20.0)


def test_a_task_with_a_residual_filter_feeds_the_composer_through_it(peg):
    """The filter sits between the residual and the composer (the observer still sees
    the policy's own action); only the residual composition can have it."""
    task, model, X_WP_start = peg
    smooth = dataclasses.replace(task, residual_filter_time_constant_s=0.1)
    rlfd = BuildRlfdDiagram(smooth, model, RlfdDiagramConfig(residual_activation_s=0.0))
    filter_system = rlfd.diagram.GetSubsystemByName("residual_filter")
    assert filter_system.config.time_constant_s == 0.1
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.array([1.0, 0, 0, 0, 0, 0]))
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.AdvanceTo(0.1)  # one time constant
    offset = (
        rlfd.diagram.GetOutputPort("X_WE_desired").Eval(context)[0]
        - rlfd.diagram.GetOutputPort("X_WE_base").Eval(context)[0]
    )
    max_translation_m, _ = RlfdDiagramConfig().residual_bounds(task)
    assert offset == pytest.approx((1.0 - np.exp(-1.0)) * max_translation_m, rel=0.03)
    with pytest.raises(ValueError, match="residual_filter_time_constant_s = 0.1"):
        BuildRlfdDiagram(smooth, model, RlfdDiagramConfig(composition="hybrid"))


def test_a_task_with_a_residual_rate_integrates_the_action(peg):
    """With ``residual_rate_per_s`` the action is a rate: the composer adds the offset it
    integrated, and the observer's residual is that offset (where the policy has moved
    the set-point), not the action; only the residual composition can have it."""
    task, model, X_WP_start = peg
    incremental = dataclasses.replace(task, residual_rate_per_s=2.0)
    rlfd = BuildRlfdDiagram(incremental, model, RlfdDiagramConfig(residual_activation_s=0.0))
    assert rlfd.diagram.GetSubsystemByName("residual_integrator").config.rate_per_s == 2.0
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.array([0.5, 0, 0, 0, 0, 0]))
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.AdvanceTo(0.2)
    offset = (
        rlfd.diagram.GetOutputPort("X_WE_desired").Eval(context)[0]
        - rlfd.diagram.GetOutputPort("X_WE_base").Eval(context)[0]
    )
    max_translation_m, _ = RlfdDiagramConfig().residual_bounds(task)
    # 0.5 * 2 per s for 0.2 s = 0.2 of the range (one 2 ms update may lag).
    assert offset == pytest.approx(0.2 * max_translation_m, rel=0.02)
    observed = rlfd.diagram.GetOutputPort("observation").Eval(context)[20]
    assert observed == pytest.approx(offset / max_translation_m, rel=1e-9)
    with pytest.raises(ValueError, match="residual_rate_per_s = 2.0"):
        BuildRlfdDiagram(incremental, model, RlfdDiagramConfig(composition="pure"))


def test_a_rate_residual_can_start_at_the_table_slope(peg):
    """``residual_starts_at_table_slope``: with no action the composer turns the
    set-point by the slope's undoing from activation on, and the observer reports it."""
    from rlfd_drake.geometry import rotation_vector_from_quat
    from rlfd_drake.tasks import table_slope_residual

    task, model, X_WP_start = peg
    tilted = dataclasses.replace(task, residual_rate_per_s=2.0, residual_starts_at_table_slope=True)
    rlfd = BuildRlfdDiagram(tilted, model, RlfdDiagramConfig(residual_activation_s=0.0))
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.zeros(6))
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.AdvanceTo(0.05)
    q_desired = rlfd.diagram.GetOutputPort("X_WE_desired").Eval(context)[3:7]
    q_base = rlfd.diagram.GetOutputPort("X_WE_base").Eval(context)[3:7]
    q_delta = quat_multiply(q_desired, quat_conjugate(q_base))
    _, max_rotation_rad = RlfdDiagramConfig().residual_bounds(task)
    expected = table_slope_residual(tilted)
    np.testing.assert_allclose(
        rotation_vector_from_quat(q_delta), expected[3:6] * max_rotation_rad, atol=1e-9
    )
    observed = rlfd.diagram.GetOutputPort("observation").Eval(context)[20:26]
    np.testing.assert_allclose(observed, expected, atol=1e-9)


def test_a_task_with_a_push_bound_gives_it_to_the_composer(peg):
    """``residual_max_push_m`` reaches the composer: a full downward residual leaves the
    set-point's height alone, a sideways one moves it; other compositions refuse it."""
    task, model, X_WP_start = peg
    no_push = dataclasses.replace(task, residual_max_push_m=0.0)
    rlfd = BuildRlfdDiagram(no_push, model, RlfdDiagramConfig(residual_activation_s=0.0))
    assert rlfd.diagram.GetSubsystemByName("composer").config.max_push_m == 0.0
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.array([1.0, 0, -1.0, 0, 0, 0]))
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.AdvanceTo(0.05)
    offset = (
        rlfd.diagram.GetOutputPort("X_WE_desired").Eval(context)[:3]
        - rlfd.diagram.GetOutputPort("X_WE_base").Eval(context)[:3]
    )
    max_translation_m, _ = RlfdDiagramConfig().residual_bounds(task)
    np.testing.assert_allclose(offset, [max_translation_m, 0.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="residual_max_push_m = 0.0"):
        BuildRlfdDiagram(no_push, model, RlfdDiagramConfig(composition="pure"))


def test_a_phase_stopped_dmp_waits_while_the_fixture_holds_the_part_back(peg):
    """With phase stopping the controller's tracking error reaches the DMP: free motion
    (lag under the deadband) keeps the paper's phase; a peg landing 6 mm beside its
    hole holds the set-point back, so the phase decays far slower than open loop."""
    task, model, X_WP_start = peg
    stopped = dataclasses.replace(
        task, dmp_phase_stop_gain_per_m2=1e6, dmp_phase_stop_deadband_m=0.0015
    )
    rlfd = BuildRlfdDiagram(
        stopped,
        model,
        RlfdDiagramConfig(log_period_s=None),
        fixture_error=RigidTransform([0.006, 0.0, 0.0]),
    )
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.zeros(6))
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.Initialize()
    dmp_context = rlfd.dmp.GetMyContextFromRoot(context)

    def open_loop_phase(t):
        return np.exp(-model.config.alpha_x * t / model.tau)

    simulator.AdvanceTo(2.0)  # free motion
    assert rlfd.dmp.time_scale(dmp_context) == 1.0
    assert rlfd.dmp.GetOutputPort("phase").Eval(dmp_context)[0] == pytest.approx(
        open_loop_phase(2.0), rel=1e-9
    )
    simulator.AdvanceTo(EPISODE_S)
    assert rlfd.dmp.time_scale(dmp_context) > 10.0
    phase = rlfd.dmp.GetOutputPort("phase").Eval(dmp_context)[0]
    assert phase > 2.0 * open_loop_phase(EPISODE_S)


def test_the_config_chooses_which_outputs_are_logged(peg):
    """By default every output of LOGGED_OUTPUTS is logged; logged_outputs keeps some
    (run_episode: the two it reads), and names no other."""
    task, model, _ = peg
    assert set(BuildRlfdDiagram(task, model).logs) == set(LOGGED_OUTPUTS)
    kept = BuildRlfdDiagram(task, model, RlfdDiagramConfig(logged_outputs=EPISODE_LOGS))
    assert set(kept.logs) == set(EPISODE_LOGS) == {"distance_to_goal", "force_metrics"}
    with pytest.raises(ValueError, match="logged_outputs must be among .*'contact'"):
        RlfdDiagramConfig(logged_outputs=("force_metrics", "contact"))


def test_a_snapshot_resumes_in_another_diagram_built_the_same_way(peg):
    """The state at 0.5 s, put into a fresh diagram of the same task, goes on as the
    original; a diagram with a stateful subsystem the snapshot lacks is refused."""
    task, model, X_WP_start = peg

    def started():
        rlfd = BuildRlfdDiagram(task, model, RlfdDiagramConfig(log_period_s=None))
        simulator = Simulator(rlfd.diagram)
        rlfd.diagram.GetInputPort("residual").FixValue(simulator.get_mutable_context(), np.zeros(6))
        return rlfd, simulator

    rlfd, simulator = started()
    SetEpisodeStart(rlfd, simulator.get_mutable_context(), X_WP_start)
    simulator.AdvanceTo(0.5)
    snapshot = SnapshotDiagramState(rlfd, simulator.get_context())
    assert snapshot.time_s == 0.5 and "plant" in snapshot.states
    simulator.AdvanceTo(0.8)
    other, resumed = started()
    ResumeFromSnapshot(other, resumed, snapshot)
    resumed.AdvanceTo(0.8)
    for name in ("observation", "X_WE_desired", "force_metrics", "phase"):
        assert np.array_equal(
            other.diagram.GetOutputPort(name).Eval(resumed.get_context()),
            rlfd.diagram.GetOutputPort(name).Eval(simulator.get_context()),
        )
    incremental = dataclasses.replace(task, residual_rate_per_s=2.0)
    rate = BuildRlfdDiagram(incremental, model, RlfdDiagramConfig(log_period_s=None))
    with pytest.raises(ValueError, match="no state of subsystem 'residual_integrator'"):
        ResumeFromSnapshot(rate, Simulator(rate.diagram), snapshot)
