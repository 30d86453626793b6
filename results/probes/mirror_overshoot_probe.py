# Ad-hoc probe (2026-12-07, evaluation grid seed 0, 200 test starts), run from the repo
# root after section 56's trainings (results/full_pose_study.md) as:
#   .venv/bin/python results/probes/mirror_overshoot_probe.py \
#     > results/probes/mirror_overshoot_probe_2026-12-07.log
# For each mirror-symmetric policy: every start on the +x side (fixture error pointing
# -45..45 deg) that it fails, and its first six successes there, run again with the
# policy's mean action; prints the held offset (the rate residual's integrated
# translation, mm) at 6, 7, 8 and 9 s against the start's fixture error (mm).
import gzip
import json

import numpy as np

from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
from rlfd_drake.evaluate import fixture_direction_deg
from rlfd_drake.policies import DeployedPolicy, load_sb3_model
from rlfd_drake.tasks import load_task

TASK = "models/tasks/variants/peg_incremental.yaml"
RUN = "peg_incremental_ppo_std2_so_tt_lr6e4lin_mirror_e700_s{}"
EVALUATION = "results/eval_peg_incremental_{}_n200_s0.episodes.json.gz"  # {} = the run
RANGE_MM = 10.0  # the residual's 1 cm translation range per unit (peg.yaml)


def held_offsets(task, dmp, spec, model):
    deployed, offsets = DeployedPolicy(model), []

    def policy(obs):
        offsets.append(np.asarray(obs[20:22], dtype=float) * RANGE_MM)
        return deployed(obs)

    result = run_episode(task, dmp, spec, policy)
    at = [
        np.round(offsets[min(len(offsets) - 1, int(round((t - 5.0) / 0.1)))], 2)
        for t in (6, 7, 8, 9)
    ]
    return result, at


if __name__ == "__main__":
    task = load_task(TASK)
    dmp = load_task_dmp(task)
    specs = make_episode_specs(task, 200, 0)
    for seed in (0, 1):
        run = RUN.format(seed)
        success = json.load(gzip.open(EVALUATION.format(run)))["success"]
        plus_x = [i for i, s in enumerate(specs) if -45 <= fixture_direction_deg(s.fixture_dp) < 45]
        failed = [i for i in plus_x if not success[i]]
        chosen = failed + [i for i in plus_x if success[i]][:6]
        model = load_sb3_model(f"runs/{run}/policy.zip")[0]
        overshoot = {True: [], False: []}
        for i in chosen:
            result, at = held_offsets(task, dmp, specs[i], model)
            error = np.round(1e3 * np.asarray(specs[i].fixture_dp[:2]), 2)
            overshoot[bool(result.success)].append(at[-1][0] - error[0])
            outcome = "success" if result.success else result.failure_reason
            print(
                f"seed {seed} start {i}: fixture error x, y {error.tolist()} mm; held offset "
                f"x, y at 6/7/8/9 s {[a.tolist() for a in at]} mm; {outcome}"
            )
        for outcome in (False, True):
            values = np.array(overshoot[outcome])
            if values.size:
                which = "inserted" if outcome else "failed"
                print(
                    f"seed {seed}, {which} +x starts ({values.size}): held offset x at 9 s minus "
                    f"the fixture error x: median {np.median(values):.2f} mm, range "
                    f"{values.min():.2f} to {values.max():.2f} mm"
                )
