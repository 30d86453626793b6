"""Training residual policies with Stable-Baselines3 / sb3-contrib (no hand-written RL).

A run folder holds everything needed to understand and resume a run:

    runs/<name>/config.json    the TrainConfig and the exact command
    runs/<name>/checkpoints/   periodic checkpoints (resume from the newest)
    runs/<name>/tb/            TensorBoard curves
    runs/<name>/episodes.csv   one line per training episode (success, return, length)
    runs/<name>/eval/          periodic evaluation (EvalCallback)
    runs/<name>/policy.zip     the final policy (SB3 format)
    runs/<name>/metrics.json   episodes, steps, wall-clock time (of the last process, if
                               resumed: resumed_at_episode says so), success over training

Residual policies start at zero output (the last layer of the actor's mean is zero),
so an untrained residual is the DMP alone.
"""

from __future__ import annotations

import csv
import json
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import (
    BaseCallback,
    CallbackList,
    CheckpointCallback,
    EvalCallback,
    EventCallback,
)
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack

from rlfd_drake.base_correction import (
    BASE_CORRECTIONS,
    BaseCorrectedAction,
    applied_residual_mode,
    check_base_correction,
)
from rlfd_drake.control_math import RESIDUAL_PARTS
from rlfd_drake.diagram import COMPOSITIONS
from rlfd_drake.env import (
    ENV_IDS,
    PRIVILEGED_SIZE,
    AppliedResidualAction,
    PrivilegedObservation,
    RlfdEnv,
    TimeLimitAsTerminal,
    check_reward_terms,
)
from rlfd_drake.mirror_symmetry import (
    MirrorSymmetricPolicy,
    action_mirror_signs,
    check_mirror_symmetric_task,
    observation_mirror_signs,
)
from rlfd_drake.observation_scaling import (
    CONTACT_SCALES,
    CONTACT_TORQUE_PER_UNIT_NM,
    ScaledObservation,
    check_hidden_entries,
    contact_scales,
)
from rlfd_drake.policies import checkpoint_steps, load_sb3_model, policy_file
from rlfd_drake.privileged_critic import PrivilegedCriticPolicy
from rlfd_drake.results import format_json, invoked_command, utc_now
from rlfd_drake.run_log import read_episode_rows, training_success_rates
from rlfd_drake.self_imitation import SelfImitation
from rlfd_drake.systems.observer import OBSERVATION_WRIST_TORQUE
from rlfd_drake.tasks import load_task

ALGORITHMS = ("ppo", "sac", "recurrent_ppo")
# Every algorithm's discount factor; the distance shaping must use the same one.
DISCOUNT = 0.99
LEARNING_RATE_SCHEDULES = ("constant", "linear")
#: PPO's and recurrent PPO's rollout steps per env between updates, unless a run sets them.
PPO_N_STEPS = 256
#: PPO's and recurrent PPO's GAE lambda (SB3's default), unless a run sets it.
PPO_GAE_LAMBDA = 0.95
#: PPO's and recurrent PPO's passes over each rollout (SB3's default), unless a run sets them.
PPO_EPOCHS = 10
#: PPO's and recurrent PPO's hidden layer widths, actor and critic each (SB3's default).
PPO_HIDDEN_LAYERS = (64, 64)


@dataclass
class EpisodeProgress:
    """Finished training episodes of a run and its budget (``EpisodeLog`` counts)."""

    done: int
    total: int

    def fraction(self) -> float:
        """``done / total`` within [0, 1] (the last rollout may run past the budget)."""
        return min(1.0, max(0.0, self.done / max(1, self.total)))


@dataclass(frozen=True)
class LinearDecayOverEpisodes:
    """An SB3 learning-rate schedule: ``initial * (1 - done / total)``, floored at 0.

    SB3 passes the fraction of its step budget remaining; ours is an upper bound (an
    episode ends early on success), so that fraction never reaches 0. This reads the
    finished episodes instead and ignores SB3's argument."""

    initial: float
    progress: EpisodeProgress

    def __call__(self, _progress_remaining: float) -> float:
        return float(self.initial * (1.0 - self.progress.fraction()))


class ExplorationNoiseSchedule(BaseCallback):
    """Holds a PPO policy's log std at ``initial + (final - initial) * done / total``
    (finished episodes, floored and capped) instead of learning it: set before every
    rollout, so a rollout and the update that learns from it share one value."""

    def __init__(self, initial: float, final: float, progress: EpisodeProgress):
        super().__init__()
        self.initial = initial
        self.final = final
        self.progress = progress

    def value(self) -> float:
        return float(self.initial + (self.final - self.initial) * self.progress.fraction())

    def _init_callback(self) -> None:
        # Out of the optimiser's reach: no gradient, so Adam leaves it alone.
        self.model.policy.log_std.requires_grad_(False)
        self._on_rollout_start()

    def _on_rollout_start(self) -> None:
        with torch.no_grad():
            self.model.policy.log_std.fill_(self.value())

    def _on_step(self) -> bool:
        return True


@dataclass(frozen=True)
class TrainConfig:
    """One training run.

    Attributes:
        task: task name (see ``rlfd tasks``) or the path of a task YAML file (a
            variant, e.g. ``models/tasks/variants/gear_rot2deg.yaml``).
        algo: "ppo", "sac" (history-stacked observations) or "recurrent_ppo" (LSTM).
        episodes: training episodes (each up to 50 residual steps of 0.1 s).
        seed: seed of the policy, the envs and the episode sampling.
        envs: parallel environments (processes when > 1).
        residual_mode: "full", "translation" or "orientation".
        reward: "sparse" (the paper's) or "dense" (pure-RL baseline).
        curriculum: grow the start perturbation from ``curriculum_start`` to 1 over the
            first half of training (PPO's physical-robot recipe in the paper).
        curriculum_start: initial perturbation scale.
        history: observations stacked for SAC (the paper's SAC needs memory).
        eval_every_episodes: periodic evaluation interval in finished episodes (0 = off);
            the best evaluated policy is kept as ``eval/best_model.zip``.
        eval_episodes: episodes per periodic evaluation (mean action).
        checkpoint_every_episodes: checkpoint interval in finished episodes.
        log_std_init: initial log std of the policy's Gaussian (exploration size; for
            SAC before its tanh squashing): small, so early exploration is a gentle
            jiggle around the DMP rather than uniform noise over the residual's range.
        log_std_final: PPO and recurrent PPO only: None (default) = the log std is a
            learned parameter, as in SB3; a number = it is no longer learned but falls
            linearly over the run's finished episodes from ``log_std_init`` to this,
            so the noise the last updates train under is closer to the mean action the
            policy is evaluated with (the peg policies' own log std barely moved from
            -2, and their sampled actions insert far fewer starts than their mean).
        learning_rate: optimiser step size.
        learning_rate_schedule: "constant" (SB3's default), or "linear": the step
            size falls linearly from ``learning_rate`` to 0 over the run's own
            ``episodes`` (counted in finished episodes, since the step budget given to
            SB3 is only an upper bound), so the last updates barely move the policy
            that is saved (PPO's last iterate lost up to 8 points of training success
            at the end of the peg runs with a constant step).
        ppo_n_steps: PPO rollout length per env between updates.
        ppo_gae_lambda: PPO's generalised advantage estimation lambda, in (0, 1]:
            how many steps of real returns an advantage weighs before it leans on the
            critic (about 1 / (1 - gamma * lambda) steps; 1 = Monte Carlo returns).
        ppo_epochs: PPO's passes over each rollout's data per update (minibatches of 64).
        ppo_hidden_layers: PPO's hidden layer widths, the critic's and, unless
            ``ppo_actor_layers`` sets its own, the actor's (each its own network;
            recurrent PPO: the layers after its LSTM).
        ppo_actor_layers: the actor's hidden widths where they differ from the
            critic's (``ppo_hidden_layers`` then shapes the critic alone); ``()`` is a
            linear actor, whose mean action is a linear function of its (scaled)
            observation; None: the same widths as the critic's.
        ppo_history: PPO only: the last N observations stacked as its input
            (``VecFrameStack``, newest last), a memory of the contact the policy has
            felt, as ``history`` is SAC's; 1 = the current observation alone (the
            recipes before 2026-12-06).
        ppo_sde_sample_steps: PPO only: 0 = SB3's independent Gaussian noise on every
            action; N > 0 = generalized state-dependent exploration (gSDE, Raffin et
            al. 2022): the noise is a fixed random linear map of the policy's last
            hidden layer, redrawn every N steps per env, so in a steady contact the
            exploration holds one direction (with an incremental residual: a steady
            drift, i.e. a search) instead of averaging out step to step. Its std per
            axis is exp(log_std_init) times the norm of that 64-unit layer.
        sac_learning_starts: SAC steps before its first update, explored with the
            initial (zero-mean) policy (see ResidualSAC).
        sac_critic_burn_in: SAC's first N gradient steps update only the critic (the
            actor and the entropy coefficient wait), so the actor first moves on a
            critic fitted to the initial policy's returns (a burn-in, as for an
            actor-critic started from a demonstration); 0 = SB3's SAC, both from the
            first update (on the rate residual the actor then followed an unfitted
            critic off the hole; section 52 of ``results/full_pose_study.md``; a
            10,000-step burn-in only delayed that collapse: section 57).
        sac_gradient_steps: SAC updates after each step of the ``envs`` envs (1 with
            two envs: half an update per transition).
        sac_initial_ent_coef: initial value of SAC's automatically tuned entropy
            coefficient alpha. A narrow policy has log pi > 0, so SAC's soft value then
            charges alpha * log pi per step alive, which makes ending an episode early
            (at a force limit) pay; a small start keeps that charge small.
        sac_target_entropy: the entropy SAC's coefficient tuning holds the policy at;
            None = SB3's -dim(A) = -6, i.e. a pre-squashing std of about 0.09 per axis
            (sub-millimetre jiggle). Each +6 multiplies that std by e: +1 keeps it
            near 0.3, the jiggle that finds a hole (paper Sec. I).
        composition: "residual" (rLfD), "hybrid" or "pure" (the paper's Table III
            baselines; see ``diagram.COMPOSITIONS``).
        init_from: a saved policy (.zip) of the same algorithm whose networks start
            this run (transfer, Table VI); None = a new zero-output policy.
        force_limit_penalty: subtracted from the reward of a training step that breaks
            the force limit (``RlfdEnv``); 0 = the paper's sparse reward.
        scaled_observation: start the networks with a fixed input layer that brings
            the contact features to order one (``observation_scaling.CONTACT_SCALES``).
        contact_torque_nm: with ``scaled_observation``, the wrist torque that the
            input layer maps to one unit, N m (``observation_scaling.contact_scales``;
            1 N m suits the peg, a small part such as the RJ-45 plug needs ~0.05).
        applied_action_only: in "translation" or "orientation" mode, the policy's
            action is only that 3-D part (``env.AppliedResidualAction``), not the 6-D
            residual whose other half the composer ignores.
        force_limit_n: a contact-force limit for the training episodes only, N
            (checked on the 20 ms low-passed force, like the task's own): an episode
            that exceeds it ends as a failure, as a Panda's collision reflex would stop
            it. None = the task's own limit (RJ-45's 30 N; none for the others). The
            sparse reward stays the paper's: the limit only removes the chance of
            success from pushing hard.
        peak_force_cost, peak_force_threshold_n: a training episode pays
            ``peak_force_cost`` per ``peak_force_threshold_n`` N of peak low-passed
            contact force above ``peak_force_threshold_n`` that its residual steps
            added (``RlfdEnv``); 0 / None = the paper's sparse reward. Unlike a force
            limit, the episode goes on, so a forceful success still scores above a
            failure and exploration keeps its successes.
        peak_force_signal: the force the peak-force cost charges: "low_passed" (the
            20 ms low-passed force that force limits check) or "one_step" (the 2 ms
            samples whose peak the evaluations report; impacts show in it).
        action_cost: each training step pays this times the mean square of its
            action (``RlfdEnv``): where the DMP alone inserts, the residual is pulled
            toward zero; 0 = the paper's sparse reward.
        sac_correlated_noise: SAC only: the stationary standard deviations (in units
            of the residual's range) of an Ornstein-Uhlenbeck noise added to the actions
            SAC explores with, restarted from 0 at each episode (``exploration_noise``):
            one value for every action component, or one per component (e.g. lateral
            only: 0.4, 0.4, 0, 0, 0, 0); all 0 = none (SAC's own noise, independent at
            each 0.1 s step, whose offsets average out before they move the part as far
            as a missed hole is off).
        sac_correlated_noise_time_s: that noise's correlation time, s.
        distance_shaping: the weight of a potential-based shaping term that pays
            each step for the distance to the true goal it closed, per cm of L1
            position error (``RlfdEnv``), discounted at the learner's ``DISCOUNT``;
            it leaves the optimal policies of episodes that end at the goal or time
            out unchanged (a force-limit break also pays its remaining distance);
            0 = the paper's sparse reward.
        distance_shaping_axes: "all" position errors, the "lateral" two across
            the insertion axis (lifting to slide sideways then costs nothing), or
            "lateral_depth": those and the depth still to go inside the fixture.
        base_correction: a hand-written rule (``base_correction.BASE_CORRECTIONS``,
            e.g. "force_search") whose action the learned residual is added to, in
            training and in evaluations (residual RL on the DMP plus that rule); None =
            the paper's rLfD, the residual on the DMP alone. The rule acts on the whole
            residual, the learner on its ``residual_mode`` part.
        timeout_terminal: the learner treats the end of an episode's time as terminal
            (``env.TimeLimitAsTerminal``: the observation carries the time, so waiting
            until it runs out scores 0) instead of bootstrapping it as a truncation
            (SB3's default, and these runs' before 2026-12-01).
        imitate: a hand-written rule (``base_correction.BASE_CORRECTIONS``, e.g.
            "force_search") whose behaviour the new PPO policy copies before RL
            (``imitation``): its mean is fitted to the rule's actions and its value to
            the returns of ``imitation_episodes`` episodes the rule runs on training
            starts, for ``imitation_epochs`` passes; that policy is saved as the
            checkpoint at step 0. At run time only the network acts. On a rate
            residual's task the rule's offsets are reached through the rate
            (``base_correction.RateTrackingRule``). None = RL from the zero residual
            (the paper's rLfD).
        imitation_episodes, imitation_epochs: the rule's episodes and the fit's passes.
        privileged_critic: PPO's critic also reads the part's pose from the fixture's
            true goal and the fixture's error (``env.PrivilegedObservation``,
            ``privileged_critic.PrivilegedCriticPolicy``: an asymmetric actor-critic,
            Pinto et al. 2018), its actor only the observation, as it runs in the
            diagram; False = the paper's PPO, whose critic reads what the actor reads.
        self_imitation_batches: PPO only: self-imitation minibatches (of 64 stored
            steps) after each PPO update (``self_imitation.SelfImitation``, Oh et al.
            2018: the policy is pulled towards stored actions whose return beat the
            critic's value); 0 = off (the paper's PPO).
        mirror_symmetry: PPO only: the actor's mean is equivariant and the critic's
            value invariant under the mirror across the world's x-z plane
            (``mirror_symmetry.MirrorSymmetricPolicy``: each is averaged with its value
            on the mirrored observation), so what an episode teaches about one side of
            the hole holds for the other; the task's scene must be symmetric across that
            plane (on peg from zero it evened +y and -y but lost starts on +x: section
            56 of ``results/full_pose_study.md``). False = the paper's PPO.
        hidden_observation: observation entries (indices into the 26 of
            ``systems/observer.py``) that the networks do not read (their fixed input
            scale is 0, in training and where the policy runs); needs
            ``scaled_observation``. E.g. 0 1 20 21: the lateral position error and the
            rate residual's held lateral offset, so a search cannot feed on its own
            integrated offset. () = the whole observation (the paper's).
        lateral_log_std_init: PPO only: the initial log std of the residual's lateral
            translation (world x and y, the action's entries 0 and 1) instead of
            ``log_std_init``, which the other entries keep: more (or less) exploration
            of where the hole lies without more noise on depth and orientation, which
            press (a larger noise on every entry did: section 38). None = one log
            std for every entry, as SB3 and the paper.
    """

    task: str = "peg_easy"
    algo: str = "ppo"
    episodes: int = 700
    seed: int = 0
    envs: int = 2
    residual_mode: str = "full"
    reward: str = "sparse"
    curriculum: bool = False
    curriculum_start: float = 0.25
    history: int = 4
    eval_every_episodes: int = 0
    eval_episodes: int = 10
    checkpoint_every_episodes: int = 100
    log_std_init: float = -1.5
    log_std_final: float | None = None
    learning_rate: float = 3e-4
    learning_rate_schedule: str = "constant"
    ppo_n_steps: int = PPO_N_STEPS
    ppo_gae_lambda: float = PPO_GAE_LAMBDA
    ppo_epochs: int = PPO_EPOCHS
    ppo_hidden_layers: tuple[int, ...] = PPO_HIDDEN_LAYERS
    ppo_actor_layers: tuple[int, ...] | None = None
    ppo_history: int = 1
    ppo_sde_sample_steps: int = 0
    sac_learning_starts: int = 0
    sac_critic_burn_in: int = 0
    sac_gradient_steps: int = 1
    sac_initial_ent_coef: float = 0.01
    sac_target_entropy: float | None = None
    composition: str = "residual"
    init_from: str | None = None
    force_limit_n: float | None = None
    force_limit_penalty: float = 0.0
    peak_force_cost: float = 0.0
    peak_force_threshold_n: float | None = None
    peak_force_signal: str = "low_passed"
    action_cost: float = 0.0
    scaled_observation: bool = False
    contact_torque_nm: float = CONTACT_TORQUE_PER_UNIT_NM
    applied_action_only: bool = False
    sac_correlated_noise: float | tuple[float, ...] = (0.0,)
    sac_correlated_noise_time_s: float = 2.0
    distance_shaping: float = 0.0
    distance_shaping_axes: str = "all"
    base_correction: str | None = None
    timeout_terminal: bool = False
    imitate: str | None = None
    imitation_episodes: int = 100
    imitation_epochs: int = 100
    privileged_critic: bool = False
    self_imitation_batches: int = 0
    mirror_symmetry: bool = False
    hidden_observation: tuple[int, ...] = ()
    lateral_log_std_init: float | None = None

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"algo must be one of {ALGORITHMS}, got {self.algo!r}")
        if self.task not in ENV_IDS.values():
            if not str(self.task).endswith((".yaml", ".yml")):
                raise ValueError(
                    f"task must be one of {sorted(ENV_IDS.values())} or a task YAML path, "
                    f"got {self.task!r}"
                )
            load_task(self.task)  # a task variant: its ValueError names the bad field
        for name in (
            "episodes",
            "envs",
            "history",
            "eval_episodes",
            "checkpoint_every_episodes",
            "ppo_n_steps",
            "ppo_epochs",
            "ppo_history",
            "sac_gradient_steps",
            "imitation_episodes",
            "imitation_epochs",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if int(self.ppo_sde_sample_steps) != self.ppo_sde_sample_steps or (
            self.ppo_sde_sample_steps < 0
        ):
            raise ValueError(
                f"ppo_sde_sample_steps must be an integer >= 0, got {self.ppo_sde_sample_steps}"
            )
        if self.ppo_sde_sample_steps and self.algo != "ppo":
            raise ValueError(
                f"ppo_sde_sample_steps={self.ppo_sde_sample_steps} needs algo 'ppo', got "
                f"{self.algo!r}"
            )
        if not (np.isfinite(self.ppo_gae_lambda) and 0.0 < self.ppo_gae_lambda <= 1.0):
            raise ValueError(f"ppo_gae_lambda must be in (0, 1], got {self.ppo_gae_lambda}")
        self._check_widths("ppo_hidden_layers", actor=False)
        self._check_widths("ppo_actor_layers", actor=True)
        for name, default in (
            ("ppo_n_steps", PPO_N_STEPS),
            ("ppo_gae_lambda", PPO_GAE_LAMBDA),
            ("ppo_epochs", PPO_EPOCHS),
            ("ppo_hidden_layers", PPO_HIDDEN_LAYERS),
            ("ppo_actor_layers", None),
        ):
            if self.algo == "sac" and getattr(self, name) != default:  # SAC does not roll out
                raise ValueError(
                    f"{name}={getattr(self, name)} needs algo 'ppo', got {self.algo!r} "
                    "('recurrent_ppo' also takes it)"
                )
        if self.ppo_history > 1:
            self._check_ppo_history()
        if self.sac_learning_starts < 0:
            raise ValueError(f"sac_learning_starts must be >= 0, got {self.sac_learning_starts}")
        if int(self.sac_critic_burn_in) != self.sac_critic_burn_in or self.sac_critic_burn_in < 0:
            raise ValueError(
                f"sac_critic_burn_in must be an integer >= 0, got {self.sac_critic_burn_in}"
            )
        if self.sac_critic_burn_in and self.algo != "sac":
            raise ValueError(
                f"sac_critic_burn_in={self.sac_critic_burn_in} needs algo 'sac', got {self.algo!r}"
            )
        if self.eval_every_episodes < 0:
            raise ValueError(f"eval_every_episodes must be >= 0, got {self.eval_every_episodes}")
        if self.applied_action_only and self.residual_mode not in RESIDUAL_PARTS:
            raise ValueError(
                f"applied_action_only needs residual_mode in {tuple(RESIDUAL_PARTS)}, got "
                f"{self.residual_mode!r}"
            )
        if self.sac_target_entropy is not None and not np.isfinite(self.sac_target_entropy):
            raise ValueError(f"sac_target_entropy must be finite, got {self.sac_target_entropy}")
        if not (np.isfinite(self.sac_initial_ent_coef) and self.sac_initial_ent_coef > 0):
            raise ValueError(
                f"sac_initial_ent_coef must be a positive number, got {self.sac_initial_ent_coef}"
            )
        if not (np.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise ValueError(f"learning_rate must be a positive number, got {self.learning_rate}")
        if self.learning_rate_schedule not in LEARNING_RATE_SCHEDULES:
            raise ValueError(
                f"learning_rate_schedule must be one of {LEARNING_RATE_SCHEDULES}, got "
                f"{self.learning_rate_schedule!r}"
            )
        if not np.isfinite(self.log_std_init):
            raise ValueError(f"log_std_init must be finite, got {self.log_std_init}")
        if self.log_std_final is not None:
            self._check_log_std_final()
        if self.composition not in COMPOSITIONS:
            raise ValueError(f"composition must be one of {COMPOSITIONS}, got {self.composition!r}")
        if self.init_from is not None and not policy_file(self.init_from).is_file():
            raise ValueError(f"init_from must be a saved policy file, got {self.init_from!r}")
        if self.force_limit_n is not None and not (
            np.isfinite(self.force_limit_n) and self.force_limit_n > 0
        ):
            raise ValueError(f"force_limit_n must be a positive number, got {self.force_limit_n}")
        if not (np.isfinite(self.contact_torque_nm) and self.contact_torque_nm > 0):
            raise ValueError(
                f"contact_torque_nm must be a positive number, got {self.contact_torque_nm}"
            )
        if self.contact_torque_nm != CONTACT_TORQUE_PER_UNIT_NM and not self.scaled_observation:
            raise ValueError(
                f"contact_torque_nm={self.contact_torque_nm} needs scaled_observation=True"
            )
        if not 0.0 <= self.curriculum_start <= 1.0:
            raise ValueError(f"curriculum_start must be in [0, 1], got {self.curriculum_start}")
        noise = np.atleast_1d(np.asarray(self.sac_correlated_noise, dtype=float))
        if noise.ndim != 1 or noise.size == 0 or not np.all(np.isfinite(noise) & (noise >= 0)):
            raise ValueError(
                "sac_correlated_noise must be one or more numbers >= 0, got "
                f"{self.sac_correlated_noise}"
            )
        if np.any(noise > 0) and self.algo != "sac":
            raise ValueError(
                f"sac_correlated_noise={self.sac_correlated_noise} needs algo 'sac', "
                f"got {self.algo!r}"
            )
        if not (
            np.isfinite(self.sac_correlated_noise_time_s) and self.sac_correlated_noise_time_s > 0
        ):
            raise ValueError(
                "sac_correlated_noise_time_s must be a positive number, got "
                f"{self.sac_correlated_noise_time_s}"
            )
        if self.base_correction is not None:
            check_base_correction(self.base_correction)
        if self.base_correction is not None and self.composition != "residual":
            raise ValueError(
                f"base_correction={self.base_correction!r} needs composition 'residual', got "
                f"{self.composition!r}"
            )
        if self.imitate is not None:
            self._check_imitation()
        if self.privileged_critic:
            self._check_privileged_critic()
        if self.self_imitation_batches < 0:
            raise ValueError(
                f"self_imitation_batches must be >= 0, got {self.self_imitation_batches}"
            )
        if self.self_imitation_batches > 0:
            why = f"{self.algo!r} (it replays PPO's rollouts without a recurrent state)"
            _refuse_conflicts(
                f"self_imitation_batches={self.self_imitation_batches}",
                {"algo": (self.algo != "ppo", why)},
            )
        if self.mirror_symmetry:
            self._check_mirror_symmetry()
        try:
            hidden = check_hidden_entries(self.hidden_observation)
        except ValueError as error:
            raise ValueError(f"hidden_observation: {error}") from error
        object.__setattr__(self, "hidden_observation", hidden)  # the tuple a list means
        if hidden:
            _refuse_conflicts(
                f"hidden_observation={hidden}",
                {
                    "scaled_observation": (
                        not self.scaled_observation,
                        "off (the hidden entries are zeroed by its input layer)",
                    ),
                    "privileged_critic": (
                        self.privileged_critic,
                        "set (its input layers read the whole observation)",
                    ),
                },
            )
        if self.lateral_log_std_init is not None:
            self._check_lateral_log_std_init()
        check_reward_terms(
            self.force_limit_penalty,
            self.peak_force_cost,
            self.peak_force_threshold_n,
            self.action_cost,
            self.peak_force_signal,
            self.distance_shaping,
            DISCOUNT,
            self.distance_shaping_axes,
        )

    def _check_widths(self, name: str, actor: bool) -> None:
        """Hidden widths: the critic's (``ppo_hidden_layers``, one or more) or the
        actor's (``ppo_actor_layers``: None for the critic's, or none for a linear
        actor)."""
        layers = getattr(self, name)
        if actor and layers is None:
            return
        if isinstance(layers, (str, bytes)) or not hasattr(layers, "__iter__"):
            raise ValueError(f"{name} must be a sequence of widths, got {layers!r}")
        layers = tuple(layers)
        if (not layers and not actor) or not all(
            isinstance(width, (int, np.integer)) and not isinstance(width, bool) and width >= 1
            for width in layers
        ):
            what = "zero or more" if actor else "one or more"
            raise ValueError(f"{name} must be {what} integer widths >= 1, got {layers!r}")
        # frozen: set once, as the tuple a list of widths means
        object.__setattr__(self, name, tuple(int(width) for width in layers))

    def _check_log_std_final(self) -> None:
        if not np.isfinite(self.log_std_final):
            raise ValueError(f"log_std_final must be finite, got {self.log_std_final}")
        if self.algo == "sac":  # SAC's log std is a layer of the actor, not a parameter
            raise ValueError(
                f"log_std_final={self.log_std_final} needs algo 'ppo' or 'recurrent_ppo', "
                f"got {self.algo!r}"
            )
        if self.ppo_sde_sample_steps:
            raise ValueError(
                f"log_std_final={self.log_std_final} cannot schedule gSDE's noise "
                f"(ppo_sde_sample_steps={self.ppo_sde_sample_steps}): give one or the other"
            )

    def _check_lateral_log_std_init(self) -> None:
        value = self.lateral_log_std_init
        if not np.isfinite(value):
            raise ValueError(f"lateral_log_std_init must be finite, got {value}")
        _refuse_conflicts(
            f"lateral_log_std_init={value}",
            {
                "algo": (self.algo != "ppo", f"{self.algo!r} (needs 'ppo')"),
                "residual_mode": (
                    self.residual_mode not in ("full", "translation"),
                    f"{self.residual_mode!r} (no lateral translation to explore)",
                ),
                "log_std_final": (
                    self.log_std_final is not None,
                    f"{self.log_std_final} (its schedule sets every entry)",
                ),
                "ppo_sde_sample_steps": (
                    self.ppo_sde_sample_steps > 0,
                    f"{self.ppo_sde_sample_steps} (gSDE's noise is a matrix, not a log std "
                    "per entry)",
                ),
                "init_from": (
                    self.init_from is not None,
                    f"{self.init_from!r} (the copied policy brings its own noise)",
                ),
                "imitate": (
                    self.imitate is not None,
                    f"{self.imitate!r} (the copy starts from its teacher's noise)",
                ),
            },
        )

    def _check_ppo_history(self) -> None:
        """ValueError naming the setting that PPO's stacked history cannot go with."""
        conflicts = {
            "algo": (self.algo != "ppo", f"{self.algo!r} (SAC stacks `history`)"),
            "privileged_critic": (
                self.privileged_critic,
                "set (its entries would be stacked with the observation)",
            ),
            "imitate": (self.imitate is not None, "set (the copy is fitted on one observation)"),
        }
        _refuse_conflicts(f"ppo_history={self.ppo_history}", conflicts)

    def _check_privileged_critic(self) -> None:
        """ValueError naming the setting that a privileged critic cannot go with."""
        conflicts = {
            "algo": (self.algo != "ppo", f"{self.algo!r} (it is PPO's actor-critic)"),
            "init_from": (
                self.init_from is not None,
                "set (a source's critic did not read the privileged entries)",
            ),
            "imitate": (
                self.imitate is not None,
                "set (the copy's value is fitted on the observation alone)",
            ),
        }
        _refuse_conflicts("privileged_critic", conflicts)

    def _check_mirror_symmetry(self) -> None:
        """ValueError naming the setting (or the task's field) that a mirror-symmetric
        policy cannot go with."""
        conflicts = {
            "algo": (self.algo != "ppo", f"{self.algo!r} (it is PPO's actor-critic)"),
            "privileged_critic": (
                self.privileged_critic,
                "set (its privileged entries have no mirror image here)",
            ),
            "ppo_sde_sample_steps": (
                self.ppo_sde_sample_steps > 0,
                f"{self.ppo_sde_sample_steps} (gSDE's noise map is not mirrored)",
            ),
            "composition": (
                self.composition != "residual",
                f"{self.composition!r} (its policy also flies the approach, which starts "
                "off the mirror plane)",
            ),
        }
        _refuse_conflicts("mirror_symmetry", conflicts)
        check_mirror_symmetric_task(load_task(self.task))

    def _check_imitation(self) -> None:
        """ValueError naming the setting that imitation of a rule cannot go with."""
        if self.imitate not in BASE_CORRECTIONS:
            raise ValueError(
                f"imitate must be one of {sorted(BASE_CORRECTIONS)}, got {self.imitate!r}"
            )
        conflicts = {
            "algo": (self.algo != "ppo", f"{self.algo!r} (imitation fits PPO's actor-critic)"),
            "init_from": (self.init_from is not None, "set (both choose the start)"),
            "base_correction": (
                self.base_correction is not None,
                "set (the rule would act twice: under the learner and in it)",
            ),
            "applied_action_only": (
                self.applied_action_only,
                "set (the rule gives the whole 6-D residual)",
            ),
            "composition": (self.composition != "residual", f"{self.composition!r}"),
        }
        _refuse_conflicts(f"imitate={self.imitate!r}", conflicts)


def _refuse_conflicts(setting: str, conflicts: dict[str, tuple[bool, str]]) -> None:
    """ValueError "<setting> cannot go with <name> <why>" for the first conflict that
    holds (``conflicts``: name -> (holds, why))."""
    for name, (holds, why) in conflicts.items():
        if holds:
            raise ValueError(f"{setting} cannot go with {name} {why}")


def _env_kwargs(config: TrainConfig) -> dict:
    task = config.task
    if config.force_limit_n is not None:
        task = replace(load_task(task), force_limit_n=float(config.force_limit_n))
    return {
        "task": task,
        "reward": config.reward,
        "residual_mode": applied_residual_mode(config.base_correction, config.residual_mode),
        "composition": config.composition,
        "force_limit_penalty": config.force_limit_penalty,
        "peak_force_cost": config.peak_force_cost,
        "peak_force_threshold_n": config.peak_force_threshold_n,
        "peak_force_signal": config.peak_force_signal,
        "action_cost": config.action_cost,
        "distance_shaping": config.distance_shaping,
        "discount": DISCOUNT,
        "distance_shaping_axes": config.distance_shaping_axes,
    }


def wrap_training_env(
    env,
    residual_mode: str,
    applied_action_only: bool,
    base_correction: str | None,
    timeout_terminal: bool = False,
    privileged_critic: bool = False,
):
    """An RlfdEnv as the learner sees it: its time limit terminal if asked, its action
    added to the base correction's (on the 6-D residual), then only the applied 3-D
    part if asked, and the privileged entries appended for a privileged critic."""
    if timeout_terminal:
        env = TimeLimitAsTerminal(env)
    if base_correction is not None:
        env = BaseCorrectedAction(env, base_correction, learned_mode=residual_mode)
    if applied_action_only:
        env = AppliedResidualAction(env, residual_mode)
    if privileged_critic:
        env = PrivilegedObservation(env)
    return env


def make_envs(config: TrainConfig, n_envs: int, seed: int):
    """The (vectorised; history-stacked for SAC, and for PPO when asked) training or
    evaluation envs."""
    vec_cls = SubprocVecEnv if n_envs > 1 else DummyVecEnv
    vec_kwargs = {"start_method": "spawn"} if n_envs > 1 else None
    wrapper = dict(  # returns the env itself when the config asks for none
        wrapper_class=wrap_training_env,
        wrapper_kwargs={
            "residual_mode": config.residual_mode,
            "applied_action_only": config.applied_action_only,
            "base_correction": config.base_correction,
            "timeout_terminal": config.timeout_terminal,
            "privileged_critic": config.privileged_critic,
        },
    )
    venv = make_vec_env(
        RlfdEnv,
        n_envs=n_envs,
        seed=seed,
        env_kwargs=_env_kwargs(config),
        vec_env_cls=vec_cls,
        **wrapper,
        vec_env_kwargs=vec_kwargs,
    )
    stacked = {"sac": config.history, "ppo": config.ppo_history}.get(config.algo, 1)
    if stacked > 1:
        venv = VecFrameStack(venv, n_stack=stacked)
    return venv


class ResidualSAC(SAC):
    """SAC whose warm-up (``learning_starts``) explores with its own policy -- the zero
    residual plus its small Gaussian jiggle, i.e. the DMP -- instead of SB3's uniform
    samples over [-1, 1] (full-range residuals). The critic then first sees what the
    DMP achieves, successes included, before the actor moves: on RJ-45, where most
    failures end early at the force limit, updating from the first step let the actor
    drift on a critic fitted to zeros (2 successes in 63 episodes against the DMP's
    ~30%). Saved models load as plain SAC."""

    #: Gradient steps, from the first, in which only the critic learns
    #: (``TrainConfig.sac_critic_burn_in``); 0 = none (SB3's SAC).
    critic_burn_in: int = 0

    def _sample_action(self, learning_starts, action_noise=None, n_envs=1):
        return super()._sample_action(0, action_noise, n_envs)

    def _update_learning_rate(self, optimizers) -> None:
        """SB3 sets every optimiser's step before each batch of gradient steps; in the
        critic's burn-in the actor's and the entropy coefficient's are 0 (Adam then
        leaves their parameters as they are), so the critic fits the initial policy's
        values before the actor follows it."""
        super()._update_learning_rate(optimizers)
        if self._n_updates < self.critic_burn_in:
            for optimizer in (self.actor.optimizer, self.ent_coef_optimizer):
                if optimizer is not None:
                    for group in optimizer.param_groups:
                        group["lr"] = 0.0


def exploration_noise(
    stationary_std: float | tuple[float, ...], time_s: float, action_size: int, step_s: float
) -> OrnsteinUhlenbeckActionNoise | None:
    """The Ornstein-Uhlenbeck noise of ``TrainConfig.sac_correlated_noise`` (None if all
    its standard deviations are 0): one std for every action component, or one each.

    SB3's process is ``x <- x + theta (0 - x) dt + sigma sqrt(dt) N(0, 1)``, whose
    stationary std is ``sigma / sqrt(2 theta)``: with ``theta = 1 / time_s`` the std
    ``stationary_std`` needs ``sigma = stationary_std sqrt(2 / time_s)``. SB3 starts it
    from 0 at each episode's end (per env), so an episode explores one slowly drifting
    offset instead of a jiggle.
    """
    std = np.atleast_1d(np.asarray(stationary_std, dtype=float))
    if std.size not in (1, action_size):
        raise ValueError(
            f"sac_correlated_noise must have 1 or {action_size} (the action's size) values, "
            f"got {std.size}: {tuple(std)}"
        )
    if not np.any(std > 0):
        return None
    return OrnsteinUhlenbeckActionNoise(
        mean=np.zeros(action_size),
        sigma=np.broadcast_to(std, (action_size,)) * np.sqrt(2.0 / time_s),
        theta=1.0 / time_s,
        dt=step_s,
    )


def zero_residual_output(model: BaseAlgorithm, log_std_init: float) -> None:
    """Zeroes the last layer of the actor's mean, so the untrained residual is 0; for
    SAC (whose log std is a layer, not a parameter) starts the log std at
    ``log_std_init``."""
    policy = model.policy
    if hasattr(policy, "action_net"):  # PPO / RecurrentPPO (log std set by policy_kwargs)
        layer = policy.action_net
    elif hasattr(policy, "actor"):  # SAC
        layer = policy.actor.mu
        with torch.no_grad():
            policy.actor.log_std.weight.zero_()
            policy.actor.log_std.bias.fill_(log_std_init)
    else:
        raise TypeError(f"cannot find the actor's output layer of {type(policy).__name__}")
    with torch.no_grad():
        layer.weight.zero_()
        layer.bias.zero_()


def ppo_net_arch(config: TrainConfig) -> list[int] | dict[str, list[int]]:
    """SB3's ``net_arch`` for PPO and recurrent PPO: one list of widths for the actor
    and the critic, or each its own when the actor's differ (``[]``: a linear actor)."""
    if config.ppo_actor_layers is None:
        return list(config.ppo_hidden_layers)
    return dict(pi=list(config.ppo_actor_layers), vf=list(config.ppo_hidden_layers))


def make_model(config: TrainConfig, venv, tensorboard_dir: Path | None) -> BaseAlgorithm:
    """A new SB3 model with the paper's architecture where it states one, logging to
    TensorBoard in ``tensorboard_dir``, or nowhere (and writing no files) for None."""
    scales = contact_scales(config.contact_torque_nm) if config.scaled_observation else None
    inputs = (
        dict(
            features_extractor_class=ScaledObservation,
            features_extractor_kwargs={"scales": scales, "hidden": config.hidden_observation},
        )
        if scales is not None
        else {}
    )
    common = dict(
        env=venv,
        seed=config.seed,
        verbose=0,
        learning_rate=config.learning_rate,
        tensorboard_log=str(tensorboard_dir) if tensorboard_dir else None,
        device="cpu",
    )
    # PPO's and recurrent PPO's rollout and update settings (SAC does not roll out).
    rollout = dict(
        n_steps=config.ppo_n_steps,
        batch_size=min(64, config.ppo_n_steps * config.envs),
        gae_lambda=config.ppo_gae_lambda,
        n_epochs=config.ppo_epochs,
        gamma=DISCOUNT,
    )
    if config.algo == "ppo":
        policy, reading = "MlpPolicy", inputs
        if config.privileged_critic:  # its own two input layers, with these scales
            policy = PrivilegedCriticPolicy
            reading = dict(privileged_size=PRIVILEGED_SIZE, observation_scales=scales)
        if config.mirror_symmetry:
            policy = MirrorSymmetricPolicy
            reading = dict(
                observation_signs=observation_mirror_signs(config.ppo_history),
                action_signs=action_mirror_signs(config.residual_mode, config.applied_action_only),
                **inputs,
            )
        model = PPO(
            policy,
            use_sde=config.ppo_sde_sample_steps > 0,
            sde_sample_freq=config.ppo_sde_sample_steps or -1,
            policy_kwargs=dict(
                net_arch=ppo_net_arch(config), log_std_init=config.log_std_init, **reading
            ),
            **rollout,
            **common,
        )
    elif config.algo == "sac":
        # Paper: actor 400-300 ReLU, critic one layer of 300; memory through the stacked
        # observation history (SB3 has no recurrent SAC).
        model = ResidualSAC(
            "MlpPolicy",
            buffer_size=100_000,
            batch_size=128,
            learning_starts=config.sac_learning_starts,
            train_freq=(1, "step"),
            gradient_steps=config.sac_gradient_steps,
            gamma=DISCOUNT,
            # SB3's default starts the entropy coefficient at 1.0, which against a
            # sparse reward of 1 per episode made the entropy bonus dominate: the
            # policy widened until its residuals knocked the part off the hole
            # (success fell from ~90% to ~35% after 100 episodes). Start it small.
            ent_coef=f"auto_{config.sac_initial_ent_coef}",
            target_entropy="auto"
            if config.sac_target_entropy is None
            else float(config.sac_target_entropy),
            policy_kwargs=dict(
                net_arch=dict(pi=[400, 300], qf=[300]), activation_fn=torch.nn.ReLU, **inputs
            ),
            action_noise=exploration_noise(
                config.sac_correlated_noise,
                config.sac_correlated_noise_time_s,
                venv.action_space.shape[0],
                venv.get_attr("diagram_config", [0])[0].residual_period_s,
            ),
            **common,
        )
        model.critic_burn_in = int(config.sac_critic_burn_in)
    else:
        from sb3_contrib import RecurrentPPO

        model = RecurrentPPO(
            "MlpLstmPolicy",
            policy_kwargs=dict(
                lstm_hidden_size=40,
                net_arch=ppo_net_arch(config),
                log_std_init=config.log_std_init,
                **inputs,
            ),
            **rollout,
            **common,
        )
    zero_residual_output(model, config.log_std_init)
    if config.lateral_log_std_init is not None:
        with torch.no_grad():  # world x and y lead both action layouts (6-D and 3-D)
            model.policy.log_std[:2] = config.lateral_log_std_init
    if tensorboard_dir is None:
        # Without it, every learn() of SB3 makes an empty folder tmp/SB3-<time> for a
        # logger that writes nothing (verbose 0): a test suite left dozens behind.
        model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def copy_policy_parameters(source: BaseAlgorithm, target: BaseAlgorithm) -> None:
    """Starts ``target`` from ``source``'s networks (and SAC's entropy coefficient):
    fine-tuning a residual trained on another task (transfer, paper Table VI). The
    optimisers and the replay buffer start afresh.

    Raises:
        ValueError: the two are different algorithms, read their observation with
            different fixed scales (``--scaled-observation``, ``--contact-torque-nm``:
            the scales live in the networks' state, so copying them would silently
            override this run's), or their networks differ in shape (e.g. another
            observation history or action size).
    """
    if type(source.policy) is not type(target.policy):  # SAC and ResidualSAC share one
        raise ValueError(
            f"init_from is a {type(source).__name__} policy, this run trains "
            f"{type(target).__name__}"
        )
    source_scales, target_scales = (_observation_scales(m.policy) for m in (source, target))
    if (source_scales is None) != (target_scales is None) or (
        source_scales is not None and not torch.equal(source_scales, target_scales)
    ):
        raise ValueError(
            f"init_from reads its observation {_describe_reading(source_scales)}, this run "
            f"{_describe_reading(target_scales)}: train with the source's "
            "--scaled-observation / --contact-torque-nm"
        )
    source_state = source.policy.state_dict()
    target_state = target.policy.state_dict()
    mismatched = [
        name
        for name, value in target_state.items()
        if name not in source_state or source_state[name].shape != value.shape
    ] + [name for name in source_state if name not in target_state]  # e.g. one more layer
    if mismatched:
        raise ValueError(f"init_from's networks do not match this run's: {mismatched[:4]}")
    target.policy.load_state_dict(source_state)
    if getattr(source, "log_ent_coef", None) is not None and target.log_ent_coef is not None:
        with torch.no_grad():
            target.log_ent_coef.copy_(source.log_ent_coef.detach())


def _observation_scales(policy) -> torch.Tensor | None:
    """The fixed input scales of ``policy``'s networks (``ScaledObservation``; SAC's
    actor and critics each hold a copy, equal), None if it reads the observation as is."""
    scales = [buffer for name, buffer in policy.named_buffers() if name.endswith(".scales")]
    return scales[0] if scales else None


def _describe_reading(scales: torch.Tensor | None) -> str:
    """ "unscaled", or the wrist torque that ``scales`` map to one unit."""
    if scales is None:
        return "unscaled"
    index = OBSERVATION_WRIST_TORQUE.start
    per_unit = CONTACT_TORQUE_PER_UNIT_NM * CONTACT_SCALES[index] / float(scales[index])
    return f"scaled, wrist torque {per_unit:g} N m per unit"


def load_model(path: str | Path) -> BaseAlgorithm:
    """Loads a saved policy of any of our algorithms (see ``policies.load_sb3_model``)."""
    return load_sb3_model(path)[0]


class EpisodeLog(BaseCallback):
    """Writes one CSV line per finished training episode and stops after N episodes;
    drives the start-perturbation curriculum."""

    def __init__(
        self,
        config: TrainConfig,
        path: Path,
        episodes_done: int = 0,
        progress: EpisodeProgress | None = None,
    ):
        super().__init__()
        self.config = config
        self.path = path
        self.episodes = episodes_done
        self.progress = progress
        self.successes: list[int] = []
        self._returns = None
        self._lengths = None

    def _on_training_start(self) -> None:
        n = self.training_env.num_envs
        self._returns = np.zeros(n)
        self._lengths = np.zeros(n, dtype=int)
        new = not self.path.exists()
        self._file = self.path.open("a", newline="")
        self._writer = csv.writer(self._file)
        if new:
            self._writer.writerow(["episode", "timesteps", "success", "return", "length"])
        self._apply_curriculum()

    def _apply_curriculum(self) -> None:
        if not self.config.curriculum:
            return
        progress = min(1.0, self.episodes / max(1, 0.5 * self.config.episodes))
        start = self.config.curriculum_start
        scale = start + (1.0 - start) * progress
        self.training_env.env_method("set_perturbation_scale", float(scale))
        self.logger.record("train/perturbation_scale", scale)

    def _on_step(self) -> bool:
        rewards = self.locals["rewards"]
        dones = self.locals["dones"]
        infos = self.locals["infos"]
        self._returns += rewards
        self._lengths += 1
        for i, done in enumerate(dones):
            if not done:
                continue
            self.episodes += 1
            if self.progress is not None:
                self.progress.done = self.episodes
            success = int(bool(infos[i].get("success", False)))
            self.successes.append(success)
            self._writer.writerow(
                [self.episodes, self.num_timesteps, success, self._returns[i], self._lengths[i]]
            )
            self._returns[i] = 0.0
            self._lengths[i] = 0
            recent = self.successes[-50:]
            self.logger.record("rollout/success_rate_50", float(np.mean(recent)))
            self.logger.record("rollout/episodes", self.episodes)
            self._apply_curriculum()
        self._file.flush()
        return self.episodes < self.config.episodes

    def _on_training_end(self) -> None:
        self._file.close()


class EveryNEpisodes(EventCallback):
    """Triggers ``callback`` each time the count of finished training episodes (over all
    envs) reaches a multiple of ``n_episodes``. SB3's own triggers count steps, and an
    episode here lasts 1-50 steps (successes end early), so a step interval drifts from
    the episode interval a user asked for."""

    def __init__(self, n_episodes: int, callback: BaseCallback, episodes_done: int = 0):
        if n_episodes < 1:
            raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
        super().__init__(callback)
        self.n_episodes = n_episodes
        self.episodes = episodes_done

    def _on_step(self) -> bool:
        before = self.episodes
        self.episodes += int(np.sum(self.locals["dones"]))
        if self.episodes // self.n_episodes == before // self.n_episodes:
            return True  # no multiple of n_episodes reached
        return self._on_event()


def start_from_teacher(model: BaseAlgorithm, config: TrainConfig) -> dict:
    """Fits ``model``'s policy to ``config.imitate``'s behaviour (``imitation``) on
    episodes of envs seeded apart from training's; returns what the fit did."""
    from rlfd_drake.imitation import collect_teacher_episodes, fit_policy_to_teacher

    start = time.perf_counter()
    venv = make_envs(config, config.envs, config.seed + 20_000)
    try:
        data = collect_teacher_episodes(venv, config.imitate, config.imitation_episodes, DISCOUNT)
    finally:
        venv.close()
    collect_wall = time.perf_counter() - start
    fit = fit_policy_to_teacher(model.policy, data, config.imitation_epochs, config.seed)
    return {
        "teacher": config.imitate,
        "teacher_episodes": data.episodes,
        "teacher_success_rate": float(np.mean(data.successes)),
        "collect_wall_time_s": collect_wall,
        **fit,
    }


def resumed_model(config: TrainConfig, checkpoint: Path, venv) -> BaseAlgorithm:
    """A run's checkpoint loaded to go on training: SAC as ResidualSAC, so that its
    warm-up and its critic's burn-in (counted in the checkpoint's updates) go on."""
    algorithm = ResidualSAC if config.algo == "sac" else type(load_model(checkpoint))
    model = algorithm.load(str(checkpoint), env=venv, device="cpu")
    if config.algo == "sac":
        model.critic_burn_in = int(config.sac_critic_burn_in)
    return model


def _newest_checkpoint(run_dir: Path) -> Path | None:
    checkpoints = sorted(
        (run_dir / "checkpoints").glob("*_steps.zip"),
        key=checkpoint_steps,
    )
    return checkpoints[-1] if checkpoints else None


def train(
    config: TrainConfig, run_dir: Path, resume: bool = False, progress_bar: bool = True
) -> dict:
    """Trains (or resumes) a residual policy; returns the run's metrics.

    A run folder that already holds a run is refused unless ``resume`` is True (a
    finished run is never overwritten).
    """
    # One intra-op thread: the env processes need the cores, and small networks gain
    # nothing from threads (two threads on two busy cores were ~5x slower per update).
    torch.set_num_threads(1)
    run_dir = Path(run_dir)
    config_path = run_dir / "config.json"
    if config_path.exists() and not resume:
        raise FileExistsError(
            f"run folder {run_dir} already holds a run; pass --resume or choose another --out"
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    if resume and config_path.exists():
        # Fields added since the run started take their defaults.
        # Compared as JSON, where tuples are lists.
        defaults = json.loads(json.dumps(asdict(TrainConfig())))
        saved = {**defaults, **json.loads(config_path.read_text())["config"]}
        if saved != json.loads(json.dumps(asdict(config))):
            raise ValueError(
                f"--resume with a different configuration than {config_path}: "
                f"saved {saved}, given {asdict(config)}"
            )
    config_path.write_text(
        format_json({"config": asdict(config), "command": invoked_command()}) + "\n"
    )
    episodes_csv = run_dir / "episodes.csv"
    episodes_done = 0
    if resume and episodes_csv.exists():
        episodes_done = max(0, sum(1 for _ in episodes_csv.open()) - 1)

    venv = make_envs(config, config.envs, config.seed)
    checkpoint = _newest_checkpoint(run_dir) if resume else None
    if checkpoint is not None:
        model = resumed_model(config, checkpoint, venv)
    else:
        model = make_model(config, venv, run_dir / "tb")
        if config.init_from is not None:
            copy_policy_parameters(load_model(config.init_from), model)
        if config.imitate is not None:
            imitation = start_from_teacher(model, config)
            (run_dir / "checkpoints").mkdir(exist_ok=True)
            model.save(str(run_dir / "checkpoints" / "policy_0_steps.zip"))
            (run_dir / "imitation.json").write_text(format_json(imitation) + "\n")
    progress = EpisodeProgress(episodes_done, config.episodes)
    if config.learning_rate_schedule == "linear":
        # Set after loading too: a saved schedule holds its own, stale, episode count.
        model.lr_schedule = LinearDecayOverEpisodes(config.learning_rate, progress)

    # Checkpoints and evaluations fire on finished episodes (their children then act
    # on every trigger).
    callbacks: list[BaseCallback] = [
        EpisodeLog(config, episodes_csv, episodes_done, progress),
        EveryNEpisodes(
            config.checkpoint_every_episodes,
            CheckpointCallback(
                save_freq=1, save_path=str(run_dir / "checkpoints"), name_prefix="policy"
            ),
            episodes_done,
        ),
    ]
    if config.log_std_final is not None:
        callbacks.append(
            ExplorationNoiseSchedule(config.log_std_init, config.log_std_final, progress)
        )
    self_imitation = None
    if config.self_imitation_batches > 0:
        self_imitation = SelfImitation(config.self_imitation_batches, seed=config.seed)
        callbacks.append(self_imitation)
    if config.eval_every_episodes > 0:
        eval_env = make_envs(config, 1, config.seed + 10_000)
        callbacks.append(
            EveryNEpisodes(
                config.eval_every_episodes,
                EvalCallback(
                    eval_env,
                    n_eval_episodes=config.eval_episodes,
                    eval_freq=1,
                    log_path=str(run_dir / "eval"),
                    best_model_save_path=str(run_dir / "eval"),
                    deterministic=True,
                ),
                episodes_done,
            )
        )
    start = time.perf_counter()
    model.learn(
        # An upper bound (an episode has at most 61 residual steps); EpisodeLog stops it.
        total_timesteps=config.episodes * 100,
        callback=CallbackList(callbacks),
        progress_bar=progress_bar,
        reset_num_timesteps=checkpoint is None,
        tb_log_name="run",
    )
    wall = time.perf_counter() - start
    model.save(str(run_dir / "policy.zip"))
    venv.close()
    log = callbacks[0]
    metrics = {
        "episodes": log.episodes,
        "timesteps": int(model.num_timesteps),
        "wall_time_s": wall,
        # Over the whole run: a resumed process saw only its own episodes.
        **training_success_rates(read_episode_rows(run_dir)),
        # A fine-tune whose episodes end before SAC's learning starts never updates: the
        # saved policy is then the copied one, and this says so.
        "gradient_updates": int(getattr(model, "_n_updates", 0)),
        "date": utc_now(),  # when training finished
    }
    if self_imitation is not None:
        # This process's only: a resumed run starts the store empty.
        metrics["self_imitation_updates"] = self_imitation.updates
        metrics["self_imitation_stored_steps"] = len(self_imitation.returns)
    if checkpoint is not None:
        # The earlier processes' time is not known (they were stopped before writing
        # metrics), so the wall time is this process's and says so.
        metrics["resumed_at_episode"] = episodes_done
        metrics["resumed_from_checkpoint"] = checkpoint.name
        metrics["wall_time_s_covers"] = f"the resumed part only (episodes {episodes_done + 1}-)"
    # Read back from the file: a resumed run did its imitation in an earlier process.
    if (run_dir / "imitation.json").is_file():
        metrics["imitation"] = json.loads((run_dir / "imitation.json").read_text())
    if metrics["gradient_updates"] == 0:
        warnings.warn(
            f"{run_dir}: no gradient update in {metrics['timesteps']} steps, so policy.zip "
            "is the initial policy (SAC updates after --sac-learning-starts steps, PPO "
            "after a full rollout)",
            stacklevel=2,
        )
    (run_dir / "metrics.json").write_text(format_json(metrics) + "\n")
    return metrics
