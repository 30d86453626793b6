"""Task specs: loading, strict validation, perturbation distributions."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from rlfd_drake.tasks import (
    describe_task,
    evaluation_grid,
    evaluation_size,
    list_tasks,
    load_task,
    sample_fixture_error,
    sample_start_offset,
    tasks_dir,
)

TASKS = ["gear", "peg", "peg_easy", "peg_hard", "rj45"]


def _angle_deg(q: np.ndarray) -> float:
    return math.degrees(2.0 * math.acos(min(1.0, abs(float(q[0])))))


def _write_variant(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load((tasks_dir() / "peg.yaml").read_text())
    edit(data)
    path = tmp_path / "variant.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_list_and_load_all():
    assert list_tasks() == TASKS
    for name in TASKS:
        task = load_task(name, check_demo=False)
        assert task.name == name
        assert task.X_FP_goal.position_m == (0.0, 0.0, -task.fixture.depth_m)
        json.dumps(describe_task(task))
    assert load_task("peg", check_demo=False).opening_size_m() == pytest.approx((0.0284, 0.0284))
    assert load_task("gear", check_demo=False).opening_size_m() == pytest.approx((0.0228, 0.0228))


def test_paper_numbers():
    peg = load_task("peg", check_demo=False)
    assert peg.part.size_m == (0.028, 0.028, 0.077)
    assert peg.fixture.clearance_m == pytest.approx(0.0004)
    gear = load_task("gear", check_demo=False)
    assert gear.part.size_m == (0.0792, 0.07985, 0.01079)
    assert gear.part.hole_size_m == (0.023, 0.023)
    for name in ("peg", "gear", "rj45"):
        assert load_task(name, check_demo=False).fixture_error.table_slope_deg == 1.0
    for name in ("peg_easy", "peg_hard"):
        task = load_task(name, check_demo=False)
        assert task.fixture_error.table_slope_deg == 0.0
        assert task.start.half_extent_m == 0.12
    assert load_task("rj45", check_demo=False).force_limit_n is not None
    hard, easy = load_task("peg_hard", check_demo=False), load_task("peg_easy", check_demo=False)
    assert hard.fixture.clearance_m < easy.fixture.clearance_m


def test_unknown_field(tmp_path):
    path = _write_variant(tmp_path, lambda d: d["part"].update(colour="red"))
    with pytest.raises(ValueError, match=r"unknown field part\.colour"):
        load_task(path, check_demo=False)
    path = _write_variant(tmp_path, lambda d: d.update(speed=1.0))
    with pytest.raises(ValueError, match=r"unknown field speed"):
        load_task(path, check_demo=False)


@pytest.mark.parametrize(
    ("section", "key", "value", "pattern"),
    [
        (
            "part",
            "size_m",
            [-0.028, 0.028, 0.077],
            r"part\.size_m\[0\] must be positive, got -0\.028",
        ),
        ("part", "mass_kg", 0.0, r"part\.mass_kg must be positive, got 0\.0"),
        ("fixture", "depth_m", -0.01, r"fixture\.depth_m must be positive, got -0\.01"),
        ("fixture", "clearance_m", -1e-4, r"fixture\.clearance_m must be non-negative"),
        ("fixture", "kind", "square_shaft", r"fixture\.kind 'square_shaft' does not fit"),
        ("part", "size_m", [0.028, 0.028], r"part\.size_m: expected 3 values"),
        ("part", "mass_kg", "heavy", r"part\.mass_kg: expected a number, got 'heavy'"),
    ],
)
def test_bad_values(tmp_path, section, key, value, pattern):
    path = _write_variant(tmp_path, lambda d: d[section].update({key: value}))
    with pytest.raises(ValueError, match=pattern):
        load_task(path, check_demo=False)


def test_missing_field_and_unknown_task(tmp_path):
    path = _write_variant(tmp_path, lambda d: d.pop("kappa_m"))
    with pytest.raises(ValueError, match="missing field kappa_m"):
        load_task(path, check_demo=False)
    with pytest.raises(ValueError, match="unknown task 'nope'"):
        load_task("nope")


def test_missing_demo_file(tmp_path):
    path = _write_variant(tmp_path, lambda d: d.update(demo="demos/does_not_exist.csv"))
    with pytest.raises(ValueError, match=r"demo: demonstration file .*does_not_exist\.csv"):
        load_task(path)
    assert load_task(path, check_demo=False).demo == "demos/does_not_exist.csv"


def test_yaml11_exponent_string_accepted(tmp_path):
    path = _write_variant(tmp_path, lambda d: d["part"].update(hydroelastic_modulus_pa="1.0e7"))
    assert load_task(path, check_demo=False).part.hydroelastic_modulus_pa == 1.0e7


def test_uniform_box_grid():
    task = load_task("peg_easy", check_demo=False)
    grid = evaluation_grid(task, seed=3)
    assert len(grid) == 500 == evaluation_size(task)
    dps = np.array([g[0] for g in grid])
    assert np.all(np.abs(dps) <= 0.12) and np.max(np.abs(dps)) > 0.11
    assert all(np.array_equal(g[1], [1, 0, 0, 0]) and g[2] == 0 for g in grid)


def test_six_boxes_grid():
    task = load_task("peg", check_demo=False)
    grid = evaluation_grid(task, seed=0)
    assert len(grid) == 500
    bins = np.array([g[2] for g in grid])
    assert np.bincount(bins).tolist() == [84, 84, 83, 83, 83, 83]
    s = task.start
    for dp, _, k in grid:
        d = s.box_distances_m[k]
        assert np.all(np.abs(np.abs(dp) - d) <= s.box_half_extent_m + 1e-12)
    # Deterministic per seed, different across seeds.
    again = evaluation_grid(task, seed=0)
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(grid, again, strict=True))
    other = evaluation_grid(task, seed=1)
    assert not np.array_equal(grid[0][0], other[0][0])


@pytest.mark.parametrize("name", ["gear", "rj45"])
def test_orientation_bins_grid(name):
    task = load_task(name, check_demo=False)
    grid = evaluation_grid(task, seed=0)
    assert len(grid) == 160
    assert np.bincount([g[2] for g in grid]).tolist() == [20] * 8
    for dp, dq, b in grid:
        assert np.linalg.norm(dq) == pytest.approx(1.0)
        assert 5.0 * b - 1e-9 <= _angle_deg(dq) <= 5.0 * (b + 1) + 1e-9
        assert np.all(np.abs(dp) <= 0.01)
    axes = np.array([g[1][1:] / np.linalg.norm(g[1][1:]) for g in grid])
    assert np.linalg.norm(axes.mean(axis=0)) < 0.2  # axes spread over the sphere


def test_sample_start_offset_bounds():
    rng = np.random.default_rng(0)
    for name in TASKS:
        task = load_task(name, check_demo=False)
        for _ in range(50):
            dp, dq = sample_start_offset(task, rng)
            assert dp.shape == (3,) and dq.shape == (4,)
            assert np.linalg.norm(dq) == pytest.approx(1.0)
            assert np.all(np.abs(dp) <= 0.12)
            assert _angle_deg(dq) <= 40.0 + 1e-9


def test_fixture_error():
    rng = np.random.default_rng(0)
    easy = load_task("peg_easy", check_demo=False)
    for _ in range(50):
        dp, dq = sample_fixture_error(easy, rng)
        assert np.all(np.abs(dp) <= np.array(easy.fixture_error.position_bound_m) + 1e-12)
        assert _angle_deg(dq) <= 1.0 + 1e-9
    peg = load_task("peg", check_demo=False)
    slope_only = dataclasses.replace(
        peg, fixture_error=dataclasses.replace(peg.fixture_error, rotation_bound_deg=0.0)
    )
    _, dq = sample_fixture_error(slope_only, rng)
    assert _angle_deg(dq) == pytest.approx(1.0)
    assert dq[1:] / np.linalg.norm(dq[1:]) == pytest.approx([0.0, 1.0, 0.0])
    angles = [_angle_deg(sample_fixture_error(peg, rng)[1]) for _ in range(100)]
    assert max(angles) <= 2.0 + 1e-9 and min(angles) >= 0.0


@pytest.mark.parametrize(
    "field",
    [
        "rotational_stiffness_Nm_per_rad",
        "translational_stiffness_N_per_m",
        "residual_rate_per_s",
        "residual_period_s",
    ],
)
@pytest.mark.parametrize("value", [0.0, -20.0, float("nan"), float("inf")])
def test_bad_positive_task_field(tmp_path, field, value):
    path = _write_variant(tmp_path, lambda d: d.update({field: value}))
    message = "must be positive" if math.isfinite(value) else "expected a finite number"
    with pytest.raises(ValueError, match=rf"{field}.*{message}"):
        load_task(path, check_demo=False)


def test_a_residual_period_longer_than_the_residual_acts_is_refused(tmp_path):
    path = _write_variant(tmp_path, lambda d: d.update({"residual_period_s": 6.0}))
    with pytest.raises(ValueError, match=r"residual_period_s = 6.0 is longer than the time"):
        load_task(path, check_demo=False)


@pytest.mark.parametrize("name", ["rj45", "peg_incremental"])
def test_the_fast_residual_variants_change_only_the_residual_period(name):
    """<name>_fast_residual is <name> with a 20 Hz residual (the paper's is 10 Hz): same
    demonstration, starts, errors and bounds, so evaluations share the starts."""
    variants = tasks_dir() / "variants"
    path = name if name == "rj45" else variants / f"{name}.yaml"
    shipped = load_task(path, check_demo=False)
    variant = load_task(variants / f"{name}_fast_residual.yaml")
    assert shipped.residual_period_s == 0.1
    assert variant.residual_period_s == 0.05
    assert dataclasses.replace(variant, name=shipped.name, residual_period_s=0.1) == shipped


@pytest.mark.parametrize(
    "field", ["residual_max_push_m", "dmp_phase_stop_gain_per_m2", "dmp_phase_stop_deadband_m"]
)
@pytest.mark.parametrize("value", [-0.001, float("nan"), float("inf")])
def test_bad_non_negative_task_field(tmp_path, field, value):
    path = _write_variant(tmp_path, lambda d: d.update({field: value}))
    message = "must be non-negative" if math.isfinite(value) else "expected a finite number"
    with pytest.raises(ValueError, match=rf"{field}.*{message}"):
        load_task(path, check_demo=False)


@pytest.mark.parametrize(
    "shipped_name, variant_name, gain_per_m2",
    [
        ("rj45", "rj45_phase_stop", 1e5),
        ("rj45", "rj45_phase_stop_strong", 1e6),
        ("variants/peg_incremental", "peg_incremental_phase_stop", 1e5),
        ("variants/peg_incremental", "peg_incremental_phase_stop_strong", 1e6),
        ("variants/gear_incremental", "gear_incremental_phase_stop", 1e5),
    ],
)
def test_the_phase_stop_variants_change_only_the_dmp_phase_stopping(
    shipped_name, variant_name, gain_per_m2
):
    """Each phase-stop variant is its task with the DMP slowed past a 1.5 mm tracking
    error: same starts and errors, so evaluations compare start by start."""
    shipped = load_task(tasks_dir() / f"{shipped_name}.yaml", check_demo=False)
    variant = load_task(tasks_dir() / "variants" / f"{variant_name}.yaml")
    assert shipped.dmp_phase_stop_gain_per_m2 == 0.0
    assert variant.dmp_phase_stop_gain_per_m2 == gain_per_m2
    assert variant.dmp_phase_stop_deadband_m == 0.0015
    same = dataclasses.replace(
        variant, name=shipped.name, dmp_phase_stop_gain_per_m2=0.0, dmp_phase_stop_deadband_m=0.0
    )
    assert same == shipped


def test_soft_wrist_variants_change_only_the_stiffness():
    """Each soft-wrist variant is its shipped task with a 20 N m/rad wrist: same part,
    fixture, starts, errors and residual bounds (so evaluations share the starts)."""
    for name in ("peg", "gear", "rj45"):
        shipped = load_task(name, check_demo=False)
        variant = load_task(tasks_dir() / "variants" / f"{name}_soft_wrist.yaml", check_demo=False)
        assert shipped.rotational_stiffness_Nm_per_rad is None
        assert variant.rotational_stiffness_Nm_per_rad == 20.0
        assert (
            dataclasses.replace(
                variant,
                name=name,
                description=shipped.description,
                rotational_stiffness_Nm_per_rad=None,
            )
            == shipped
        )
        assert evaluation_size(variant) == evaluation_size(shipped)


def test_incremental_variants_change_only_the_residual_rate():
    """Each incremental variant is its shipped task whose residual action is a rate:
    same part, fixture, starts, errors and bounds (so evaluations share the starts)."""
    variants = tasks_dir() / "variants"
    for shipped_name_or_path in ("peg", "gear", variants / "rj45_slow_insert.yaml"):
        shipped = load_task(shipped_name_or_path, check_demo=False)
        variant = load_task(variants / f"{shipped.name}_incremental.yaml")
        assert shipped.residual_rate_per_s is None
        assert variant.residual_rate_per_s == 2.0
        assert dataclasses.replace(variant, name=shipped.name, residual_rate_per_s=None) == shipped


def test_push_bounded_incremental_variants_change_only_the_push_bound():
    """peg's, gear's and slow RJ-45's no-push incremental variants (the DMP does all the
    pressing) and peg's 2 mm one are their incremental variants with a bound on the
    residual's push."""
    variants = tasks_dir() / "variants"
    for name, suffix, bound in (
        ("peg_incremental", "nopush", 0.0),
        ("gear_incremental", "nopush", 0.0),
        ("rj45_slow_insert_incremental", "nopush", 0.0),
        ("peg_incremental", "push2mm", 0.002),
    ):
        incremental = load_task(variants / f"{name}.yaml", check_demo=False)
        bounded = load_task(variants / f"{name}_{suffix}.yaml", check_demo=False)
        assert incremental.residual_max_push_m is None
        assert bounded.residual_max_push_m == bound
        assert dataclasses.replace(bounded, name=name, residual_max_push_m=None) == incremental


def test_every_variant_loads_and_is_named_by_its_file():
    """Evaluations of a variant given by path are named by its file stem (``rlfd
    evaluate``, ``rlfd reproduce``): each variant's name must be that stem, and each
    differs from its shipped task in fields the task format has."""
    variants = sorted((tasks_dir() / "variants").glob("*.yaml"))
    assert len(variants) >= 10
    for path in variants:
        variant = load_task(path)
        assert variant.name == path.stem, path
        shipped = load_task(path.stem.split("_")[0], check_demo=False)
        # A variant keeps its task's demonstration or names another one of the same task
        # (e.g. demos/rj45_slow_insert.csv).
        assert Path(variant.demo).stem.startswith(shipped.name), path
        assert evaluation_size(variant) == evaluation_size(shipped)


@pytest.mark.parametrize(
    "shipped, variant, field, shipped_value, variant_value",
    [
        (
            "variants/peg_incremental",
            "peg_incremental_wide_error",
            "position_bound_m",
            (0.002, 0.002, 0.0),
            (0.0025, 0.0025, 0.0),
        ),
        ("rj45", "rj45_wide_rotation", "rotation_bound_deg", 2.0, 3.0),
    ],
)
def test_the_wide_error_training_variants_change_only_one_fixture_error_bound(
    shipped, variant, field, shipped_value, variant_value
):
    """Training distributions for policies evaluated on the shipped task: the same task
    with a wider unseen fixture error, so more episodes are where its residuals fail."""
    task = load_task(tasks_dir() / f"{shipped}.yaml", check_demo=False)
    wide = load_task(tasks_dir() / "variants" / f"{variant}.yaml", check_demo=False)
    assert getattr(task.fixture_error, field) == shipped_value
    assert getattr(wide.fixture_error, field) == variant_value
    narrowed = dataclasses.replace(
        wide,
        name=task.name,
        fixture_error=dataclasses.replace(wide.fixture_error, **{field: shipped_value}),
    )
    assert narrowed == task


def test_a_variant_based_on_a_task_merges_its_changes_field_by_field(tmp_path):
    """``based_on``: nested mappings merge key by key (the other fixture-error bounds
    stay the base's), lists and scalars replace, and a relative path is read from the
    variant's folder."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "wide.yaml").write_text(
        "based_on: peg\nname: wide\nfixture_error:\n  position_bound_m: [0.003, 0.003, 0.0]\n"
    )
    (tmp_path / "sub" / "wide_slow.yaml").write_text(
        "based_on: wide.yaml\nname: wide_slow\nepisode_time_s: 12.0\n"
    )
    peg = load_task("peg")
    wide_slow = load_task(tmp_path / "sub" / "wide_slow.yaml")
    assert wide_slow.episode_time_s == 12.0
    assert wide_slow.fixture_error.position_bound_m == (0.003, 0.003, 0.0)
    assert wide_slow.fixture_error.rotation_bound_deg == peg.fixture_error.rotation_bound_deg
    assert (
        dataclasses.replace(
            wide_slow,
            name="peg",
            episode_time_s=peg.episode_time_s,
            fixture_error=peg.fixture_error,
        )
        == peg
    )


@pytest.mark.parametrize(
    "files, pattern",
    [
        ({"v.yaml": "based_on: 3\nname: v\n"}, r"based_on must name a task or a YAML file, got 3"),
        ({"v.yaml": "based_on: nowhere.yaml\nname: v\n"}, r"based_on 'nowhere.yaml': no such"),
        ({"v.yaml": "based_on: nothing\nname: v\n"}, r"based_on 'nothing': no such task"),
        ({"v.yaml": "based_on: peg\nkappa_m: 0.001\n"}, r"must give its own name"),
        ({"v.yaml": "based_on: peg\nname: v\nkapa_m: 0.001\n"}, r"unknown field kapa_m"),
        ({"v.yaml": "based_on: peg\nname: v\nkappa_m: -1.0\n"}, r"kappa_m must be positive"),
        (
            {"v.yaml": "based_on: w.yaml\nname: v\n", "w.yaml": "based_on: v.yaml\nname: w\n"},
            r"makes a loop: v.yaml -> w.yaml -> v.yaml",
        ),
    ],
)
def test_a_bad_based_on_is_refused_with_a_named_error(tmp_path, files, pattern):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=pattern):
        load_task(tmp_path / "v.yaml")


def test_every_variant_file_holds_only_its_changes():
    """Each variant names its base and repeats none of the base's values, so a fix to a
    task reaches its variants and a variant's file reads as its difference."""
    for path in sorted((tasks_dir() / "variants").glob("*.yaml")):
        data = yaml.safe_load(path.read_text())
        assert "based_on" in data, path
        variant = load_task(path)
        base = load_task((path.parent / data["based_on"]).resolve())
        for key, value in data.items():
            if key in ("based_on", "name"):
                continue
            inner_keys = value if isinstance(value, dict) else [None]
            for inner in inner_keys:
                mine, theirs = getattr(variant, key), getattr(base, key)
                if inner is not None:
                    mine, theirs = getattr(mine, inner), getattr(theirs, inner)
                assert mine != theirs, f"{path}: {key} {inner or ''} repeats the base's value"


def test_a_residual_that_starts_at_the_table_slope_needs_a_rate_and_the_range(tmp_path):
    """residual_starts_at_table_slope: the variant's integrator starts at the turn that
    undoes the slope (1 deg of peg's 5 deg about y); refused on an offset residual, with a
    range too small for the turn, or given as anything but true/false."""
    from rlfd_drake.tasks import table_slope_residual

    variant = load_task("models/tasks/variants/peg_incremental_slope_start.yaml")
    incremental = load_task("models/tasks/variants/peg_incremental.yaml")
    assert variant.residual_starts_at_table_slope
    assert (
        dataclasses.replace(variant, name=incremental.name, residual_starts_at_table_slope=False)
        == incremental
    )
    np.testing.assert_allclose(
        table_slope_residual(variant), [0, 0, 0, 0, np.radians(1.0) / 0.087, 0], atol=1e-12
    )
    base = tasks_dir() / "variants" / "peg_incremental.yaml"
    for changes, pattern in (
        ({"based_on": "peg"}, "needs a rate residual .*residual_rate_per_s = None"),
        ({"residual_max_rotation_rad": 0.01}, "the slope's turn is 1.75 of"),
        ({"residual_starts_at_table_slope": "yes"}, "expected true or false, got 'yes'"),
    ):
        data = {"based_on": str(base), "name": "v", "residual_starts_at_table_slope": True}
        path = tmp_path / "v.yaml"
        path.write_text(yaml.safe_dump({**data, **changes}))
        with pytest.raises(ValueError, match=pattern):
            load_task(path)


def test_a_models_path_written_from_the_checkout_loads_from_any_folder(tmp_path, monkeypatch):
    """RUNS' and the README's commands name variants as models/tasks/variants/...; from a
    folder without models/ (rlfd reproduce in an empty folder) they are the installed
    package's. A path that exists here wins, and a missing one is named as given."""
    from rlfd_drake.paths import models_dir, shipped_path

    monkeypatch.chdir(tmp_path)
    variant = "models/tasks/variants/gear_incremental_nopush.yaml"
    assert shipped_path(variant) == models_dir() / "tasks/variants/gear_incremental_nopush.yaml"
    assert load_task(variant).name == "gear_incremental_nopush"
    with pytest.raises(ValueError, match="task file models/tasks/variants/nope.yaml does not"):
        load_task("models/tasks/variants/nope.yaml")
    assert shipped_path("elsewhere/peg.yaml") == Path("elsewhere/peg.yaml")
    local = tmp_path / "models/tasks/variants/gear_incremental_nopush.yaml"
    local.parent.mkdir(parents=True)
    local.write_text("based_on: peg\nname: my_own\n")
    assert shipped_path(variant) == Path(variant)
    assert load_task(variant).name == "my_own"
