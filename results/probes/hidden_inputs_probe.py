# Ad-hoc probe (2026-12-07, evaluation grid seed 0, 200 test starts), run from the repo
# root as:
#   .venv/bin/python results/probes/hidden_inputs_probe.py RUN ENTRIES [ENTRIES ...] \
#     >> results/probes/hidden_inputs_probe_2026-12-07.log
# RUN: a peg_incremental run folder name under runs/ whose 200-start evaluation is in
# results/. ENTRIES: comma-separated observation entries (systems/observer.py) set to 0
# before the policy reads them, at deployment only (no retraining): 0,1 the lateral
# position error, 20,21 the held lateral offset, 12,13,14 the wrist torque. Every start
# with more than 1.5 mm of lateral fixture error is run again with the mean action, and
# the outcomes are counted against the stored evaluation's.
import gzip
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
from rlfd_drake.policies import DeployedPolicy, load_sb3_model
from rlfd_drake.tasks import load_task

TASK = "models/tasks/variants/peg_incremental.yaml"


def one(job):
    run, hidden, index = job
    task = load_task(TASK)
    deployed = DeployedPolicy(load_sb3_model(f"runs/{run}/policy.zip")[0])

    def policy(obs):
        obs = np.array(obs, dtype=np.float32)
        obs[list(hidden)] = 0.0
        return deployed(obs)

    spec = make_episode_specs(task, 200, 0)[index]
    return index, bool(run_episode(task, load_task_dmp(task), spec, policy).success)


if __name__ == "__main__":
    run, hidden_sets = sys.argv[1], [tuple(map(int, a.split(","))) for a in sys.argv[2:]]
    specs = make_episode_specs(load_task(TASK), 200, 0)
    wide = [i for i, s in enumerate(specs) if 1e3 * np.linalg.norm(s.fixture_dp[:2]) > 1.5]
    stored = json.load(gzip.open(f"results/eval_peg_incremental_{run}_n200_s0.episodes.json.gz"))
    failed = [i for i in wide if not stored["success"][i]]
    inserted = [i for i in wide if stored["success"][i]]
    for hidden in hidden_sets:
        with ProcessPoolExecutor(2) as pool:
            now = dict(pool.map(one, [(run, hidden, i) for i in wide], chunksize=8))
        print(
            f"{run}, entries {list(hidden)} hidden: of its {len(failed)} failed starts beyond "
            f"1.5 mm {sum(now[i] for i in failed)} now inserted; of its {len(inserted)} "
            f"inserted ones {sum(now[i] for i in inserted)} still inserted"
        )
