"""Fixtures shared by the test modules."""

from __future__ import annotations

import pytest

from rlfd_drake.episode import load_task_dmp
from rlfd_drake.tasks import load_task


@pytest.fixture(scope="session")
def peg_easy():
    return load_task("peg_easy")


@pytest.fixture(scope="session")
def dmp(peg_easy):
    """The DMP fitted on peg_easy's shipped demonstration."""
    return load_task_dmp(peg_easy)
