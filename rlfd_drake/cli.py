"""The ``rlfd`` command.

Subcommands import their modules lazily so that ``rlfd --help`` and ``rlfd tasks`` are
fast. Every measurement subcommand writes JSON to ``results/`` with its command line,
seed and date (see ``results.write_result``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from rlfd_drake.control_math import COMPOSITIONS, PEAK_FORCE_SIGNALS


def _print_json(data: dict) -> None:
    print(json.dumps(data, indent=2))


def _cmd_tasks(args: argparse.Namespace) -> int:
    from rlfd_drake.tasks import describe_task, list_tasks, load_task

    rows = {name: describe_task(load_task(name, check_demo=False)) for name in list_tasks()}
    if args.json:
        _print_json(rows)
    else:
        for name, row in rows.items():
            print(name)
            for key, value in row.items():
                print(f"  {key}: {value}")
    return 0


def _bench_cell(words: list[str]) -> tuple[str, str, str]:
    """(task, policy, residual mode) of one ``--cell TASK POLICY [MODE]``."""
    if len(words) not in (2, 3):
        raise ValueError(f"--cell takes TASK POLICY [MODE], got {' '.join(words)!r}")
    return (words[0], words[1], words[2] if len(words) == 3 else "full")


def _cmd_bench(args: argparse.Namespace) -> int:
    from rlfd_drake.results import write_result

    queue_flags = (args.queue_runs, args.queue_episodes, args.queue_parallel)
    if queue_flags != (None, None, None) and args.what != "train-queue":
        raise ValueError(
            "--queue-runs/--queue-episodes/--queue-parallel: only the train-queue benchmark "
            f"takes them, not {args.what!r}"
        )
    if args.tasks and args.what != "diagram":
        raise ValueError(f"--tasks: only the diagram benchmark takes tasks, not {args.what!r}")
    if (args.cell or args.starts is not None) and args.what != "evaluate":
        raise ValueError(
            f"--cell/--starts: only the evaluate benchmark takes them, not {args.what!r}"
        )
    if (args.against is not None) != (args.what == "evaluate"):
        raise ValueError(
            "--against REV: the evaluate benchmark needs it (the commit to compare with) "
            f"and only it takes it, got {args.against!r} for {args.what!r}"
        )
    name = f"bench_{args.what}"
    if args.what == "sim":
        from rlfd_drake.bench import sim

        data = sim.run(repeats=args.repeats)
        if args.study:
            study = sim.time_step_study()
            print(f"wrote {write_result('bench_sim_time_step_study', study)}")
    elif args.what == "dmp":
        from rlfd_drake.bench import dmp

        data = dmp.run(repeats=args.repeats)
    elif args.what == "diagram":
        from rlfd_drake.bench import diagram
        from rlfd_drake.tasks import load_task

        if args.tasks:
            # A chosen set of tasks is its own record: bench_diagram.json keeps all tasks'.
            name += "_" + "_vs_".join(load_task(task).name for task in args.tasks)
            data = diagram.run(repeats=args.repeats, tasks=args.tasks, profile_task=args.tasks[-1])
        else:
            data = diagram.run(repeats=args.repeats)
    elif args.what == "train-queue":
        from rlfd_drake.bench import train_queue

        given = {"runs": args.queue_runs, "episodes": args.queue_episodes}
        if args.queue_parallel is not None:
            given["parallel"] = tuple(args.queue_parallel)
        settings = {key: value for key, value in given.items() if value is not None}
        data = train_queue.run(repeats=args.repeats, **settings)  # its defaults otherwise
        name = f"bench_train_queue_{data['runs']}x{data['episodes']}"
        if args.queue_parallel is not None:
            name += "_at_once_" + "_".join(data["wall_s"])
    elif args.what == "evaluate":
        from rlfd_drake.bench import evaluate_speed

        cells = {}
        if args.cell:
            cells["cells"] = [_bench_cell(cell) for cell in args.cell]
        if args.starts is not None:
            cells["episodes"] = args.starts
        data = evaluate_speed.run(against=args.against, repeats=args.repeats, **cells)
        name = bench_evaluate_name(data["against_commit"], cells.get("cells"))
    else:  # argparse restricts the choices
        raise ValueError(f"unknown benchmark {args.what!r}")
    path = write_result(name, data)
    if args.json:
        _print_json(data)
    else:
        print(f"wrote {path}")
    return 0


#: Longest results file stem ``rlfd bench evaluate`` writes (file names stop at 255 bytes).
_BENCH_NAME_MAX = 160


def bench_evaluate_name(against_commit: str, cells: list[tuple[str, str, str]] | None) -> str:
    """``bench_evaluate_vs_<commit>``, and for chosen cells their tasks and policies
    (a run's ``policy.zip`` by its run folder, as evaluations are named); a name that
    would be too long for a file keeps its start and ends in a hash of the whole."""
    from rlfd_drake.evaluate import policy_stem
    from rlfd_drake.results import capped_stem

    name = f"bench_evaluate_vs_{against_commit[:7]}"
    if cells:  # chosen cells are their own record
        name += "_" + "__".join(f"{Path(t).stem}_{policy_stem(p)}" for t, p, _ in cells)
    return capped_stem(name, _BENCH_NAME_MAX)


def _cmd_demo_record(args: argparse.Namespace) -> int:
    from rlfd_drake.demonstration import save_demonstration
    from rlfd_drake.expert import ExpertConfig, record_demonstration
    from rlfd_drake.tasks import load_task

    if Path(args.out).exists() and not args.overwrite:
        raise FileExistsError(f"{args.out} exists; pass --overwrite to replace it")
    config = ExpertConfig() if args.insert_s is None else ExpertConfig(insert_s=args.insert_s)
    task = load_task(args.task, check_demo=False)
    demo = record_demonstration(task, seed=args.seed, config=config)
    path = save_demonstration(demo, args.out, overwrite=args.overwrite)
    print(f"recorded {len(demo.times)} poses over {demo.duration:.2f} s -> {path}")
    return 0


def _cmd_demo_teleop(args: argparse.Namespace) -> int:
    """A demonstration driven from Meshcat sliders, recorded at 100 Hz."""
    from pydrake.geometry import Meshcat

    from rlfd_drake.demonstration import save_demonstration
    from rlfd_drake.tasks import load_task
    from rlfd_drake.teleop import (
        STOP_BUTTON,
        AddTeleopControls,
        TeleopConfig,
        record_teleop_demonstration,
    )

    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise FileExistsError(f"{out} exists; pass --overwrite to replace it")
    if out.suffix.lower() not in (".csv", ".npz"):
        raise ValueError(f"--out must end in .csv or .npz, got {str(out)!r}")
    config = TeleopConfig(duration_s=args.duration)
    task = load_task(args.task, check_demo=False)
    meshcat = Meshcat()
    AddTeleopControls(meshcat, config)
    print(
        f"Meshcat: {meshcat.web_url()}\n"
        "  drive the part with the x, y, z, roll, pitch, yaw sliders (offsets from the "
        f"start pose); click '{STOP_BUTTON}' to finish (at most {config.duration_s:g} s)",
        flush=True,
    )
    session = record_teleop_demonstration(task, config=config, meshcat=meshcat)
    demo = session.demonstration
    path = save_demonstration(demo, out, overwrite=args.overwrite)
    print(
        f"recorded {len(demo)} poses over {demo.duration:.2f} s "
        f"(stopped by the {session.stopped_by}) -> {path}"
    )
    return 0


def _cmd_view(args: argparse.Namespace) -> int:
    """One episode in Meshcat: live (prints the URL), or saved as a standalone HTML
    replay that any browser opens without a server."""

    from pydrake.geometry import Meshcat

    from rlfd_drake.diagram import NominalGoal, RlfdDiagramConfig
    from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
    from rlfd_drake.evaluate import make_policy
    from rlfd_drake.tasks import load_task
    from rlfd_drake.view import LookAtWorkCell

    html = Path(args.html) if args.html else None
    if html is not None:
        if html.exists() and not args.overwrite:
            raise FileExistsError(f"{html} exists; pass --overwrite to replace it")
        if html.suffix.lower() not in (".html", ".htm"):
            raise ValueError(f"--html must end in .html, got {str(html)!r}")
        if not html.parent.is_dir():
            raise ValueError(f"--html folder {str(html.parent)!r} does not exist")
    if not (np.isfinite(args.realtime_rate) and args.realtime_rate >= 0):
        raise ValueError(f"--realtime-rate must be >= 0, got {args.realtime_rate}")
    task = load_task(args.task)
    from rlfd_drake.evaluate import NAMED_POLICIES, diagram_residual_mode, trained_mode
    from rlfd_drake.policies import policy_file

    if args.policy not in NAMED_POLICIES and not policy_file(args.policy).is_file():
        raise ValueError(
            f"--policy must be one of {NAMED_POLICIES} or a saved policy .zip, got "
            f"{args.policy!r} (no such file)"
        )
    # The parts of the residual the policy was trained to set (see rlfd evaluate).
    residual_mode = trained_mode(args.policy)
    dmp_model = load_task_dmp(task)
    spec = make_episode_specs(task, 1, args.seed, grid=False)[0]
    policy = make_policy(
        args.policy,
        residual_mode,
        episode_seed=args.seed,
        task=task,
        dmp=dmp_model,
        fixture_dq=spec.fixture_dq,
    )
    meshcat = Meshcat()
    LookAtWorkCell(meshcat, NominalGoal(task))
    print(f"Meshcat: {meshcat.web_url()}", flush=True)
    result = run_episode(
        task,
        dmp_model,
        spec,
        policy,
        diagram_config=RlfdDiagramConfig(
            residual_mode=diagram_residual_mode(args.policy, residual_mode)
        ),
        meshcat=meshcat,
        record_html=html,
        realtime_rate=None if html is not None else args.realtime_rate,
    )
    outcome = "success" if result.success else f"failure ({result.failure_reason})"
    print(
        f"{task.name} {args.policy} seed {args.seed}: {outcome}, {result.sim_time_s:.1f} s "
        f"simulated, final distance {1e3 * result.final_distance_m:.1f} mm"
    )
    if html is not None:
        print(f"replay saved to {html} ({html.stat().st_size / 1e6:.1f} MB): open it in a browser")
    else:
        print("the recording is published: replay it from Meshcat's Animations controls")
        if sys.stdin.isatty():
            print("Ctrl-C to quit", flush=True)
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass
    return 0


from rlfd_drake.paths import SHIPPED_POLICY  # noqa: E402  (re-exported for notebooks)
from rlfd_drake.reproduce import (  # noqa: E402  (light: numpy only; --table choices)
    PAPER_TABLES,
    QUICK_RUN_EPISODES,
    TABLES,
)
from rlfd_drake.run_queue import TrainingFailed  # noqa: E402  (light: standard library only)


def _cmd_demo_main(args: argparse.Namespace) -> int:
    """The main job: DMP from the shipped demo, DMP alone vs rLfD on perturbed starts,
    and a Meshcat HTML replay of one rLfD episode."""
    from pydrake.geometry import Meshcat

    from rlfd_drake.diagram import RlfdDiagramConfig
    from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode
    from rlfd_drake.evaluate import (
        evaluate,
        make_policy,
        shared_evaluation_workers,
        trained_mode,
        write_evaluation,
    )
    from rlfd_drake.paths import models_dir
    from rlfd_drake.results import results_dir, write_result
    from rlfd_drake.tasks import load_task

    wall_start = time.perf_counter()
    for name in ("episodes", "workers"):  # before the DMP is fitted, not after
        if getattr(args, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(args, name)}")
    task = load_task(args.task)
    dmp_model = load_task_dmp(task)
    print(f"[1/4] fitted the DMP on {task.demo_path().name} ({task.name})")
    policy_path = models_dir() / SHIPPED_POLICY
    policies = ["dmp"] + ([str(policy_path)] if policy_path.exists() else [])
    residual_mode = trained_mode(str(policy_path))
    if len(policies) == 1:
        print(f"      no trained residual at {policy_path}: running the DMP alone")
    rows = {}
    # One pool for both: rLfD's episodes resume from the DMP's first halves.
    with shared_evaluation_workers(args.workers):
        for step, spec in enumerate(policies, start=2):
            label = "DMP only" if spec == "dmp" else "rLfD (DMP + residual)"
            print(f"[{step}/4] {label} on {args.episodes} perturbed starts (seed {args.seed})")
            result = evaluate(
                task.name,
                spec,
                args.episodes,
                args.seed,
                workers=args.workers,
                grid=False,
                residual_mode=residual_mode,
            )
            name = f"demo_{task.name}_{'dmp' if spec == 'dmp' else 'rlfd'}"
            write_evaluation(result, name, plot=True)
            rows[label] = result
    print()
    print(f"{'policy':<24}{'success %':>10}{'insert s':>10}{'peak N':>9}{'mean N':>9}")
    for label, result in rows.items():
        time_s = result["insertion_time_s"]
        print(
            f"{label:<24}{100 * result['success_rate']:>10.1f}"
            f"{(time_s if time_s is not None else float('nan')):>10.2f}"
            f"{result['peak_force_n']:>9.1f}{result['mean_force_n']:>9.1f}"
        )
    print("[4/4] recording a Meshcat replay of one episode")
    spec = make_episode_specs(task, 1, args.seed, grid=False)[0]
    meshcat = Meshcat()
    html = results_dir() / f"demo_{task.name}_replay.html"
    replay = run_episode(
        task,
        dmp_model,
        spec,
        make_policy(policies[-1], residual_mode, task=task),
        diagram_config=RlfdDiagramConfig(residual_mode=residual_mode),
        meshcat=meshcat,
        record_html=html,
    )
    write_result(
        f"demo_{task.name}",
        {
            label: {k: r[k] for k in ("success_rate", "success_std", "episodes")}
            for label, r in rows.items()
        }
        | {
            "replay_html": html.name,
            "replay_success": replay.success,
            "wall_time_s": time.perf_counter() - wall_start,
        },
        seed=args.seed,
    )
    print(f"      replay ({'success' if replay.success else 'failure'}) saved to {html}")
    return 0


def _cmd_fit(args: argparse.Namespace) -> int:
    from rlfd_drake.demonstration import load_demonstration
    from rlfd_drake.dmp import DmpConfig, fit_cartesian_dmp, rollout
    from rlfd_drake.geometry import quat_error

    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise FileExistsError(f"{out} exists; pass --overwrite to replace it")
    if out.suffix != ".npz":
        raise ValueError(f"--out must end in .npz, got {str(out)!r}")
    demo = load_demonstration(args.demo)
    config = DmpConfig(
        n_basis_translation=args.basis_translation, n_basis_orientation=args.basis_orientation
    )
    model = fit_cartesian_dmp(demo.times, demo.positions, demo.quats, config)
    _, positions, _, quats, _ = rollout(model, dt=float(np.median(np.diff(demo.times))))
    n = min(len(positions), len(demo.positions))
    rmse_mm = 1000 * float(np.sqrt(np.mean(np.sum((positions[:n] - demo.positions[:n]) ** 2, 1))))
    angles = np.linalg.norm(quat_error(demo.quats[:n], quats[:n]), axis=1)
    rmse_deg = float(np.degrees(np.sqrt(np.mean(angles**2))))
    np.savez(
        out,
        weights_translation=model.weights_translation,
        weights_orientation=model.weights_orientation,
        y0=model.y0,
        g=model.g,
        q0=model.q0,
        qg=model.qg,
        tau=model.tau,
        n_basis_translation=args.basis_translation,
        n_basis_orientation=args.basis_orientation,
    )
    print(
        json.dumps({"out": str(out), "position_rmse_mm": rmse_mm, "orientation_rmse_deg": rmse_deg})
    )
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from rlfd_drake.train import TrainConfig, train

    # Only a given --ppo-n-steps / --ppo-gae-lambda / --ppo-epochs / --ppo-hidden-layers /
    # --ppo-actor-layers reaches the config, whose defaults they are.
    ppo_rollout = {
        key: value
        for key, value in (
            ("ppo_n_steps", args.ppo_n_steps),
            ("ppo_gae_lambda", args.ppo_gae_lambda),
            ("ppo_epochs", args.ppo_epochs),
            ("ppo_hidden_layers", args.ppo_hidden_layers),
            ("ppo_actor_layers", args.ppo_actor_layers),
        )
        if value is not None
    }
    config = TrainConfig(
        task=args.task,
        algo=args.algo,
        episodes=args.episodes,
        seed=args.seed,
        envs=args.envs,
        residual_mode=args.residual_mode,
        reward=args.reward,
        curriculum=args.curriculum,
        eval_every_episodes=args.eval_every,
        eval_episodes=args.eval_episodes,
        checkpoint_every_episodes=args.checkpoint_every,
        sac_target_entropy=args.sac_target_entropy,
        log_std_init=args.log_std_init,
        log_std_final=args.log_std_final,
        learning_rate=args.learning_rate,
        learning_rate_schedule=args.learning_rate_schedule,
        ppo_sde_sample_steps=args.ppo_sde_sample_steps,
        ppo_history=args.ppo_history,
        **ppo_rollout,
        sac_learning_starts=args.sac_learning_starts,
        sac_critic_burn_in=args.sac_critic_burn_in,
        sac_initial_ent_coef=args.sac_initial_ent_coef,
        sac_gradient_steps=args.sac_gradient_steps,
        composition=args.composition,
        init_from=args.init_from,
        force_limit_n=args.force_limit_n,
        force_limit_penalty=args.force_limit_penalty,
        peak_force_cost=args.peak_force_cost,
        peak_force_threshold_n=args.peak_force_threshold_n,
        peak_force_signal=args.peak_force_signal,
        action_cost=args.action_cost,
        distance_shaping=args.distance_shaping,
        distance_shaping_axes=args.distance_shaping_axes,
        base_correction=args.base_correction,
        timeout_terminal=args.timeout_terminal,
        imitate=args.imitate,
        privileged_critic=args.privileged_critic,
        mirror_symmetry=args.mirror_symmetry,
        hidden_observation=tuple(args.hide_observation),
        lateral_log_std_init=args.lateral_log_std_init,
        self_imitation_batches=args.self_imitation_batches,
        scaled_observation=args.scaled_observation,
        applied_action_only=args.applied_action_only,
        sac_correlated_noise=tuple(args.sac_correlated_noise),
        sac_correlated_noise_time_s=args.sac_correlated_noise_time_s,
        # The default stays TrainConfig's (importing it here would load torch).
        **({} if args.contact_torque_nm is None else {"contact_torque_nm": args.contact_torque_nm}),
        **{
            key: value
            for key, value in (
                ("imitation_episodes", args.imitation_episodes),
                ("imitation_epochs", args.imitation_epochs),
            )
            if value is not None
        },
    )
    out = Path(args.out) if args.out else Path("runs") / f"{args.task}_{args.algo}_s{args.seed}"
    metrics = train(config, out, resume=args.resume, progress_bar=not args.no_progress)
    _print_json({"run": str(out), **metrics})
    return 0


def _cmd_baseline(args: argparse.Namespace) -> int:
    from rlfd_drake.baselines.episodic import BaselineConfig, train_baseline

    config = BaselineConfig(
        task=args.task,
        method=args.method,
        episodes=args.episodes,
        seed=args.seed,
        workers=args.workers,
        residual_mode=args.residual_mode,
    )
    out = Path(args.out) if args.out else Path("runs") / f"{args.task}_{args.method}_s{args.seed}"
    metrics = train_baseline(config, out, progress=not args.no_progress)
    _print_json({"run": str(out), "policy": str(out / "baseline.npz"), **metrics})
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from rlfd_drake.policies import export_policy

    path = export_policy(args.policy, args.out, overwrite=args.overwrite)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


def _print_training_plan(name: str, numbers: list[str], training_seeds: tuple[int, ...]) -> int:
    """``rlfd reproduce --plan``: the runs the tables rest on, with their recorded training
    times, printed and written to results/reproduce_plan_<table>[_training_seeds_..].json."""
    from rlfd_drake.reproduce import table_name, training_plan
    from rlfd_drake.results import write_result

    plan = training_plan(numbers, training_seeds)
    print(
        "| run | starts from | policy here | quick budget trains | recorded training min "
        "| command |"
    )
    print("|---|---|---|---|---|---|")
    yes_no = {True: "yes", False: "no"}
    for run in plan["runs"]:
        wall = run["recorded_wall_time_s"]
        minutes = "no record" if wall is None else f"{wall / 60:.1f}"
        print(
            f"| {run['folder']} | {run['after'] or '-'} | {yes_no[run['policy_here']]} "
            f"| {yes_no[run['quick_budget_trains']]} | {minutes} | {run['command']} |"
        )
    total = plan["recorded_total_wall_time_s"] / 3600
    quick = sum(run["quick_budget_trains"] for run in plan["runs"])
    print(
        f"\n{len(plan['runs'])} runs, {total:.1f} h of recorded training one at a time "
        f"({plan['runs_without_record']} without a record); rlfd reproduce --train-missing "
        "trains those with neither a policy here nor a stored evaluation, the quick budget "
        f"without it only those among the {quick} short ones (quick budget trains: yes)"
    )
    path = write_result(
        f"reproduce_plan_{table_name(name, training_seeds).removeprefix('table_')}", plan
    )
    print(f"wrote {path}")
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from rlfd_drake.reproduce import reproduce_tables
    from rlfd_drake.run_queue import default_parallel_runs

    groups = {"all": sorted(TABLES), "paper": list(PAPER_TABLES)}
    for group in groups:
        if group in args.table and len(args.table) > 1:
            raise ValueError(f"--table: {group!r} stands alone, got {args.table}")
    grouped = args.table[0] in groups
    numbers = groups[args.table[0]] if grouped else list(dict.fromkeys(args.table))
    if args.plan:
        name = args.table[0] if grouped else "_".join(numbers)
        return _print_training_plan(name, numbers, tuple(args.training_seeds))
    reproduce_tables(
        numbers,
        budget=args.budget,
        seed=args.seed,
        workers=args.workers,
        training_seeds=tuple(args.training_seeds),
        train_missing=args.train_missing,
        parallel_runs=default_parallel_runs() if args.parallel_runs is None else args.parallel_runs,
    )
    return 0


def _parse_targets(items: list[str]) -> dict[str, float]:
    """``task=percent`` items as a dict; ValueError naming the malformed one."""
    targets = {}
    for item in items:
        task, _, value = item.partition("=")
        try:
            targets[task] = float(value)
        except ValueError:
            raise ValueError(
                f"--target must be TASK=PERCENT (e.g. peg_easy=95), got {item!r}"
            ) from None
    return targets


def _cmd_keep(args: argparse.Namespace) -> int:
    from rlfd_drake.run_log import keep_run_log

    if args.name is not None and len(args.runs) > 1:
        raise ValueError(f"--name names one run's log, got {len(args.runs)} runs")
    for run in args.runs:
        kept = keep_run_log(run, name=args.name, overwrite=args.overwrite)
        print(f"kept {run} in {kept}")
    return 0


def _cmd_select(args: argparse.Namespace) -> int:
    if args.runs is not None:
        return _select_seed(args)
    if args.name is not None:
        raise ValueError(f"--name names a selection among seeds (--runs), got --run {args.run}")
    for option in ("test_episodes", "test_task", "target"):
        if getattr(args, option) is not None:
            raise ValueError(
                f"--{option.replace('_', '-')} judges a selection among seeds (--runs) on test "
                f"starts, got --run {args.run}"
            )
    if len(args.seed) > 1 or len(args.episodes) > 1:
        raise ValueError(
            f"--seed and --episodes take one value when choosing a checkpoint (--run), got "
            f"--seed {args.seed} --episodes {args.episodes}"
        )
    from rlfd_drake.checkpoint_selection import select_checkpoint

    data = select_checkpoint(
        args.run,
        args.task,
        episodes=args.episodes[0],
        seed=args.seed[0],
        test_seed=args.test_seed,
        workers=args.workers,
        from_episode=args.from_episode,
        overwrite=args.overwrite,
    )
    for index, row in enumerate(data["candidates"]):
        mark = "  <- chosen" if index == data["chosen"] else ""
        print(
            f"{row['training_episodes']:>6} episodes: {100 * row['success_rate']:.1f} % "
            f"({Path(row['policy']).name}){mark}"
        )
    print(f"wrote {data['selected_folder']}/policy.zip and results/select_*.json, .md")
    return 0


def _select_seed(args: argparse.Namespace) -> int:
    from rlfd_drake.seed_study import seed_selection_name, select_seed

    if args.from_episode:
        raise ValueError(
            f"--from-episode chooses among a run's checkpoints (--run); with --runs each "
            f"seed's final policy is a candidate, got --from-episode {args.from_episode}"
        )
    data = select_seed(
        args.runs,
        args.task,
        episodes=args.episodes[0] if len(args.episodes) == 1 else args.episodes,
        seed=args.seed[0] if len(args.seed) == 1 else args.seed,
        test_seed=args.test_seed,
        workers=args.workers,
        name=args.name,
        overwrite=args.overwrite,
        test_episodes=args.test_episodes,
        test_task=args.test_task,
        target=args.target,
    )
    for index, row in enumerate(data["candidates"]):
        mark = "  <- chosen" if index == data["chosen"] else ""
        test = f", test {100 * row['test_success_rate']:.1f} %" if "test" in data else ""
        print(
            f"seed {row['seed']:>3}: {100 * row['success_rate']:.1f} %, peak "
            f"{row['peak_force_n']:.0f} N{test}{mark}"
        )
    name = seed_selection_name(data["name"], data["validation_episodes"], data["validation_seed"])
    print(f"chosen: {data['chosen_policy']}; wrote results/{name}.json, .md")
    return 0


def _cmd_seeds(args: argparse.Namespace) -> int:
    from rlfd_drake.seed_study import format_spread, seed_study

    data = seed_study(
        args.runs,
        args.tasks,
        episodes=args.episodes,
        seed=args.seed,
        workers=args.workers,
        targets=_parse_targets(args.target),
        name=args.name,
        actions=tuple(args.actions),
        overwrite=args.overwrite,
    )
    for column, spread in data["over_seeds"].items():
        print(f"{column}: {format_spread(spread)} % over {len(data['per_seed'])} seeds")
    if data["targets"]:
        print(
            f"seeds meeting the targets: {data['seeds_meeting_targets']} of {len(data['per_seed'])}"
        )
    print(f"wrote results/seeds_{data['name']}.json and .md")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from rlfd_drake.evaluate import evaluate, evaluation_name, trained_mode, write_evaluation
    from rlfd_drake.results import check_result_name, results_dir
    from rlfd_drake.tasks import evaluation_size, load_task

    if args.residual_mode is None:
        args.residual_mode = trained_mode(args.policy)
    if args.episodes is None:  # the task's grid (160 orientation starts, 500 peg starts)
        args.episodes = evaluation_size(load_task(args.task, check_demo=False))
    if args.noise_scale is not None and not args.stochastic:
        raise ValueError(f"--noise-scale {args.noise_scale} needs --stochastic")
    noise_scale = 1.0 if args.noise_scale is None else args.noise_scale
    name = args.name or evaluation_name(
        args.task,
        args.policy,
        args.residual_mode,
        args.stochastic,
        args.seed,
        noise_scale,
        args.episodes,
    )
    check_result_name(name)
    existing = results_dir() / f"{name}.json"
    if existing.exists() and not args.overwrite:
        raise FileExistsError(f"{existing} exists; pass --overwrite or --name to keep both")
    result = evaluate(
        args.task,
        args.policy,
        episodes=args.episodes,
        seed=args.seed,
        workers=args.workers,
        grid=not args.random_starts,
        residual_mode=args.residual_mode,
        deterministic=not args.stochastic,
        composition=args.composition,
        noise_scale=noise_scale,
    )
    paths = write_evaluation(result, name, plot=args.plot)
    if args.json:
        _print_json(result)
    else:
        print(
            f"{args.task} {args.policy}: success {100 * result['success_rate']:.1f}% "
            f"+- {100 * result['success_std']:.1f} over {result['episodes']} episodes"
        )
        for path in paths.values():
            print(f"wrote {path}")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from rlfd_drake.breakdown import load_evaluation
    from rlfd_drake.evaluate import evaluation_markdown

    # Read every file before printing any, so a bad path prints nothing half-way.
    results = [load_evaluation(path, field="results")[1] for path in args.results]
    print("\n".join(evaluation_markdown(result) for result in results), end="")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from rlfd_drake.breakdown import load_evaluation
    from rlfd_drake.evaluate import plot_peak_forces, plot_success_panels

    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise ValueError(f"--out must name a .png file, got {args.out!r}")
    if out.exists() and not args.overwrite:
        raise FileExistsError(f"{out} exists; pass --overwrite or choose another --out")
    labels = args.labels or [Path(path).stem for path in args.results]
    if len(labels) != len(args.results):
        raise ValueError(
            f"--labels: one per result file ({len(args.results)}), got {len(labels)}: {labels}"
        )
    panels: dict[str, list[tuple[str, dict]]] = {}
    for label, path in zip(labels, args.results, strict=True):
        _, result = load_evaluation(path, field="results")
        panels.setdefault(result["task"], []).append((label, result))
    draw = plot_success_panels if args.kind == "success" else plot_peak_forces
    print(f"wrote {draw(panels, out)}")
    return 0


def _cmd_breakdown(args: argparse.Namespace) -> int:
    from rlfd_drake.breakdown import breakdown

    data = breakdown(
        args.evaluations,
        by=args.by,
        edges=tuple(args.edges) if args.edges else None,
        labels=args.labels,
        name=args.name,
        overwrite=args.overwrite,
    )
    print(f"{data['task']}: {len(data['columns'])} evaluations grouped by {data['by']}")
    print(f"wrote results/breakdown_{args.name}.json and .md")
    return 0


def _add_stored_result_arguments(parser: argparse.ArgumentParser, prefix: str) -> None:
    """The evaluations, --labels, --name and --overwrite of a command that regroups
    stored evaluations."""
    parser.add_argument("evaluations", nargs="+", help="evaluation JSON files of one task")
    parser.add_argument("--labels", nargs="+", help="one label per evaluation file")
    parser.add_argument("--name", required=True, help=f"writes results/{prefix}_<name>.{{json,md}}")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")


def _cmd_paired_forces(args: argparse.Namespace) -> int:
    from rlfd_drake.paired_forces import paired_forces, paired_forces_markdown

    data = paired_forces(
        args.baseline, args.evaluations, args.labels, name=args.name, overwrite=args.overwrite
    )
    print(paired_forces_markdown(data), end="")
    print(f"wrote results/paired_forces_{args.name}.json and .md")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rlfd", description="Residual Learning from Demonstration on Drake."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    tasks = sub.add_parser("tasks", help="list the tasks with their parameters")
    tasks.add_argument("--json", action="store_true", help="print one JSON object")
    tasks.set_defaults(func=_cmd_tasks)

    bench = sub.add_parser("bench", help="speed benchmarks, written to results/")
    bench.add_argument(
        "what",
        choices=["sim", "dmp", "diagram", "train-queue", "evaluate"],
        help="train-queue: 4 short PPO runs one at a time against two at a time (rlfd "
        "reproduce --train-missing's --parallel-runs); evaluate: evaluations as rlfd "
        "reproduce runs them, this code against --against's, alternating",
    )
    bench.add_argument(
        "--cell",
        nargs="+",
        action="append",
        metavar="WORD",
        help="evaluate only: TASK POLICY [MODE] instead of the 4 default cells (repeat the "
        "flag for several; results/bench_evaluate_vs_<commit>_<task>_<policy>.json)",
    )
    bench.add_argument(
        "--starts",
        type=int,
        default=None,
        help="evaluate only: starts per cell (default 8)",
    )
    bench.add_argument(
        "--against",
        default=None,
        metavar="REV",
        help="evaluate only: the git revision of this checkout to compare with (results/"
        "bench_evaluate_vs_<commit>.json: each code's median wall time of the same 4 cells "
        "of 8 starts, the speed-up and whether the episodes were the same)",
    )
    bench.add_argument("--json", action="store_true", help="print the JSON result")
    bench.add_argument("--repeats", type=int, default=5, help="runs per figure (median)")
    bench.add_argument(
        "--study",
        action="store_true",
        help="sim only: also the time-step stability study (its own results file)",
    )
    bench.add_argument(
        "--tasks",
        nargs="+",
        help="diagram only: these task names or task YAML paths (variants), side by side "
        "in one run, written to results/bench_diagram_<A>_vs_<B>....json; the last is "
        "profiled (default: every shipped task, results/bench_diagram.json)",
    )
    bench.add_argument(
        "--queue-runs", type=int, default=None, help="train-queue only: runs trained (default 4)"
    )
    bench.add_argument(
        "--queue-episodes",
        type=int,
        default=None,
        help="train-queue only: PPO episodes per run (default 10; results/"
        "bench_train_queue_<runs>x<episodes>.json)",
    )
    bench.add_argument(
        "--queue-parallel",
        type=int,
        nargs="+",
        default=None,
        help="train-queue only: the numbers of runs at once to compare (default 1 2; "
        "results/bench_train_queue_<runs>x<episodes>_at_once_<p>_...json)",
    )
    bench.set_defaults(func=_cmd_bench)

    demo = sub.add_parser("demo", help="demonstrations (and, with no subcommand, the main demo)")
    demo.add_argument("--task", default="peg_easy")
    demo.add_argument("--episodes", type=int, default=20)
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--workers", type=int, default=2)
    demo.set_defaults(func=_cmd_demo_main)
    demo_sub = demo.add_subparsers(dest="demo_command")
    record = demo_sub.add_parser("record", help="record a scripted-expert demonstration")
    record.add_argument("--task", required=True)
    record.add_argument("--out", required=True, help="file .csv or .npz")
    record.add_argument("--seed", type=int, default=0)
    record.add_argument(
        "--insert-s",
        type=float,
        default=None,
        help="duration of the expert's descent into the fixture, s (default: ExpertConfig's "
        "2.6 s; a slower descent lands softer)",
    )
    record.add_argument("--overwrite", action="store_true")
    record.set_defaults(func=_cmd_demo_record)
    teleop = demo_sub.add_parser(
        "teleop", help="record a demonstration by driving the part from Meshcat sliders"
    )
    teleop.add_argument("--task", required=True)
    teleop.add_argument("--out", required=True, help="file .csv or .npz")
    teleop.add_argument("--duration", type=float, default=60.0, help="longest recording, s")
    teleop.add_argument("--overwrite", action="store_true")
    teleop.set_defaults(func=_cmd_demo_teleop)

    fit = sub.add_parser("fit", help="fit a Cartesian DMP to a demonstration")
    fit.add_argument("--demo", required=True, help="demonstration file .csv or .npz")
    fit.add_argument("--out", required=True, help="DMP parameters .npz")
    fit.add_argument("--basis-translation", type=int, default=40)
    fit.add_argument("--basis-orientation", type=int, default=70)
    fit.add_argument("--overwrite", action="store_true")
    fit.set_defaults(func=_cmd_fit)

    train = sub.add_parser("train", help="train a residual policy (Stable-Baselines3)")
    train.add_argument(
        "--task",
        default="peg_easy",
        help="a task name (rlfd tasks) or a task YAML path (e.g. a variant in "
        "models/tasks/variants/)",
    )
    train.add_argument("--algo", choices=["ppo", "sac", "recurrent_ppo"], default="ppo")
    train.add_argument("--episodes", type=int, default=700)
    train.add_argument("--seed", type=int, default=0)
    train.add_argument("--envs", type=int, default=2, help="parallel env processes")
    train.add_argument(
        "--residual-mode", choices=["full", "translation", "orientation"], default="full"
    )
    train.add_argument("--reward", choices=["sparse", "dense"], default="sparse")
    train.add_argument(
        "--curriculum",
        action="store_true",
        help="scale the start offsets from 0.25 up to 1 over the first half of the run's "
        "episodes (the paper's PPO recipe on the physical robot; the fixture error is not "
        "scaled)",
    )
    train.add_argument(
        "--eval-every",
        type=int,
        default=0,
        help="evaluate the mean action every N finished episodes (0 = off); the best "
        "policy is kept as eval/best_model.zip",
    )
    train.add_argument("--eval-episodes", type=int, default=10, help="episodes per evaluation")
    train.add_argument(
        "--checkpoint-every", type=int, default=100, help="checkpoint every N finished episodes"
    )
    train.add_argument(
        "--sac-target-entropy",
        type=float,
        default=None,
        help="SAC: entropy the tuning holds (default SB3's -6; +1 keeps a ~0.3 std jiggle)",
    )
    train.add_argument("--learning-rate", type=float, default=3e-4, help="optimiser step size")
    train.add_argument(
        "--learning-rate-schedule",
        choices=["constant", "linear"],
        default="constant",
        help="linear: the step size falls to 0 over the run's episodes",
    )
    train.add_argument(
        "--ppo-n-steps",
        type=int,
        default=None,
        help="PPO and recurrent PPO: steps each env collects between updates (256: "
        "about 18 peg episodes over 2 envs at the 10 Hz residual)",
    )
    train.add_argument(
        "--ppo-epochs",
        type=int,
        default=None,
        help="PPO and recurrent PPO: passes over each rollout per update (10, SB3's default)",
    )
    train.add_argument(
        "--ppo-hidden-layers",
        type=int,
        nargs="+",
        default=None,
        metavar="WIDTH",
        help="PPO and recurrent PPO: hidden layer widths of the actor and of the critic "
        "(64 64, SB3's default; recurrent PPO: the layers after its LSTM; the critic's "
        "alone with --ppo-actor-layers)",
    )
    train.add_argument(
        "--ppo-actor-layers",
        type=int,
        nargs="*",
        default=None,
        metavar="WIDTH",
        help="PPO and recurrent PPO: the actor's own hidden widths (--ppo-hidden-layers "
        "then shapes the critic alone); given with no widths, a linear actor",
    )
    train.add_argument(
        "--ppo-gae-lambda",
        type=float,
        default=None,
        help="PPO and recurrent PPO: GAE lambda in (0, 1] (0.95, SB3's default; 1 = "
        "Monte Carlo returns)",
    )
    train.add_argument(
        "--ppo-sde-sample-steps",
        type=int,
        default=0,
        help="PPO: state-dependent exploration (gSDE) redrawn every N steps; 0 = "
        "independent noise per step",
    )
    train.add_argument(
        "--ppo-history",
        type=int,
        default=1,
        help="PPO: the last N observations stacked as the policy's input (a memory of "
        "the contact felt); 1 = the current observation alone",
    )
    train.add_argument(
        "--sac-learning-starts",
        type=int,
        default=0,
        help="SAC: steps explored with the initial policy before the first update",
    )
    train.add_argument(
        "--sac-critic-burn-in",
        type=int,
        default=0,
        metavar="N",
        help="SAC: its first N gradient steps update only the critic (the actor and the "
        "entropy coefficient wait), so the actor first moves on a critic fitted to the "
        "initial policy's returns; default 0: both from the first update",
    )
    train.add_argument(
        "--sac-initial-ent-coef",
        type=float,
        default=0.01,
        help="SAC: initial entropy coefficient (then tuned to --sac-target-entropy)",
    )
    train.add_argument(
        "--sac-correlated-noise",
        type=float,
        nargs="+",
        default=[0.0],
        help="SAC: std (in units of the residual's range) of an Ornstein-Uhlenbeck noise "
        "added to the explored actions, restarted at each episode: one value, or one per "
        "action component (e.g. 0.4 0.4 0 0 0 0: lateral only); default 0: none",
    )
    train.add_argument(
        "--sac-correlated-noise-time-s",
        type=float,
        default=2.0,
        help="SAC: the correlation time of --sac-correlated-noise, s",
    )
    train.add_argument(
        "--sac-gradient-steps",
        type=int,
        default=1,
        help="SAC: updates after each step of the --envs envs (1 with 2 envs = half an "
        "update per transition)",
    )
    train.add_argument(
        "--log-std-init",
        type=float,
        default=-1.5,
        help="initial log std of the policy's Gaussian (-1.5: a std of 0.22 of the "
        "residual's range; RJ-45's 30 N limit needs smaller, e.g. -3)",
    )
    train.add_argument(
        "--lateral-log-std-init",
        type=float,
        default=None,
        help="PPO: the initial log std of the residual's lateral translation (world x "
        "and y) instead of --log-std-init, which depth and orientation keep",
    )
    train.add_argument(
        "--log-std-final",
        type=float,
        default=None,
        help="PPO and recurrent PPO: the log std is not learned but falls linearly over "
        "the run's episodes from --log-std-init to this",
    )
    train.add_argument(
        "--composition",
        choices=list(COMPOSITIONS),
        default="residual",
        help="residual (rLfD) | hybrid (DMP, then velocity commands) | pure (no DMP)",
    )
    train.add_argument(
        "--init-from", help="start from this saved policy's networks (transfer, Table VI)"
    )
    train.add_argument(
        "--force-limit-n",
        type=float,
        help="end training episodes whose low-passed contact force exceeds this, N (a "
        "collision reflex; default: the task's own limit)",
    )
    train.add_argument(
        "--force-limit-penalty",
        type=float,
        default=0.0,
        help="subtract this from the reward of a training step that breaks the force "
        "limit (default 0: the paper's sparse reward, a broken part scores as a timeout)",
    )
    train.add_argument(
        "--peak-force-cost",
        type=float,
        default=0.0,
        help="with --peak-force-threshold-n F: a training episode pays this per F newtons "
        "of peak low-passed contact force above F that the residual added (default 0: "
        "the paper's sparse reward)",
    )
    train.add_argument(
        "--peak-force-threshold-n",
        type=float,
        help="the peak contact force that --peak-force-cost starts at, N",
    )
    train.add_argument(
        "--peak-force-signal",
        choices=PEAK_FORCE_SIGNALS,
        default="low_passed",
        help="the force --peak-force-cost charges: low_passed (20 ms, as force limits; "
        "default) or one_step (the 2 ms samples whose peak evaluations report)",
    )
    train.add_argument(
        "--action-cost",
        type=float,
        default=0.0,
        help="each training step pays this times the mean square of its action (default "
        "0: the paper's sparse reward; pulls the residual to zero where the DMP suffices)",
    )
    train.add_argument(
        "--distance-shaping",
        type=float,
        default=0.0,
        help="potential-based shaping: each step gains this times the L1 distance to the "
        "true goal it closed, per cm (potential-based, discounted: it leaves the best "
        "policies as they were, except that a force-limit break also pays its remaining "
        "distance; default 0: the paper's sparse reward)",
    )
    train.add_argument(
        "--distance-shaping-axes",
        choices=["all", "lateral", "lateral_depth"],
        default="all",
        help="the position errors the shaping counts: all three; the two across the "
        "insertion axis (lifting to slide sideways then costs nothing); or those and the "
        "depth still to go once inside the fixture",
    )
    train.add_argument(
        "--scaled-observation",
        action="store_true",
        help="a fixed input layer brings the contact features (lateral position, wrist "
        "wrench) to order one (observation_scaling.CONTACT_SCALES)",
    )
    train.add_argument(
        "--contact-torque-nm",
        type=float,
        help="with --scaled-observation: the wrist torque the input layer maps to one "
        "unit, N m (default 1, which suits the peg; ~0.05 for the RJ-45 plug)",
    )
    train.add_argument(
        "--applied-action-only",
        action="store_true",
        help="with --residual-mode translation or orientation: the policy outputs only "
        "that 3-D part of the residual",
    )
    train.add_argument(
        "--base-correction",
        choices=["force_search", "force_search_and_slope", "force_search_toward", "slope"],
        help="learn the residual on top of this hand-written rule (added to the "
        "learned action in training and in evaluations); default: none, the paper's rLfD",
    )
    train.add_argument(
        "--timeout-terminal",
        action="store_true",
        help="the learner treats the end of the episode's time as terminal (the "
        "observation carries the time) instead of bootstrapping it as a truncation",
    )
    train.add_argument(
        "--imitate",
        default=None,
        help="PPO first copies this hand-written rule (e.g. force_search): its mean fitted "
        "to the rule's actions on the rule's own episodes, then RL; the copy is "
        "checkpoints/policy_0_steps.zip. Only the network acts at run time. On a rate "
        "residual the rule's offsets are reached through the rate",
    )
    train.add_argument(
        "--imitation-episodes", type=int, default=None, help="the rule's episodes (100)"
    )
    train.add_argument(
        "--imitation-epochs", type=int, default=None, help="passes of the fit over them (100)"
    )
    train.add_argument(
        "--privileged-critic",
        action="store_true",
        help="PPO's critic also reads the part's pose from the fixture's true goal and the "
        "fixture's error (simulation only; an asymmetric actor-critic, a deviation); the "
        "actor reads the observation alone, as it runs in the diagram",
    )
    train.add_argument(
        "--hide-observation",
        type=int,
        nargs="+",
        default=[],
        metavar="I",
        help="with --scaled-observation: observation entries the networks do not read "
        "(indices into the 26 of systems/observer.py; e.g. 0 1 20 21: the lateral position "
        "error and the rate residual's held lateral offset), in training and where the "
        "policy runs (a deviation)",
    )
    train.add_argument(
        "--mirror-symmetry",
        action="store_true",
        help="PPO: the policy is symmetric across the world's x-z plane (y -> -y): its mean "
        "action is averaged with the mirror image of its action on the mirrored observation, "
        "its value with the value there, so what one side of the hole teaches holds for the "
        "other (a deviation from the paper's PPO); the task's fixture must sit on that plane",
    )
    train.add_argument(
        "--self-imitation-batches",
        type=int,
        default=0,
        metavar="N",
        help="PPO: N self-imitation minibatches of 64 steps after each PPO update, drawn "
        "from every finished episode so far (Oh et al. 2018; a deviation from the paper's "
        "PPO); 0 = off",
    )
    train.add_argument("--out", help="run folder (default runs/<task>_<algo>_s<seed>)")
    train.add_argument("--resume", action="store_true", help="continue the run in --out")
    train.add_argument("--no-progress", action="store_true", help="no progress bar")
    train.set_defaults(func=_cmd_train)

    baseline = sub.add_parser(
        "baseline", help="train an episodic baseline (PoWER, FDG, eNAC, RLS linear)"
    )
    baseline.add_argument("--task", default="peg_easy")
    baseline.add_argument("--method", choices=["power", "fdg", "enac", "linear"], required=True)
    baseline.add_argument("--episodes", type=int, default=100)
    baseline.add_argument("--seed", type=int, default=0)
    baseline.add_argument("--workers", type=int, default=2)
    baseline.add_argument(
        "--residual-mode",
        choices=["full", "translation", "orientation"],
        default="full",
        help="linear only: which parts of the residual it adapts",
    )
    baseline.add_argument("--out", help="run folder (default runs/<task>_<method>_s<seed>)")
    baseline.add_argument("--no-progress", action="store_true")
    baseline.set_defaults(func=_cmd_baseline)

    export = sub.add_parser(
        "export", help="a deployment copy of a trained policy (no optimizer state)"
    )
    export.add_argument("--policy", required=True, help="trained SB3 policy zip")
    export.add_argument("--out", required=True, help="destination .zip")
    export.add_argument("--overwrite", action="store_true")
    export.set_defaults(func=_cmd_export)

    reproduce = sub.add_parser(
        "reproduce", help="measure the paper's tables (training what is missing)"
    )
    reproduce.add_argument(
        "--table",
        choices=[*sorted(TABLES), "all", "paper"],
        nargs="+",
        default=["paper"],
        help="one or more tables (their missing runs trained together), or a group: paper "
        f"(the default: {' '.join(PAPER_TABLES)}) or all (every table, the studies' too)",
    )
    reproduce.add_argument("--budget", choices=["quick", "paper"], default="quick")
    reproduce.add_argument("--seed", type=int, default=0, help="evaluation seed")
    reproduce.add_argument(
        "--training-seeds",
        type=int,
        nargs="+",
        default=[0],
        help="rows of `rlfd train` policies over these training seeds (mean +- std; "
        "runs/<folder>_s<seed>); writes results/table_<n>_training_seeds_<seeds>",
    )
    reproduce.add_argument("--workers", type=int, default=2)
    reproduce.add_argument(
        "--train-missing",
        action="store_true",
        help="train the deep-RL runs (RUNS) a row needs that have neither a policy in runs/ "
        "nor a stored evaluation, and what they start from, by their rlfd train commands "
        "(resumed if interrupted; 5-45 min each on 2 cores); without it the quick budget "
        f"trains only those of at most {QUICK_RUN_EPISODES} episodes (sources included) "
        "and lists the others as not run, with the command",
    )
    reproduce.add_argument(
        "--plan",
        action="store_true",
        help="measure nothing: list the rlfd train runs the tables rest on (sources first), "
        "whether each policy is here and its recorded training time -> "
        "results/reproduce_plan_<table>.json",
    )
    reproduce.add_argument(
        "--parallel-runs",
        type=int,
        default=None,
        help="runs trained at once (each in its own subprocess, its "
        "output in runs/<run>.train.log when more than one; a fine-tune after its source); "
        "default: one per core this process may use (measured fastest: rlfd bench train-queue)",
    )
    reproduce.set_defaults(func=_cmd_reproduce)

    keep = sub.add_parser(
        "keep",
        help="copy training runs' logs (configuration, metrics, episodes) to results/train_<run>/",
    )
    keep.add_argument("runs", nargs="+", help="run folders (runs/<name>)")
    keep.add_argument("--name", default=None, help="results/train_<name> (one run only)")
    keep.add_argument("--overwrite", action="store_true", help="replace a kept log")
    keep.set_defaults(func=_cmd_keep)

    seeds = sub.add_parser(
        "seeds", help="a training recipe's success over seeds (one run folder per seed)"
    )
    seeds.add_argument("--runs", nargs="+", required=True, help="run folders, one per seed")
    seeds.add_argument("--tasks", nargs="+", default=["peg_easy", "peg_hard"])
    seeds.add_argument("--episodes", type=int, default=200, help="evaluation starts per task")
    seeds.add_argument("--seed", type=int, default=0, help="evaluation seed")
    seeds.add_argument("--workers", type=int, default=2)
    seeds.add_argument(
        "--target",
        nargs="*",
        default=[],
        help="TASK=PERCENT the mean action should reach, e.g. peg_easy=95 peg_hard=55",
    )
    seeds.add_argument("--name", default=None, help="results/seeds_<name> (default: the runs')")
    seeds.add_argument(
        "--actions",
        nargs="+",
        choices=["mean", "sampled"],
        default=["mean", "sampled"],
        help="evaluate the policies' mean action and/or sampled actions",
    )
    seeds.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a stored study of the same name even if this one leaves some of it out "
        "(one that keeps all of it, e.g. with a seed added, replaces it without this)",
    )
    seeds.set_defaults(func=_cmd_seeds)

    select = sub.add_parser(
        "select",
        help="choose on validation starts a run's policy among its checkpoints (--run; "
        "written as runs/<recipe>_selected_s<seed>/) or one of a recipe's seeds (--runs)",
    )
    chosen_among = select.add_mutually_exclusive_group(required=True)
    chosen_among.add_argument(
        "--run", help="a finished run folder (runs/<name>): choose among its checkpoints"
    )
    chosen_among.add_argument(
        "--runs",
        nargs="+",
        help="one finished run folder per training seed of one recipe: choose one seed by its "
        "final policy (highest validation success, then the lower mean peak force, then the "
        "lower seed)",
    )
    select.add_argument(
        "--task", default=None, help="the task (a name or a YAML path; default: the run's)"
    )
    select.add_argument(
        "--name",
        default=None,
        help="with --runs: the record's name after select_seeds_ (default: the folders' "
        "common name)",
    )
    select.add_argument(
        "--episodes",
        type=int,
        nargs="+",
        default=[100],
        help="validation starts (with --runs and several --seed: one count or one per seed)",
    )
    select.add_argument(
        "--seed",
        type=int,
        nargs="+",
        default=[1],
        help="validation seed, not the test seed (with --runs several may be given: their "
        "starts are pooled)",
    )
    select.add_argument(
        "--test-seed",
        type=int,
        default=0,
        help="the evaluation seed results are reported on, refused as validation seed",
    )
    select.add_argument(
        "--from-episode",
        type=int,
        default=0,
        help="with --run: consider the policies saved after this many training episodes",
    )
    select.add_argument(
        "--test-episodes",
        type=int,
        default=None,
        help="with --runs: also judge the rule on this many test starts (--test-seed) of "
        "every seed: rank agreement with validation and the best of k seeds for every k",
    )
    select.add_argument(
        "--test-task",
        default=None,
        help="with --test-episodes: the task tested on (default: the runs' training task)",
    )
    select.add_argument(
        "--target",
        type=float,
        default=None,
        help="with --test-episodes: a test success %%; count the best-of-k choices reaching it",
    )
    select.add_argument("--workers", type=int, default=2)
    select.add_argument(
        "--overwrite", action="store_true", help="replace an earlier selection of these runs"
    )
    select.set_defaults(func=_cmd_select)

    evaluate = sub.add_parser("evaluate", help="evaluate a policy on the paper's grids")
    evaluate.add_argument(
        "--task",
        default="peg_easy",
        help="a task name (rlfd tasks) or a task YAML path (e.g. a variant in "
        "models/tasks/variants/)",
    )
    evaluate.add_argument(
        "--policy",
        default="dmp",
        help="dmp | random | force_search | force_search_toward (its mirror, for a hole "
        "going onto a shaft) | slope | fixture_oracle | PATH to a policy zip or "
        "baseline.npz; A|B: translation from A, orientation from B",
    )
    evaluate.add_argument("--episodes", type=int, default=None, help="default: the task's grid")
    evaluate.add_argument("--seed", type=int, default=0)
    evaluate.add_argument("--workers", type=int, default=2)
    evaluate.add_argument(
        "--residual-mode",
        choices=["full", "translation", "orientation"],
        default=None,
        help="the parts of the residual applied (default: what the policy was trained "
        "with, from its saved training configuration; else full)",
    )
    evaluate.add_argument(
        "--random-starts", action="store_true", help="sample starts instead of the grid"
    )
    evaluate.add_argument(
        "--stochastic", action="store_true", help="sample the policy's actions (seeded)"
    )
    evaluate.add_argument(
        "--noise-scale",
        type=float,
        default=None,
        help="with --stochastic: the factor on the policy's standard deviation (default "
        "1, as trained; 0.5 samples with half its noise: SAC and PPO)",
    )
    evaluate.add_argument(
        "--composition",
        choices=list(COMPOSITIONS),
        default="residual",
        help="how the policy was trained to act (see rlfd train --composition)",
    )
    evaluate.add_argument(
        "--name",
        help="results file stem (default: eval_<task>_<policy>[_<mode>][_stochastic]"
        "_n<episodes>_s<seed>, the name rlfd reproduce looks for)",
    )
    evaluate.add_argument(
        "--overwrite", action="store_true", help="replace an existing result of the same name"
    )
    evaluate.add_argument("--json", action="store_true", help="print the JSON result")
    evaluate.add_argument(
        "--plot",
        action="store_true",
        help="also write results/<name>.png, success against the start perturbation "
        "(rlfd plot draws it, or several side by side, from the JSON later)",
    )
    evaluate.set_defaults(func=_cmd_evaluate)

    show = sub.add_parser(
        "show",
        help="print stored evaluations (results/eval_*.json) as the Markdown tables "
        "evaluate writes beside them (not tracked in git: this makes them again)",
    )
    show.add_argument("results", nargs="+", help="evaluation JSON files written by evaluate")
    show.set_defaults(func=_cmd_show)

    plot = sub.add_parser(
        "plot", help="draw stored evaluations (results/eval_*.json): success or peak force"
    )
    plot.add_argument("results", nargs="+", help="evaluation JSON files written by evaluate")
    plot.add_argument("--out", required=True, help="the PNG to write")
    plot.add_argument(
        "--labels", nargs="+", help="one legend label per file (default: the file stems)"
    )
    plot.add_argument(
        "--kind",
        choices=["success", "forces"],
        default="success",
        help="success against the start perturbation (paper Fig. 4), one panel per task; "
        "or the mean peak contact forces",
    )
    plot.add_argument("--overwrite", action="store_true", help="replace an existing PNG")
    plot.set_defaults(func=_cmd_plot)

    regroup = sub.add_parser(
        "breakdown",
        help="stored evaluations side by side, grouped by the unseen fixture error",
    )
    regroup.add_argument(
        "--by",
        choices=["fixture_rotation", "fixture_position", "fixture_direction"],
        default="fixture_rotation",
        help="group by the fixture's rotation error (deg, table slope included), "
        "position error (mm), or the side of the hole it moved to (the direction of its "
        "position error in the world's x-y plane, deg in [-45, 315): 0 = +x, 90 = +y)",
    )
    regroup.add_argument(
        "--edges",
        nargs="+",
        type=float,
        help="group edges (default: 0 1 1.5 2 2.5 inf deg, 0 1 2 3 inf mm, or the four "
        "sides -45 45 135 225 315 deg)",
    )
    _add_stored_result_arguments(regroup, "breakdown")
    regroup.set_defaults(func=_cmd_breakdown)

    paired = sub.add_parser(
        "paired-forces",
        help="stored evaluations' contact forces (and starts gained / lost) against a "
        "baseline's on the same starts",
    )
    paired.add_argument(
        "--baseline",
        required=True,
        help="the evaluation compared against (e.g. the DMP alone), same task, starts and seed",
    )
    _add_stored_result_arguments(paired, "paired_forces")
    paired.set_defaults(func=_cmd_paired_forces)

    view = sub.add_parser("view", help="run one episode in Meshcat (live or as an HTML replay)")
    view.add_argument("--task", default="peg_easy")
    view.add_argument(
        "--policy",
        default="dmp",
        help="dmp | random | force_search | force_search_toward | PATH to a policy zip",
    )
    view.add_argument("--seed", type=int, default=0, help="seed of the start and fixture error")
    view.add_argument("--html", help="save a standalone HTML replay here instead of live")
    view.add_argument("--overwrite", action="store_true", help="replace an existing --html")
    view.add_argument(
        "--realtime-rate",
        type=float,
        default=1.0,
        help="live only: pace as a multiple of real time (0 = as fast as possible)",
    )
    view.set_defaults(func=_cmd_view)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileExistsError, FileNotFoundError) as error:
        print(f"rlfd: error: {error}", file=sys.stderr)
        return 2
    except TrainingFailed as error:
        print(f"rlfd: error: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
