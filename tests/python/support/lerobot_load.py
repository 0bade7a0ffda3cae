"""Loads a dataset with LeRobot's own loader and dumps what it gives, for the recording tests.

Runs in the LeRobot interpreter (`.venv-lerobot/`, with `lerobot-dataset` or `lerobot`, and
torch), not envhub's: `python lerobot_load.py ROOT OUT.npz`. Writes, per feature, the values of every
frame as `ds[i]` returns them (videos decoded by the loader, as uint8 `(h, w, 3)`), the raw
columns of `ds.hf_dataset` as stored (`raw/<key>`), the task text of every frame, and a JSON summary.

`python lerobot_load.py --serve` does the same for each `ROOT\tOUT` line on stdin and answers
each with a JSON line (`{"ok": true}`, or `{"ok": false, "error": traceback}`). Importing torch
and LeRobot takes about 8 s of CPU, loading a test's dataset well under one: a test process
keeps one server for all its loads. Every load makes a new `LeRobotDataset`, and nothing of one
dataset is kept for the next (LeRobot's one in-process cache, torchcodec's video decoders by
path, is emptied after each load; `datasets`' cache on disk is keyed by the files' mtimes, as it
is across processes).
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import traceback

import numpy as np

# LeRobot's dataset code: `lerobot` itself (0.4 on), or the `lerobot-dataset` package of it
# without the robot stack (`ledataset`), whichever this interpreter has.
try:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    _PACKAGE = "lerobot.datasets"
except ImportError:
    from ledataset.datasets.lerobot_dataset import LeRobotDataset

    _PACKAGE = "ledataset.datasets"
try:  # its in-process cache of video decoders, where this version has one
    video_utils = importlib.import_module(f"{_PACKAGE}.video_utils")
except ImportError:
    video_utils = None


def main(root: str, out: str) -> None:
    ds = LeRobotDataset("envhub/test", root=root)
    video_keys = list(ds.meta.video_keys)
    items = [ds[i] for i in range(len(ds))]
    arrays: dict[str, np.ndarray] = {}
    for key in items[0] if items else []:
        if key == "task":
            continue
        values = [item[key].numpy() for item in items]
        if key in video_keys:  # (c, h, w) floats in [0, 1] -> (h, w, c) uint8
            values = [np.round(v.transpose(1, 2, 0) * 255.0).astype(np.uint8) for v in values]
        arrays[key] = np.stack(values)
    # The columns exactly as stored (the numpy and torch formats turn float64 into float32).
    table = ds.hf_dataset.with_format("arrow")[:]
    for key in table.column_names:
        column = table.column(key).combine_chunks()
        if hasattr(column.type, "list_size"):
            values = column.flatten().to_numpy(zero_copy_only=False).reshape(len(column), column.type.list_size)
        else:
            values = column.to_numpy(zero_copy_only=False)
        arrays[f"raw/{key}"] = values
    episodes = ds.meta.episodes
    summary = {
        "num_episodes": ds.num_episodes,
        "num_frames": ds.num_frames,
        "fps": ds.fps,
        "video_keys": video_keys,
        "features": {k: {"dtype": f["dtype"], "shape": list(f["shape"])} for k, f in ds.features.items()},
        "tasks": [item["task"] for item in items],
        "episode_lengths": [int(x) for x in episodes["length"]],
        "episode_success": list(episodes["success"]) if "success" in _columns(episodes) else None,
        "stats_keys": sorted(ds.meta.stats or {}),
    }
    np.savez(out, summary=np.array(json.dumps(summary)), **arrays)


def _columns(table) -> list[str]:
    """The column names of LeRobot's episodes table (a `datasets.Dataset`, or a DataFrame)."""
    names = getattr(table, "column_names", None)
    return list(names) if names is not None else list(table.columns)


def serve() -> None:
    # The answers go to the original stdout; anything else printed (by the libraries, in
    # Python or C) goes to stderr, so that it cannot be taken for an answer.
    answers = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    for line in sys.stdin:
        root, out = line.rstrip("\n").split("\t")
        try:
            main(root, out)
            answer = {"ok": True}
        except Exception:
            answer = {"ok": False, "error": traceback.format_exc()}
        finally:
            cache = getattr(video_utils, "_default_decoder_cache", None) if video_utils is not None else None
            if cache is not None:
                cache.clear()
        answers.write(json.dumps(answer) + "\n")
        answers.flush()


if __name__ == "__main__":
    if sys.argv[1:] == ["--serve"]:
        serve()
    else:
        main(sys.argv[1], sys.argv[2])
