"""Perturbation axes: a perturbation benchmark's results grouped by what was perturbed.

A perturbation suite (LIBERO-PRO, LIBERO-Plus) asks one question per axis: how much does a
policy's success fall when the objects, their positions, the instruction, ... change? Its
benchmark declares `axes:` (`benchmarks.py`), every task carries its axis, and the results
gain one row per axis (`per_axis`): episodes, successes, errors, the success rate with its
standard error and Wilson 95 % interval (`stats.wilson`), the mean return and, where the
benchmark has an `original` axis, the rate's difference from it.

Pure functions of the results' `tasks` and `episodes`, so a results.json written before
`per_axis` existed gets its rows too.
"""

from __future__ import annotations

import math
from typing import Any

from .stats import wilson

__all__ = ["AXES", "ORIGINAL", "axis_rows", "per_axis", "rows"]

#: The axes a benchmark may name, with what each perturbs. LIBERO-PRO's five (object,
#: position, language, task, environment) and LIBERO-Plus's seven (camera, robot_init,
#: language, light, background, noise, layout), and `original`: the unperturbed tasks.
AXES = {
    "original": "nothing: the suite's own tasks, the baseline the other axes are read against",
    "object": "the objects themselves (LIBERO-PRO `_object`: objects of another look in their place)",
    "position": "where the objects start (LIBERO-PRO `_swap`: objects' positions swapped)",
    "language": "the instruction's wording (LIBERO-PRO `_lan`, LIBERO-Plus: paraphrases)",
    "task": "the goal itself (LIBERO-PRO `_task`: another task in the same scene)",
    "environment": "the scene the table stands in (LIBERO-PRO `_env`)",
    "camera": "the camera's viewpoint (LIBERO-Plus)",
    "robot_init": "the robot's initial joint state (LIBERO-Plus)",
    "light": "the lighting (LIBERO-Plus)",
    "background": "the table's and walls' textures (LIBERO-Plus)",
    "noise": "sensor noise on the images (LIBERO-Plus)",
    "layout": "added or moved distractor objects (LIBERO-Plus)",
}
ORIGINAL = "original"


def per_axis(tasks: list[dict[str, Any]], episodes: list[dict[str, Any]], rule: str) -> list[dict[str, Any]]:
    """One row per axis, in the order the tasks list them: `{axis, tasks, episodes,
    successes, errors, success_rate, stderr, ci95, mean_return, vs_original}`; empty when
    no task has an axis. An errored episode counts as a failure (as per task); with the
    success rule `none` the rates are None."""
    axis_of = {t["id"]: t["axis"] for t in tasks if t.get("axis")}
    if not axis_of:
        return []
    order: list[str] = []
    for t in tasks:
        if t.get("axis") and t["axis"] not in order:
            order.append(t["axis"])
    out = []
    for axis in order:
        ids = {i for i, a in axis_of.items() if a == axis}
        mine = [e for e in episodes if e.get("task") in ids]
        n = len(mine)
        successes = sum(1 for e in mine if e.get("success"))
        returns = [e["return"] for e in mine if e.get("return") is not None]
        row: dict[str, Any] = {
            "axis": axis,
            "tasks": len(ids),
            "episodes": n,
            "successes": successes,
            "errors": sum(1 for e in mine if e.get("error") is not None),
        }
        if rule == "none" or n == 0:
            row.update(success_rate=None, stderr=None, ci95=None)
        else:
            p = successes / n
            ci = wilson(successes, n)
            row.update(success_rate=p, stderr=math.sqrt(p * (1 - p) / n), ci95=None if ci is None else list(ci))
        row["mean_return"] = sum(returns) / len(returns) if returns else None
        out.append(row)
    base = next((r["success_rate"] for r in out if r["axis"] == ORIGINAL), None)
    for r in out:
        r["vs_original"] = None if base is None or r["success_rate"] is None else r["success_rate"] - base
    return out


def axis_rows(tasks: list[dict[str, Any]], episodes: list[dict[str, Any]], rule: str) -> dict[str, Any]:
    """`{"per_axis": [...]}` for a perturbation benchmark's results (its tasks carry an axis),
    `{}` for any other, whose results keep their keys."""
    if not any(t.get("axis") for t in tasks):
        return {}
    return {"per_axis": per_axis(tasks, episodes, rule)}


def rows(results: dict[str, Any]) -> list[dict[str, Any]]:
    """`results["per_axis"]` where the results have it, else computed from their tasks and
    episodes (the markdown table and the HTML report use this)."""
    if results.get("per_axis") is not None:
        return list(results["per_axis"])
    rule = ((results.get("protocol") or {}).get("success") or {}).get("rule", "any_step")
    return per_axis(results.get("tasks") or [], results.get("episodes") or [], rule)
