"""The evaluation's episode videos and HTML report.

- `EpisodeVideos`: one H.264 MP4 per kept episode (all, or failures only), frames as given
  (odd sizes padded to even), nothing left of a discarded episode, a bounded queue.
- `write_report`: one self-contained file (nothing fetched from the network), opened in a
  real browser (Debian's headless Chromium, driven by Playwright from PyPI in the tests'
  peer environment, eval_peers.py): the tables render with the right rows, sorting by
  task and outcome works, the failures filter works, and a video plays in place (its
  `currentTime` advances), linked beside the results or embedded as a data URI.

Without chromium or the peer environment the browser tests skip with the reason; under
ENVHUB_BROWSER_REQUIRED=1 that is a failure.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import av
import eval_peers
import numpy as np
import pytest
from harness import import_envhub

import_envhub()

from envhub.evaluation.policy import Episode, Task  # noqa: E402
from envhub.evaluation.report import write_report  # noqa: E402
from envhub.evaluation.video import EpisodeVideos, VideoError  # noqa: E402

BROWSER_REQUIRED = bool(os.environ.get("ENVHUB_BROWSER_REQUIRED"))
FRAMES = 30


def episode(task: int, index: int) -> Episode:
    return Episode(Task("bench", f"bench/{task}", "bench-entry", f"task number {task}", task), index)


def frames(seed: int, n: int = FRAMES, shape=(63, 81, 3)) -> list[np.ndarray]:
    """A moving bright square on a coloured background: easy to compare after H.264."""
    out = []
    for k in range(n):
        frame = np.full(shape, (40 + 60 * seed) % 256, dtype=np.uint8)
        frame[10 + k % 30 : 30 + k % 30, 20:40] = 250
        out.append(frame)
    return out


def decode(path: Path) -> tuple[list[np.ndarray], av.video.stream.VideoStream]:
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return [f.to_ndarray(format="rgb24") for f in container.decode(stream)], stream


# -- videos --------------------------------------------------------------------------------


def test_one_video_per_kept_episode_frames_as_given(tmp_path) -> None:
    with EpisodeVideos(tmp_path, only_failures=False, fps=15) as videos:
        given = {slot: frames(slot) for slot in range(3)}
        for k in range(FRAMES):  # interleaved, as a vector of envs steps
            for slot in range(3):
                videos.frame(slot, given[slot][k])
        paths = [videos.finish(slot, episode(slot, 7), success=slot == 1) for slot in range(3)]
    assert paths == [f"videos/bench_{s}_ep0007.mp4" for s in range(3)]
    for slot, path in enumerate(paths):
        decoded, stream = decode(tmp_path / path)
        assert stream.codec_context.name == "h264" and stream.codec_context.pix_fmt == "yuv420p"
        assert (stream.width, stream.height) == (82, 64)  # 81x63 padded to even sides
        assert stream.average_rate == 15
        assert len(decoded) == FRAMES
        for got, want in zip(decoded, given[slot]):
            assert np.abs(got[:63, :81].astype(int) - want).mean() < 4  # lossy, but the same picture
    assert sorted(p.name for p in (tmp_path / "videos").iterdir()) == [Path(p).name for p in paths]


def test_only_failures_discard_and_no_frames_leave_nothing(tmp_path) -> None:
    with EpisodeVideos(tmp_path, only_failures=True, fps=29.97, queue_frames=2) as videos:
        for f in frames(0):
            videos.frame(0, f)
            videos.frame(1, f)
            videos.frame(2, f)
        assert videos.finish(0, episode(0, 0), success=True) is None
        assert videos.finish(1, episode(0, 1), success=False) == "videos/bench_0_ep0001.mp4"
        videos.discard(2)
        assert videos.finish(3, episode(0, 3), success=False) is None  # no frames
        # A slot's next episode starts a new video.
        for f in frames(1, 5):
            videos.frame(2, f)
        assert videos.finish(2, episode(1, 0), success=False) == "videos/bench_1_ep0000.mp4"
    assert sorted(p.name for p in (tmp_path / "videos").iterdir()) == [
        "bench_0_ep0001.mp4",
        "bench_1_ep0000.mp4",
    ]
    decoded, stream = decode(tmp_path / "videos" / "bench_1_ep0000.mp4")
    assert len(decoded) == 5 and stream.average_rate == pytest.approx(29.97, abs=0.01)


def test_bad_frames_are_refused_naming_what_is_expected(tmp_path) -> None:
    with EpisodeVideos(tmp_path) as videos:
        with pytest.raises(ValueError, match=r"HxWx3 uint8 image; slot 0 gave float32 \(8, 8, 3\)"):
            videos.frame(0, np.zeros((8, 8, 3), np.float32))
        videos.frame(0, np.zeros((8, 8, 3), np.uint8))
        with pytest.raises(ValueError, match=r"changed size within an episode, from \(8, 8\) to \(10, 8\)"):
            videos.frame(0, np.zeros((10, 8, 3), np.uint8))
        videos.discard(0)
    with pytest.raises(VideoError, match="closed"):
        videos.frame(0, np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(ValueError, match="fps must be"):
        EpisodeVideos(tmp_path, fps=0)


# -- the report ----------------------------------------------------------------------------


def make_results(out: Path) -> dict:
    """Results as envhub eval writes them (docs/guide/eval.md's schema), with real videos: two
    tasks of three episodes, one failure and one error among them."""
    outcomes = {(0, 0): True, (0, 1): False, (0, 2): True, (1, 0): True, (1, 1): None, (1, 2): True}
    episodes = []
    with EpisodeVideos(out, fps=10) as videos:
        for slot, ((t, k), success) in enumerate(outcomes.items()):
            for f in frames(slot):
                videos.frame(slot, f)
            path = videos.finish(slot, episode(t, k), bool(success)) if success is not None else None
            if success is None:
                videos.discard(slot)
            episodes.append(
                {
                    "task": f"bench/{t}",
                    "index": k,
                    "init": {"init_state": k},
                    "success": success,
                    "return": 10.0 * t + k + (0.5 if success else 0.0),
                    "length": 20 + 5 * k + t,
                    "seconds": 1.5 + k,
                    "error": "the policy server at ws://127.0.0.1:9 closed the connection"
                    if success is None
                    else None,
                    "video": path,
                }
            )
    return {
        "schema": "envhub.eval/1",
        "benchmark": "bench",
        "description": "A test benchmark <with markup> & ampersands.",
        "protocol": {
            "source": "configs/env_registry.yaml",
            "entry": "bench-entry",
            "episodes_per_task": 3,
            "init": {"init_states": True},
            "horizon": 220,
            "settle": {"steps": 10, "action": [0, 0, 0, 0, 0, 0, -1]},
            "success": {"rule": "any_step", "key": "success"},
            "observation": {},
            "kwargs": {},
            "python_env": None,
        },
        "tasks": [
            {"id": "bench/0", "entry": "bench-entry", "text": "task number 0", "index": 0},
            {"id": "bench/1", "entry": "bench-entry", "text": "task number 1", "index": 1},
        ],
        "policy": {"kind": "server", "protocol": "vla-eval", "name": "ws://127.0.0.1:9", "url": "ws://127.0.0.1:9"},
        "versions": {"envhub": "0.1.0", "python": "3.11.7", "packages": {"libero": "0.1.0"}},
        "run": {
            "started": "2026-11-26T11:30:00Z",
            "finished": "2026-11-26T11:31:00Z",
            "seconds": 60.0,
            "num_envs": 6,
            "workers": None,
            "hubs": None,
            "resumed": False,
            "host": "test",
            "out": str(out),
        },
        "summary": {
            "episodes": 6,
            "done": 6,
            "errors": 1,
            "successes": 4,
            "success_rate": 4 / 6,
            "stderr": (4 / 6 * 2 / 6 / 6) ** 0.5,
            "mean_return": 5.7,
            "mean_length": 26.0,
            "episodes_per_minute": 6.0,
        },
        "per_task": [
            {"task": "bench/0", "text": "task number 0", "episodes": 3, "successes": 2, "errors": 0,
             "success_rate": 2 / 3, "stderr": 0.272, "mean_return": 1.33, "mean_length": 25.0},
            {"task": "bench/1", "text": "task number 1", "episodes": 3, "successes": 2, "errors": 1,
             "success_rate": 2 / 3, "stderr": 0.272, "mean_return": 11.33, "mean_length": 26.0},
        ],
        "episodes": episodes,
    }  # fmt: skip


def test_the_report_is_one_self_contained_file(tmp_path) -> None:
    results = make_results(tmp_path)
    page = Path(write_report(results, tmp_path / "report.html")).read_text()
    assert "<with markup>" not in page and "&lt;with markup&gt; &amp; ampersands." in page
    for remote in ('src="http', "src='http", 'href="http', "@import", "url(http"):
        assert remote not in page
    assert page.count('<tr data-task="bench/') == 6
    assert page.count('src="videos/bench_') == 5  # the errored episode has none
    assert "66.7%" in page and "± 19.2" in page  # the overall rate and its standard error
    # Embedded: the report carries its videos.
    embedded = Path(
        write_report(results, tmp_path / "alone" / "report.html", embed_video_bytes=1 << 20)
    ).read_text()
    assert embedded.count('src="data:video/mp4;base64,') == 5
    # A report elsewhere points back at the videos beside the results.
    other = Path(write_report(results, tmp_path / "elsewhere" / "r.html")).read_text()
    assert other.count('src="../videos/bench_') == 5


def test_a_benchmark_scored_by_return_leads_with_it(tmp_path) -> None:
    results = make_results(tmp_path)
    results["protocol"]["success"] = {"rule": "none"}
    results["summary"].update(success_rate=None, stderr=None, successes=0)
    for row in results["per_task"]:
        row.update(success_rate=None, stderr=None, successes=0)
    for episode in results["episodes"]:
        episode["success"] = None
    page = Path(write_report(results, tmp_path / "report.html")).read_text()
    assert '<div class="stat big"><div class="label">Mean return</div><div class="value">5.70</div>' in page
    assert "Success rate</div>" not in page and 'class="bar"' not in page
    assert page.count('data-outcome="done"') == 5 and page.count('data-outcome="error"') == 1


BROWSER_SCRIPT = r"""
import json, shutil, sys, time
from playwright.sync_api import sync_playwright

page_url, shot = sys.argv[1], sys.argv[2]
out = {}
with sync_playwright() as p:
    # Chromium's start is not what this test checks, and on a busy machine it can outlast
    # Playwright's 30 s default or crash (CI saw both): a longer wait and two more tries, 10 s
    # apart. (`make py-test` runs this test alone, after the others.)
    for attempt in range(3):
        try:
            browser = p.chromium.launch(
                executable_path=shutil.which("chromium"), args=["--no-sandbox"], timeout=120_000)
            break
        except Exception as e:
            print(f"chromium launch {attempt + 1} failed: {str(e)[:500]}", file=sys.stderr)
            if attempt == 2:
                raise
            time.sleep(10)
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.set_default_timeout(120_000)
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(page_url)
    rows = lambda: page.eval_on_selector_all(
        "#episodes tbody tr:not([hidden])",
        "rs => rs.map(r => [r.dataset.task, r.cells[1].textContent, r.dataset.outcome])")
    out["task_rows"] = page.eval_on_selector_all(
        "#tasks tbody tr", "rs => rs.map(r => Array.from(r.cells).map(c => c.textContent.trim()))")
    out["initial"] = rows()
    page.click("#episodes th:nth-child(3)")   # Outcome, ascending: errors, failures, successes
    out["by_outcome"] = rows()
    page.click("#episodes th:nth-child(3)")   # descending
    out["by_outcome_desc"] = rows()
    page.click("#episodes th:nth-child(1)")   # Task
    page.click("#episodes th:nth-child(1)")   # Task, descending
    out["by_task_desc"] = rows()
    page.click("#tasks th:nth-child(8)")      # per-task mean length
    out["tasks_by_length"] = page.eval_on_selector_all("#tasks tbody tr", "rs => rs.map(r => r.cells[0].textContent)")
    page.check("#failures-only")
    out["failures"] = rows()
    out["shown"] = page.text_content("#shown")
    page.uncheck("#failures-only")
    page.select_option("#task-filter", "bench/1")
    out["task1"] = rows()
    page.select_option("#task-filter", "")
    page.click("#episodes th:nth-child(1)")   # back to task order for the screenshot
    video = page.locator("#episodes video").first
    out["played"] = video.evaluate('''v => new Promise(done => {
        const t0 = performance.now();
        v.play().catch(e => done({error: String(e)}));
        (function poll() {
            if (v.currentTime > 0.3) return done({currentTime: v.currentTime, error: null});
            if (v.error) return done({error: 'media error ' + v.error.code});
            if (performance.now() - t0 > 15000) return done({error: 'timeout', currentTime: v.currentTime});
            setTimeout(poll, 50);
        })();
    })''')
    page.screenshot(path=shot, full_page=True)
    out["errors"] = errors
    browser.close()
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def browser_python() -> str:
    reason = None
    if shutil.which("chromium") is None:
        reason = "chromium is not installed (apt-get install chromium)"
    python = None if reason else eval_peers.peer_python()
    if reason is None and python is None:
        reason = f"the peers' environment (Playwright) cannot be built: {eval_peers.LAST_REASON}"
    if reason:
        if BROWSER_REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_BROWSER_REQUIRED is set")
        pytest.skip(reason)
    return python


def browse(python: str, report: Path, shot: Path) -> dict:
    run = subprocess.run(
        [python, "-c", BROWSER_SCRIPT, report.resolve().as_uri(), str(shot)],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    # Playwright's own message comes first and the browser's log after it: keep both ends.
    assert run.returncode == 0, run.stderr[:2000] + "\n[...]\n" + run.stderr[-2000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("embed", [False, True], ids=["linked", "embedded"])
def test_the_report_in_a_browser(browser_python, tmp_path, embed) -> None:
    results = make_results(tmp_path)
    folder = tmp_path / ("alone" if embed else "")
    report = Path(write_report(results, folder / "report.html", embed_video_bytes=(1 << 20) if embed else 0))
    if embed:  # the report travels alone: the videos beside the results are gone
        shutil.rmtree(tmp_path / "videos")
    seen = browse(browser_python, report, tmp_path / "report.png")
    assert seen["errors"] == []
    assert [row[0] for row in seen["task_rows"]] == ["bench/0", "bench/1"]
    assert seen["task_rows"][0][5].startswith("66.7%")
    order = [(t, int(i), o) for t, i, o in seen["initial"]]
    assert order == [(e["task"], e["index"], _outcome(e)) for e in results["episodes"]]
    assert [o for _, _, o in seen["by_outcome"]] == [
        "error",
        "failure",
        "success",
        "success",
        "success",
        "success",
    ]
    assert [o for _, _, o in seen["by_outcome_desc"]][:4] == ["success"] * 4
    assert [o for _, _, o in seen["by_outcome_desc"]][4:] == ["failure", "error"]
    # Ties keep the task-then-index order, whatever was sorted before.
    assert [(t, int(i)) for t, i, _ in seen["by_task_desc"]] == [("bench/1", k) for k in range(3)] + [
        ("bench/0", k) for k in range(3)
    ]
    assert seen["tasks_by_length"] == ["bench/0", "bench/1"]
    assert sorted((t, i) for t, i, _ in seen["failures"]) == [("bench/0", "1"), ("bench/1", "1")]
    assert seen["shown"] == "2 of 6 episodes"
    assert [t for t, _, _ in seen["task1"]] == ["bench/1"] * 3
    assert seen["played"]["error"] is None and seen["played"]["currentTime"] > 0.3, seen["played"]
    if os.environ.get("ENVHUB_REPORT_SHOT"):  # keep the screenshot to look at
        shutil.copy(tmp_path / "report.png", os.environ["ENVHUB_REPORT_SHOT"])


def _outcome(episode: dict) -> str:
    if episode["error"]:
        return "error"
    return "success" if episode["success"] else "failure"
