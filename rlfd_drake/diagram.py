"""BuildRlfdDiagram: the multi-rate rLfD diagram of one task.

    DmpSystem (100 Hz) -> QuinticExtrapolator (samples at 100 Hz, read at 500 Hz)
      -> ResidualComposer (residual held, 10 Hz) -> CartesianImpedanceController (500 Hz)
      -> MultibodyPlant (Panda + part + fixture, hydroelastic, 2 ms) -> Observer

The residual comes either from the exported input port ``residual`` (the Gym env
drives it) or from a :class:`ResidualPolicy` inside the diagram (deployment). The
controller only knows the arm and its payload; the DMP only knows the demonstration
(its goal is the demonstrated, nominal one); only the plant knows where the fixture
really is. A task with ``dmp_phase_stop_gain_per_m2 > 0`` closes one loop: the
controller's tracking error slows the DMP (phase stopping) while contact holds the part.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import InitializeParams, Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import Gain, LogVectorOutput, PassThrough, VectorLogSink

from rlfd_drake.control_math import COMPOSITIONS
from rlfd_drake.dmp import CartesianDmp
from rlfd_drake.scene import (
    AddRlfdScene,
    GoalPoseInWorld,
    Scene,
    SceneConfig,
    SetFixtureError,
    SolvePandaIK,
)
from rlfd_drake.systems.composer import ResidualComposer, ResidualComposerConfig
from rlfd_drake.systems.dmp_system import DmpSystem
from rlfd_drake.systems.extrapolator import QuinticExtrapolator, QuinticExtrapolatorConfig
from rlfd_drake.systems.impedance import (
    CartesianImpedanceConfig,
    CartesianImpedanceController,
    MakePandaControlModel,
)
from rlfd_drake.systems.observer import OBSERVATION_SIZE, Observer, ObserverConfig
from rlfd_drake.systems.residual_filter import ResidualFilter, ResidualFilterConfig
from rlfd_drake.systems.residual_integrator import (
    ResidualIntegrator,
    ResidualIntegratorConfig,
)
from rlfd_drake.systems.residual_policy import ResidualPolicy, ResidualPolicyConfig
from rlfd_drake.systems.setpoint_triad import SetpointTriad
from rlfd_drake.systems.velocity_command import VelocityCommandConfig, VelocityCommandSetpoint
from rlfd_drake.tasks import TaskSpec, table_slope_residual
from rlfd_drake.view import (
    BASE_SETPOINT_PATH,
    SETPOINT_PATH,
    DrawDmpPlan,
    DrawGoals,
    EpisodeViewConfig,
)

#: The residual's dimension: translation (3) then angle-axis (3), in [-1, 1].
RESIDUAL_SIZE = 6
#: The outputs an episode can log (``RlfdDiagram.logs``), each every ``log_period_s``.
LOGGED_OUTPUTS = (
    "panda_state",
    "X_WE_desired",
    "X_WE_base",
    "residual",
    "observation",
    "distance_to_goal",
    "force_metrics",
)


#: The controller gains a task may set: each TaskSpec field (a scalar, or None for the
#: controller's own) sets the CartesianImpedanceConfig field of the same name on all
#: three axes.
_TASK_GAINS = ("rotational_stiffness_Nm_per_rad", "translational_stiffness_N_per_m")
#: Task fields that shape a residual added to the DMP (a filter, a push bound, a rate): the
#: hybrid and pure compositions have no such residual and refuse a task that sets them.
_RESIDUAL_COMPOSITION_FIELDS = (
    "residual_filter_time_constant_s",
    "residual_max_push_m",
    "residual_rate_per_s",
)


@dataclass
class RlfdDiagramConfig:
    """Rates and gains of the rLfD diagram (the paper's by default).

    Attributes:
        scene: plant and contact configuration (plant step 2 ms).
        dmp_period_s: DMP base policy period (100 Hz).
        impedance: Cartesian impedance controller (500 Hz).
        extrapolator: quintic extrapolation of the DMP set-points.
        residual_mode: "full", "translation", "orientation" or "off".
        max_translation_m, max_rotation_rad: physical bounds of a residual of 1; None
            = the task's (``residual_max_translation_m`` / ``_rotation_rad``: 1 cm and
            0.087 rad (5 deg) for the pegs and the gear, a few times the fixture calibration
            errors; larger bounds make early exploration knock the part off a hole it
            would have found).
        residual_activation_s: when the residual starts acting; None = the task's
            (5 s: the paper's simulated half-episode).
        residual_period_s: residual policy period, s; None = the task's
            (``residual_period_s``: 0.1 s, the paper's 10 Hz).
        log_period_s: period of the episode logs; None = no logs (training, where
            nobody reads them).
        logged_outputs: which of ``LOGGED_OUTPUTS`` are logged (None: all). Each log
            evaluates its output at every sample, which costs: ``run_episode`` keeps
            the two it reads.
        composition: one of ``COMPOSITIONS``.
        residual_policy_from_activation: a policy run inside the diagram is first
            called at the residual's activation time (``ResidualPolicyConfig``), as in
            training; False calls it from the start, its actions held but not applied
            until then, so that they showed in the observation's residual entries and
            in the memory of a stacked or recurrent policy, unlike in training
            (evaluations stored before 2026-12-06; kept to reproduce them).
        max_speed_m_s, max_angular_speed_rad_s: velocity of an action of 1 for the
            "hybrid" and "pure" compositions (5 cm/s, 20 deg/s).
    """

    scene: SceneConfig = field(default_factory=SceneConfig)
    dmp_period_s: float = 0.01
    impedance: CartesianImpedanceConfig = field(default_factory=CartesianImpedanceConfig)
    extrapolator: QuinticExtrapolatorConfig = field(default_factory=QuinticExtrapolatorConfig)
    residual_mode: str = "full"
    max_translation_m: float | None = None
    max_rotation_rad: float | None = None
    residual_activation_s: float | None = None
    residual_period_s: float | None = None
    log_period_s: float | None = 0.01
    logged_outputs: tuple[str, ...] | None = None
    composition: str = "residual"
    residual_policy_from_activation: bool = True
    max_speed_m_s: float = 0.05
    max_angular_speed_rad_s: float = 0.35

    def __post_init__(self) -> None:
        for name in ("dmp_period_s", "residual_period_s", "log_period_s"):
            value = getattr(self, name)
            if value is None and name in ("residual_period_s", "log_period_s"):
                continue
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value}")
        if self.residual_mode not in ("full", "translation", "orientation", "off"):
            raise ValueError(
                "residual_mode must be one of full, translation, orientation, off; "
                f"got {self.residual_mode!r}"
            )
        for name in ("max_translation_m", "max_rotation_rad"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number or None, got {value}")
        if self.composition not in COMPOSITIONS:
            raise ValueError(f"composition must be one of {COMPOSITIONS}, got {self.composition!r}")
        unknown = set(self.logged_outputs or ()) - set(LOGGED_OUTPUTS)
        if unknown:
            raise ValueError(
                f"logged_outputs must be among {LOGGED_OUTPUTS}, got {self.logged_outputs!r}"
            )

    def residual_bounds(self, task: TaskSpec) -> tuple[float, float]:
        """(m, rad) of a residual action of 1 on ``task``: this config's or the task's."""
        translation = (
            task.residual_max_translation_m
            if self.max_translation_m is None
            else self.max_translation_m
        )
        rotation = (
            task.residual_max_rotation_rad
            if self.max_rotation_rad is None
            else self.max_rotation_rad
        )
        return float(translation), float(rotation)

    def residual_period_for(self, task: TaskSpec) -> float:
        """Period of the residual policy on ``task``, s: this config's or the task's."""
        period = (
            task.residual_period_s if self.residual_period_s is None else self.residual_period_s
        )
        return float(period)

    def impedance_for(self, task: TaskSpec) -> CartesianImpedanceConfig:
        """The controller's gains on ``task``: this config's, with the task's rotational
        and translational stiffness where the task sets them (``_TASK_GAINS``)."""
        overrides = {
            name: (getattr(task, name),) * 3
            for name in _TASK_GAINS
            if getattr(task, name) is not None
        }
        return replace(self.impedance, **overrides) if overrides else self.impedance


@dataclass
class RlfdDiagram:
    """The built diagram and handles to its parts."""

    diagram: Diagram
    scene: Scene
    task: TaskSpec
    config: RlfdDiagramConfig
    dmp: DmpSystem
    extrapolator: QuinticExtrapolator
    composer: ResidualComposer | VelocityCommandSetpoint
    controller: CartesianImpedanceController
    observer: Observer
    residual_policy: ResidualPolicy | None
    logs: dict[str, VectorLogSink]
    coupling_policy: ResidualPolicy | None
    X_WGoal_nominal: RigidTransform
    meshcat: Meshcat | None = None
    view_config: EpisodeViewConfig | None = None


def MakeSceneControlModel(scene: Scene) -> MultibodyPlant:
    """The impedance controller's model of the arm in ``scene``: it knows its payload (as a
    real Franka is told its load), the part's mass and centre of mass in the hand frame
    H, and controls the part frame P (E = P), but not the fixture."""
    inertia = scene.part_body.default_spatial_inertia()
    return MakePandaControlModel(
        X_HE=scene.X_HP,
        payload_mass_kg=inertia.get_mass(),
        payload_com_H=scene.X_HP @ inertia.get_com(),
    )


def NominalGoal(task: TaskSpec) -> RigidTransform:
    """X_WGoal as the demonstration saw it (no fixture error)."""
    from rlfd_drake.scene import PoseSpecToRigidTransform

    return PoseSpecToRigidTransform(task.X_WFixture) @ PoseSpecToRigidTransform(task.X_FP_goal)


def BuildRlfdDiagram(
    task: TaskSpec,
    dmp_model: CartesianDmp,
    config: RlfdDiagramConfig | None = None,
    *,
    policy: Callable[[np.ndarray], np.ndarray] | None = None,
    coupling_policy: Callable[[np.ndarray], np.ndarray] | None = None,
    fixture_error: RigidTransform | None = None,
    meshcat: Meshcat | None = None,
    view_config: EpisodeViewConfig | None = None,
) -> RlfdDiagram:
    """Builds the rLfD diagram of ``task``.

    Args:
        task: the task (scene, goal, success radius, episode timing).
        dmp_model: the DMP fitted on the task's demonstration (the base policy).
        config: rates and gains (default RlfdDiagramConfig()).
        policy: a residual policy obs (26,) -> action (6,) in [-1, 1] run inside the
            diagram at 10 Hz; None exports the input port ``residual`` instead.
        coupling_policy: a policy obs (26,) -> normalised coupling term (6,) in
            [-1, 1] of the DMP (the eNAC baseline explores there, Table I type B), run
            at the residual's rate from t = 0; a unit value is the C_t that moves the
            DMP's rest point by ``max_translation_m`` / ``max_rotation_rad`` (C_t /
            (alpha_z beta_z)). None leaves the coupling input unconnected (C_t = 0).
        fixture_error: X_err, calibration error of the fixture (None = none): the
            default of the fixture's pose parameter; ``SetEpisodeFixture`` moves the
            fixture in a context without rebuilding.
        meshcat: if given, the scene, the hydroelastic contact surfaces and forces, the
            nominal and true goals and (as triads that follow them) the corrected and the
            DMP's set-points are drawn; ``SetEpisodeStart`` draws the DMP's plan (see
            :mod:`rlfd_drake.view`).
        view_config: how the goals, set-points and plan are drawn (default
            EpisodeViewConfig()).

    Exported ports: input ``residual`` (6, only when ``policy`` is None); outputs
    ``observation`` (26), ``reward`` (1), ``success`` (1), ``force_metrics`` (3),
    ``distance_to_goal`` (1), ``X_WE_desired`` (7), ``X_WE_base`` (7), ``phase`` (1).
    """
    config = config if config is not None else RlfdDiagramConfig()
    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task, config.scene, fixture_error)
    plant = scene.plant

    control_plant = MakeSceneControlModel(scene)
    controller = builder.AddNamedSystem(
        "impedance", CartesianImpedanceController(control_plant, config.impedance_for(task))
    )
    X_WGoal_nominal = NominalGoal(task)
    dmp_system = builder.AddNamedSystem(
        "dmp",
        DmpSystem(
            dmp_model,
            period_s=config.dmp_period_s,
            phase_stop_gain_per_m2=task.dmp_phase_stop_gain_per_m2,
            phase_stop_deadband_m=task.dmp_phase_stop_deadband_m,
        ),
    )
    extrapolator_config = replace(config.extrapolator, source_period_s=config.dmp_period_s)
    extrapolator = builder.AddNamedSystem("extrapolator", QuinticExtrapolator(extrapolator_config))
    activation = (
        task.residual_activation_s
        if config.residual_activation_s is None
        else config.residual_activation_s
    )
    max_translation_m, max_rotation_rad = config.residual_bounds(task)
    if config.composition != "residual":
        for name in _RESIDUAL_COMPOSITION_FIELDS:
            if getattr(task, name) is not None:
                raise ValueError(
                    f"task {task.name!r} sets {name} = {getattr(task, name)}, which only "
                    f"the 'residual' composition has; got composition {config.composition!r}"
                )
    if config.composition == "residual":
        composer = ResidualComposer(
            ResidualComposerConfig(
                max_translation_m=max_translation_m,
                max_rotation_rad=max_rotation_rad,
                mode=config.residual_mode,
                activation_time_s=activation,
                max_push_m=task.residual_max_push_m,
            )
        )
    else:
        composer = VelocityCommandSetpoint(
            VelocityCommandConfig(
                max_speed_m_s=config.max_speed_m_s,
                max_angular_speed_rad_s=config.max_angular_speed_rad_s,
                mode=config.residual_mode,
                activation_time_s=0.0 if config.composition == "pure" else activation,
                period_s=config.impedance.period_s,
            )
        )
    composer = builder.AddNamedSystem("composer", composer)
    # When the policy's actions start to count (pure RL: from the start).
    policy_activation = (
        composer.config.activation_time_s if config.residual_policy_from_activation else 0.0
    )
    observer = builder.AddNamedSystem(
        "observer",
        Observer(
            plant,
            scene.part_body.index(),
            RigidTransform(),
            scene.frame_goal.body().index(),
            scene.frame_goal.GetFixedPoseInBodyFrame(),
            X_WGoal_nominal,
            scene.part_weld.index(),
            scene.panda,
            ObserverConfig(kappa_m=task.kappa_m, episode_time_s=task.episode_time_s),
        ),
    )

    connect = builder.Connect
    connect(dmp_system.GetOutputPort("X_WE_desired"), extrapolator.GetInputPort("X_WE_dmp"))
    connect(dmp_system.GetOutputPort("V_WE_desired"), extrapolator.GetInputPort("V_WE_dmp"))
    connect(extrapolator.GetOutputPort("X_WE_desired"), composer.GetInputPort("X_WE_base"))
    connect(extrapolator.GetOutputPort("V_WE_desired"), composer.GetInputPort("V_WE_base"))
    connect(composer.GetOutputPort("X_WE_desired"), controller.GetInputPort("X_WE_desired"))
    connect(composer.GetOutputPort("V_WE_desired"), controller.GetInputPort("V_WE_desired"))
    connect(plant.get_state_output_port(scene.panda), controller.GetInputPort("panda_state"))
    connect(controller.GetOutputPort("panda_torque"), plant.get_actuation_input_port(scene.panda))
    connect(plant.get_body_poses_output_port(), observer.GetInputPort("body_poses"))
    connect(
        plant.get_body_spatial_velocities_output_port(),
        observer.GetInputPort("body_spatial_velocities"),
    )
    connect(plant.get_reaction_forces_output_port(), observer.GetInputPort("reaction_forces"))
    connect(plant.get_contact_results_output_port(), observer.GetInputPort("contact_results"))
    connect(
        plant.get_generalized_contact_forces_output_port(scene.panda),
        observer.GetInputPort("generalized_contact_forces"),
    )
    connect(dmp_system.GetOutputPort("phase"), observer.GetInputPort("phase"))
    if task.dmp_phase_stop_gain_per_m2 > 0.0:
        connect(
            controller.GetOutputPort("tracking_error"), dmp_system.GetInputPort("tracking_error")
        )

    residual_policy = None
    if policy is None:
        # One exported input feeds both the composer and the observer.
        residual_in = builder.AddNamedSystem("residual_input", PassThrough(RESIDUAL_SIZE))
        builder.ExportInput(residual_in.get_input_port(), "residual")
        residual_source = residual_in.get_output_port()
    else:
        residual_policy = builder.AddNamedSystem(
            "residual_policy",
            ResidualPolicy(
                policy,
                ResidualPolicyConfig(
                    period_s=config.residual_period_for(task),
                    observation_size=OBSERVATION_SIZE,
                    activation_time_s=policy_activation,
                ),
            ),
        )
        connect(observer.GetOutputPort("observation"), residual_policy.GetInputPort("observation"))
        residual_source = residual_policy.GetOutputPort("residual")
    if task.residual_rate_per_s is not None:
        # The action is a rate: the offset it integrates is the residual from here on,
        # for the composer and for the observation (the policy must see where it is).
        residual_integrator = builder.AddNamedSystem(
            "residual_integrator",
            ResidualIntegrator(
                ResidualIntegratorConfig(
                    rate_per_s=task.residual_rate_per_s,
                    period_s=config.impedance.period_s,
                    activation_time_s=activation,
                    start_offset=tuple(
                        table_slope_residual(task)
                        if task.residual_starts_at_table_slope
                        else np.zeros(RESIDUAL_SIZE)
                    ),
                )
            ),
        )
        connect(residual_source, residual_integrator.get_input_port())
        residual_source = residual_integrator.get_output_port()
    composer_residual = residual_source
    time_constant_s = task.residual_filter_time_constant_s
    if time_constant_s is not None:
        residual_filter = builder.AddNamedSystem(
            "residual_filter",
            ResidualFilter(
                ResidualFilterConfig(
                    time_constant_s=time_constant_s,
                    period_s=config.impedance.period_s,
                    activation_time_s=activation,
                )
            ),
        )
        connect(residual_source, residual_filter.get_input_port())
        composer_residual = residual_filter.get_output_port()
    connect(composer_residual, composer.GetInputPort("residual"))
    coupling = None
    if coupling_policy is not None:
        coupling = builder.AddNamedSystem(
            "coupling_policy",
            ResidualPolicy(
                coupling_policy,
                ResidualPolicyConfig(
                    period_s=config.residual_period_for(task), observation_size=OBSERVATION_SIZE
                ),
            ),
        )
        rest_gain = dmp_model.config.alpha_z * dmp_model.config.beta_z
        scale = np.array([max_translation_m] * 3 + [max_rotation_rad] * 3) * rest_gain
        coupling_gain = builder.AddNamedSystem("coupling_scale", Gain(scale))
        connect(observer.GetOutputPort("observation"), coupling.GetInputPort("observation"))
        connect(coupling.GetOutputPort("residual"), coupling_gain.get_input_port())
        connect(coupling_gain.get_output_port(), dmp_system.GetInputPort("coupling"))
    connect(residual_source, observer.GetInputPort("residual"))

    for name in ("observation", "reward", "success", "force_metrics", "distance_to_goal"):
        builder.ExportOutput(observer.GetOutputPort(name), name)
    builder.ExportOutput(composer.GetOutputPort("X_WE_desired"), "X_WE_desired")
    builder.ExportOutput(extrapolator.GetOutputPort("X_WE_desired"), "X_WE_base")
    builder.ExportOutput(dmp_system.GetOutputPort("phase"), "phase")

    period = config.log_period_s
    logged = {
        "panda_state": plant.get_state_output_port(scene.panda),
        "X_WE_desired": composer.GetOutputPort("X_WE_desired"),
        "X_WE_base": extrapolator.GetOutputPort("X_WE_desired"),
        "residual": residual_source,
        "observation": observer.GetOutputPort("observation"),
        "distance_to_goal": observer.GetOutputPort("distance_to_goal"),
        "force_metrics": observer.GetOutputPort("force_metrics"),
    }
    names = LOGGED_OUTPUTS if config.logged_outputs is None else config.logged_outputs
    logs = (
        {}
        if period is None
        else {name: LogVectorOutput(logged[name], builder, period) for name in names}
    )
    if meshcat is not None:
        from pydrake.multibody.meshcat import ContactVisualizer, ContactVisualizerParams
        from pydrake.visualization import AddDefaultVisualization

        AddDefaultVisualization(builder, meshcat)
        params = ContactVisualizerParams()
        params.force_threshold = 0.5
        ContactVisualizer.AddToBuilder(builder, plant, meshcat, params)

        view_config = view_config if view_config is not None else EpisodeViewConfig()
        # The gap between the two triads is the residual's correction.
        corrected = builder.AddNamedSystem(
            "setpoint_triad",
            SetpointTriad(meshcat, SETPOINT_PATH, view_config.triad_period_s, view_config.setpoint),
        )
        connect(composer.GetOutputPort("X_WE_desired"), corrected.GetInputPort("X_WE"))
        base = builder.AddNamedSystem(
            "dmp_setpoint_triad",
            SetpointTriad(
                meshcat, BASE_SETPOINT_PATH, view_config.triad_period_s, view_config.base_setpoint
            ),
        )
        connect(extrapolator.GetOutputPort("X_WE_desired"), base.GetInputPort("X_WE"))
        X_WGoal_true = GoalPoseInWorld(scene, plant.CreateDefaultContext())
        DrawGoals(meshcat, X_WGoal_nominal, X_WGoal_true, view_config)

    diagram = builder.Build()
    diagram.set_name(f"rlfd_{task.name}")
    return RlfdDiagram(
        diagram=diagram,
        scene=scene,
        task=task,
        config=config,
        dmp=dmp_system,
        extrapolator=extrapolator,
        composer=composer,
        controller=controller,
        observer=observer,
        residual_policy=residual_policy,
        logs=logs,
        coupling_policy=coupling,
        X_WGoal_nominal=X_WGoal_nominal,
        meshcat=meshcat,
        view_config=view_config,
    )


def SetEpisodeStart(
    rlfd: RlfdDiagram,
    context: Context,
    X_WP_start: RigidTransform,
    q_seed: np.ndarray | None = None,
) -> np.ndarray:
    """Puts the arm at rest with the part at ``X_WP_start`` (by IK) and starts the DMP
    there: the DMP generalises from the robot's actual start pose. Returns q (7,).

    If the diagram draws into a Meshcat, the DMP's plan from there is drawn too."""
    scene = rlfd.scene
    q = SolvePandaIK(scene, X_WP_start, q_seed)
    plant_context = scene.plant.GetMyMutableContextFromRoot(context)
    scene.plant.SetPositions(plant_context, scene.panda, q)
    scene.plant.SetVelocities(plant_context, scene.panda, np.zeros(7))
    X_WP = scene.frame_P.CalcPoseInWorld(plant_context)
    dmp_context = rlfd.dmp.GetMyMutableContextFromRoot(context)
    rlfd.dmp.SetStartPose(dmp_context, X_WP.translation(), X_WP.rotation().ToQuaternion().wxyz())
    if rlfd.meshcat is not None:
        DrawDmpPlan(rlfd.meshcat, rlfd.dmp.model, X_WP, rlfd.task.episode_time_s, rlfd.view_config)
    return q


def SetEpisodeFixture(
    rlfd: RlfdDiagram, context: Context, fixture_error: RigidTransform | None
) -> None:
    """Puts the fixture at its nominal pose times ``fixture_error`` (None = no error)
    in ``context`` (a root context of ``rlfd.diagram``): the diagram is built once and
    each episode moves the fixture (and, with a Meshcat, redraws the true goal)."""
    plant_context = rlfd.scene.plant.GetMyMutableContextFromRoot(context)
    SetFixtureError(rlfd.scene, plant_context, fixture_error)
    if rlfd.meshcat is not None:
        X_WGoal_true = GoalPoseInWorld(rlfd.scene, plant_context)
        DrawGoals(rlfd.meshcat, rlfd.X_WGoal_nominal, X_WGoal_true, rlfd.view_config)


def PoseFromOffset(X_WP_nominal: RigidTransform, dp: np.ndarray, dq_wxyz: np.ndarray):
    """The nominal pose moved by a start offset: translation ``dp`` (3,) m in the world
    and rotation ``dq`` (4,) wxyz applied in the world frame about the part origin."""
    from pydrake.common.eigen_geometry import Quaternion
    from pydrake.math import RotationMatrix

    R = RotationMatrix(Quaternion(np.asarray(dq_wxyz, float) / np.linalg.norm(dq_wxyz)))
    return RigidTransform(R @ X_WP_nominal.rotation(), X_WP_nominal.translation() + dp)


def MakeSimulator(rlfd: RlfdDiagram) -> Simulator:
    """A simulator for the diagram (discrete systems only: no integrator tuning)."""
    simulator = Simulator(rlfd.diagram)
    return simulator


@dataclass(frozen=True)
class DiagramStateSnapshot:
    """The time and the state of every stateful subsystem of a diagram's context, by
    subsystem name: discrete state groups (copies) and abstract states (clones, e.g.
    the plant's memory of its last step, which its sampled output ports read)."""

    time_s: float
    states: dict[str, tuple[tuple[np.ndarray, ...], tuple[AbstractValue, ...]]]


def SnapshotDiagramState(rlfd: RlfdDiagram, context: Context) -> DiagramStateSnapshot:
    """Copies the state of ``context`` (a root context of ``rlfd.diagram``)."""
    states = {}
    for system in rlfd.diagram.GetSystems():
        sub = system.GetMyContextFromRoot(context)
        if sub.num_continuous_states():
            raise ValueError(f"system {system.get_name()!r} has continuous state: not snapshotted")
        groups = sub.num_discrete_state_groups()
        abstract = sub.num_abstract_states()
        if groups or abstract:
            states[system.get_name()] = (
                tuple(sub.get_discrete_state(g).get_value().copy() for g in range(groups)),
                tuple(sub.get_abstract_state(a).Clone() for a in range(abstract)),
            )
    return DiagramStateSnapshot(float(context.get_time()), states)


def ResumeFromSnapshot(
    rlfd: RlfdDiagram, simulator: Simulator, snapshot: DiagramStateSnapshot
) -> None:
    """Puts ``simulator`` (of ``rlfd.diagram``, not yet advanced) where ``snapshot``
    was taken, in another diagram built the same way, and initialises it without the
    initialisation events (which would restart the DMP, the controller's filter and
    the observer's peaks): the simulation then goes on bit for bit as the one the
    snapshot was taken from. Parameters are not copied (the geometry is each diagram's
    own): the diagram must have been built from the same task and configuration, and
    its fixture put where the snapshot's was (``SetEpisodeFixture``) beforehand.

    A ``ResidualPolicy`` missing from the snapshot (taken without a policy, or with
    another one) starts from its initial state, its policy reset: right only while
    the policy has not acted yet (before its activation time).

    Raises:
        ValueError: a stateful subsystem other than the residual policy is missing
            from the snapshot, or its state is shaped otherwise.
    """
    context = simulator.get_mutable_context()
    context.SetTime(snapshot.time_s)
    policy_name = None if rlfd.residual_policy is None else rlfd.residual_policy.get_name()
    for system in rlfd.diagram.GetSystems():
        name = system.get_name()
        sub = system.GetMyMutableContextFromRoot(context)
        groups = sub.num_discrete_state_groups()
        abstract = sub.num_abstract_states()
        if not (groups or abstract):
            continue
        if name not in snapshot.states:
            if name == policy_name:
                continue
            raise ValueError(f"the snapshot has no state of subsystem {name!r}")
        values, abstract_values = snapshot.states[name]
        shapes = [sub.get_discrete_state(g).size() for g in range(groups)]
        if shapes != [v.size for v in values] or abstract != len(abstract_values):
            raise ValueError(
                f"subsystem {name!r}: state of sizes {shapes} and {abstract} abstract, "
                f"snapshot of sizes {[v.size for v in values]} and {len(abstract_values)}"
            )
        for g, value in enumerate(values):
            sub.SetDiscreteState(g, value)
        for a, value in enumerate(abstract_values):
            sub.get_mutable_abstract_state(a).SetFrom(value)
    if rlfd.residual_policy is not None:
        rlfd.residual_policy.ResetPolicy()
    simulator.Initialize(InitializeParams(suppress_initialization_events=True))
