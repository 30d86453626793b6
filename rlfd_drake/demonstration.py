"""One kinesthetic/scripted demonstration: type, validation, CSV/NPZ file I/O, DMP fit.

A demonstration is the end-effector pose over time: ``times`` (s), ``positions`` (m) and
``quats`` ([w, x, y, z], scalar first) of the end-effector frame E in the world W.

File formats (chosen by the path's suffix):

- ``.csv``: header ``t,x,y,z,qw,qx,qy,qz`` then one row per sample.
- ``.npz``: arrays ``times`` (N,), ``positions`` (N, 3), ``quats`` (N, 4).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rlfd_drake.dmp import CartesianDmp, DmpConfig, fit_cartesian_dmp

__all__ = [
    "CSV_HEADER",
    "QUAT_NORM_WARN_TOL",
    "Demonstration",
    "load_demonstration",
    "save_demonstration",
    "fit_dmp_from_demonstration",
]

#: Column names of the CSV format.
CSV_HEADER = ("t", "x", "y", "z", "qw", "qx", "qy", "qz")
#: Quaternions with ``| |q| - 1 |`` below this are normalised with a warning; farther ones
#: are rejected.
QUAT_NORM_WARN_TOL = 1e-2
# Below this deviation the norm is round-off and is fixed silently.
_QUAT_NORM_SILENT_TOL = 1e-9
#: Default minimum number of samples: the largest basis-function count of the DMP (70).
DEFAULT_MIN_SAMPLES = DmpConfig().n_basis_orientation


@dataclass
class Demonstration:
    """End-effector poses over time.

    Attributes:
        times: sample times (s), shape (N,), strictly increasing.
        positions: positions p_WE (m), shape (N, 3).
        quats: orientations q_WE [w, x, y, z], shape (N, 4), unit norm.
    """

    times: np.ndarray
    positions: np.ndarray
    quats: np.ndarray

    def __len__(self) -> int:
        return int(np.shape(self.times)[0]) if np.ndim(self.times) > 0 else 0

    @property
    def duration(self) -> float:
        """``times[-1] - times[0]`` (s)."""
        return float(self.times[-1] - self.times[0])

    def validate(self, min_samples: int = DEFAULT_MIN_SAMPLES) -> Demonstration:
        """Check shapes and values; normalise slightly non-unit quaternions in place.

        Args:
            min_samples: fewest samples accepted (default 70, the number of orientation
                basis functions: fewer samples under-determine the DMP fit).

        Returns:
            ``self`` (arrays converted to float64), for chaining.

        Raises:
            ValueError: naming the field and the offending value, for wrong shapes,
                NaN/inf, non-increasing times, too few samples, or quaternions whose norm
                differs from 1 by ``QUAT_NORM_WARN_TOL`` or more.

        Warns:
            UserWarning: when quaternions had to be normalised (norm off by less than
                ``QUAT_NORM_WARN_TOL``).
        """
        times = np.asarray(self.times, dtype=float)
        positions = np.asarray(self.positions, dtype=float)
        quats = np.asarray(self.quats, dtype=float)
        if times.ndim != 1:
            raise ValueError(f"times must have shape (N,), got shape {times.shape}")
        n = times.shape[0]
        if positions.ndim != 2 or positions.shape[1] != 3:
            raise ValueError(f"positions must have shape (N, 3), got shape {positions.shape}")
        if quats.ndim != 2 or quats.shape[1] != 4:
            raise ValueError(f"quats must have shape (N, 4), got shape {quats.shape}")
        for name, arr in (("positions", positions), ("quats", quats)):
            if arr.shape[0] != n:
                raise ValueError(f"{name} has {arr.shape[0]} rows but times has {n} samples")
        if n < min_samples:
            raise ValueError(f"times has {n} samples, fewer than the minimum {min_samples}")
        for name, arr in (("times", times), ("positions", positions), ("quats", quats)):
            bad = ~np.isfinite(arr)
            if np.any(bad):
                idx = np.argwhere(bad)[0]
                raise ValueError(
                    f"{name} must be finite, got {arr[tuple(idx)]} at index {tuple(idx.tolist())}"
                )
        dt = np.diff(times)
        if np.any(dt <= 0.0):
            i = int(np.argmax(dt <= 0.0))
            raise ValueError(
                f"times must be strictly increasing, got times[{i}]={times[i]} "
                f"then times[{i + 1}]={times[i + 1]}"
            )
        norms = np.linalg.norm(quats, axis=1)
        dev = np.abs(norms - 1.0)
        worst = int(np.argmax(dev))
        if dev[worst] >= QUAT_NORM_WARN_TOL:
            raise ValueError(
                f"quats must be unit quaternions, got norm {norms[worst]} at row {worst}"
            )
        if dev[worst] > _QUAT_NORM_SILENT_TOL:
            warnings.warn(
                f"quats normalised: norm {norms[worst]} at row {worst} (max deviation "
                f"{dev[worst]:.2e})",
                UserWarning,
                stacklevel=2,
            )
        quats = quats / norms[:, None]
        self.times, self.positions, self.quats = times, positions, quats
        return self


def _check_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise ValueError(f"unknown demonstration file suffix {path.suffix!r} of {path}")
    return suffix


def load_demonstration(path: str | Path, min_samples: int = DEFAULT_MIN_SAMPLES) -> Demonstration:
    """Load and validate a demonstration from ``.csv`` or ``.npz`` (see module docstring).

    Raises:
        ValueError: unknown suffix, wrong CSV header, missing NPZ keys, or invalid data.
        FileNotFoundError: if ``path`` does not exist.
    """
    path = Path(path)
    suffix = _check_suffix(path)
    if not path.exists():
        raise FileNotFoundError(f"no demonstration file at {path}")
    if suffix == ".csv":
        with path.open() as fh:
            header = tuple(h.strip() for h in fh.readline().strip().split(","))
        if header != CSV_HEADER:
            raise ValueError(f"CSV header of {path} must be {','.join(CSV_HEADER)}, got {header}")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        if data.shape[1] != len(CSV_HEADER):
            raise ValueError(f"CSV rows of {path} must have 8 columns, got {data.shape[1]}")
        demo = Demonstration(times=data[:, 0], positions=data[:, 1:4], quats=data[:, 4:8])
    else:
        with np.load(path) as npz:
            missing = {"times", "positions", "quats"} - set(npz.files)
            if missing:
                raise ValueError(f"NPZ file {path} lacks keys {sorted(missing)}")
            demo = Demonstration(times=npz["times"], positions=npz["positions"], quats=npz["quats"])
    return demo.validate(min_samples)


def save_demonstration(demo: Demonstration, path: str | Path, overwrite: bool = False) -> Path:
    """Validate and write ``demo`` to ``.csv`` or ``.npz`` (full float precision).

    Raises:
        FileExistsError: if ``path`` exists and ``overwrite`` is False.
        ValueError: unknown suffix or invalid demonstration.

    Returns:
        The path written.
    """
    path = Path(path)
    suffix = _check_suffix(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    demo.validate(min_samples=1)
    if suffix == ".csv":
        data = np.column_stack([demo.times, demo.positions, demo.quats])
        np.savetxt(path, data, delimiter=",", header=",".join(CSV_HEADER), comments="", fmt="%.17g")
    else:
        with path.open("wb") as fh:
            np.savez(fh, times=demo.times, positions=demo.positions, quats=demo.quats)
    return path


def fit_dmp_from_demonstration(
    demo: Demonstration, config: DmpConfig | None = None
) -> CartesianDmp:
    """Validate ``demo`` (at least as many samples as basis functions) and fit the DMPs."""
    cfg = config if config is not None else DmpConfig()
    demo.validate(min_samples=max(cfg.n_basis_translation, cfg.n_basis_orientation))
    return fit_cartesian_dmp(demo.times, demo.positions, demo.quats, cfg)
