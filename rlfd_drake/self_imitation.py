"""Self-imitation learning (Oh, Guo, Singh & Lee, ICML 2018) beside PPO's updates.

PPO learns from each rollout once and forgets it. On peg, the starts a policy fails are
the rare ones (2-3 mm fixture errors), and the noisy policy does insert some of them
during training; self-imitation keeps every finished episode and, between PPO's
updates, pulls the policy towards the actions of past steps whose discounted return R
beat the critic's value V, weighted by the clipped advantage (R - V)+, and the critic up
to those returns:

    L_sil = -log pi(a | s) (R - V(s))+  +  beta / 2 ((R - V(s))+)^2

with transitions sampled in proportion to (R - V(s))+ (the paper's prioritised replay,
without its exponent). Steps whose return the critic already expects weigh nothing.

``EpisodeReturns`` (numpy) turns consecutive PPO rollouts into finished episodes with
their returns; ``SelfImitation`` (an SB3 callback, so the model stays a plain PPO that
saves and loads as one) stores them and makes the updates.
"""

from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

#: The weight of the critic's term in the paper (beta_sil).
VALUE_WEIGHT = 0.01
#: Transitions per self-imitation minibatch (PPO's minibatch here).
BATCH_SIZE = 64
#: Transitions kept, oldest dropped first (a 700-episode peg run makes about 20,000).
CAPACITY = 100_000


def discounted_returns(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """R_t = r_t + gamma R_(t+1) over one finished episode's rewards, R after the end = 0."""
    rewards = np.asarray(rewards, dtype=float)
    returns = np.empty_like(rewards)
    following = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        following = rewards[t] + gamma * following
        returns[t] = following
    return returns


class EpisodeReturns:
    """Collects steps env by env across rollouts and hands back each episode with its
    discounted returns once the episode has finished (an episode may span rollouts).

    Args:
        n_envs: parallel envs of the rollouts.
        gamma: discount in (0, 1].
    """

    def __init__(self, n_envs: int, gamma: float):
        if not (isinstance(n_envs, (int, np.integer)) and n_envs >= 1):
            raise ValueError(f"n_envs must be an integer >= 1, got {n_envs!r}")
        if not (np.isfinite(gamma) and 0.0 < gamma <= 1.0):
            raise ValueError(f"gamma must be in (0, 1], got {gamma}")
        self.gamma = float(gamma)
        self._open = [([], [], []) for _ in range(n_envs)]  # observations, actions, rewards

    def add_rollout(
        self,
        observations: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        episode_starts: np.ndarray,
        last_dones: np.ndarray,
    ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Adds one rollout, arrays shaped (steps, envs, ...) as SB3's rollout buffer holds
        them (``episode_starts[t]``: step t opened an episode); ``last_dones`` (envs,)
        says whether each env's last step ended its episode. Returns the episodes that
        finished, each as (observations, actions, returns)."""
        steps, envs = np.shape(rewards)[:2]
        if envs != len(self._open):
            raise ValueError(f"rewards must hold {len(self._open)} envs, got shape {rewards.shape}")
        ends = np.concatenate(
            [np.asarray(episode_starts[1:], bool), [np.asarray(last_dones, bool)]]
        )
        finished = []
        for env in range(envs):
            observed, acted, rewarded = self._open[env]
            for t in range(steps):
                observed.append(observations[t, env])
                acted.append(actions[t, env])
                rewarded.append(float(rewards[t, env]))
                if ends[t, env]:
                    returns = discounted_returns(rewarded, self.gamma)
                    finished.append((np.array(observed), np.array(acted), returns))
                    observed, acted, rewarded = [], [], []
            self._open[env] = (observed, acted, rewarded)
        return finished


class SelfImitation(BaseCallback):
    """Self-imitation updates of a PPO policy, run before each rollout from the second
    on (that is, after each PPO update), on every finished episode seen so far.

    The store lives in this callback only: a resumed run starts it empty.

    The loss has the paper's weight 1 and takes its own optimiser steps (PPO's Adam):
    how strongly it pulls is set by how many steps it takes, ``batches`` per PPO update
    against PPO's ``n_epochs`` x rollout / 64 (10 x 8 on peg's recipe).

    Args:
        batches: minibatches of ``BATCH_SIZE`` stored steps per PPO update (>= 1).
        seed: seed of the minibatch sampling.
    """

    def __init__(self, batches: int, seed: int = 0):
        super().__init__()
        if not (isinstance(batches, (int, np.integer)) and batches >= 1):
            raise ValueError(f"batches must be an integer >= 1, got {batches!r}")
        self.batches = int(batches)
        self.rng = np.random.default_rng(seed)
        self.observations: np.ndarray | None = None
        self.actions: np.ndarray | None = None
        self.returns = np.zeros(0)
        self.updates = 0
        self.last_positive_fraction = 0.0

    def _init_callback(self) -> None:
        self.episodes = EpisodeReturns(self.model.n_envs, self.model.gamma)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        # The buffer is complete and not yet flattened by PPO's update.
        buffer = self.model.rollout_buffer
        for observations, actions, returns in self.episodes.add_rollout(
            buffer.observations,
            buffer.actions,
            buffer.rewards,
            buffer.episode_starts,
            self.model._last_episode_starts,
        ):
            self._store(observations, actions, returns)

    def _store(self, observations, actions, returns) -> None:
        if self.observations is None:
            self.observations, self.actions = observations, actions
        else:
            self.observations = np.concatenate([self.observations, observations])[-CAPACITY:]
            self.actions = np.concatenate([self.actions, actions])[-CAPACITY:]
        self.returns = np.concatenate([self.returns, returns])[-CAPACITY:]

    def _on_rollout_start(self) -> None:
        if self.observations is None:
            return  # nothing stored: before the first rollout, or none has ended an episode
        policy = self.model.policy
        with torch.no_grad():
            values = policy.predict_values(torch.as_tensor(self.observations)).flatten().numpy()
        advantage = np.maximum(self.returns - values, 0.0)
        self.last_positive_fraction = float(np.mean(advantage > 0))
        if advantage.sum() <= 0:
            return  # the critic already expects every stored return
        probabilities = advantage / advantage.sum()
        policy.set_training_mode(True)
        for _ in range(self.batches):
            rows = self.rng.choice(len(advantage), size=BATCH_SIZE, p=probabilities)
            observations = torch.as_tensor(self.observations[rows])
            actions = torch.as_tensor(self.actions[rows])
            returns = torch.as_tensor(self.returns[rows], dtype=torch.float32)
            values, log_prob, _ = policy.evaluate_actions(observations, actions)
            clipped = torch.clamp(returns - values.flatten(), min=0.0)
            loss = -(log_prob * clipped.detach()).mean() + VALUE_WEIGHT * 0.5 * (clipped**2).mean()
            policy.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), self.model.max_grad_norm)
            policy.optimizer.step()
            self.updates += 1
        policy.set_training_mode(False)
        self.logger.record("self_imitation/positive_fraction", self.last_positive_fraction)
        self.logger.record("self_imitation/stored", len(self.returns))
