"""Episodic training of the paper's non-residual and linear baselines on the simulator.

Table I of the paper compares where exploration enters the DMP:

* type B, ``enac``: episodic Natural Actor-Critic on the DMP's coupling term C_t, a
  linear-Gaussian policy on phase features, acting at 10 Hz for the whole episode;
* type C, ``power`` / ``fdg``: PoWER and finite-difference gradients on the DMP's
  forcing weights w (translation and orientation, 3 x 40 + 3 x 70 by default);
* type D baselines without deep RL, ``linear``: the RLS-adapted linear residual in
  task space (Tables II and IV's "Linear").

Each learner proposes what the next episodes run (a weight vector, a coupling or
linear policy), episodes run in worker processes (``workers``), and the learner is
told each episode's return. The return is the paper's sparse reward summed over the
episode, normalised by the episode length: ``R = 1[success] (1 - t_insert / T)``
(the time spent inserted, assuming the part stays in, as it does once latched).

``train_baseline`` writes a run folder: ``config.json`` (with the command),
``episodes.csv``, ``baseline.npz`` (the learnt parameters, loadable by
:func:`load_baseline` and by ``rlfd evaluate --policy PATH.npz``) and ``metrics.json``.
"""

from __future__ import annotations

import csv
import json
import multiprocessing
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rlfd_drake.baselines.enac import EpisodicNaturalActorCritic
from rlfd_drake.baselines.fdg import FiniteDifferenceGradient
from rlfd_drake.baselines.power import PoWER
from rlfd_drake.baselines.rls import LinearPolicyConfig, LinearResidualPolicy
from rlfd_drake.diagram import RESIDUAL_SIZE
from rlfd_drake.dmp import CartesianDmp, get_weights, with_weights
from rlfd_drake.episode import (
    EpisodeResult,
    EpisodeSpec,
    load_task_dmp,
    make_episode_specs,
    run_episode,
)
from rlfd_drake.results import invoked_command
from rlfd_drake.systems.observer import OBSERVATION_SIZE
from rlfd_drake.tasks import TaskSpec, list_tasks, load_task

__all__ = [
    "BASELINE_METHODS",
    "BaselineConfig",
    "BaselineKit",
    "CouplingPolicy",
    "episode_return",
    "load_baseline",
    "train_baseline",
]

#: Learners of :func:`train_baseline`.
BASELINE_METHODS = ("power", "fdg", "enac", "linear")
#: Index of the DMP phase in the observation (see systems/observer.py).
_PHASE_INDEX = 18


def episode_return(result: EpisodeResult, task: TaskSpec) -> float:
    """``1[success] (1 - t_insert / T)``: the sparse reward summed over the episode / T."""
    if not result.success or not np.isfinite(result.insertion_time_s):
        return 0.0
    return float(max(0.0, 1.0 - result.insertion_time_s / task.episode_time_s))


@dataclass(frozen=True)
class BaselineConfig:
    """One episodic baseline run.

    Attributes:
        task: task name.
        method: one of ``BASELINE_METHODS``.
        episodes: training episodes (random starts and fixture errors of the task).
        seed: seed of the episodes and of the learner's exploration.
        workers: episodes run in parallel (processes).
        residual_mode: ``linear`` only: "full", "translation" or "orientation".
        weight_sigma_fraction: ``power``/``fdg``: exploration std of each forcing
            weight, as a fraction of the std of the fitted weights of its part.
        power_n_best: ``power``: rollouts kept for importance sampling.
        fdg_perturbations: ``fdg``: perturbed rollouts per gradient step.
        fdg_learning_rate: ``fdg``: step (normalised gradient), in units of sigma.
        coupling_basis: ``enac``: Gaussian basis functions over the phase (plus a bias).
        enac_sigma: ``enac``: exploration std of the normalised coupling (1 = the
            coupling that shifts the DMP's rest point by the residual's bound).
        enac_learning_rate: ``enac``: step of the normalised natural gradient.
        enac_episodes_per_update: ``enac``: episodes per natural-gradient estimate.
        linear_exploration_std: ``linear``: Gaussian exploration std (action units).
    """

    task: str = "peg_easy"
    method: str = "power"
    episodes: int = 100
    seed: int = 0
    workers: int = 2
    residual_mode: str = "full"
    weight_sigma_fraction: float = 0.1
    power_n_best: int = 10
    fdg_perturbations: int = 10
    fdg_learning_rate: float = 0.5
    coupling_basis: int = 6
    enac_sigma: float = 0.3
    enac_learning_rate: float = 0.2
    enac_episodes_per_update: int = 10
    linear_exploration_std: float = 0.2

    def __post_init__(self) -> None:
        if self.method not in BASELINE_METHODS:
            raise ValueError(f"method must be one of {BASELINE_METHODS}, got {self.method!r}")
        if self.task not in list_tasks():
            raise ValueError(f"task must be one of {list_tasks()}, got {self.task!r}")
        if self.residual_mode not in ("full", "translation", "orientation"):
            raise ValueError(
                f"residual_mode must be full/translation/orientation, got {self.residual_mode!r}"
            )
        for name in (
            "episodes",
            "workers",
            "power_n_best",
            "fdg_perturbations",
            "coupling_basis",
            "enac_episodes_per_update",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in (
            "weight_sigma_fraction",
            "fdg_learning_rate",
            "enac_sigma",
            "enac_learning_rate",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be > 0, got {value}")
        if not (np.isfinite(self.linear_exploration_std) and self.linear_exploration_std >= 0):
            raise ValueError(
                f"linear_exploration_std must be >= 0, got {self.linear_exploration_std}"
            )


# --------------------------------------------------------------------------------------
# The policies the learners act through.
# --------------------------------------------------------------------------------------
def phase_features(phase: float, n_basis: int) -> np.ndarray:
    """``[psi_i(x) / sum psi, 1]``: normalised Gaussians over the phase x in [0, 1] (centres
    evenly spaced, width so neighbours overlap at half height), plus a bias. (n_basis + 1,)"""
    centres = np.linspace(0.0, 1.0, n_basis)
    width = 1.0 / max(n_basis - 1, 1)
    psi = np.exp(-0.5 * ((float(phase) - centres) / (0.6 * width)) ** 2)
    return np.append(psi / max(psi.sum(), 1e-12), 1.0)


class CouplingPolicy:
    """The eNAC learner as the coupling-term policy inside the diagram (10 Hz).

    ``obs (26,) -> C_t (6,)`` normalised (the diagram scales it, see
    ``BuildRlfdDiagram(coupling_policy=...)``): ``theta^T phi(x) + noise`` with
    ``phi`` the phase features of :func:`phase_features`.
    """

    def __init__(self, learner: EpisodicNaturalActorCritic, n_basis: int):
        self.learner = learner
        self.n_basis = n_basis

    def reset(self) -> None:
        self.learner.reset()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        u, _ = self.learner.act(phase_features(observation[_PHASE_INDEX], self.n_basis))
        return np.clip(u, -1.0, 1.0)


@dataclass
class BaselineKit:
    """What an episode of a baseline runs: the residual policy, the coupling policy
    and the DMP (any may be the plain DMP's: None / None / the task's)."""

    policy: object | None
    coupling_policy: object | None
    dmp: CartesianDmp


def _linear_policy(config: BaselineConfig, seed: int, deterministic: bool) -> LinearResidualPolicy:
    return LinearResidualPolicy(
        OBSERVATION_SIZE,
        LinearPolicyConfig(
            translation=config.residual_mode in ("full", "translation"),
            orientation=config.residual_mode in ("full", "orientation"),
            exploration_std=config.linear_exploration_std,
        ),
        seed=seed,
        deterministic=deterministic,
    )


def _enac(config: BaselineConfig, seed: int, theta: np.ndarray | None, deterministic: bool):
    return EpisodicNaturalActorCritic(
        config.coupling_basis + 1,
        RESIDUAL_SIZE,
        sigma=config.enac_sigma,
        learning_rate=config.enac_learning_rate,
        seed=seed,
        episodes_per_update=config.enac_episodes_per_update,
        normalize_step=True,
        theta0=theta,
        deterministic=deterministic,
    )


def load_baseline(
    path: str | Path, task: TaskSpec, dmp: CartesianDmp, seed: int = 0
) -> BaselineKit:
    """The deterministic (evaluation) kit of a ``baseline.npz`` written by ``train_baseline``,
    for an episode of ``task`` whose DMP is ``dmp``."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no baseline file at {path}")
    data = dict(np.load(path, allow_pickle=False))
    if "config_json" not in data:
        raise ValueError(f"{path} is not a baseline file (no config_json)")
    config = BaselineConfig(**json.loads(str(data["config_json"])))
    # A baseline trained on one task may be evaluated on another (the paper trains on
    # the easy hole and evaluates on both); learnt forcing weights then replace the
    # other task's weights, keeping its start and goal.
    if config.method in ("power", "fdg"):
        return BaselineKit(None, None, with_weights(dmp, data["theta"]))
    if config.method == "enac":
        learner = _enac(config, seed, data["theta"], deterministic=True)
        return BaselineKit(None, CouplingPolicy(learner, config.coupling_basis), dmp)
    policy = _linear_policy(config, seed, deterministic=True)
    policy.set_state({k[len("rls_") :]: v for k, v in data.items() if k.startswith("rls_")})
    return BaselineKit(policy, None, dmp)


# --------------------------------------------------------------------------------------
# Workers: one episode per job.
# --------------------------------------------------------------------------------------
_WORKER: dict[str, object] = {}


def _init_worker(config: BaselineConfig) -> None:
    task = load_task(config.task)
    _WORKER.update(config=config, task=task, dmp=load_task_dmp(task))


def _run_job(job: tuple) -> tuple[EpisodeResult, dict]:
    """``job = (kind, episode_seed, spec, parameters)`` -> (result, what the learner needs)."""
    kind, seed, spec, parameters = job
    config, task, dmp = _WORKER["config"], _WORKER["task"], _WORKER["dmp"]
    if kind == "weights":
        result = run_episode(task, with_weights(dmp, parameters), spec)
        return result, {}
    if kind == "enac":
        learner = _enac(config, seed, parameters, deterministic=False)
        coupling = CouplingPolicy(learner, config.coupling_basis)
        result = run_episode(task, dmp, spec, coupling_policy=coupling)
        score, steps = learner.episode_score()
        return result, {"score": score, "steps": steps}
    policy = _linear_policy(config, seed, deterministic=False)
    policy.set_state(parameters)
    result = run_episode(task, dmp, spec, policy=policy)
    features, actions = policy.episode_samples()
    return result, {"features": features, "actions": actions}


# --------------------------------------------------------------------------------------
# The learners behind one interface: jobs out, results in.
# --------------------------------------------------------------------------------------
class _WeightSearch:
    """PoWER or FDG on the DMP's forcing weights (type C)."""

    def __init__(self, config: BaselineConfig, dmp: CartesianDmp):
        theta0 = get_weights(dmp)
        n = dmp.weights_translation.size
        sigma = np.empty_like(theta0)
        sigma[:n] = config.weight_sigma_fraction * max(float(np.std(theta0[:n])), 1e-6)
        sigma[n:] = config.weight_sigma_fraction * max(float(np.std(theta0[n:])), 1e-6)
        if config.method == "power":
            self.learner = PoWER(theta0, sigma, n_best=config.power_n_best, seed=config.seed)
        else:
            self.learner = FiniteDifferenceGradient(
                theta0,
                sigma,
                n_perturbations=config.fdg_perturbations,
                learning_rate=config.fdg_learning_rate * float(np.linalg.norm(sigma)),
                normalize_step=True,
                seed=config.seed,
            )

    def batch_limit(self) -> int:
        # FDG hands out one iteration's rollouts, then waits for all their returns.
        if isinstance(self.learner, FiniteDifferenceGradient):
            return self.learner.rollouts_left_to_ask
        return 1 << 30

    def job(self, seed: int, spec: EpisodeSpec) -> tuple:
        return ("weights", seed, spec, self.learner.ask())

    def tell(self, job: tuple, result: EpisodeResult, payload: dict, return_: float) -> None:
        self.learner.tell(job[3], return_)

    def parameters(self) -> dict[str, np.ndarray]:
        # PoWER's mean is its importance-weighted estimate; FDG's is its last step.
        return {"theta": self.learner.theta.copy()}


class _Enac:
    def batch_limit(self) -> int:
        return 1 << 30

    def __init__(self, config: BaselineConfig):
        self.learner = _enac(config, config.seed, None, deterministic=False)

    def job(self, seed: int, spec: EpisodeSpec) -> tuple:
        return ("enac", seed, spec, self.learner.theta.copy())

    def tell(self, job: tuple, result: EpisodeResult, payload: dict, return_: float) -> None:
        self.learner.tell_episode(payload["score"], payload["steps"], return_)

    def parameters(self) -> dict[str, np.ndarray]:
        return {"theta": self.learner.theta.copy()}


class _Linear:
    def batch_limit(self) -> int:
        return 1 << 30

    def __init__(self, config: BaselineConfig):
        self.policy = _linear_policy(config, config.seed, deterministic=False)

    def job(self, seed: int, spec: EpisodeSpec) -> tuple:
        return ("linear", seed, spec, self.policy.get_state())

    def tell(self, job: tuple, result: EpisodeResult, payload: dict, return_: float) -> None:
        self.policy.tell_episode(payload["features"], payload["actions"], return_)

    def parameters(self) -> dict[str, np.ndarray]:
        return {f"rls_{k}": v for k, v in self.policy.get_state().items()}


def _make_learner(config: BaselineConfig, dmp: CartesianDmp):
    if config.method in ("power", "fdg"):
        return _WeightSearch(config, dmp)
    if config.method == "enac":
        return _Enac(config)
    return _Linear(config)


def train_baseline(config: BaselineConfig, out: str | Path, progress: bool = True) -> dict:
    """Trains ``config.method`` for ``config.episodes`` episodes; writes the run folder.

    Episodes run ``config.workers`` at a time with the learner's current parameters;
    the learner is told their returns in episode order. Refuses to write into a
    folder that already holds a ``baseline.npz``.
    """
    out = Path(out)
    if (out / "baseline.npz").exists():
        raise FileExistsError(f"{out} already holds a trained baseline; choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(
        json.dumps({"config": asdict(config), "command": invoked_command()}, indent=2)
    )
    task = load_task(config.task)
    learner = _make_learner(config, load_task_dmp(task))
    specs = make_episode_specs(task, config.episodes, config.seed, grid=False)
    seeds = np.random.SeedSequence([config.seed, 1]).generate_state(config.episodes)
    rows = []
    start = time.perf_counter()
    context = multiprocessing.get_context("spawn")
    with context.Pool(config.workers, initializer=_init_worker, initargs=(config,)) as pool:
        first = 0
        while first < config.episodes:
            size = min(config.workers, learner.batch_limit(), config.episodes - first)
            batch = range(first, first + size)
            first += size
            jobs = [learner.job(int(seeds[i]), specs[i]) for i in batch]
            for i, job, (result, payload) in zip(
                batch, jobs, pool.map(_run_job, jobs), strict=True
            ):
                return_ = episode_return(result, task)
                learner.tell(job, result, payload, return_)
                rows.append(
                    {
                        "episode": i,
                        "success": int(result.success),
                        "return": round(return_, 4),
                        "insertion_time_s": result.insertion_time_s,
                        "peak_force_n": round(result.peak_force_n, 2),
                        "failure": result.failure_kind or "",
                    }
                )
            if progress:
                recent = [r["success"] for r in rows[-20:]]
                print(
                    f"[{config.method}] episode {len(rows)}/{config.episodes}: "
                    f"success over the last {len(recent)} = {np.mean(recent):.2f}",
                    flush=True,
                )
    wall = time.perf_counter() - start
    with open(out / "episodes.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    np.savez(
        out / "baseline.npz",
        config_json=np.array(json.dumps(asdict(config))),
        **learner.parameters(),
    )
    success = np.array([r["success"] for r in rows], dtype=float)
    tenth = max(1, len(success) // 10)
    metrics = {
        "episodes": len(rows),
        "wall_time_s": round(wall, 1),
        "training_success_first_10pct": float(success[:tenth].mean()),
        "training_success_last_10pct": float(success[-tenth:].mean()),
        "training_success_mean": float(success.mean()),
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics
