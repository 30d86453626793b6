"""Writing measured results to ``results/`` with the command, seed and date that made them."""

from __future__ import annotations

import datetime as _dt
import functools
import gzip
import hashlib
import json
import platform
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np


def results_dir() -> Path:
    """``results/`` in the current working directory (created if missing)."""
    path = Path.cwd() / "results"
    path.mkdir(parents=True, exist_ok=True)
    return path


#: How ``sys.argv[0]`` reads when the ``rlfd`` command started this process: its
#: console script, or ``python -m rlfd_drake.cli`` (as ``run_queue`` starts each training
#: run), whose argv[0] is the module's file path. (".../bin/rlfd" ends in "rlfd".)
_RLFD_ENTRY_POINTS = ("rlfd", "rlfd_drake/cli.py")


def invoked_command() -> str:
    """The command line that started this process, as a user would retype it."""
    argv = list(sys.argv)
    if argv and argv[0].endswith(_RLFD_ENTRY_POINTS):
        argv[0] = "rlfd"
    return shlex.join(argv)


def _to_jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _is_scalar(value: Any) -> bool:
    return value is None or isinstance(value, bool | int | float | str)


def format_json(value: Any, indent: int = 2, _level: int = 0) -> str:
    """``json.dumps(value, indent=indent)``, except that a list of numbers, strings or
    nulls stays on one line: per-episode columns are most of a result's bytes, and one
    number per line tripled them. ``json.loads`` reads back the same value."""
    pad, inner = " " * (indent * _level), " " * (indent * (_level + 1))
    if isinstance(value, dict) and value:
        items = (
            f"{inner}{json.dumps(str(key))}: {format_json(item, indent, _level + 1)}"
            for key, item in value.items()
        )
        return "{\n" + ",\n".join(items) + f"\n{pad}}}"
    if isinstance(value, list | tuple) and value and not all(map(_is_scalar, value)):
        items = (f"{inner}{format_json(item, indent, _level + 1)}" for item in value)
        return "[\n" + ",\n".join(items) + f"\n{pad}]"
    return json.dumps(value)


def utc_now() -> str:
    """The current UTC time, ISO 8601 to the second (the date of a measurement)."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def check_result_name(name: str) -> None:
    """Raises a ValueError unless ``name`` is a plain file stem (no folder, no dot
    first): checked before a measurement runs, not after."""
    if not name or "/" in name or name.startswith("."):
        raise ValueError(f"result name must be a plain file stem, got {name!r}")


def capped_stem(name: str, limit: int) -> str:
    """``name`` if it has at most ``limit`` characters, else its start and a hash of the
    whole (12 hex digits), ``limit`` characters in all: file names stop at 255 bytes, and
    two long names that share their start still name two files."""
    if limit < 24:
        raise ValueError(f"limit must leave room for a start and a hash (>= 24), got {limit}")
    if len(name) <= limit:
        return name
    digest = hashlib.sha256(name.encode()).hexdigest()[:12]
    return f"{name[: limit - 13]}_{digest}"


def new_result_path(name: str, overwrite: bool = False) -> Path:
    """``results/<name>.json``, checked before a measurement runs: a plain file stem,
    and no existing result unless ``overwrite`` (FileExistsError names the way out)."""
    check_result_name(name)
    path = results_dir() / f"{name}.json"
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass --overwrite or another --name")
    return path


#: The installed distributions an episode's numbers depend on: the same code and seed in
#: another environment (these versions, or the machine) gave the same outcomes but other
#: contact-force peaks (the demo's rLfD mean peak: 213 N in the environment of
#: 2026-11-30, 232 N in the one re-created on 2026-12-01).
RECORDED_PACKAGES = ("drake", "torch", "stable-baselines3", "gymnasium", "numpy")


@functools.cache  # the environment does not change within a process
def package_versions() -> dict[str, str | None]:
    """{distribution: installed version, or None if it is not installed}; callers get
    one shared dict and must not change it."""
    from importlib.metadata import PackageNotFoundError, version

    versions: dict[str, str | None] = {}
    for package in RECORDED_PACKAGES:
        try:
            versions[package] = version(package)
        except PackageNotFoundError:
            versions[package] = None
    return versions


@functools.cache
def cpu_model() -> str | None:
    """The processor's model name (Linux), None where it cannot be read."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def write_result(
    name: str, data: dict, seed: int | None = None, command: str | None = None
) -> Path:
    """Writes ``results/<name>.json`` = {"command", "seed", "date", "machine", "data"}.

    The file is the record of a measurement: it is overwritten by a re-run of the same
    command (that is the point of a reproducible result), never by anything else.
    """
    check_result_name(name)
    record = {
        "command": command if command is not None else invoked_command(),
        "seed": seed,
        "date": utc_now(),
        "machine": {
            "python": platform.python_version(),
            "processor": platform.machine(),
            "cores_used": 1,
            "cpu": cpu_model(),
            "packages": dict(package_versions()),
        },
        "data": _to_jsonable(data),
    }
    path = results_dir() / f"{name}.json"
    path.write_text(format_json(record) + "\n")
    return path


EPISODES_SUFFIX = ".episodes.json.gz"


def episodes_path(json_path: str | Path) -> Path:
    """The compressed per-episode file beside ``results/<name>.json``."""
    json_path = Path(json_path)
    return json_path.with_name(json_path.name.removesuffix(".json") + EPISODES_SUFFIX)


def write_episodes(json_path: str | Path, table: dict) -> Path:
    """Writes a per-episode table (column name -> list) gzip-compressed beside its
    result: the per-episode columns are most of a result's bytes and repeat a lot, so
    compressed they are about a fifth."""
    text = json.dumps(_to_jsonable(table), separators=(",", ":"))
    return write_compressed(episodes_path(json_path), text.encode())


def write_compressed(path: str | Path, data: bytes) -> Path:
    """Writes ``data`` gzip-compressed to ``path``, with no time stamp in the header, so
    the same data gives the same bytes (a re-run changes nothing in git)."""
    path = Path(path)
    path.write_bytes(gzip.compress(data, compresslevel=9, mtime=0))
    return path


def read_episodes(json_path: str | Path) -> dict:
    """The per-episode table ``write_episodes`` stored beside ``json_path``."""
    path = episodes_path(json_path)
    if not path.is_file():
        raise ValueError(f"episodes: no per-episode file {str(path)!r} beside its result")
    return json.loads(gzip.decompress(path.read_bytes()))


def compact_png(path: str | Path, colors: int = 64) -> Path:
    """Re-saves a plot PNG with a palette of ``colors`` colours (about a third of the
    bytes of matplotlib's RGBA for line plots), so that results/ stays small."""
    from PIL import Image

    path = Path(path)
    with Image.open(path) as image:
        palette = image.convert("RGB").quantize(colors=colors)
    palette.save(path, format="PNG", optimize=True)
    return path


def spread_over_seeds(values: list[float]) -> dict:
    """Mean, sample standard deviation (ddof 1; None for one value), min and max of one
    figure over training seeds."""
    if not values:
        raise ValueError("values must hold at least one seed's figure, got none")
    return {
        "mean": float(np.mean(values)),
        "std": float(np.std(values, ddof=1)) if len(values) > 1 else None,
        "min": float(np.min(values)),
        "max": float(np.max(values)),
    }


def format_spread(spread: dict) -> str:
    """``mean +- std`` of a ``spread_over_seeds`` (the mean alone for a single seed)."""
    std = f" +- {spread['std']:.1f}" if spread["std"] is not None else ""
    return f"{spread['mean']:.1f}{std}"
