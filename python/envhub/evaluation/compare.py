"""`envhub eval compare RUN_A RUN_B`: is policy B better than policy A on the same episodes?

Episodes are paired by (task, episode index): both runs must be of one benchmark under one
protocol (the same initial condition for each pair). For each task and overall: both
success rates, the difference B - A with its 95 % interval (Newcombe's method 10 for paired
data) and McNemar's exact p-value (stats.py). An errored episode counts as a failure, as in
the run's own table; an episode that only one run has is left out (the pairs are counted).
"""

from __future__ import annotations

import json
import os
from typing import Any

from .benchmarks import BenchmarkError
from .stats import paired

__all__ = ["compare", "load_run", "markdown", "write_html"]

#: Protocol fields two runs may differ in and still be paired.
LOOSE = ("source", "episodes_per_task")


def load_run(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A finished run's results (its folder or its results.json)."""
    path = os.fspath(path)
    file = os.path.join(path, "results.json") if os.path.isdir(path) else path
    try:
        with open(file, encoding="utf-8") as f:
            results = json.load(f)
    except FileNotFoundError:
        raise BenchmarkError(f"{path}: no results.json (a finished `envhub eval` run's folder)") from None
    except json.JSONDecodeError as e:
        raise BenchmarkError(f"{file} is not a results file: {e}") from None
    if not isinstance(results, dict) or not str(results.get("schema", "")).startswith("envhub.eval/"):
        raise BenchmarkError(f"{file} is not an envhub eval results file (no `schema: envhub.eval/1`)")
    results["_path"] = path
    return results


def _successes(results: dict[str, Any]) -> dict[tuple[str, int], bool]:
    return {(e["task"], int(e["index"])): bool(e.get("success")) for e in results.get("episodes") or []}


def compare(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """The paired comparison of runs `a` and `b` (results dicts)."""
    if a.get("benchmark") != b.get("benchmark"):
        raise BenchmarkError(f"the runs are of different benchmarks: `{a.get('benchmark')}` and `{b.get('benchmark')}`")
    # Where the declaration was read and how many episodes ran do not change how a pair starts.
    pa, pb = ({k: v for k, v in (r.get("protocol") or {}).items() if k not in LOOSE} for r in (a, b))
    if pa != pb:
        changed = sorted(k for k in set(pa) | set(pb) if pa.get(k) != pb.get(k))
        raise BenchmarkError(
            f"the runs' protocols differ (in {', '.join(changed)}): their episodes do not start alike, so they cannot be paired"
        )
    if (pa.get("success") or {}).get("rule") == "none":
        raise BenchmarkError(f"`{a.get('benchmark')}` has no success rule (by return only): nothing to compare")
    sa, sb = _successes(a), _successes(b)
    order = [t["id"] for t in a.get("tasks") or []]
    order += [t["id"] for t in b.get("tasks") or [] if t["id"] not in order]
    rows = []
    for task in order:
        ka = {str(k[1]): v for k, v in sa.items() if k[0] == task}
        kb = {str(k[1]): v for k, v in sb.items() if k[0] == task}
        if set(ka) & set(kb):
            rows.append({"task": task, **paired(ka, kb)})
    overall = paired({f"{k[0]}#{k[1]}": v for k, v in sa.items()}, {f"{k[0]}#{k[1]}": v for k, v in sb.items()})
    return {
        "schema": "envhub.eval.compare/1",
        "benchmark": a.get("benchmark"),
        "a": {"path": a.get("_path"), "policy": a.get("policy")},
        "b": {"path": b.get("_path"), "policy": b.get("policy")},
        "only_in_a": len(set(sa) - set(sb)),
        "only_in_b": len(set(sb) - set(sa)),
        "method": {
            "difference": "success rate B - A; 95% interval: Newcombe (1998) method 10, hybrid score for paired data",
            "test": "McNemar's exact test: two-sided binomial test of the discordant pairs against 1/2",
        },
        "per_task": rows,
        "overall": overall,
    }


def _policy_name(policy: Any) -> str:
    if not isinstance(policy, dict):
        return "?"
    return str(policy.get("name") or policy.get("url") or policy.get("kind") or "?")


def _pct(x: Any) -> str:
    return "–" if x is None else f"{100 * x:.1f}%"


def _diff(x: Any) -> str:
    return "–" if x is None else f"{100 * x:+.1f}"


def _interval(ci: Any) -> str:
    return "–" if not ci else f"{100 * ci[0]:+.1f} to {100 * ci[1]:+.1f}"


def _p(p: Any) -> str:
    return "–" if p is None else (f"{p:.4f}" if p >= 1e-4 else f"{p:.1e}")


def _rows(comparison: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    return [(r["task"], r) for r in comparison["per_task"]] + [("all", comparison["overall"])]


def markdown(comparison: dict[str, Any]) -> str:
    a, b = _policy_name(comparison["a"]["policy"]), _policy_name(comparison["b"]["policy"])
    lines = [
        f"### {comparison['benchmark']}: B ({b}) against A ({a})",
        "",
        "| task | pairs | A | B | B − A (points) | 95% CI | only A | only B | McNemar p |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in _rows(comparison):
        label = "**all**" if name == "all" else name
        lines.append(
            f"| {label} | {r['pairs']} | {_pct(r['rate_a'])} | {_pct(r['rate_b'])} | {_diff(r['difference'])} "
            f"| {_interval(r['interval'])} | {r['only_a']} | {r['only_b']} | {_p(r['mcnemar_p'])} |"
        )
    lines += ["", f"Interval: {comparison['method']['difference']}. Test: {comparison['method']['test']}."]
    if comparison["only_in_a"] or comparison["only_in_b"]:
        lines.append(
            f"Left out, unpaired: {comparison['only_in_a']} episodes only in A, {comparison['only_in_b']} only in B."
        )
    return "\n".join(lines) + "\n"


def write_html(comparison: dict[str, Any], path: str | os.PathLike[str]) -> str:
    """One self-contained page with the comparison's table."""
    from .report import _CSS, _e

    a, b = _policy_name(comparison["a"]["policy"]), _policy_name(comparison["b"]["policy"])
    rows = "".join(
        "<tr>"
        f'<td class="mono">{_e(name)}</td><td class="num">{r["pairs"]}</td>'
        f'<td class="num">{_pct(r["rate_a"])}</td><td class="num">{_pct(r["rate_b"])}</td>'
        f'<td class="num"><b>{_diff(r["difference"])}</b></td><td class="num">{_interval(r["interval"])}</td>'
        f'<td class="num">{r["only_a"]}</td><td class="num">{r["only_b"]}</td>'
        f'<td class="num">{_p(r["mcnemar_p"])}</td>'
        "</tr>"
        for name, r in _rows(comparison)
    )
    head = "".join(
        f"<th>{_e(h)}</th>"
        for h in ("Task", "Pairs", "A", "B", "B − A (points)", "95% CI", "Only A solved", "Only B solved", "McNemar p")
    )
    o = comparison["overall"]
    page = "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            f"<title>{_e(comparison['benchmark'])}: B against A — envhub eval compare</title>",
            f"<style>{_CSS}</style></head><body>",
            '<header class="top"><div class="eyebrow">envhub eval compare</div>',
            f"<h1>{_e(comparison['benchmark'])}</h1>",
            f'<p class="desc">A: {_e(a)} ({_e(comparison["a"]["path"])})<br>B: {_e(b)} ({_e(comparison["b"]["path"])})</p>',
            f'<p class="desc">B − A: <b>{_diff(o["difference"])}</b> points, 95% CI {_interval(o["interval"])}; '
            f"McNemar exact p = {_p(o['mcnemar_p'])} ({o['pairs']} paired episodes)</p>",
            "</header><main>",
            f'<section><h2>Per task</h2><table id="compare"><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table></section>',
            "</main>",
            f"<footer>Interval: {_e(comparison['method']['difference'])}. Test: {_e(comparison['method']['test'])}. "
            "An errored episode counts as a failure.</footer>",
            "</body></html>",
        ]
    )
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = path + ".partial"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(page)
    os.replace(tmp, path)
    return path
