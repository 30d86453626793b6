"""Starting a residual policy from a hand-written one: behaviour cloning before RL.

On RJ-45 the learned residual never found the search a hand-written rule does (lift when
the plug rests on the entrance, slide away from the centre of pressure): its exploration
noise does not steer by the wrist torque long enough to meet the socket, so RL alone
stays at the DMP's success (``results/rj45_study.md``). Learning on top of the rule
(``--base-correction``) needs the rule at run time. Here the rule is a teacher instead:
the residual policy's mean is fitted to the rule's actions on the observations the rule
itself meets (DMP plus rule, the training distribution of starts), its value function to
the discounted returns of those episodes, and RL then improves the network alone. At
run time only the learned network acts.

Pure torch on SB3's actor-critic policy; no Drake here beyond stepping the env given.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from rlfd_drake.base_correction import make_base_correction
from rlfd_drake.self_imitation import discounted_returns

__all__ = ["TeacherEpisodes", "collect_teacher_episodes", "fit_policy_to_teacher"]


@dataclass(frozen=True)
class TeacherEpisodes:
    """The teacher's finished episodes, step by step: what the learner saw
    (``observations``, (n, obs)), what the teacher did (``actions``, (n, 6)), the
    discounted return from each step on (``returns``, (n,)), and per episode whether
    it succeeded."""

    observations: np.ndarray
    actions: np.ndarray
    returns: np.ndarray
    successes: np.ndarray

    @property
    def episodes(self) -> int:
        return int(self.successes.size)


def collect_teacher_episodes(venv, teacher_name: str, episodes: int, gamma: float):
    """Runs the rule ``teacher_name`` (``base_correction.BASE_CORRECTIONS``) as the
    whole residual in the vectorised training env ``venv`` (its wrappers as the learner
    has them) until ``episodes`` episodes have ended; episodes still running then are
    dropped. On a rate residual's task the rule acts through the rate
    (``base_correction.RateTrackingRule``), so the actions recorded are rates. Returns
    :class:`TeacherEpisodes`.

    Raises:
        ValueError: ``episodes`` < 1, an unknown teacher, or an env whose observation
            is not the Observer's flat vector (e.g. SAC's stacked history).
    """
    if episodes < 1:
        raise ValueError(f"imitation_episodes must be >= 1, got {episodes}")
    try:
        task = venv.get_attr("task", [0])[0]  # a rule may read the task (its table slope)
    except AttributeError:
        task = None
    # On a rate residual the rule's offsets are reached through the rate (RateTrackingRule).
    teachers = [
        make_base_correction(teacher_name, task, through_rate=True) for _ in range(venv.num_envs)
    ]
    if len(venv.observation_space.shape) != 1:
        raise ValueError(
            f"imitation needs a flat observation, the env gives {venv.observation_space.shape}"
        )
    running = [{"obs": [], "actions": [], "rewards": []} for _ in teachers]
    done_steps: list[tuple[list, list, list[float]]] = []
    successes: list[bool] = []
    obs = venv.reset()
    while len(successes) < episodes:
        actions = np.stack([teacher(o) for teacher, o in zip(teachers, obs, strict=True)])
        next_obs, rewards, dones, infos = venv.step(actions.astype(np.float32))
        for i, trajectory in enumerate(running):
            trajectory["obs"].append(np.array(obs[i], dtype=np.float32))
            trajectory["actions"].append(actions[i].astype(np.float32))
            trajectory["rewards"].append(float(rewards[i]))
            if dones[i] and len(successes) < episodes:
                done_steps.append(
                    (
                        trajectory["obs"],
                        trajectory["actions"],
                        discounted_returns(trajectory["rewards"], gamma),
                    )
                )
                successes.append(bool(infos[i].get("success", False)))
            if dones[i]:
                running[i] = {"obs": [], "actions": [], "rewards": []}
                teachers[i].reset()
        obs = next_obs
    return TeacherEpisodes(
        observations=np.concatenate([np.stack(o) for o, _, _ in done_steps]),
        actions=np.concatenate([np.stack(a) for _, a, _ in done_steps]),
        returns=np.concatenate([np.asarray(r, dtype=np.float32) for _, _, r in done_steps]),
        successes=np.asarray(successes, dtype=bool),
    )


def _mean_actions_and_values(policy, observations: torch.Tensor):
    distribution = policy.get_distribution(observations)
    return distribution.distribution.mean, policy.predict_values(observations).flatten()


def fit_policy_to_teacher(
    policy,
    data: TeacherEpisodes,
    epochs: int,
    seed: int,
    batch_size: int = 256,
    learning_rate: float = 1e-3,
) -> dict:
    """Fits an SB3 actor-critic ``policy`` (PPO's): the mean action to the teacher's
    (mean squared error over the 6 components) and the value to the returns, by Adam
    over shuffled mini-batches for ``epochs`` passes. Its log std is left as it is: RL
    explores around the copied behaviour with the run's own noise. Returns the losses
    before and after and the wall-clock time.

    Raises:
        ValueError: ``epochs`` < 1 or a policy without an action distribution mean
            and a value head (e.g. SAC's).
    """
    if epochs < 1:
        raise ValueError(f"imitation_epochs must be >= 1, got {epochs}")
    if not hasattr(policy, "predict_values") or not hasattr(policy, "get_distribution"):
        raise ValueError(
            f"imitation fits an actor-critic policy (PPO's), got {type(policy).__name__}"
        )
    start = time.perf_counter()
    observations = torch.as_tensor(data.observations)
    actions = torch.as_tensor(data.actions)
    returns = torch.as_tensor(data.returns)

    def losses() -> tuple[float, float]:
        with torch.no_grad():
            mean, values = _mean_actions_and_values(policy, observations)
            return (
                float(torch.mean((mean - actions) ** 2)),
                float(torch.mean((values - returns) ** 2)),
            )

    before = losses()
    policy.set_training_mode(True)
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    generator = torch.Generator().manual_seed(seed)
    n = observations.shape[0]
    for _ in range(epochs):
        order = torch.randperm(n, generator=generator)
        for first in range(0, n, batch_size):
            batch = order[first : first + batch_size]
            mean, values = _mean_actions_and_values(policy, observations[batch])
            loss = torch.mean((mean - actions[batch]) ** 2) + torch.mean(
                (values - returns[batch]) ** 2
            )
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    policy.set_training_mode(False)
    after = losses()
    return {
        "samples": int(n),
        "epochs": int(epochs),
        "action_mse_before": before[0],
        "action_mse_after": after[0],
        "value_mse_before": before[1],
        "value_mse_after": after[1],
        "fit_wall_time_s": time.perf_counter() - start,
    }
