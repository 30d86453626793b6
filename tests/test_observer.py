"""Observer on a small scene: Panda + welded box part + box fixture (hydroelastic)."""

from __future__ import annotations

import time

import numpy as np
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    ProximityProperties,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from rlfd_drake.panda import PANDA_HAND_BODY, PANDA_HOME_Q, AddPanda
from rlfd_drake.systems.impedance import CartesianImpedanceController, MakePandaControlModel
from rlfd_drake.systems.observer import OBSERVATION_SIZE, Observer, ObserverConfig

PART_MASS_KG = 0.2
PART_SIZE_M = (0.03, 0.03, 0.08)
P_H_PART_CENTER = np.array([0.0, 0.0, 0.12])  # part centre in the hand frame
X_BP = RigidTransform([0.0, 0.0, 0.04])  # P: the part's tip (bottom face centre)
X_HP = RigidTransform(P_H_PART_CENTER + X_BP.translation())


def _build(tip_setpoint_below_m: float, goal_offset_m: float, kappa_m: float = 0.005):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=0.002, discrete_contact_approximation="sap"), builder
    )
    panda = AddPanda(plant)
    part = plant.AddRigidBody(
        "part",
        panda,
        SpatialInertia.MakeFromCentralInertia(
            PART_MASS_KG, np.zeros(3), UnitInertia.SolidBox(*PART_SIZE_M) * PART_MASS_KG
        ),
    )
    hand = plant.GetBodyByName(PANDA_HAND_BODY, panda)
    weld = plant.WeldFrames(hand.body_frame(), part.body_frame(), RigidTransform(P_H_PART_CENTER))
    compliant = ProximityProperties()
    AddCompliantHydroelasticProperties(0.01, 1e6, compliant)
    AddContactMaterial(1.0, None, None, compliant)
    plant.RegisterCollisionGeometry(part, RigidTransform(), Box(*PART_SIZE_M), "part", compliant)
    # The tip of the part at home, and a fixture whose top face is 5 mm below it.
    probe = MakePandaControlModel(X_HP)
    ctx = probe.CreateDefaultContext()
    probe.SetPositions(ctx, PANDA_HOME_Q)
    X_WP0 = probe.GetFrameByName("controlled_frame_E").CalcPoseInWorld(ctx)
    top_z = X_WP0.translation()[2] - 0.005
    rigid = ProximityProperties()
    AddRigidHydroelasticProperties(0.01, rigid)
    AddContactMaterial(None, None, None, rigid)
    p_fixture = X_WP0.translation() - np.array([0.0, 0.0, X_WP0.translation()[2] - top_z + 0.05])
    plant.RegisterCollisionGeometry(
        plant.world_body(), RigidTransform(p_fixture), Box(0.2, 0.2, 0.1), "fixture", rigid
    )
    plant.Finalize()

    controller = builder.AddSystem(
        CartesianImpedanceController(MakePandaControlModel(X_HP, PART_MASS_KG, P_H_PART_CENTER))
    )
    X_d = np.concatenate(
        [
            X_WP0.translation() - [0.0, 0.0, tip_setpoint_below_m],
            X_WP0.rotation().ToQuaternion().wxyz(),
        ]
    )
    builder.Connect(plant.get_state_output_port(panda), controller.GetInputPort("panda_state"))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(X_d)).get_output_port(),
        controller.GetInputPort("X_WE_desired"),
    )
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(6))).get_output_port(),
        controller.GetInputPort("V_WE_desired"),
    )
    builder.Connect(controller.GetOutputPort("panda_torque"), plant.get_actuation_input_port(panda))

    X_WGoal_true = RigidTransform(X_WP0.rotation(), X_WP0.translation() + [0, 0, goal_offset_m])
    X_WGoal_nominal = RigidTransform(X_WP0.rotation(), X_WP0.translation() + [0.01, 0, 0])
    observer = builder.AddSystem(
        Observer(
            plant,
            part.index(),
            X_BP,
            plant.world_body().index(),
            X_WGoal_true,
            X_WGoal_nominal,
            weld.index(),
            panda,
            ObserverConfig(kappa_m=kappa_m, episode_time_s=10.0),
        )
    )
    builder.Connect(plant.get_body_poses_output_port(), observer.GetInputPort("body_poses"))
    builder.Connect(
        plant.get_body_spatial_velocities_output_port(),
        observer.GetInputPort("body_spatial_velocities"),
    )
    builder.Connect(
        plant.get_reaction_forces_output_port(), observer.GetInputPort("reaction_forces")
    )
    builder.Connect(
        plant.get_contact_results_output_port(), observer.GetInputPort("contact_results")
    )
    builder.Connect(
        plant.get_generalized_contact_forces_output_port(panda),
        observer.GetInputPort("generalized_contact_forces"),
    )
    builder.Connect(
        builder.AddSystem(ConstantVectorSource([0.7])).get_output_port(),
        observer.GetInputPort("phase"),
    )
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.full(6, 0.25))).get_output_port(),
        observer.GetInputPort("residual"),
    )
    diagram = builder.Build()
    return diagram, observer


def _outputs(simulator, observer):
    context = observer.GetMyContextFromRoot(simulator.get_context())
    return {
        name: observer.GetOutputPort(name).Eval(context)
        for name in ("observation", "reward", "success", "force_metrics", "distance_to_goal")
    }


def test_reward_iff_within_kappa_and_observation_layout():
    # Set-point at the start pose (no contact); goal 4 mm then 6 mm above the tip.
    for offset, expected in ((0.004, 1.0), (0.006, 0.0)):
        diagram, observer = _build(0.0, offset, kappa_m=0.005)
        simulator = Simulator(diagram)
        simulator.AdvanceTo(0.1)
        out = _outputs(simulator, observer)
        assert out["distance_to_goal"][0] == np.float64(out["distance_to_goal"][0])
        assert abs(out["distance_to_goal"][0] - offset) < 5e-4
        assert out["reward"][0] == expected
        assert out["success"][0] == expected
        obs = out["observation"]
        assert obs.shape == (OBSERVATION_SIZE,)
        assert np.all(np.isfinite(obs))
        # Position relative to the nominal goal (1 cm in -x), scaled by 2 cm.
        np.testing.assert_allclose(obs[0:3], [-0.5, 0.0, 0.0], atol=0.05)
        assert np.linalg.norm(obs[3:6]) < 0.01  # same orientation as the nominal goal
        # Wrist force: the weld carries the part's weight (0.2 kg * 9.81 N / 50 N).
        np.testing.assert_allclose(np.linalg.norm(obs[15:18]), 0.2 * 9.81 / 50.0, rtol=0.05)
        assert obs[18] == np.float32(0.7) or abs(obs[18] - 0.7) < 1e-12
        np.testing.assert_allclose(obs[19], 0.01)
        np.testing.assert_allclose(obs[20:26], 0.25)
        np.testing.assert_array_equal(out["force_metrics"], 0.0)  # never touched


def test_force_metrics_grow_when_pushed_into_fixture():
    diagram, observer = _build(0.02, 0.0)  # set-point 2 cm below the tip: 1.5 cm into it
    simulator = Simulator(diagram)
    start = time.perf_counter()
    simulator.AdvanceTo(0.05)
    early = _outputs(simulator, observer)["force_metrics"].copy()
    simulator.AdvanceTo(0.6)
    print(f"pushing: 0.6 s simulated in {time.perf_counter() - start:.2f} s")
    late = _outputs(simulator, observer)["force_metrics"]
    print("force metrics early", early, "late", late)
    assert late[0] > early[0] and late[1] > early[1] and late[2] > early[2]
    # K_z * 1.5 cm = 30 N pressing (plus the part's weight) at rest; the impact
    # when the part lands (2 ms steps, ~12 kg apparent mass) makes the peak larger.
    assert late[0] > 30.0
    assert 10.0 < late[1] < 60.0
    assert late[2] > 1.0
    # The low-passed force settles at the pressing force and stays below the spike.
    assert 25.0 < late[3] < late[0]
    obs = _outputs(simulator, observer)["observation"]
    # The fixture pushes the part up, so the hand pushes it down: the reaction force
    # on the part (the weld's child) has a large -z component.
    assert obs[17] * 50.0 < -15.0


def test_observation_cost():
    diagram, observer = _build(0.0, 0.0)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.01)
    root = simulator.get_mutable_context()
    context = observer.GetMyContextFromRoot(root)
    port = observer.GetOutputPort("observation")
    n = 300
    start = time.perf_counter()
    for i in range(n):
        root.SetTime(0.01 + 1e-6 * i)
        port.Eval(context)
    print(f"Observer observation: {(time.perf_counter() - start) / n * 1e6:.1f} us per call")
    state = context.get_discrete_state().Clone()
    start = time.perf_counter()
    for _ in range(n):
        observer._update_metrics(context, state)
    print(f"Observer force-metric update: {(time.perf_counter() - start) / n * 1e6:.1f} us")
