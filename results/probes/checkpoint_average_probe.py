# Ad-hoc probe (2026-12-07), run from the repo root as:
#   .venv/bin/python results/probes/checkpoint_average_probe.py RUN K
# Averages, entry by entry, the parameters (and buffers) of RUN's last K checkpoints
# (checkpoints/policy_<steps>_steps.zip, ordered by steps) into one PPO policy and
# saves it as runs/<RUN's name with _sS replaced by _avgK_sS>/policy.zip with RUN's
# config.json, so `rlfd evaluate` takes it like any run. Refuses to overwrite.
import re
import shutil
import sys
from pathlib import Path

import torch

from rlfd_drake.policies import load_sb3_model

if __name__ == "__main__":
    run, k = Path(sys.argv[1]), int(sys.argv[2])
    files = sorted(
        (run / "checkpoints").glob("policy_*_steps.zip"),
        key=lambda p: int(re.search(r"policy_(\d+)_steps", p.name).group(1)),
    )[-k:]
    if len(files) < k:
        raise ValueError(f"{run} has {len(files)} checkpoints, fewer than K={k}")
    models = [load_sb3_model(str(f))[0] for f in files]
    states = [m.policy.state_dict() for m in models]
    averaged = {
        name: (
            torch.stack([s[name].float() for s in states]).mean(0).to(states[-1][name].dtype)
            if states[-1][name].is_floating_point()
            else states[-1][name]
        )
        for name in states[-1]
    }
    target = models[-1]
    target.policy.load_state_dict(averaged)
    name = re.sub(r"_s(\d+)$", rf"_avg{k}_s\1", run.name)
    if name == run.name:
        raise ValueError(f"run name {run.name!r} does not end in _s<seed>")
    out = run.parent / name
    if out.exists():
        raise ValueError(f"{out} exists; not overwriting it")
    out.mkdir()
    target.save(str(out / "policy.zip"))
    shutil.copy(run / "config.json", out / "config.json")
    print(f"{out}/policy.zip: the mean of {', '.join(f.name for f in files)}")
