"""The ``rlfd`` command.

Subcommands import their modules lazily so that ``rlfd --help`` and ``rlfd tasks`` are
fast. Every measurement subcommand writes JSON to ``results/`` with its command line,
seed and date (see ``results.write_result``).
"""

from __future__ import annotations

import argparse
import json
import sys


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


def _cmd_bench(args: argparse.Namespace) -> int:
    from rlfd_drake.results import write_result

    if args.what == "sim":
        from rlfd_drake.bench import sim

        data = sim.run(repeats=args.repeats)
        if args.study:
            data = {"tasks": data, "time_step_study": sim.time_step_study()}
    elif args.what == "dmp":
        from rlfd_drake.bench import dmp

        data = dmp.run(repeats=args.repeats)
    elif args.what == "diagram":
        from rlfd_drake.bench import diagram

        data = diagram.run(repeats=args.repeats)
    else:  # argparse restricts the choices
        raise ValueError(f"unknown benchmark {args.what!r}")
    path = write_result(f"bench_{args.what}", data)
    if args.json:
        _print_json(data)
    else:
        print(f"wrote {path}")
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
    bench.add_argument("what", choices=["sim", "dmp", "diagram"])
    bench.add_argument("--json", action="store_true", help="print the JSON result")
    bench.add_argument("--repeats", type=int, default=5, help="runs per figure (median)")
    bench.add_argument(
        "--study", action="store_true", help="sim only: add the time-step stability study"
    )
    bench.set_defaults(func=_cmd_bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileExistsError, FileNotFoundError) as error:
        print(f"rlfd: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
