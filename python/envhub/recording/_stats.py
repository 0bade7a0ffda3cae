"""LeRobot's feature statistics: min, max, mean, std, count and the quantiles q01, q10, q50,
q90, q99, per episode and over the dataset.

LeRobot (`compute_stats.py`) takes an episode's quantiles from a histogram of 5,000 equal bins
over `[min - 1e-10, max + 1e-10]`, interpolating within the bin where the count crosses
`q * n` (an episode of one frame has its mean as every quantile), and a dataset's as the
count-weighted mean of its episodes'. The same numbers here come without building histograms:
each value's bin is computed as `np.histogram` places it (half-open bins over `np.linspace`'s
edges, the last one closed), and sorting the bins of an episode gives the crossing bin and the
counts before and in it, for every episode of a commit at once.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_KEYS = tuple(f"q{int(q * 100):02d}" for q in QUANTILES)
BINS = 5000
NAMES = ("min", "max", "mean", "std", "count", *QUANTILE_KEYS)
#: The float64 values `column_stats` takes at once (dimensions of a wide column in turn).
SLICE_BYTES = 2**20


def _bins(v: np.ndarray, lo: np.ndarray, step: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The bin of each value, as `np.histogram(v, np.linspace(lo, hi, BINS + 1))` counts it."""
    with np.errstate(divide="ignore", invalid="ignore"):
        b = np.floor((v - lo) / step)
    b = np.clip(np.nan_to_num(b, nan=0.0, posinf=BINS - 1, neginf=0.0), 0, BINS - 1).astype(np.int64)
    b -= (v < b * step + lo) & (b > 0)
    right = np.where(b + 1 == BINS, hi, (b + 1) * step + lo)
    b += (v >= right) & (b < BINS - 1)
    return b


def _edge(k: np.ndarray, lo: np.ndarray, step: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.where(k >= BINS, hi, k * step + lo)


def _edge_of(k: int, lo: float, step: float, hi: float) -> float:
    """`_edge` of one bin, on Python numbers."""
    return hi if k >= BINS else k * step + lo


def episode_quantiles(v: np.ndarray, starts: np.ndarray, lengths: np.ndarray, lo: np.ndarray,
                      hi: np.ndarray) -> dict[str, np.ndarray]:
    """The quantiles of `v` (`(frames, dims)`) per episode (`(episodes, dims)`), the bins over
    `[lo, hi]` per episode (LeRobot's padded min and max)."""
    episodes, dims = lo.shape
    step = (hi - lo) / BINS
    ep = np.repeat(np.arange(episodes), lengths)
    b = _bins(v, lo[ep], step[ep], hi[ep])
    out = {key: np.empty((episodes, dims)) for key in QUANTILE_KEYS}
    for d in range(dims):
        keys = np.sort(ep * BINS + b[:, d])  # each episode's bins, in order, in its own rows
        for q, name in zip(QUANTILES, QUANTILE_KEYS, strict=True):
            target = q * lengths
            k = np.clip(np.ceil(target).astype(np.int64), 1, lengths)
            idx = keys[starts + k - 1] - np.arange(episodes) * BINS  # the bin where the count reaches q*n
            base = np.arange(episodes) * BINS + idx
            before = np.searchsorted(keys, base, "left") - starts
            inside = np.searchsorted(keys, base, "right") - starts - before
            left = _edge(idx, lo[:, d], step[:, d], hi[:, d])
            width = _edge(idx + 1, lo[:, d], step[:, d], hi[:, d]) - left
            value = left + (target - before) / inside * width
            out[name][:, d] = np.where(idx == 0, lo[:, d], value)
    return out


def column_stats(values: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[dict, dict]:
    """A column's statistics (`(frames,)` or `(frames, dims)`) per episode (rows `starts[e]`
    on, `lengths[e]` of them; each of shape `(episodes, dims)`, dims 1 for scalars) and over
    all of them (each `(dims,)`)."""
    values = np.asarray(values)
    if values.ndim == 1:
        values = values[:, None]
    frames, dims = values.shape
    return sliced_stats(lambda d0, d1: values[:, d0:d1], frames, dims, starts, lengths)


def sliced_stats(read: Callable[[int, int], np.ndarray], frames: int, dims: int, starts: np.ndarray,
                 lengths: np.ndarray) -> tuple[dict, dict]:
    """`column_stats` of the column whose dimensions `d0..d1` of every frame `read(d0, d1)`
    gives (`(frames, d1 - d0)`). Taken a few dimensions at a time, so that the temporaries
    (about ten float64 copies of what they cover) stay near `SLICE_BYTES` for any width."""
    step = max(1, SLICE_BYTES // max(8 * frames, 1))
    if step >= dims:
        return _column_stats(read(0, dims), starts, lengths)
    parts = [_column_stats(read(d, min(d + step, dims)), starts, lengths) for d in range(0, dims, step)]
    per_episode = {k: v if k == "count" else np.concatenate([p[0][k] for p in parts], axis=1)
                   for k, v in parts[0][0].items()}
    whole = {k: v if k == "count" else np.concatenate([p[1][k] for p in parts]) for k, v in parts[0][1].items()}
    return per_episode, whole


def _column_stats(values: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[dict, dict]:
    v = np.asarray(values, dtype=np.float64)
    n = lengths[:, None].astype(np.float64)
    mean = np.add.reduceat(v, starts, axis=0) / n
    centred = v - np.repeat(mean, lengths, axis=0)
    lo, hi = np.minimum.reduceat(v, starts, axis=0), np.maximum.reduceat(v, starts, axis=0)
    per_episode = {
        "min": lo,
        "max": hi,
        "mean": mean,
        "std": np.sqrt(np.add.reduceat(centred * centred, starts, axis=0) / n),
        "count": lengths[:, None].astype(np.int64),
    }
    quantiles = episode_quantiles(v, starts, lengths, lo - 1e-10, hi + 1e-10)
    for name, value in quantiles.items():
        per_episode[name] = np.where(n < 2, mean, value)
    whole = {"min": v.min(0), "max": v.max(0), "mean": v.mean(0), "std": v.std(0), "count": np.array([len(v)])}
    for name in QUANTILE_KEYS:
        whole[name] = (per_episode[name] * n).sum(0) / n.sum()
    return per_episode, whole


def level_quantiles(counts: np.ndarray) -> dict[str, np.ndarray]:
    """Per-channel quantiles of pixel values in [0, 1] from their counts (`(channels, 256)`,
    by uint8 level), shaped `(channels, 1, 1)` as LeRobot keeps a camera's. The bins of the
    levels present are computed as `episode_quantiles` computes them; the rest is done on
    Python numbers (the same float64 operations, one episode and camera at a time: numpy's
    per-call cost on arrays of a few levels was most of a short episode's statistics)."""
    levels = np.arange(256) / 255.0
    out = {name: np.zeros((len(counts), 1, 1)) for name in QUANTILE_KEYS}
    for c, count in enumerate(counts):
        present = np.flatnonzero(count)
        # LeRobot takes a camera's quantiles over its pixels: a single frame has many.
        if count.sum() < 2 or not len(present):
            mean = (count * levels).sum() / max(count.sum(), 1)
            for name in QUANTILE_KEYS:
                out[name][c] = mean
            continue
        lo, hi = levels[present[0]] - 1e-10, levels[present[-1]] + 1e-10
        step = (hi - lo) / BINS
        # Bins rise with the level: the levels of a bin are consecutive among those present.
        bins = _bins(levels[present], lo, step, hi).tolist()
        cum = np.cumsum(count[present]).tolist()
        lo, hi, step = float(lo), float(hi), float(step)
        for q, name in zip(QUANTILES, QUANTILE_KEYS, strict=True):
            target = q * cum[-1]
            idx = bins[bisect.bisect_left(cum, max(math.ceil(target), 1))]
            first, last = bisect.bisect_left(bins, idx), bisect.bisect_right(bins, idx)
            before = cum[first - 1] if first else 0
            inside = cum[last - 1] - before
            left, right = _edge_of(idx, lo, step, hi), _edge_of(idx + 1, lo, step, hi)
            out[name][c] = lo if idx == 0 else left + (target - before) / inside * (right - left)
    return out


def aggregate(a: dict[str, np.ndarray] | None, b: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Statistics over the frames of both (LeRobot's `aggregate_feature_stats`: exact mean and
    std, quantiles weighted by count); quantiles only where both have them (a dataset written
    without them keeps none)."""
    if a is None:
        return {k: np.asarray(v) for k, v in b.items()}
    na, nb = float(a["count"][0]), float(b["count"][0])
    n = na + nb
    mean = (a["mean"] * na + b["mean"] * nb) / n
    var = ((a["std"] ** 2 + (a["mean"] - mean) ** 2) * na + (b["std"] ** 2 + (b["mean"] - mean) ** 2) * nb) / n
    out = {
        "min": np.minimum(a["min"], b["min"]),
        "max": np.maximum(a["max"], b["max"]),
        "mean": mean,
        "std": np.sqrt(var),
        "count": np.array([int(n)]),
    }
    for name in QUANTILE_KEYS:
        if name in a and name in b:
            out[name] = (np.asarray(a[name]) * na + np.asarray(b[name]) * nb) / n
    return out


def aggregate_all(episodes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Statistics over many episodes at once (each statistic stacked, episodes first), as
    `aggregate` pairs them: exact mean and std, quantiles weighted by count."""
    counts = episodes["count"].reshape(len(episodes["count"]), -1)[:, 0]
    n = counts.sum()
    w = counts.reshape(-1, *([1] * (episodes["mean"].ndim - 1)))
    mean = (episodes["mean"] * w).sum(0) / n
    var = ((episodes["std"] ** 2 + (episodes["mean"] - mean) ** 2) * w).sum(0) / n
    out = {
        "min": episodes["min"].min(0),
        "max": episodes["max"].max(0),
        "mean": mean,
        "std": np.sqrt(var),
        "count": np.array([int(n)]),
    }
    for name in QUANTILE_KEYS:
        if name in episodes:
            out[name] = (episodes[name] * w).sum(0) / n
    return out
