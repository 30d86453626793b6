# Ad-hoc probe (2026-12-07, evaluation grid seed 0), run from the repo root as:
#   .venv/bin/python results/probes/wrench_chatter_probe.py RUN N \
#     >> results/probes/wrench_chatter_probe_2026-12-07.log
# How much of the wrist torque the policy reads at 10 Hz is chatter of the 2 ms plant
# step rather than the slow signal a search could steer by. The first N test starts with
# more than 1.5 mm of lateral fixture error are run in the training env with RUN's mean
# action; within each 100 ms residual step the wrist torque (observation 12-14, x and y)
# is sampled every 2 ms. Reported: the spread of the 2 ms samples inside a step against
# the spread of the steps' means, and how often the sample the policy reads (the step's
# first) has the other sign from the step's mean on an axis where the mean is > 0.1 N m.
import sys

import numpy as np

from rlfd_drake.env import RlfdEnv
from rlfd_drake.episode import make_episode_specs
from rlfd_drake.policies import load_sb3_model
from rlfd_drake.tasks import load_task

TASK = "models/tasks/variants/peg_incremental.yaml"
SUBSTEPS = 50  # 100 ms residual step / 2 ms plant step

if __name__ == "__main__":
    run, n = sys.argv[1], int(sys.argv[2])
    task = load_task(TASK)
    model = load_sb3_model(f"runs/{run}/policy.zip")[0]
    specs = make_episode_specs(task, 200, 0)
    wide = [i for i, s in enumerate(specs) if 1e3 * np.linalg.norm(s.fixture_dp[:2]) > 1.5][:n]
    env = RlfdEnv(task=task)
    inside, between, flips, read = [], [], 0, 0
    for index in wide:
        spec = specs[index]
        obs, _ = env.reset(
            seed=0,
            options=dict(
                start_dp=spec.start_dp,
                start_dq=spec.start_dq,
                fixture_dp=spec.fixture_dp,
                fixture_dq=spec.fixture_dq,
            ),
        )
        means = []
        for _ in range(int(task.episode_time_s * 10)):
            action, _ = model.predict(obs, deterministic=True)
            context = env.simulator.get_mutable_context()
            env.action_port.FixValue(context, np.clip(action, -1.0, 1.0))
            first = np.asarray(obs[12:14], dtype=float).copy()
            samples = []
            t0 = context.get_time()
            for k in range(1, SUBSTEPS + 1):
                env.simulator.AdvanceTo(t0 + k * 0.1 / SUBSTEPS)
                samples.append(env.observation_port.Eval(context)[12:14].copy())
            samples = np.array(samples) * 5.0  # torque_scale_Nm: back to N m
            mean = samples.mean(axis=0)
            inside.append(samples.std(axis=0))
            means.append(mean)
            for axis in range(2):
                if abs(mean[axis]) > 0.1:
                    read += 1
                    flips += int(np.sign(first[axis] * 5.0) != np.sign(mean[axis]))
            obs = env.observation_port.Eval(context).astype(np.float32)
            if env.rlfd.diagram.GetOutputPort("success").Eval(context)[0] > 0.5:
                break
        between.append(np.array(means).std(axis=0))
    inside, between = np.array(inside), np.array(between)
    print(
        f"{run}, {len(wide)} starts beyond 1.5 mm: wrist torque x / y, median spread of the "
        f"2 ms samples within a 100 ms step {np.median(inside[:, 0]):.3f} / "
        f"{np.median(inside[:, 1]):.3f} N m (90th pct {np.percentile(inside[:, 0], 90):.3f} / "
        f"{np.percentile(inside[:, 1], 90):.3f}); spread of the steps' means over an episode, "
        f"median {np.median(between[:, 0]):.3f} / {np.median(between[:, 1]):.3f} N m; the "
        f"sample read has the other sign from its step's mean on {flips} of {read} "
        f"step-axes with |mean| > 0.1 N m"
    )
