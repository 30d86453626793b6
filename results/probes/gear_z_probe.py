# Ad-hoc probe (2026-12-01, seed: evaluation grid seed 0), run from the repo root as:
#   .venv/bin/python results/probes/gear_z_probe.py runs/<run>/policy.zip -1:1 0:0 0:0.3
"""Probe: a trained gear no-push residual with its z action clipped to [lo, hi] at
deployment; success, one-step / LP peak, peak time and distance, over 40 starts."""

import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
from rlfd_drake.evaluate import make_policy
from rlfd_drake.tasks import load_task

PATH = "models/tasks/variants/gear_soft_wrist_smooth_rot2deg_nopush.yaml"
POLICY = sys.argv[1]


def one(args):
    i, lo, hi = args
    task = load_task(PATH)
    dmp = load_task_dmp(task)
    spec = make_episode_specs(task, 40, 0)[i]
    policy = make_policy(POLICY, "full", episode_seed=i, task=task, dmp=dmp)
    zs = []

    def clipped(obs):
        a = np.array(policy(obs), dtype=np.float32)
        zs.append(float(a[2]))
        a[2] = np.clip(a[2], lo, hi)
        return a

    if hasattr(policy, "reset"):
        policy.reset()
    r = run_episode(task, dmp, spec, policy=clipped)
    return (
        (lo, hi),
        i,
        r.success,
        r.peak_force_n,
        r.peak_low_passed_force_n,
        r.peak_force_time_s,
        r.peak_force_distance_m * 1e3,
        zs[:12],
    )


if __name__ == "__main__":
    ranges = [tuple(float(v) for v in s.split(":")) for s in sys.argv[2:]]
    jobs = [(i, lo, hi) for (lo, hi) in ranges for i in range(40)]
    with ProcessPoolExecutor(2) as ex:
        res = list(ex.map(one, jobs))
    for rg in ranges:
        rs = [r for r in res if r[0] == rg]
        print(
            rg,
            "success %.1f" % (100 * np.mean([r[2] for r in rs])),
            f"peak {np.mean([r[3] for r in rs]):.0f}",
            f"LP {np.mean([r[4] for r in rs]):.0f}",
            f"t {np.median([r[5] for r in rs]):.2f}",
            f"d {np.median([r[6] for r in rs]):.1f}",
        )
        if rg == ranges[0]:
            for r in rs[:4]:
                print("  z actions", np.round(r[7], 2))
