"""Perturbation benchmarks: `axes:` checked like every other field, tasks that carry their axis,
and the results grouped by axis (`envhub.evaluation.axes`).

- Per-axis rows count each axis's episodes, successes and errors (an error a failure), with
  the success rate, its standard error and Wilson interval (`stats.wilson`'s), and the
  difference from the `original` axis; the markdown table and the HTML report show them.
- A bad axis, an unknown axis field, an empty `axes`, `axes` with `entries` or with
  `task_reset_option`: errors that name what is valid.
- `--tasks` picks an axis, `<axis>/<task>`, or a task on every axis.
- End to end on Pendulum (fast, real workers): an `environment` axis that changes gravity
  (`g`, the task option) runs beside `original`; each task carries its axis, and the rows'
  mean returns are their episodes'.
"""

from __future__ import annotations

import json
import math

import pytest
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation import BenchmarkError, evaluate  # noqa: E402
from envhub.evaluation.axes import AXES, per_axis, rows  # noqa: E402
from envhub.evaluation.benchmarks import parse  # noqa: E402
from envhub.evaluation.catalog import Catalog  # noqa: E402
from envhub.evaluation.merge import merge  # noqa: E402
from envhub.evaluation.report import write_report  # noqa: E402
from envhub.evaluation.results import markdown  # noqa: E402
from envhub.evaluation.stats import wilson  # noqa: E402

GOAL = {
    "entry": "libero-pro-goal",
    "tasks": 2,
    "axes": {"original": {}, "position": {"options": {"suite": "libero_goal_swap"}}},
    "episodes_per_task": 3,
    "horizon": 5,
    "success": "any_step",
}


def _tasks_and_episodes():
    tasks = [
        {"id": "b/original/0", "axis": "original"},
        {"id": "b/original/1", "axis": "original"},
        {"id": "b/position/0", "axis": "position"},
        {"id": "b/language/0", "axis": "language"},
    ]
    outcomes = {
        "b/original/0": [True, True, True, False],
        "b/original/1": [True, True, True, True],
        "b/position/0": [False, True, False, False],
        "b/language/0": [True, None, False, False],  # None: the episode errored
    }
    episodes = []
    for task, flags in outcomes.items():
        for i, ok in enumerate(flags):
            e = {"task": task, "index": i, "success": bool(ok), "return": float(i), "error": None}
            if ok is None:
                e["error"] = "worker died"
            episodes.append(e)
    return tasks, episodes


def test_rows_count_each_axis_with_wilson_intervals_and_the_drop_from_original():
    tasks, episodes = _tasks_and_episodes()
    got = per_axis(tasks, episodes, "any_step")
    assert [r["axis"] for r in got] == ["original", "position", "language"]
    expected = {"original": (2, 8, 7, 0), "position": (1, 4, 1, 0), "language": (1, 4, 1, 1)}
    for r in got:
        n_tasks, n, k, errors = expected[r["axis"]]
        assert (r["tasks"], r["episodes"], r["successes"], r["errors"]) == (n_tasks, n, k, errors)
        assert r["success_rate"] == k / n
        assert r["stderr"] == pytest.approx(math.sqrt(k / n * (1 - k / n) / n))
        assert r["ci95"] == list(wilson(k, n))
        assert r["mean_return"] == pytest.approx(1.5)
        assert r["vs_original"] == pytest.approx(k / n - 7 / 8)
    assert got[0]["vs_original"] == 0


def test_no_axes_no_rows_and_rule_none_no_rates():
    tasks, episodes = _tasks_and_episodes()
    assert per_axis([{"id": t["id"]} for t in tasks], episodes, "any_step") == []
    unscored = per_axis(tasks, episodes, "none")
    assert all(r["success_rate"] is None and r["ci95"] is None and r["vs_original"] is None for r in unscored)
    assert [r["episodes"] for r in unscored] == [8, 4, 4]
    # Without an `original` axis there is nothing to read the others against.
    assert all(r["vs_original"] is None for r in per_axis(tasks[2:], episodes, "any_step"))


def test_the_markdown_and_the_report_show_the_axes(tmp_path):
    tasks, episodes = _tasks_and_episodes()
    results = {
        "benchmark": "b",
        "policy": {"name": "p"},
        "protocol": {"success": {"rule": "any_step"}},
        "tasks": [{**t, "text": t["id"]} for t in tasks],
        "per_task": [],
        "summary": {"episodes": 16, "success_rate": 0.5, "ci95": [0.3, 0.7], "stderr": 0.1, "errors": 1,
                    "mean_return": 1.5},
        "episodes": episodes,
    }
    table = markdown(results)
    assert "| axis | tasks | episodes | success | 95% CI (Wilson) | ± s.e. | vs original | errors |" in table
    lo, hi = wilson(1, 4)
    assert f"| position | 1 | 4 | 0.250 | {lo:.3f}–{hi:.3f} | 0.217 | -0.625 | 0 |" in table
    assert "| original | 2 | 8 | 0.875 |" in table and "| +0.000 |" in table
    # `per_axis` where the results carry it wins over recomputing it.
    assert rows({**results, "per_axis": [{"axis": "x"}]}) == [{"axis": "x"}]
    page = open(write_report(results, tmp_path / "report.html"), encoding="utf-8").read()
    assert "Per perturbation axis" in page and 'id="axes"' in page
    assert "-62.5 pts" in page and f'title="{AXES["position"]}"' in page.replace("&#x27;", "'")
    plain = {**results, "tasks": [{"id": t["id"], "text": t["id"]} for t in tasks]}
    assert "| axis |" not in markdown(plain)
    assert "Per perturbation axis" not in open(write_report(plain, tmp_path / "plain.html"), encoding="utf-8").read()


def test_axes_are_checked_naming_the_valid_choices():
    catalog = Catalog()
    bench = catalog.check("goal", GOAL)
    assert [t.id for t in bench.tasks] == ["goal/original/0", "goal/original/1", "goal/position/0", "goal/position/1"]
    assert [t.axis for t in bench.tasks] == ["original", "original", "position", "position"]
    assert bench.env_options(bench.tasks[3])["suite"] == "libero_goal_swap"
    assert "suite" not in bench.env_options(bench.tasks[0])
    assert bench.protocol()["axes"]["position"] == {"options": {"suite": "libero_goal_swap"}, "tasks": [0, 1]}

    def error(**change) -> str:
        with pytest.raises(BenchmarkError) as e:
            catalog.check("goal", {**GOAL, **change})
        return str(e.value)

    msg = error(axes={"positon": {}})
    assert "unknown perturbation axis in benchmark `goal` `positon`; valid: `position`" in msg
    assert all(f"`{a}`" in msg for a in AXES)
    assert "valid: `options`, `tasks`" in error(axes={"object": {"option": {}}})
    assert "`axes` is empty" in error(axes={})
    assert "`axes.object.tasks` must be" in error(axes={"object": {"tasks": "x"}})
    assert "`axes.object.options` must be a mapping" in error(axes={"object": {"options": [1]}})
    entries = {k: v for k, v in GOAL.items() if k not in ("entry", "tasks")}
    with pytest.raises(BenchmarkError, match="go with `entry`, not with `entries`"):
        catalog.check("goal", {**entries, "entries": ["gym-pendulum"]})
    no_tasks = dict(GOAL)
    del no_tasks["tasks"]
    with pytest.raises(BenchmarkError, match="axis `original` has no tasks"):
        catalog.check("goal", no_tasks)
    with pytest.raises(BenchmarkError, match="`axes` and `task_reset_option` do not go together"):
        parse("goal", {**GOAL, "task_reset_option": "task"})


def test_tasks_pick_an_axis_one_task_or_a_task_on_every_axis():
    bench = Catalog().get("libero-pro-goal")
    assert len(bench.tasks) == 50 and len({t.id for t in bench.tasks}) == 50
    ids = lambda b: [t.id for t in b.tasks]  # noqa: E731
    assert ids(bench.select(["3"], 1)) == [f"libero-pro-goal/{a}/3" for a in ("original", "object", "position", "language", "task")]
    assert ids(bench.select(["position"], 1)) == [f"libero-pro-goal/position/{i}" for i in range(10)]
    assert ids(bench.select(["task/9", "libero-pro-goal/language/0", "task/9"], 1)) == [
        "libero-pro-goal/task/9", "libero-pro-goal/language/0"
    ]
    with pytest.raises(BenchmarkError, match="unknown task of `libero-pro-goal` `positon`; valid: `position`"):
        bench.select(["positon"], 1)
    # A benchmark without axes picks as before: a last part names one task.
    assert [t.id for t in Catalog().get("libero-goal").select(["3"], 1).tasks] == ["libero-goal/3"]


def test_an_axis_runs_its_own_tasks_end_to_end(tmp_path):
    decl = {
        "entry": "gym-pendulum",
        "task_option": "g",
        "tasks": [10],
        "axes": {"original": {}, "environment": {"tasks": [5, 20]}},
        "episodes_per_task": 2,
        "init": {"seed_start": 3},
        "horizon": 20,
        "success": "none",
    }

    def act(observations, tasks):
        import numpy as np

        return np.zeros((len(observations), 1), np.float32)

    results = evaluate({**decl, "name": "pendulum-g"}, act, out=tmp_path / "run", progress=False)
    assert results["summary"]["errors"] == 0, [e["error"] for e in results["episodes"]]
    assert [(t["id"], t["axis"]) for t in results["tasks"]] == [
        ("pendulum-g/original/10", "original"),
        ("pendulum-g/environment/5", "environment"),
        ("pendulum-g/environment/20", "environment"),
    ]
    got = rows(results)
    assert [(r["axis"], r["tasks"], r["episodes"]) for r in got] == [("original", 1, 2), ("environment", 2, 4)]
    for r in got:
        mine = [e["return"] for e in results["episodes"] if e["task"].split("/")[1] == r["axis"]]
        assert r["mean_return"] == pytest.approx(sum(mine) / len(mine))
    # Gravity is the perturbation: the same zero actions from the same seeds return differently.
    by_task = {row["task"]: row["mean_return"] for row in results["per_task"]}
    assert len(set(by_task.values())) == 3, by_task
    assert "| environment | 2 | 4 |" in markdown(results)
    # results.json carries the rows; two shards of the run merge to the same rows.
    assert results["per_axis"] == got
    assert json.loads((tmp_path / "run" / "results.json").read_text())["per_axis"] == got
    for i in range(2):
        evaluate({**decl, "name": "pendulum-g"}, act, out=tmp_path / f"s{i}", progress=False, shard=f"{i}/2")
    merged = merge(tmp_path / "merged", [tmp_path / "s0", tmp_path / "s1"])
    assert merged["per_axis"] == got and merged["per_task"] == results["per_task"]
