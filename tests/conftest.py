"""Fixtures shared by the test modules."""

from __future__ import annotations

import pytest
from pydrake.systems.analysis import Simulator

from rlfd_drake.episode import clear_diagram_cache, clear_prefix_cache, load_task_dmp
from rlfd_drake.tasks import load_task


@pytest.fixture(autouse=True)
def _no_episode_start_from_another_test():
    """Each test starts with empty caches of episodes' DMP-only first halves
    (``run_episode``'s ``reuse_prefix``) and of built diagrams: a test that patches the
    simulation must not resume from a half simulated, or reuse a diagram built, by
    another test."""
    clear_prefix_cache()
    clear_diagram_cache()


@pytest.fixture(scope="session")
def peg_easy():
    return load_task("peg_easy")


@pytest.fixture(scope="session")
def dmp(peg_easy):
    """The DMP fitted on peg_easy's shipped demonstration."""
    return load_task_dmp(peg_easy)


@pytest.fixture
def sample_output():
    """A function (system, input value, until_s) -> [(time, output)] that simulates a
    one-input, one-output system with its input fixed and samples its output at every
    simulator step."""

    def simulate(system, value, until_s):
        simulator = Simulator(system)
        context = simulator.get_mutable_context()
        system.get_input_port().FixValue(context, value)
        samples = []
        simulator.set_monitor(
            lambda root: samples.append(
                (root.get_time(), system.get_output_port().Eval(root).copy())
            )
        )
        simulator.AdvanceTo(until_s)
        return samples

    return simulate
