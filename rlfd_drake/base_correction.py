"""A hand-written correction under the learned residual (residual RL on a base rule).

rLfD learns its residual on top of the DMP alone. Residual RL in general (Johannink et
al., ICRA 2019; Silver et al., 2018) learns on top of any base controller: here the DMP
plus a stateless correction rule, obs (26,) -> residual (6,), whose action the learned
residual's is added to (the sum clipped to the residual's range). The learner then
starts from what the rule achieves and only has to learn what to change, not the whole
search; the replay buffer and the policy keep the learner's own action.

:data:`BASE_CORRECTIONS` names the rules; a run trained with one (``rlfd train
--base-correction NAME``) stores the name in its configuration, and ``rlfd evaluate``
adds the same rule under the policy (``evaluate.make_policy``).
"""

from __future__ import annotations

from collections.abc import Callable

import gymnasium as gym
import numpy as np

from rlfd_drake.baselines.force_guided import ForceGuidedSearch
from rlfd_drake.baselines.orientation_reference import slope_residual
from rlfd_drake.baselines.split import SplitResidualPolicy
from rlfd_drake.control_math import keep_residual_part, rate_toward_offset
from rlfd_drake.systems.observer import OBSERVATION_RESIDUAL
from rlfd_drake.tasks import TaskSpec

__all__ = [
    "BASE_CORRECTIONS",
    "BaseCorrectedAction",
    "BaseCorrectedPolicy",
    "RateTrackingRule",
    "add_base_correction",
    "applied_residual_mode",
    "check_base_correction",
    "check_offset_rule",
    "make_base_correction",
]


def _force_search_and_slope(task: TaskSpec | None) -> SplitResidualPolicy:
    if not isinstance(task, TaskSpec):
        raise ValueError(f"force_search_and_slope needs the task (its table slope), got {task!r}")
    # The search's translation with the constant turn that undoes the table's slope:
    # the part of the fixture's rotation that is the same in every episode, which a
    # residual can learn as a constant (baselines/orientation_reference.py).
    return SplitResidualPolicy(ForceGuidedSearch(), slope_residual(task))


def _slope(task: TaskSpec | None):
    if not isinstance(task, TaskSpec):
        raise ValueError(f"slope needs the task (its table slope), got {task!r}")
    return slope_residual(task)


#: Name -> factory of a stateless correction rule (obs -> 6-D residual in [-1, 1]) on
#: a task.
BASE_CORRECTIONS: dict[str, Callable[[TaskSpec | None], Callable[[np.ndarray], np.ndarray]]] = {
    "force_search": lambda task: ForceGuidedSearch(),
    # Its mirror image, for a hole going onto a shaft (baselines/force_guided.py).
    "force_search_toward": lambda task: ForceGuidedSearch(toward_pressure=True),
    "force_search_and_slope": _force_search_and_slope,
    # Only the constant turn that undoes the table's slope: no translation.
    "slope": _slope,
}


def _integrates_a_rate(task: TaskSpec | None) -> bool:
    """Whether ``task``'s residual action is a rate (``residual_rate_per_s``)."""
    return isinstance(task, TaskSpec) and task.residual_rate_per_s is not None


def check_offset_rule(name: str, task: TaskSpec | None) -> None:
    """ValueError unless ``task``'s residual is an offset: the hand-written rules name
    the offset they want, and on a rate residual (``residual_rate_per_s``) the same
    action would be integrated into a drift to the range's end."""
    if _integrates_a_rate(task):
        raise ValueError(
            f"the rule {name!r} gives a residual offset, but task {task.name!r} integrates "
            f"its residual as a rate (residual_rate_per_s={task.residual_rate_per_s}); "
            "use the task it is based on"
        )


def check_base_correction(name: str) -> None:
    """ValueError naming ``name`` unless it is one of :data:`BASE_CORRECTIONS`."""
    if name not in BASE_CORRECTIONS:
        raise ValueError(f"base_correction must be one of {sorted(BASE_CORRECTIONS)}, got {name!r}")


class RateTrackingRule:
    """An offset rule acting through a rate residual (``residual_rate_per_s``): each
    policy step it asks for the rate that moves the held offset (the observation's
    residual input) to the offset the rule names, as fast as the rate allows
    (:func:`control_math.rate_toward_offset`). It lets a rule teach a rate residual
    (``rlfd train --imitate`` on a rate task); under a learned rate residual it would
    pull against the learner, so ``--base-correction`` still refuses rate tasks."""

    def __init__(self, rule, rate_per_s: float, residual_period_s: float):
        self.rule = rule
        self.step = float(rate_per_s) * float(residual_period_s)
        rate_toward_offset(np.zeros(6), np.zeros(6), self.step)  # ValueError on a bad step

    def reset(self) -> None:
        if hasattr(self.rule, "reset"):
            self.rule.reset()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        obs = np.asarray(observation, dtype=float).reshape(-1)
        return rate_toward_offset(self.rule(obs), obs[OBSERVATION_RESIDUAL], self.step)

    def __repr__(self) -> str:
        return f"RateTrackingRule({self.rule!r}, step={self.step})"


def make_base_correction(name: str, task: TaskSpec | None = None, through_rate: bool = False):
    """A new instance of the rule ``name`` on ``task`` (None for rules that do not read
    it); ValueError naming an unknown rule, or a missing task a rule needs. On a rate
    residual's task, ``through_rate`` gives the rule as a :class:`RateTrackingRule`
    (for imitation); without it such a task is refused (:func:`check_offset_rule`)."""
    check_base_correction(name)
    if through_rate and _integrates_a_rate(task):
        rule = BASE_CORRECTIONS[name](task)
        return RateTrackingRule(rule, task.residual_rate_per_s, task.residual_period_s)
    check_offset_rule(name, task)
    return BASE_CORRECTIONS[name](task)


def applied_residual_mode(base_correction: str | None, learned_mode: str) -> str:
    """The residual mode the diagram runs a learner with: its own (``learned_mode``), or
    "full" on a base correction, whose rule acts on the whole residual."""
    return learned_mode if base_correction is None else "full"


def add_base_correction(base: np.ndarray, learned: np.ndarray) -> np.ndarray:
    """The applied residual: the rule's plus the learner's, clipped to [-1, 1]."""
    base = np.asarray(base, dtype=float).reshape(-1)
    learned = np.asarray(learned, dtype=float).reshape(-1)
    if base.shape != learned.shape:
        raise ValueError(
            f"the base correction has {base.size} components and the learned residual "
            f"{learned.size}"
        )
    return np.clip(base + learned, -1.0, 1.0)


class BaseCorrectedPolicy:
    """A residual policy (obs -> 6-D action, with ``reset()``) run on top of a rule, as
    the diagram's ``ResidualPolicy`` calls it in evaluations (the diagram applying the
    full residual); only the ``learned_mode`` part of the learned action is added."""

    def __init__(self, base, learned, learned_mode: str = "full"):
        keep_residual_part(np.zeros(6), learned_mode)  # ValueError naming a bad mode
        self.base = base
        self.learned = learned
        self.learned_mode = learned_mode

    def reset(self) -> None:
        for part in (self.base, self.learned):
            if hasattr(part, "reset"):
                part.reset()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        learned = keep_residual_part(self.learned(observation), self.learned_mode)
        return add_base_correction(self.base(observation), learned)


class BaseCorrectedAction(gym.Wrapper):
    """An RlfdEnv whose (6-D) action is added to the rule's action on the observation the
    agent acted on, for training: the env (residual mode "full") applies the sum, the
    agent keeps its own. Only the ``learned_mode`` part of the agent's action is added."""

    def __init__(self, env: gym.Env, base_correction: str, learned_mode: str = "full"):
        keep_residual_part(np.zeros(6), learned_mode)  # ValueError naming a bad mode
        super().__init__(env)
        self.base = make_base_correction(base_correction, getattr(env.unwrapped, "task", None))
        self.learned_mode = learned_mode
        self._observation: np.ndarray | None = None

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        self.base.reset()
        self._observation = np.asarray(observation)
        return observation, info

    def step(self, action):
        if self._observation is None:
            raise RuntimeError("BaseCorrectedAction.step before reset")
        learned = keep_residual_part(action, self.learned_mode)
        applied = add_base_correction(self.base(self._observation), learned).astype(np.float32)
        observation, reward, terminated, truncated, info = self.env.step(applied)
        self._observation = np.asarray(observation)
        return observation, reward, terminated, truncated, info
