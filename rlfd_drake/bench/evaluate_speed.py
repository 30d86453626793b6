"""Evaluation throughput of this code against another commit's (``rlfd bench evaluate``).

``run()`` evaluates the same cells (task, policy) the way ``rlfd reproduce`` does, one
after another with two worker processes, once with this checkout's package and once with
the package of ``against`` (a git revision, extracted with ``git archive`` into a
temporary folder), each in a fresh interpreter, the two alternating within every repeat
so that they share the machine's state. It reports each code's median wall time, their
ratio, and whether the two ran the very same episodes (success, insertion time and peak
forces of every start), so a speed-up that changed the physics shows as such, and the
largest resident set an evaluation worker reached (a diagram kept per episode shows as
memory that grows with the episodes a worker runs).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from rlfd_drake.paths import models_dir
from rlfd_drake.run_queue import check_count, check_seed

__all__ = ["DEFAULT_CELLS", "run"]

#: (task, policy, residual mode): the DMP and shipped residuals on each task, the
#: kinds of cell the paper tables evaluate (paths are made absolute under models/).
DEFAULT_CELLS = (
    ("gear", "dmp", "full"),
    ("peg_easy", "policies/peg_easy_sac_translation_gs4.zip", "translation"),
    (
        "tasks/variants/rj45_phase_stop_incremental_nopush.yaml",
        "policies/rj45_phase_stop_nopush_ppo_imitate.zip",
        "full",
    ),
    ("peg", "policies/peg_ppo_imitate_peak_cost.zip", "full"),
)

#: Keys of each episode compared between the two codes.
_COMPARED = ("success", "insertion_time_s", "peak_force_n", "peak_low_passed_force_n")

# Run in a fresh interpreter with PYTHONPATH set to the code under test. Old code has
# no shared pool: each evaluation then spawns its own, as it did.
_SCRIPT = """
import contextlib, json, resource, sys, time
import rlfd_drake, rlfd_drake.models, rlfd_drake.evaluate as E
cells, episodes, seed, keys = json.loads(sys.argv[1])
shared = getattr(E, "shared_evaluation_workers", None)
out = {"package": rlfd_drake.__file__, "models": rlfd_drake.models.__file__, "cells": []}
started = time.perf_counter()
with (shared(2) if shared else contextlib.nullcontext()):
    for task, policy, mode in cells:
        t = time.perf_counter()
        r = E.evaluate(task, policy, episodes, seed, workers=2, progress=False,
                       residual_mode=mode)
        out["cells"].append({"wall_s": time.perf_counter() - t,
                             "episodes": {k: r["episode_table"][k] for k in keys}})
out["wall_s"] = time.perf_counter() - started
# The workers have been joined: the largest resident set any of them reached (kB).
out["worker_max_rss_mb"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
print("RESULT " + json.dumps(out))
"""


def _absolute(name: str) -> str:
    """A file here or under models/ made absolute (both codes read the same files,
    from the temporary folder they run in)."""
    if Path(name).exists():
        return str(Path(name).resolve())
    path = models_dir() / name
    return str(path) if path.exists() else name


def _cells(cells) -> list[tuple[str, str, str]]:
    return [(_absolute(task), _absolute(policy), mode) for task, policy, mode in cells]


def _checkout_root() -> Path:
    """The folder holding this package (PYTHONPATH for this code)."""
    import rlfd_drake

    return Path(rlfd_drake.__file__).resolve().parent.parent


def _extract(revision: str, into: Path) -> str:
    """Extracts ``revision`` of this checkout's repository into ``into``; its commit."""
    root = _checkout_root()
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--verify", f"{revision}^{{commit}}"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError) as error:
        raise ValueError(
            f"against: {revision!r} is not a commit of a git checkout at {root} ({error})"
        ) from error
    archive = subprocess.run(
        ["git", "-C", str(root), "archive", commit, "rlfd_drake", "models"],
        check=True,
        capture_output=True,
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    # Installed, models/ is the package rlfd_drake.models: the same from the tree alone.
    (into / "rlfd_drake" / "models").symlink_to(into / "models", target_is_directory=True)
    return commit


def _time_code(code_root: Path, cells, episodes: int, seed: int, folder: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code_root))
    done = subprocess.run(
        [sys.executable, "-c", _SCRIPT, json.dumps([cells, episodes, seed, _COMPARED])],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"the evaluation with {code_root} failed:\n{done.stderr[-2000:]}")
    result = json.loads(lines[-1][len("RESULT ") :])
    for key in ("package", "models"):
        path = Path(result[key])  # not resolved: the tree's models/ is a link
        if code_root not in path.parents:
            raise RuntimeError(f"ran the {key} at {path}, not the one in {code_root}")
    return result


def run(
    against: str = "HEAD~1",
    repeats: int = 3,
    episodes: int = 8,
    seed: int = 0,
    cells=DEFAULT_CELLS,
) -> dict:
    """Median wall time of evaluating ``cells`` (``episodes`` starts each, seed
    ``seed``, two workers) with this code and with ``against``'s.

    Returns:
        ``{"wall_s": {"this", "against"}, "speedup": against / this,
        "samples_s", "per_episode_s", "worker_max_rss_mb" (median over repeats of the
        largest resident set an evaluation worker reached), "same_episodes",
        "success_pct" (per code, per
        cell, of the last repeat), "against_commit", "cells",
        "episodes", "repeats", "seed"}``.
    """
    check_count("repeats", repeats)
    check_count("episodes", episodes)
    check_seed("seed", seed)
    cells = _cells(cells)
    samples: dict[str, list[float]] = {"this": [], "against": []}
    rss: dict[str, list[float]] = {"this": [], "against": []}
    episodes_of: dict[str, list] = {}
    with tempfile.TemporaryDirectory(prefix="rlfd_bench_evaluate_") as folder:
        tree = Path(folder) / "against"
        tree.mkdir()
        commit = _extract(against, tree)
        work = Path(folder) / "work"
        work.mkdir()
        roots = {"this": _checkout_root(), "against": tree}
        for repeat in range(repeats):
            # Alternate which goes first, so neither always runs on a cold machine.
            order = ("this", "against") if repeat % 2 == 0 else ("against", "this")
            for code in order:
                result = _time_code(roots[code], cells, episodes, seed, work)
                samples[code].append(result["wall_s"])
                rss[code].append(result["worker_max_rss_mb"])
                episodes_of[code] = [cell["episodes"] for cell in result["cells"]]
    wall = {code: statistics.median(s) for code, s in samples.items()}
    total = episodes * len(cells)
    success_pct = {
        code: [100.0 * sum(cell["success"]) / episodes for cell in of]
        for code, of in episodes_of.items()
    }
    return {
        "wall_s": wall,
        "speedup": wall["against"] / wall["this"],
        "samples_s": samples,
        "per_episode_s": {code: w / total for code, w in wall.items()},
        "worker_max_rss_mb": {code: statistics.median(r) for code, r in rss.items()},
        "worker_max_rss_mb_samples": rss,
        "same_episodes": episodes_of["this"] == episodes_of["against"],
        "success_pct": success_pct,
        "against": against,
        "against_commit": commit,
        "cells": [list(cell) for cell in cells],
        "episodes": episodes,
        "repeats": repeats,
        "seed": seed,
        "workers": 2,
    }
