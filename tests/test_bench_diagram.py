"""The diagram benchmark's replays: the plant alone and the Python-floor probes."""

import dataclasses

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder

from rlfd_drake.bench import diagram as bench
from rlfd_drake.bench.python_floor import AddPythonFloorProbes
from rlfd_drake.scene import AddRlfdScene
from rlfd_drake.tasks import load_task


@pytest.fixture(scope="module")
def recorded():
    task = load_task("peg_easy")
    rlfd, X_WP_start = bench._build(task)
    return task, rlfd, *bench._record_torques(rlfd, X_WP_start)


def test_replay_reproduces_the_episode_with_and_without_probes(recorded):
    task, rlfd, times, torques, q0, q_end = recorded
    _, q_plain = bench._time_replay(task, rlfd, times, torques, q0)
    _, q_probed = bench._time_replay(task, rlfd, times, torques, q0, python_probes=True)
    # The probes drive nothing: the physics is bit-identical to the closed loop.
    assert np.max(np.abs(q_plain - q_end)) == 0.0
    assert np.max(np.abs(q_probed - q_end)) == 0.0


def test_probes_run_at_the_rates_of_the_systems_they_stand_for(recorded):
    _, rlfd, *_ = recorded
    builder = DiagramBuilder()
    probes = AddPythonFloorProbes(builder, AddRlfdScene(builder, rlfd.task, rlfd.config.scene))

    def period(system):
        return system.GetUniquePeriodicDiscreteUpdateAttribute().period_sec()

    source, hold, _, controller, observer = probes
    assert period(source) == pytest.approx(period(rlfd.dmp))
    assert period(hold) == pytest.approx(period(rlfd.extrapolator))
    assert period(controller) == pytest.approx(period(rlfd.controller))
    assert period(observer) == pytest.approx(rlfd.observer.config.force_metrics_period_s)


def test_tasks_must_be_distinct_and_are_checked_before_any_run():
    with pytest.raises(ValueError, match=r"tasks: expected distinct tasks, got \['peg', 'peg'\]"):
        bench.run(repeats=1, tasks=["peg", "peg"])
    with pytest.raises(ValueError, match="tasks: expected distinct tasks"):
        bench.run(repeats=1, tasks=[])


def test_zero_rate_incremental_episode_is_its_shipped_tasks_episode():
    """The benchmark runs an incremental task on a zero rate: the same episode as its
    shipped task's, so the difference in wall time is the integrator's cost."""
    task = load_task("peg_easy")
    outcomes = []
    for spec in (task, dataclasses.replace(task, residual_rate_per_s=2.0)):
        rlfd, X_WP_start = bench._build(spec)
        outcomes.append(bench._time_full(rlfd, X_WP_start)[1])
    assert outcomes[0]["success"]
    assert outcomes[1] == outcomes[0]
