"""The rLfD insertion tasks as Gymnasium environments, on ``pydrake.gym.DrakeGymEnv``.

``DrakeGymEnv`` (Drake 1.51) has defects that this subclass fixes, each covered by a
test in ``tests/test_env.py``:

* a user ``info_handler`` is silently dropped (``if info_handler is
  callable(info_handler)`` is always False for a function): we keep it;
* ``reset(options=...)`` is refused by an assertion: we accept the options below;
* ``render_mode="ansi"`` is declared as ``"ascii"`` in ``metadata``: we declare and
  implement ``"ansi"``;
* ``reset()`` runs ``Simulator.Initialize()`` *before* the reset handler sets the
  state, so initialisation events see the default state: we set the state first;
* a solver failure in ``step()`` returns an empty ``info``: we say why in it.

All the environments are registered here, in one place (see ``ENV_IDS``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from pydrake.gym import DrakeGymEnv
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context

from rlfd_drake.control_math import PEAK_FORCE_SIGNALS, pad_residual_part
from rlfd_drake.diagram import (
    RESIDUAL_SIZE,
    BuildRlfdDiagram,
    NominalGoal,
    PoseFromOffset,
    RlfdDiagram,
    RlfdDiagramConfig,
    SetEpisodeFixture,
    SetEpisodeStart,
)
from rlfd_drake.episode import demo_start_pose, load_task_dmp
from rlfd_drake.geometry import quat_from_rotation_vector, rotation_vector_from_quat
from rlfd_drake.scene import FixtureErrorTransform, GoalPoseInWorld
from rlfd_drake.systems.observer import OBSERVATION_SIZE
from rlfd_drake.tasks import TaskSpec, load_task, sample_fixture_error, sample_start_offset

#: Gymnasium ids -> task names. Registered by :func:`register_envs`.
ENV_IDS: dict[str, str] = {
    "rlfd/PegInsertion-v0": "peg_easy",
    "rlfd/PegInsertionHard-v0": "peg_hard",
    "rlfd/Peg28mm-v0": "peg",
    "rlfd/GearInsertion-v0": "gear",
    "rlfd/RJ45Insertion-v0": "rj45",
}

#: Keys ``reset(options=...)`` accepts.
RESET_OPTIONS = ("start_dp", "start_dq", "fixture_dp", "fixture_dq", "perturbation_scale")

#: Entries of :meth:`RlfdEnv.privileged_state`: what the simulator knows and the policy
#: does not, for a learner's critic (``PrivilegedObservation``).
PRIVILEGED_SIZE = 12
#: Units of those entries (one unit each), chosen as ``observation_scaling``'s so that
#: what matters in contact is of order one: the part's position from the true goal in
#: the goal's frame (4 mm across, 2 cm along the insertion axis), its orientation
#: error (rotation vector in the goal's frame, 0.05 rad), the fixture's calibration
#: error (position 1 mm, rotation vector 1 deg).
PRIVILEGED_UNITS = np.array([0.004, 0.004, 0.02] + [0.05] * 3 + [0.001] * 3 + [np.radians(1.0)] * 3)

# The pure-RL baseline's dense reward (paper Sec. V-C): alpha, beta, eps.
DENSE_ALPHA, DENSE_BETA, DENSE_EPS = 10.0, 0.002, 1e-4
# The distance that one unit of the distance-shaping potential stands for.
SHAPING_DISTANCE_UNIT_M = 0.01
# "all": the three position errors; "lateral": the two across the insertion axis (the
# true goal frame's x and y), so that lifting to slide sideways costs nothing;
# "lateral_depth": those and the depth still to go once inside the fixture (the axial
# error capped at the fixture's depth), so that the last millimetres pay too.
SHAPING_AXES = ("all", "lateral", "lateral_depth")


@dataclass(frozen=True)
class EpisodeSetup:
    """What ``reset`` sampled: start offset (dp (3,) m, dq (4,) wxyz, world) from the
    demonstration's start, and fixture calibration error (dp (3,) m, dq (4,) wxyz)."""

    start_dp: np.ndarray
    start_dq: np.ndarray
    fixture_dp: np.ndarray
    fixture_dq: np.ndarray


def _vector_option(options: dict, key: str, size: int, default: np.ndarray) -> np.ndarray:
    if key not in options:
        return default
    value = np.asarray(options[key], dtype=float)
    if value.shape != (size,) or not np.all(np.isfinite(value)):
        raise ValueError(f"reset option {key} must be {size} finite numbers, got {options[key]!r}")
    if size == 4:
        norm = np.linalg.norm(value)
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"reset option {key} must be a unit quaternion, got norm {norm}")
    return value


def _check_non_negative(value: float, name: str) -> None:
    if not (isinstance(value, int | float) and np.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a number >= 0, got {value!r}")


# Where each of PEAK_FORCE_SIGNALS sits in the observer's force_metrics port.
_FORCE_METRICS_INDEX = {"low_passed": 3, "one_step": 0}


def check_reward_terms(
    force_limit_penalty: float,
    peak_force_cost: float,
    peak_force_threshold_n: float | None,
    action_cost: float = 0.0,
    peak_force_signal: str = "low_passed",
    distance_shaping: float = 0.0,
    discount: float = 0.99,
    distance_shaping_axes: str = "all",
) -> None:
    """Raises a ValueError naming the field unless the reward's extra terms are valid:
    ``force_limit_penalty``, ``peak_force_cost``, ``action_cost`` and
    ``distance_shaping`` >= 0, ``discount`` in (0, 1], ``distance_shaping_axes`` in
    ``SHAPING_AXES`` (other than "all" only with shaping), a peak
    force cost with a threshold > 0 (a threshold without a cost is refused too: it
    would do nothing) and ``peak_force_signal`` in ``PEAK_FORCE_SIGNALS``."""
    if peak_force_signal not in PEAK_FORCE_SIGNALS:
        raise ValueError(
            f"peak_force_signal must be one of {PEAK_FORCE_SIGNALS}, got {peak_force_signal!r}"
        )
    _check_non_negative(force_limit_penalty, "force_limit_penalty")
    _check_non_negative(action_cost, "action_cost")
    _check_non_negative(distance_shaping, "distance_shaping")
    if not (isinstance(discount, int | float) and 0.0 < discount <= 1.0):
        raise ValueError(f"discount must be a number in (0, 1], got {discount!r}")
    if distance_shaping_axes not in SHAPING_AXES:
        raise ValueError(
            f"distance_shaping_axes must be one of {SHAPING_AXES}, got {distance_shaping_axes!r}"
        )
    if distance_shaping_axes != "all" and distance_shaping == 0:
        raise ValueError(
            f"distance_shaping_axes {distance_shaping_axes!r} needs distance_shaping > 0"
        )
    _check_non_negative(peak_force_cost, "peak_force_cost")
    cost, threshold_n = peak_force_cost, peak_force_threshold_n
    if cost > 0 and threshold_n is None:
        raise ValueError(f"peak_force_cost {cost} needs peak_force_threshold_n")
    if threshold_n is not None:
        if cost == 0:
            raise ValueError(f"peak_force_threshold_n {threshold_n} needs peak_force_cost > 0")
        finite = isinstance(threshold_n, int | float) and np.isfinite(threshold_n)
        if not (finite and threshold_n > 0):
            raise ValueError(f"peak_force_threshold_n must be a number > 0, got {threshold_n!r}")


class RlfdEnv(DrakeGymEnv):
    """Residual Learning from Demonstration on one insertion task.

    A DMP fitted on the task's single demonstration drives a simulated Franka Panda
    (Cartesian impedance control at 500 Hz, hydroelastic contact) towards the
    demonstrated goal. The agent outputs a residual that corrects the DMP's set-point in
    task space, at 10 Hz, in the second half of each episode.

    ## Action Space
    ``Box(-1, 1, (6,), float32)``: the residual ``[dp (3), r (3)]``. ``dp`` is scaled to
    ``max_translation_m`` (1 cm) and added to the DMP position; ``r`` is an angle-axis
    vector scaled to ``max_rotation_rad`` (5 deg), ``Q_delta = [cos(a/2), r/|r|
    sin(a/2)]`` composed as ``Q_f = Q_delta o Q_b``. ``residual_mode`` may restrict it to
    translation or orientation. The action is held for one step (the task's
    ``residual_period_s``: 0.1 s, 10 Hz).

    ## Observation Space
    ``Box(-inf, inf, (26,), float32)`` (see ``systems/observer.py``): part position
    relative to the *demonstrated* goal (/2 cm), orientation error (rad), twist,
    wrist force/torque, DMP phase, normalised time, last residual. The true fixture
    pose is not observed.

    ## Rewards
    ``reward="sparse"`` (default, the paper's): ``1[L2 <= kappa]`` with L2 the distance
    of the part frame to its fully inserted pose (and, for tasks with ``kappa_deg``
    such as RJ-45, its orientation within ``kappa_deg``). ``reward="dense"`` (pure-RL baseline):
    ``-alpha L1 + beta / (L2 + eps)`` with alpha=10, beta=0.002, eps=1e-4; the paper
    prints ``-(alpha L1 + beta/(L2 - eps))``, which would penalise getting close; we
    read it as a sign typo and say so.

    ## Starting State
    ``reset`` samples, with the env's seed, the start offset from the task's start
    distribution (scaled by ``perturbation_scale``, for curricula) and the fixture's
    calibration error; rebuilds the diagram with the fixture at its true pose; puts the
    arm at the start by IK; and runs the DMP alone until the residual's activation time
    (5 s), so the agent only sees the steps where it acts. ``options`` may fix any of
    ``start_dp``, ``start_dq``, ``fixture_dp``, ``fixture_dq``, ``perturbation_scale``.

    ## Episode End
    Terminated on success (part within kappa) or when the task's force limit is broken
    (failure, ``info["force_limit_broken"]``; the step's reward is then
    ``-force_limit_penalty``, 0 by default as in the paper's sparse reward, which cannot
    tell a broken part from a timeout); truncated at the episode time (10 s) or
    when the contact solver fails (``info["failure_reason"]`` says why).

    ## Arguments
    ``task`` (name or TaskSpec), ``reward`` ("sparse" | "dense"), ``residual_mode``
    ("full" | "translation" | "orientation"), ``perturbation_scale`` (0..1),
    ``composition`` ("residual": rLfD; "hybrid" or "pure": the action is a velocity
    command that moves the set-point, from the DMP's pose at the activation time or
    from the start with no DMP: the paper's Table III baselines; "pure" acts for the
    whole 10 s), ``force_limit_penalty`` (>= 0: subtracted from the reward of the step
    that breaks the force limit), ``peak_force_cost`` and ``peak_force_threshold_n``
    (a step's reward loses ``cost * (e_t - e_(t-1))``, where ``e = max(0, F / threshold
    - 1)`` and F is the peak contact force so far: an episode pays ``cost`` per
    threshold of peak force above the threshold that its residual steps added; 0 by
    default, the paper's reward), ``peak_force_signal`` ("low_passed": F is the 20 ms
    low-passed force, as force limits; "one_step": the 2 ms samples), ``action_cost``
    (a step's reward loses ``action_cost`` times the mean square of its clipped action:
    a residual that is not needed costs; 0 by default, the paper's reward),
    ``distance_shaping`` and ``discount`` (potential-based shaping, Ng, Harada and
    Russell 1999: a step's reward gains ``discount * phi(s') - phi(s)`` with
    ``phi = -distance_shaping * L1 / 1 cm``, L1 the sum of the part's absolute position
    errors from the true goal; it tells the learner which way the goal lies, and over
    an episode it sums to ``discount**T * phi(s_T) - phi(s_0)``: where episodes end at
    the goal (success, phi ~ 0) or run out of time (bootstrapped) the optimal policies
    stay the paper's; an episode that breaks the force limit keeps the potential where
    it broke, i.e. also pays for the distance it had left. Unlike the dense reward,
    whose per-step bonus near the goal outweighs ending the episode by inserting.
    ``discount`` must be the learner's; 0 by default, the paper's sparse reward;
    ``distance_shaping_axes`` "lateral" counts only the errors across the insertion
    axis, in the true goal's frame, "lateral_depth" those and the axial error capped
    at the fixture's depth),
    ``diagram_config`` (RlfdDiagramConfig),
    ``render_mode`` (None | "ansi" | "human": Meshcat), ``info_handler``
    (callable(simulator) -> dict merged into ``info``).
    """

    metadata = {"render_modes": ["ansi", "human"], "render_fps": 10}

    def __init__(
        self,
        task: str | TaskSpec = "peg_easy",
        reward: str = "sparse",
        residual_mode: str = "full",
        perturbation_scale: float = 1.0,
        diagram_config: RlfdDiagramConfig | None = None,
        render_mode: str | None = None,
        info_handler=None,
        composition: str = "residual",
        force_limit_penalty: float = 0.0,
        peak_force_cost: float = 0.0,
        peak_force_threshold_n: float | None = None,
        action_cost: float = 0.0,
        peak_force_signal: str = "low_passed",
        distance_shaping: float = 0.0,
        discount: float = 0.99,
        distance_shaping_axes: str = "all",
    ) -> None:
        self._init_args = dict(
            task=task,
            reward=reward,
            residual_mode=residual_mode,
            composition=composition,
            force_limit_penalty=force_limit_penalty,
            peak_force_cost=peak_force_cost,
            peak_force_threshold_n=peak_force_threshold_n,
            action_cost=action_cost,
            peak_force_signal=peak_force_signal,
            distance_shaping=distance_shaping,
            discount=discount,
            distance_shaping_axes=distance_shaping_axes,
            perturbation_scale=perturbation_scale,
            diagram_config=diagram_config,
            render_mode=render_mode,
            info_handler=info_handler,
        )
        self.task = task if isinstance(task, TaskSpec) else load_task(task)
        if reward not in ("sparse", "dense"):
            raise ValueError(f"reward must be 'sparse' or 'dense', got {reward!r}")
        if render_mode not in (None, "ansi", "human"):
            raise ValueError(f"render_mode must be None, 'ansi' or 'human', got {render_mode!r}")
        if info_handler is not None and not callable(info_handler):
            raise ValueError("info_handler must be callable(simulator) -> dict")
        check_reward_terms(
            force_limit_penalty,
            peak_force_cost,
            peak_force_threshold_n,
            action_cost,
            peak_force_signal,
            distance_shaping,
            discount,
            distance_shaping_axes,
        )
        self.distance_shaping = float(distance_shaping)
        self.distance_shaping_axes = distance_shaping_axes
        self.discount = float(discount)
        self._potential = 0.0
        self.peak_force_signal = peak_force_signal
        self.action_cost = float(action_cost)
        self.reward_kind = reward
        self.force_limit_penalty = float(force_limit_penalty)
        self.peak_force_cost = float(peak_force_cost)
        self.peak_force_threshold_n = (
            None if peak_force_threshold_n is None else float(peak_force_threshold_n)
        )
        self._peak_force_excess = 0.0
        self.set_perturbation_scale(perturbation_scale)
        config = diagram_config if diagram_config is not None else RlfdDiagramConfig()
        if residual_mode not in ("full", "translation", "orientation"):
            raise ValueError(
                f"residual_mode must be full, translation or orientation, got {residual_mode!r}"
            )
        # No episode logs: the env reads ports, and the loggers cost time every step.
        self.diagram_config = RlfdDiagramConfig(
            **{
                **config.__dict__,
                "residual_mode": residual_mode,
                "composition": composition,
                "log_period_s": None,
                # Resolved, so that time_step and the readers of diagram_config see it.
                "residual_period_s": config.residual_period_for(self.task),
            }
        )
        self.dmp_model = load_task_dmp(self.task)
        self._X_WP_demo_start = demo_start_pose(self.dmp_model)
        self._X_WGoal_nominal = NominalGoal(self.task)
        self._meshcat = None
        # DrakeGymEnv writes "ascii" into self.metadata: give it an instance copy so the
        # class attribute stays right.
        self.metadata = {
            **type(self).metadata,
            "render_modes": list(type(self).metadata["render_modes"]),
        }
        super().__init__(
            simulator=self._make_simulator,
            time_step=self.diagram_config.residual_period_s,
            action_space=gym.spaces.Box(-1.0, 1.0, (RESIDUAL_SIZE,), np.float32),
            observation_space=gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32),
            reward="reward",
            action_port_id="residual",
            observation_port_id="observation",
            render_mode=render_mode if render_mode is not None else "ansi",
        )
        # Fixes: DrakeGymEnv drops a callable info_handler, and says "ascii" for "ansi".
        self.user_info_handler = info_handler
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_modes": ["ansi", "human"]}
        self.rlfd: RlfdDiagram | None = None
        self.setup: EpisodeSetup | None = None
        self._last_observation = np.zeros(OBSERVATION_SIZE, np.float32)

    # -- pickling (SubprocVecEnv, deepcopy): rebuild from the constructor arguments --
    def __getstate__(self) -> dict:
        return {"init_args": self._init_args}

    def __setstate__(self, state: dict) -> None:
        self.__init__(**state["init_args"])

    def set_perturbation_scale(self, scale: float) -> None:
        """Scales the start offsets (curriculum), in [0, 1]."""
        if not (np.isfinite(scale) and 0.0 <= scale <= 1.0):
            raise ValueError(f"perturbation_scale must be in [0, 1], got {scale}")
        self.perturbation_scale = float(scale)

    def _make_simulator(self, _generator=None) -> Simulator:
        setup = self.setup
        if self.render_mode == "human" and self._meshcat is None:
            from pydrake.geometry import StartMeshcat

            self._meshcat = StartMeshcat()
        if self.rlfd is None:
            # Built once, the fixture moved per episode: pydrake never frees a diagram
            # holding a Python system (results/probes/memory_per_episode.md).
            self.rlfd = BuildRlfdDiagram(
                self.task, self.dmp_model, self.diagram_config, meshcat=self._meshcat
            )
        simulator = Simulator(self.rlfd.diagram)
        fixture_error = FixtureErrorTransform(setup.fixture_dp, setup.fixture_dq)
        SetEpisodeFixture(self.rlfd, simulator.get_mutable_context(), fixture_error)
        return simulator

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        gym.Env.reset(self, seed=seed)
        options = {} if options is None else dict(options)
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; known: {list(RESET_OPTIONS)}")
        if "perturbation_scale" in options:
            self.set_perturbation_scale(float(options["perturbation_scale"]))
        rng = self.np_random
        dp, dq = sample_start_offset(self.task, rng)
        dp = dp * self.perturbation_scale
        # Scale the rotation angle too, about the same axis.
        dq = quat_from_rotation_vector(rotation_vector_from_quat(dq) * self.perturbation_scale)
        fixture_dp, fixture_dq = sample_fixture_error(self.task, rng)
        self.setup = EpisodeSetup(
            start_dp=_vector_option(options, "start_dp", 3, dp),
            start_dq=_vector_option(options, "start_dq", 4, dq),
            fixture_dp=_vector_option(options, "fixture_dp", 3, fixture_dp),
            fixture_dq=_vector_option(options, "fixture_dq", 4, fixture_dq),
        )
        self.simulator = self._make_simulator()
        self._setup()
        context = self.simulator.get_mutable_context()
        context.SetTime(0.0)
        X_WP_start = PoseFromOffset(self._X_WP_demo_start, self.setup.start_dp, self.setup.start_dq)
        self._failure_reason = None
        self._force_limit_broken = False
        self._succeeded = False
        try:
            SetEpisodeStart(self.rlfd, context, X_WP_start)
        except RuntimeError as error:
            # An unreachable start is a bad sample, not a crash: say so clearly.
            raise ValueError(f"start pose not reachable by the Panda: {error}") from error
        self.action_port.FixValue(context, np.zeros(RESIDUAL_SIZE))
        self.simulator.Initialize()
        activation = self.rlfd.composer.config.activation_time_s
        try:
            self.simulator.AdvanceTo(activation)
        except RuntimeError as error:
            self._failure_reason = f"solver: {error.args[0] if error.args else error}"
        observation = self._observe()
        self._succeeded = self._failure_reason is None and self._inserted()
        # The DMP's approach before the residual acts is not charged to it.
        self._peak_force_excess = self._excess_peak_force(self._peak_force(self.peak_force_signal))
        self._potential = self._distance_potential()
        return observation, self._info()

    def _observe(self) -> np.ndarray:
        value = self.observation_port.Eval(self.simulator.get_context())
        self._last_observation = np.asarray(value, dtype=np.float32)
        return self._last_observation

    def _peak_force(self, signal: str) -> float:
        """The peak so far of one of PEAK_FORCE_SIGNALS, N ("low_passed": what limits
        check; the cost charges ``self.peak_force_signal``)."""
        return float(self._port("force_metrics")[_FORCE_METRICS_INDEX[signal]])

    def _excess_peak_force(self, peak_n: float) -> float:
        """max(0, peak_n / peak_force_threshold_n - 1); 0 without a threshold."""
        if self.peak_force_threshold_n is None:
            return 0.0
        return max(0.0, peak_n / self.peak_force_threshold_n - 1.0)

    def _port(self, name: str) -> np.ndarray:
        return self.rlfd.diagram.GetOutputPort(name).Eval(self.simulator.get_context())

    def _info(self) -> dict[str, Any]:
        forces = self._port("force_metrics")
        info = {
            "success": self._succeeded,
            "distance_to_goal_m": float(self._port("distance_to_goal")[0]),
            "peak_force_n": float(forces[0]),
            "mean_force_n": float(forces[1]),
            "force_limit_broken": self._force_limit_broken,
            "failure_reason": self._failure_reason,
            "time_s": float(self.simulator.get_context().get_time()),
            "start_dp": self.setup.start_dp.copy(),
            "start_dq": self.setup.start_dq.copy(),
            "fixture_dp": self.setup.fixture_dp.copy(),
            "fixture_dq": self.setup.fixture_dq.copy(),
        }
        if info["success"]:
            info["insertion_time_s"] = info["time_s"]
        if self.user_info_handler is not None:
            info.update(self.user_info_handler(self.simulator))
        return info

    def step(self, action):
        action = np.asarray(action, dtype=float).reshape(-1)
        if action.shape != (RESIDUAL_SIZE,) or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be {RESIDUAL_SIZE} finite numbers, got {action!r}")
        if self._failure_reason is not None:
            raise RuntimeError("step() after a solver failure: call reset()")
        context = self.simulator.get_mutable_context()
        action = np.clip(action, -1.0, 1.0)
        self.action_port.FixValue(context, action)
        try:
            self.simulator.AdvanceTo(context.get_time() + self.time_step)
        except RuntimeError as error:
            self._failure_reason = f"solver: {error.args[0] if error.args else error}"
            return self._last_observation, 0.0, False, True, self._info()
        observation = self._observe()
        success = self._inserted()
        self._succeeded = self._succeeded or success
        if self.reward_kind == "sparse":
            reward = 1.0 if success else 0.0
        else:
            error, _ = self._part_error()
            l1 = float(np.sum(np.abs(error)))
            reward = -DENSE_ALPHA * l1 + DENSE_BETA / (float(np.linalg.norm(error)) + DENSE_EPS)
        if self.action_cost > 0.0:
            reward -= self.action_cost * float(np.mean(np.square(action)))
        if self.distance_shaping > 0.0:
            # A terminal state keeps its potential (not the textbook 0): a part that
            # breaks the limit far from the goal must not score as if it had arrived.
            potential = self._distance_potential()
            reward += self.discount * potential - self._potential
            self._potential = potential
        # Force limits apply to the low-passed contact force (ObserverConfig).
        peak_n = self._peak_force("low_passed")
        if self.peak_force_cost > 0.0:
            excess = self._excess_peak_force(self._peak_force(self.peak_force_signal))
            reward -= self.peak_force_cost * (excess - self._peak_force_excess)
            self._peak_force_excess = excess
        limit = self.task.force_limit_n
        if limit is not None and peak_n > limit:
            if not self._force_limit_broken:
                reward -= self.force_limit_penalty
            self._force_limit_broken = True
        terminated = success or self._force_limit_broken
        truncated = (not terminated) and context.get_time() >= self.task.episode_time_s - 1e-9
        return observation, reward, terminated, truncated, self._info()

    def _distance_potential(self) -> float:
        """phi(s) = -distance_shaping * L1(part position error) / 1 cm, over the axes
        ``distance_shaping_axes`` names; 0 unshaped."""
        if self.distance_shaping == 0.0:
            return 0.0
        error, _ = self._part_error()
        if self.distance_shaping_axes != "all":
            error_goal = self._true_goal().rotation().inverse() @ error
            error = error_goal[:2]
            if self.distance_shaping_axes == "lateral_depth":
                depth = min(abs(float(error_goal[2])), self.task.fixture.depth_m)
                error = np.append(error, depth)
        l1_units = float(np.sum(np.abs(error))) / SHAPING_DISTANCE_UNIT_M
        return -self.distance_shaping * l1_units

    def _plant_context(self) -> Context:
        return self.rlfd.scene.plant.GetMyContextFromRoot(self.simulator.get_context())

    def _true_goal(self) -> RigidTransform:
        """X_WGoal_true: the goal on the fixture where this episode put it."""
        return GoalPoseInWorld(self.rlfd.scene, self._plant_context())

    def _part_error(self) -> tuple[np.ndarray, float]:
        """(p_WP - p_WGoal_true (3,) m, angle between R_WP and R_WGoal_true in deg)."""
        X_WP = self.rlfd.scene.frame_P.CalcPoseInWorld(self._plant_context())
        X_WGoal = self._true_goal()
        angle = X_WGoal.rotation().InvertAndCompose(X_WP.rotation()).ToAngleAxis().angle()
        return X_WP.translation() - X_WGoal.translation(), float(np.degrees(angle))

    def privileged_state(self) -> np.ndarray:
        """(PRIVILEGED_SIZE,) float32 in ``PRIVILEGED_UNITS``: the part's pose relative to
        the fixture's *true* goal, in the goal's frame, and the fixture's calibration
        error of this episode. Not part of the observation (the paper's policy does not
        know the fixture's error); for a critic trained in simulation only."""
        X_WP = self.rlfd.scene.frame_P.CalcPoseInWorld(self._plant_context())
        X_GoalP = self._true_goal().InvertAndCompose(X_WP)
        state = np.concatenate(
            [
                X_GoalP.translation(),
                rotation_vector_from_quat(X_GoalP.rotation().ToQuaternion().wxyz()),
                self.setup.fixture_dp,
                rotation_vector_from_quat(self.setup.fixture_dq),
            ]
        )
        return (state / PRIVILEGED_UNITS).astype(np.float32)

    def _inserted(self) -> bool:
        """Within kappa of the goal, and within kappa_deg of its orientation when the
        task asks for it (RJ-45: a plug upside down is not inserted)."""
        error, angle_deg = self._part_error()
        if float(np.linalg.norm(error)) > self.task.kappa_m:
            return False
        return self.task.kappa_deg is None or angle_deg <= self.task.kappa_deg

    def render(self):
        if self.render_mode == "ansi":
            if self.rlfd is None:
                return "RlfdEnv (not reset)"
            info = self._info()
            return (
                f"{self.task.name} t={info['time_s']:.2f}s "
                f"distance={info['distance_to_goal_m'] * 1000:.1f}mm "
                f"peak_force={info['peak_force_n']:.1f}N success={info['success']}"
            )
        if self.render_mode == "human":
            self.simulator.get_system().ForcedPublish(self.simulator.get_context())
            return None
        return None


class AppliedResidualAction(gym.ActionWrapper):
    """An RlfdEnv whose action is only the part of the residual ``residual_mode``
    applies: 3-D (translation, or angle-axis orientation, in [-1, 1]), the other part
    zero (``control_math.pad_residual_part``). A policy trained on it has no outputs
    that do nothing; on the 6-D action of a translation-only env the three orientation
    outputs are ignored by the composer, yet the critic must learn to ignore them and
    SAC's entropy tuning counts them. ``policies.DeployedPolicy`` pads such a policy's
    action the same way in the diagram."""

    def __init__(self, env: gym.Env, residual_mode: str):
        pad_residual_part(np.zeros(3), residual_mode)  # ValueError naming a bad mode
        super().__init__(env)
        self.residual_mode = residual_mode
        self.action_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)

    def action(self, action: np.ndarray) -> np.ndarray:
        return pad_residual_part(action, self.residual_mode).astype(np.float32)


class TimeLimitAsTerminal(gym.Wrapper):
    """Reports the end of an episode's time as a terminal state, for learners.

    The observation carries the DMP phase and the time, so the task is a finite-horizon
    one whose end is part of it (Pardo et al., "Time Limits in Reinforcement Learning",
    ICML 2018). Left as a truncation, Stable-Baselines3 bootstraps the last step from
    the critic's value of the next state, as if the episode went on: a residual that
    holds the part just short of the goal (or lifts it off the fixture) until the time
    runs out then scores what the critic guesses for states near the goal, without the
    force-limit penalty that pushing on risks. As terminal, waiting scores 0. A success
    or a break is terminal either way; the env's own semantics are unchanged."""

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return observation, reward, terminated or truncated, False, info


class PrivilegedObservation(gym.Wrapper):
    """An RlfdEnv whose observation has ``privileged_state()`` appended (26 + 12): an
    asymmetric actor-critic's input (Pinto et al., "Asymmetric Actor Critic for
    Image-Based Robot Learning", RSS 2018), whose critic reads the true state in
    simulation while its actor reads only the first 26 entries, so that the trained
    actor runs on the robot's observation alone (``privileged_critic``). Outermost:
    the wrappers inside it (a base correction's rule) see the plain observation."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        size = int(env.observation_space.shape[0])
        self.observation_space = gym.spaces.Box(
            -np.inf, np.inf, (size + PRIVILEGED_SIZE,), np.float32
        )

    def _with_privileged(self, observation: np.ndarray) -> np.ndarray:
        privileged = self.env.unwrapped.privileged_state()
        return np.concatenate([np.asarray(observation, np.float32), privileged])

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        return self._with_privileged(observation), info

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return self._with_privileged(observation), reward, terminated, truncated, info


def register_envs() -> None:
    """Registers every id of ``ENV_IDS`` with Gymnasium (idempotent)."""
    for env_id, task_name in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=RlfdEnv, kwargs={"task": task_name})


register_envs()
