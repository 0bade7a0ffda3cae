"""The statistics that say whether policy B is better than policy A (stdlib only).

- `wilson`: the Wilson score interval of a success rate (k successes of n), the interval
  LeRobot reports; unlike the normal approximation it stays inside [0, 1] and is not empty
  at 0 or n successes.
- `paired`: two runs of the same episodes (paired by task and episode index): the
  difference of success rates B - A with Newcombe's hybrid score interval for paired data
  (Newcombe 1998, Statistics in Medicine 17:2635, method 10: the two rates' Wilson limits
  combined with the phi correlation of the pairs, phi's numerator reduced by n/2 when
  positive), and McNemar's exact test: a two-sided binomial test of the discordant pairs
  (episodes one policy solved and the other did not) against p = 1/2.
- `spread`: the success rates of one protocol under several seeds: mean, sample standard
  deviation, min and max.

`tests/python/evaluation/test_stats.py` checks every figure against statsmodels and scipy.
"""

from __future__ import annotations

import math
from statistics import NormalDist
from typing import Any, Sequence

__all__ = ["mcnemar_exact", "newcombe_paired", "paired", "spread", "wilson", "z_value"]

LEVEL = 0.95


def z_value(level: float = LEVEL) -> float:
    """The two-sided standard normal quantile of `level` (1.95996... at 95 %)."""
    return NormalDist().inv_cdf(0.5 + level / 2)


def wilson(k: int, n: int, level: float = LEVEL) -> tuple[float, float] | None:
    """The Wilson score interval of k successes in n trials (None when n is 0)."""
    if n <= 0:
        return None
    z = z_value(level)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def newcombe_paired(both: int, only_a: int, only_b: int, neither: int, level: float = LEVEL) -> tuple[float, float]:
    """Newcombe's method 10 interval of p_B - p_A from the paired table (episodes both
    policies solved, only A, only B, neither)."""
    n = both + only_a + only_b + neither
    if n == 0:
        raise ValueError("no paired episodes")
    pa, pb = (both + only_a) / n, (both + only_b) / n
    la, ua = wilson(both + only_a, n, level)  # type: ignore[misc]
    lb, ub = wilson(both + only_b, n, level)  # type: ignore[misc]
    # phi of the pairs (A's outcome against B's), its numerator corrected as Newcombe's method 10 does.
    margins = (both + only_a) * (only_b + neither) * (both + only_b) * (only_a + neither)
    phi = 0.0
    if margins > 0:
        cross = both * neither - only_a * only_b
        corrected = max(cross - n / 2, 0.0) if cross > 0 else cross
        phi = corrected / math.sqrt(margins)
    d = pb - pa
    lower = d - math.sqrt(max(0.0, (pb - lb) ** 2 - 2 * phi * (pb - lb) * (ua - pa) + (ua - pa) ** 2))
    upper = d + math.sqrt(max(0.0, (ub - pb) ** 2 - 2 * phi * (ub - pb) * (pa - la) + (pa - la) ** 2))
    return max(-1.0, lower), min(1.0, upper)


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """McNemar's exact two-sided p-value: the binomial test of `only_b` of the discordant
    pairs against p = 1/2 (twice the smaller tail, at most 1; 1 with no discordant pair)."""
    m = only_a + only_b
    if m == 0:
        return 1.0
    k = min(only_a, only_b)
    tail = sum(math.comb(m, i) for i in range(k + 1)) / 2**m
    return min(1.0, 2 * tail)


def paired(a: dict[str, bool], b: dict[str, bool], level: float = LEVEL) -> dict[str, Any]:
    """Two runs' successes by episode key, compared on the keys both have."""
    keys = sorted(set(a) & set(b))
    both = sum(1 for k in keys if a[k] and b[k])
    only_a = sum(1 for k in keys if a[k] and not b[k])
    only_b = sum(1 for k in keys if b[k] and not a[k])
    neither = len(keys) - both - only_a - only_b
    n = len(keys)
    out: dict[str, Any] = {
        "pairs": n,
        "both": both,
        "only_a": only_a,
        "only_b": only_b,
        "neither": neither,
        "rate_a": None,
        "rate_b": None,
        "difference": None,
        "interval": None,
        "mcnemar_p": mcnemar_exact(only_a, only_b),
    }
    if n:
        out["rate_a"] = (both + only_a) / n
        out["rate_b"] = (both + only_b) / n
        out["difference"] = out["rate_b"] - out["rate_a"]
        out["interval"] = list(newcombe_paired(both, only_a, only_b, neither, level))
    return out


def spread(rates: Sequence[float | None]) -> dict[str, Any]:
    """Mean, sample standard deviation, min and max of several runs' success rates."""
    values = [r for r in rates if r is not None]
    if not values:
        return {"runs": len(rates), "mean": None, "std": None, "min": None, "max": None}
    mean = sum(values) / len(values)
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else None
    return {"runs": len(rates), "mean": mean, "std": std, "min": min(values), "max": max(values)}
