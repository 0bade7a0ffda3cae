"""The evaluation's statistics against reference implementations, on fixed tables.

- Wilson 95 % intervals equal statsmodels' `proportion_confint(method="wilson")`.
- McNemar's exact p-value equals statsmodels' `mcnemar(exact=True)` and scipy's
  `binomtest` on the discordant pairs.
- Newcombe's paired interval: where the pairs' corrected phi is 0 it is the hybrid score
  interval of two independent samples, which statsmodels computes
  (`confint_proportions_2indep(method="newcomb")`); otherwise it equals Newcombe's formula
  evaluated on statsmodels' Wilson limits.
- `envhub eval compare` pairs two runs' episodes by (task, index): the table, JSON and HTML
  carry those figures; runs of different protocols are refused (exit 2).
- A run's table, results.json, tasks.csv and report carry each task's Wilson interval.
"""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys

import pytest
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation import stats  # noqa: E402
from envhub.evaluation.results import markdown, summarize, write_outputs  # noqa: E402


def _reference(module: str):
    try:
        return pytest.importorskip(module)
    except pytest.skip.Exception:
        if os.environ.get("ENVHUB_PY_REQUIRED"):
            pytest.fail(f"{module} (requirements-dev.txt) is not installed, and ENVHUB_PY_REQUIRED is set")
        raise


# (both, only A, only B, neither)
TABLES = [(10, 15, 5, 20), (12, 2, 9, 21), (0, 0, 3, 7), (40, 0, 0, 10), (5, 1, 1, 3), (0, 6, 0, 44), (25, 3, 11, 11)]


@pytest.mark.parametrize(("k", "n"), [(0, 10), (1, 10), (5, 10), (10, 10), (431, 500), (3, 50), (49, 50)])
def test_wilson_equals_statsmodels(k, n):
    proportion = _reference("statsmodels.stats.proportion")
    lo, hi = stats.wilson(k, n)
    ref = proportion.proportion_confint(k, n, alpha=0.05, method="wilson")
    assert lo == pytest.approx(ref[0], abs=1e-12) and hi == pytest.approx(ref[1], abs=1e-12)
    assert stats.wilson(0, 0) is None


@pytest.mark.parametrize("table", TABLES)
def test_mcnemar_exact_equals_statsmodels_and_scipy(table):
    contingency = _reference("statsmodels.stats.contingency_tables")
    scipy_stats = _reference("scipy.stats")
    both, only_a, only_b, neither = table
    p = stats.mcnemar_exact(only_a, only_b)
    ref = contingency.mcnemar([[both, only_a], [only_b, neither]], exact=True).pvalue
    assert p == pytest.approx(ref, rel=1e-12, abs=1e-15)
    if only_a + only_b:
        assert p == pytest.approx(scipy_stats.binomtest(only_b, only_a + only_b, 0.5).pvalue, rel=1e-12)


@pytest.mark.parametrize("table", TABLES)
def test_newcombe_paired_interval(table):
    proportion = _reference("statsmodels.stats.proportion")
    both, only_a, only_b, neither = table
    n = sum(table)
    lo, hi = stats.newcombe_paired(*table)
    ka, kb = both + only_a, both + only_b
    d = (kb - ka) / n
    assert lo <= d <= hi
    cross = both * neither - only_a * only_b
    margins = ka * (n - ka) * kb * (n - kb)
    phi = 0.0 if margins == 0 else (max(cross - n / 2, 0) if cross > 0 else cross) / math.sqrt(margins)
    if phi == 0:
        # No correlation left: the independent samples' hybrid score interval (statsmodels).
        ref = proportion.confint_proportions_2indep(kb, n, ka, n, method="newcomb", compare="diff")
        assert (lo, hi) == pytest.approx((max(-1, ref[0]), min(1, ref[1])), abs=1e-12)
    la, ua = proportion.proportion_confint(ka, n, method="wilson")
    lb, ub = proportion.proportion_confint(kb, n, method="wilson")
    pa, pb = ka / n, kb / n
    ref_lo = d - math.sqrt((pb - lb) ** 2 - 2 * phi * (pb - lb) * (ua - pa) + (ua - pa) ** 2)
    ref_hi = d + math.sqrt((pa - la) ** 2 - 2 * phi * (pa - la) * (ub - pb) + (ub - pb) ** 2)
    assert (lo, hi) == pytest.approx((max(-1, ref_lo), min(1, ref_hi)), abs=1e-12)


def test_the_interval_is_symmetric_in_the_runs():
    for table in TABLES:
        both, only_a, only_b, neither = table
        lo, hi = stats.newcombe_paired(both, only_a, only_b, neither)
        lo2, hi2 = stats.newcombe_paired(both, only_b, only_a, neither)
        assert (lo, hi) == pytest.approx((-hi2, -lo2), abs=1e-12)


def test_spread():
    s = stats.spread([0.5, 0.7, 0.6])
    assert s["mean"] == pytest.approx(0.6) and s["std"] == pytest.approx(0.1) and (s["min"], s["max"]) == (0.5, 0.7)
    assert stats.spread([0.4])["std"] is None


# Runs and their comparison -----------------------------------------------------------------

PROTOCOL = {"source": "x", "episodes_per_task": 20, "success": {"rule": "any_step"}, "horizon": 10}


def _run(folder, successes: dict[str, list[bool]], name: str, protocol=None):
    tasks = [{"id": t, "entry": "e", "text": t, "index": i} for i, t in enumerate(successes)]
    records = [
        {"task": t, "index": k, "init": {}, "success": s, "return": float(s), "length": 5, "seconds": 0.1,
         "error": None, "video": None}
        for t, flags in successes.items() for k, s in enumerate(flags)
    ]
    total = sum(len(f) for f in successes.values())
    summary, per_task = summarize(records, tasks, "any_step", total)
    results = {"schema": "envhub.eval/1", "benchmark": "b", "protocol": protocol or PROTOCOL, "tasks": tasks,
               "policy": {"kind": "callable", "name": name}, "summary": summary, "per_task": per_task,
               "episodes": records, "run": {"out": str(folder)}, "versions": {}}
    os.makedirs(folder, exist_ok=True)
    write_outputs(str(folder), results)
    return results


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "envhub.evaluation", *args], capture_output=True, text=True,
                          timeout=300)


def test_a_runs_table_json_csv_and_report_carry_wilson_intervals(tmp_path):
    from envhub.evaluation.report import write_report

    results = _run(tmp_path / "a", {"t0": [True] * 7 + [False] * 3, "t1": [False] * 10}, "p.py:act")
    lo, hi = stats.wilson(7, 10)
    assert results["per_task"][0]["ci95"] == [lo, hi] and results["summary"]["ci95"] == list(stats.wilson(7, 20))
    table = markdown(results)
    assert f"{lo:.3f}–{hi:.3f}" in table and "95% CI (Wilson)" in table
    rows = list(csv.DictReader(open(tmp_path / "a" / "tasks.csv")))
    assert [r["task"] for r in rows] == ["t0", "t1", "all"]
    assert float(rows[0]["ci95_low"]) == lo and float(rows[0]["ci95_high"]) == hi
    page = open(write_report(results, tmp_path / "a" / "report.html")).read()
    assert f"95% CI {100 * lo:.1f}–{100 * hi:.1f}%" in page


def test_compare_pairs_episodes_by_task_and_index(tmp_path):
    a = {"t0": [True, True, False, False, True, False, True, False], "t1": [False] * 6}
    b = {"t0": [True, True, True, True, True, False, True, True], "t1": [True, False, True, False, True, True]}
    _run(tmp_path / "a", a, "old.py:act")
    _run(tmp_path / "b", b, "new.py:act")
    done = _cli("compare", str(tmp_path / "a"), str(tmp_path / "b"), "--json")
    assert done.returncode == 0, done.stderr
    c = json.loads(done.stdout)
    # Overall: both 4, only A 0, only B 7, neither 3.
    o = c["overall"]
    assert (o["pairs"], o["both"], o["only_a"], o["only_b"], o["neither"]) == (14, 4, 0, 7, 3)
    assert o["difference"] == pytest.approx(7 / 14)
    assert o["interval"] == pytest.approx(list(stats.newcombe_paired(4, 0, 7, 3)))
    assert o["mcnemar_p"] == pytest.approx(2 / 2**7)
    t1 = c["per_task"][1]
    assert t1["task"] == "t1" and (t1["only_a"], t1["only_b"]) == (0, 4)
    table = _cli("compare", str(tmp_path / "a"), str(tmp_path / "b"), "--html", str(tmp_path / "c.html"))
    assert table.returncode == 0, table.stderr
    assert "| **all** | 14 | 28.6% | 78.6% | +50.0 |" in table.stdout and "McNemar" in table.stdout
    page = (tmp_path / "c.html").read_text()
    assert "+50.0" in page and "Newcombe" in page and f"{o['mcnemar_p']:.4f}" in page
    # Another protocol: the pairs do not start alike.
    _run(tmp_path / "c", b, "new.py:act", {**PROTOCOL, "horizon": 11})
    refused = _cli("compare", str(tmp_path / "a"), str(tmp_path / "c"))
    assert refused.returncode == 2 and "protocols differ (in horizon)" in refused.stderr
    missing = _cli("compare", str(tmp_path / "a"), str(tmp_path / "nothing"))
    assert missing.returncode == 2 and "no results.json" in missing.stderr
