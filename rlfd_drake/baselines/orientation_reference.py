"""Constant orientation residuals that know what the robot does not: references for how
much of a task's failure is the fixture's unseen rotation.

Not the paper's baselines, and not policies a robot could learn from its observation
alone:

* ``"slope"`` undoes the task's table slope (``fixture_error.table_slope_deg`` about
  its axis), the part of the fixture's rotation that is the same in every episode: what
  a residual could learn as a constant.
* ``"fixture_oracle"`` undoes the episode's whole fixture rotation (the slope and the
  random part). Privileged: an upper bound on what correcting the orientation gives.

Both set only the orientation half of the residual; run them as the orientation part
of a split policy (``"force_search|fixture_oracle"``) to pair them with a translation
rule. The fixture's error X_err is expressed in F (X_WF_true = X_WF_nominal X_err) and
the residual's rotation in the world (R_cmd = R_delta R_dmp), so the rotation that
turns the part with the fixture is R_delta = R_WF_nominal R_err R_WF_nominal^T.
"""

from __future__ import annotations

import numpy as np

from rlfd_drake.diagram import RESIDUAL_SIZE
from rlfd_drake.tasks import TaskSpec, fixture_turn_in_world, table_slope_quaternion

__all__ = ["ConstantRotationResidual", "fixture_rotation_residual", "slope_residual"]


class ConstantRotationResidual:
    """obs -> the same residual every step: no translation, the rotation vector
    ``rotation_vector_rad`` (world) in units of ``max_rotation_rad``, clipped to [-1, 1]
    per component (``clipped`` says whether the clip cut it)."""

    def __init__(self, rotation_vector_rad: np.ndarray, max_rotation_rad: float):
        rotation = np.asarray(rotation_vector_rad, dtype=float).reshape(-1)
        if rotation.shape != (3,) or not np.all(np.isfinite(rotation)):
            raise ValueError(f"rotation_vector_rad must be 3 finite numbers, got {rotation!r}")
        if not (np.isfinite(max_rotation_rad) and max_rotation_rad > 0):
            raise ValueError(f"max_rotation_rad must be a positive number, got {max_rotation_rad}")
        units = rotation / max_rotation_rad
        self.clipped = bool(np.any(np.abs(units) > 1.0))
        self._action = np.zeros(RESIDUAL_SIZE)
        self._action[3:6] = np.clip(units, -1.0, 1.0)

    def reset(self) -> None:
        """Stateless."""

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self._action.copy()


def slope_residual(task: TaskSpec) -> ConstantRotationResidual:
    """The constant residual that undoes ``task``'s table slope."""
    return ConstantRotationResidual(
        fixture_turn_in_world(task, table_slope_quaternion(task)), task.residual_max_rotation_rad
    )


def fixture_rotation_residual(task: TaskSpec, fixture_dq) -> ConstantRotationResidual:
    """The constant residual that undoes an episode's whole fixture rotation
    ``fixture_dq`` (wxyz, in F; ``EpisodeSpec.fixture_dq``)."""
    dq = np.asarray(fixture_dq, dtype=float).reshape(-1)
    if dq.shape != (4,) or abs(np.linalg.norm(dq) - 1.0) > 1e-6:
        raise ValueError(f"fixture_dq must be a unit quaternion (wxyz), got {fixture_dq!r}")
    return ConstantRotationResidual(fixture_turn_in_world(task, dq), task.residual_max_rotation_rad)
