# Ad-hoc probe (2026-12-01, seed: evaluation grid seed 0), run from the repo root as:
#   .venv/bin/python results/probes/rj45_lift_probe.py 0.0 0.5 1.0
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
from rlfd_drake.tasks import load_task

PATH = "models/tasks/variants/rj45_soft_wrist_smooth.yaml"


def one(args):
    i, lift = args
    task = load_task(PATH)
    dmp = load_task_dmp(task)
    spec = make_episode_specs(task, 40, 0)[i]
    a = np.zeros(6, np.float32)
    a[2] = lift
    r = run_episode(task, dmp, spec, policy=(lambda obs: a))
    return lift, i, r.success, r.peak_low_passed_force_n, (r.failure_reason or "")[:12]


if __name__ == "__main__":
    lifts = [float(x) for x in sys.argv[1:]]
    jobs = [(i, l) for l in lifts for i in range(40)]
    with ProcessPoolExecutor(2) as ex:
        res = list(ex.map(one, jobs))
    for l in lifts:
        rs = [r for r in res if r[0] == l]
        print(
            l,
            "success",
            sum(r[2] for r in rs),
            "/40",
            "LP mean",
            np.mean([r[3] for r in rs]).round(1),
            "force_limit",
            sum(r[4].startswith("force") for r in rs),
        )
