# Ad-hoc probe (2026-12-07, evaluation grid seed 0, 200 test starts), run from the repo
# root as:
#   .venv/bin/python results/probes/search_overshoot_probe.py RUN [RUN ...] \
#     > results/probes/search_overshoot_probe_2026-12-07.log
# RUN: a peg_incremental run folder name under runs/ whose 200-start evaluation is in
# results/ (eval_peg_incremental_<RUN>_n200_s0). Of the starts with more than 1.5 mm of
# lateral fixture error, every one the stored evaluation failed and the first ten it
# inserted are run again with the policy's mean action (two processes), and the rate
# residual's held translation at the episode's end is projected on the direction of the
# start's lateral error: "progress" (mm) against the error's size.
# A search that runs past the hole ends with progress above the error's size, one that
# stops short or never starts below it.
import gzip
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
from rlfd_drake.policies import DeployedPolicy, load_sb3_model
from rlfd_drake.tasks import load_task

TASK = "models/tasks/variants/peg_incremental.yaml"
RANGE_MM = 10.0  # the residual's 1 cm translation range per unit (peg.yaml)
MIN_ERROR_MM = 1.5
_MODELS = {}


def one(job):
    run, index = job
    task = load_task(TASK)
    spec = make_episode_specs(task, 200, 0)[index]
    if run not in _MODELS:
        _MODELS[run] = load_sb3_model(f"runs/{run}/policy.zip")[0]
    deployed, offsets = DeployedPolicy(_MODELS[run]), []

    def policy(obs):
        offsets.append(np.asarray(obs[20:22], dtype=float) * RANGE_MM)
        return deployed(obs)

    result = run_episode(task, load_task_dmp(task), spec, policy)
    error = 1e3 * np.asarray(spec.fixture_dp[:2])
    size = float(np.linalg.norm(error))
    progress = float(offsets[-1] @ error / size)
    return run, index, bool(result.success), size, progress, result.failure_reason or ""


if __name__ == "__main__":
    runs = sys.argv[1:]
    task = load_task(TASK)
    specs = make_episode_specs(task, 200, 0)
    sizes = [1e3 * float(np.linalg.norm(s.fixture_dp[:2])) for s in specs]
    jobs = []
    for run in runs:
        stored = json.load(
            gzip.open(f"results/eval_peg_incremental_{run}_n200_s0.episodes.json.gz")
        )
        wide = [i for i in range(200) if sizes[i] > MIN_ERROR_MM]
        failed = [i for i in wide if not stored["success"][i]]
        jobs += [(run, i) for i in failed + [i for i in wide if stored["success"][i]][:10]]
    with ProcessPoolExecutor(2) as pool:
        rows = list(pool.map(one, jobs, chunksize=8))
    for run in runs:
        stored = json.load(
            gzip.open(f"results/eval_peg_incremental_{run}_n200_s0.episodes.json.gz")
        )
        mine = [r for r in rows if r[0] == run]
        same = sum(r[2] == bool(stored["success"][r[1]]) for r in mine)
        print(f"{run}: {len(mine)} starts run again, outcome as stored on {same}")
        for outcome in (False, True):
            gaps = np.array([r[4] - r[3] for r in mine if r[2] == outcome])
            if gaps.size:
                print(
                    f"  {'inserted' if outcome else 'failed'} ({gaps.size}): progress minus error "
                    f"size, mm: median {np.median(gaps):+.2f}, quartiles "
                    f"{np.percentile(gaps, 25):+.2f} / {np.percentile(gaps, 75):+.2f}; past the "
                    f"error {int(np.sum(gaps > 0))}, short by more than 1.2 mm "
                    f"{int(np.sum(gaps < -1.2))}"
                )
        for r in mine:
            if not r[2]:
                print(f"    start {r[1]}: error {r[3]:.2f} mm, progress {r[4]:+.2f} mm; {r[5]}")
