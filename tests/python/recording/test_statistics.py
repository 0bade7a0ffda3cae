"""The dataset's statistics as LeRobot computes them: quantiles are LeRobot's histogram
quantiles, and they stay LeRobot's across appends."""

from __future__ import annotations

import json
import textwrap

import numpy as np
from harness import import_envhub
from lerobot_datasets import (
    lerobot_python,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
    )

envhub = import_envhub()


# Statistics ------------------------------------------------------------------------------------


def _histogram_quantile(x: np.ndarray, q: float) -> float:
    """A quantile as LeRobot's `RunningQuantileStats` defines it, from `np.histogram`: 5,000
    bins over the padded range, the bin where the count reaches `q * n`, interpolated."""
    edges = np.linspace(x.min() - 1e-10, x.max() + 1e-10, 5001)
    cum = np.cumsum(np.histogram(x, edges)[0])
    target = q * len(x)
    i = int(np.searchsorted(cum, target))
    if i == 0:
        return float(edges[0])
    before, inside = cum[i - 1], cum[i] - cum[i - 1]
    return float(edges[i] + (target - before) / inside * (edges[i + 1] - edges[i]))


def test_quantiles_are_lerobots_histogram_quantiles():
    """Every episode's q01..q99, computed for a whole commit at once without histograms, equal
    the histogram's, bit for bit, for spread, tied and few-valued columns; an episode of one
    frame has its mean."""
    from envhub.recording._stats import QUANTILE_KEYS, QUANTILES, column_stats

    rng = np.random.default_rng(0)
    for trial in range(12):
        lengths = rng.integers(1, 40, 10)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        v = rng.normal(size=(int(lengths.sum()), 3)) * 10.0 ** rng.integers(-3, 4)
        if trial % 3 == 1:
            v = np.round(v)
        elif trial % 3 == 2:
            v = rng.integers(0, 3, size=v.shape).astype(np.float64)
        per_episode, whole = column_stats(v, starts, lengths)
        for e, (s, n) in enumerate(zip(starts, lengths, strict=True)):
            for d in range(3):
                for q, key in zip(QUANTILES, QUANTILE_KEYS, strict=True):
                    want = v[s : s + n, d].mean() if n < 2 else _histogram_quantile(v[s : s + n, d], q)
                    assert per_episode[key][e, d] == want, (trial, e, d, key)
        for key in QUANTILE_KEYS:  # the dataset's: weighted by the episodes' frames
            np.testing.assert_allclose(whole[key], (per_episode[key] * lengths[:, None]).sum(0) / lengths.sum())


LEROBOT_STATS = textwrap.dedent(
    """\
    # In LeRobot's interpreter: its own statistics of the dataset's frames, against the files'.
    import json, sys
    from pathlib import Path
    import numpy as np, pyarrow as pa, pyarrow.parquet as pq
    try:
        from lerobot.datasets.compute_stats import aggregate_stats, get_feature_stats
    except ImportError:
        from ledataset.datasets.compute_stats import aggregate_stats, get_feature_stats

    root = Path(sys.argv[1])
    data = pa.concat_tables([pq.read_table(p) for p in sorted((root / "data").glob("*/*.parquet"))])
    eps = pa.concat_tables([pq.read_table(p) for p in sorted((root / "meta/episodes").glob("*/*.parquet"))])
    keys = ["observation.state", "action", "next.reward"]
    mine = json.loads((root / "meta/stats.json").read_text())
    theirs = []
    worst = 0.0
    for e in range(eps.num_rows):
        lo, hi = eps.column("dataset_from_index")[e].as_py(), eps.column("dataset_to_index")[e].as_py()
        stats = {}
        for key in keys:
            col = data.column(key).combine_chunks().slice(lo, hi - lo)
            v = np.array(col.to_pylist(), dtype=np.float64)
            stats[key] = get_feature_stats(v, axis=0, keepdims=v.ndim == 1)
            for q in ("q01", "q10", "q50", "q90", "q99"):
                got = np.asarray(eps.column(f"stats/{key}/{q}")[e].as_py(), dtype=np.float64)
                want = np.asarray(stats[key][q], dtype=np.float64).reshape(got.shape)
                worst = max(worst, float(np.max(np.abs(got - want) / np.maximum(np.abs(want), 1e-12))))
        theirs.append(stats)
    total = aggregate_stats(theirs)
    for key in keys:
        for q in ("q01", "q10", "q50", "q90", "q99"):
            want = np.asarray(total[key][q], dtype=np.float64).reshape(-1)
            got = np.asarray(mine[key][q], dtype=np.float64).reshape(-1)
            worst = max(worst, float(np.max(np.abs(got - want) / np.maximum(np.abs(want), 1e-12))))
    print(json.dumps({"worst_relative": worst, "episodes": eps.num_rows}))
    """
)


def test_quantiles_as_lerobot_computes_them_kept_on_append(tmp_path):
    """LeRobot's own `get_feature_stats` over each episode's frames and `aggregate_stats` over
    the episodes give the quantiles the files hold, per episode and in `stats.json`, after an
    append too."""
    import subprocess

    python = lerobot_python()
    root = tmp_path / "q"
    for seed in (0, 1):
        envhub.record("gym-pendulum", 4, root, num_envs=2, video=False, max_episode_steps=7 + seed, seed=seed)
    script = tmp_path / "stats.py"
    script.write_text(LEROBOT_STATS)
    proc = subprocess.run([python, str(script), str(root)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["episodes"] == 8 and result["worst_relative"] < 1e-9, result
    stats = json.loads((root / "meta/stats.json").read_text())
    assert {"q01", "q10", "q50", "q90", "q99"} <= set(stats["observation.state"])
