"""Where the shipped model files live, whether the package is installed editable or not."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def models_dir() -> Path:
    """The folder of the shipped models (top-level ``models/``, installed as
    ``rlfd_drake.models``)."""
    return Path(str(resources.files("rlfd_drake.models")))


def model_path(relative: str) -> Path:
    """Absolute path of a shipped model file; ValueError if it does not exist."""
    path = models_dir() / relative
    if not path.exists():
        raise ValueError(f"model file {relative!r} not found under {models_dir()}")
    return path
