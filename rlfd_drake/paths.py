"""Where the shipped model files live, whether the package is installed editable or not."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

#: The shipped rLfD residual (SAC, peg_easy) that `make demo` and `rlfd reproduce` use,
#: and the earlier PPO one; their commands are in models/policies/README.md.
SHIPPED_POLICY = "policies/peg_easy_sac_translation_gs4.zip"
SHIPPED_FULL_POSE_POLICY = "policies/peg_easy_sac.zip"
SHIPPED_PPO_POLICY = "policies/peg_easy_ppo.zip"
#: The RJ-45 policy (PPO from a copy of the force search, rj45_slow_insert variant).
SHIPPED_RJ45_POLICY = "policies/rj45_slow_insert_ppo_imitate.zip"
#: A full-pose peg policy meeting both peg targets (PPO, incremental residual, trained on
#: peg_incremental_wide_error and run on peg_incremental; results/full_pose_study.md 19).
SHIPPED_PEG_INCREMENTAL_POLICY = "policies/peg_incremental_ppo_wide_error.zip"
#: The paper's full-pose recipe from a zero residual on peg_incremental (step 6e-4 falling
#: to zero): of seven training seeds, the one a fixed rule chose on validation starts
#: (results/full_pose_study.md 38 and 39).
SHIPPED_PEG_FROM_ZERO_POLICY = "policies/peg_incremental_ppo_best_of_seven.zip"
#: A full-pose peg policy on the shipped peg (PPO from a copy of the search with the
#: slope's turn, with a peak-force cost): 98.5 % of fresh starts, its one-step peak 7 %
#: above the DMP's there (results/full_pose_study.md 26).
SHIPPED_PEG_IMITATION_POLICY = "policies/peg_ppo_imitate_peak_cost.zip"
#: A full-pose gear policy (PPO, incremental residual that may not push, run on
#: gear_incremental_nopush, 2,100 episodes; results/full_pose_study.md 17 and 30).
SHIPPED_GEAR_POLICY = "policies/gear_incremental_nopush_ppo_e2100.zip"
#: The same recipe charged 0.5 per newton of one-step peak contact force above 103 N (the
#: DMP's mean on validation starts): gear's 93 % with the DMP's peak, on test and fresh
#: starts (results/full_pose_study.md 31).
SHIPPED_GEAR_PEAK_COST_POLICY = "policies/gear_incremental_nopush_ppo_peak_cost_e2100.zip"
#: A full-pose RJ-45 policy on the shipped rj45 (PPO from a copy of the search with the
#: slope's turn, the paper's open-loop DMP; results/rj45_study.md, full_pose_study.md 29).
SHIPPED_RJ45_IMITATION_POLICY = "policies/rj45_ppo_imitate_slope.zip"
#: The same recipe run on rj45_phase_stop (the DMP phase-stopped while the controller lags
#: it, a deviation), where it meets RJ-45's 75 % target (results/rj45_study.md).
SHIPPED_RJ45_PHASE_STOP_POLICY = "policies/rj45_phase_stop_ppo_imitate_slope.zip"
#: A rate residual that may not push, on rj45_phase_stop_incremental_nopush (PPO from a
#: copy of the search taught through the rate): RJ-45's 75 % with the DMP's peak, on test
#: and fresh starts (results/full_pose_study.md 30, models/policies/README.md).
SHIPPED_RJ45_PHASE_STOP_RATE_POLICY = "policies/rj45_phase_stop_nopush_ppo_imitate.zip"


def models_dir() -> Path:
    """The folder of the shipped models (top-level ``models/``, installed as
    ``rlfd_drake.models``)."""
    return Path(str(resources.files("rlfd_drake.models")))


def shipped_path(path: str | Path) -> Path:
    """``path`` as given where it exists; a relative ``models/...`` path that does not
    exist from here (RUNS' ``--task models/tasks/variants/...``, README commands: written
    from the checkout's root) read from the installed package's models folder instead, so
    they run from any folder; otherwise as given, for the caller's error to name."""
    path = Path(path)
    if path.exists() or path.is_absolute() or path.parts[:1] != ("models",):
        return path
    installed = models_dir().joinpath(*path.parts[1:])
    return installed if installed.exists() else path


def model_path(relative: str) -> Path:
    """Absolute path of a shipped model file; ValueError if it does not exist."""
    path = models_dir() / relative
    if not path.exists():
        raise ValueError(f"model file {relative!r} not found under {models_dir()}")
    return path
