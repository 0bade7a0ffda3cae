"""The evaluation's HTML report: one self-contained file (inline CSS and JavaScript, nothing
fetched from the network) that a person opens in a browser.

It shows the overall success rate with its standard error, the per-task table (and, for a
perturbation benchmark, the per-axis table: each axis's rate and its difference from the
unperturbed `original` axis), the protocol, versions, policy and run the results came from, and every episode as a row whose
video plays in place. Both tables sort by clicking a column's header; the episodes filter
to failures or one task. Rows are rendered here, in Python, so the tables read without
JavaScript too; the script only sorts and filters them.

Videos are referenced by their path relative to the report (they stay beside the results),
or embedded as data URIs when `embed_video_bytes` allows: then the file travels alone.
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
from pathlib import Path
from typing import Any

from .axes import AXES
from .axes import rows as axis_rows

# Above this many videos, players load nothing until played (each would otherwise read its
# file's header when the page opens).
_PRELOAD_LIMIT = 200


def write_report(
    results: dict[str, Any],
    path: str | os.PathLike[str],
    *,
    embed_video_bytes: int = 0,
    embed_total_bytes: int = 64 << 20,
) -> str:
    """Writes the report of `results` (the results.json dict) to `path`; returns the path.

    Video paths in `results` are relative to the results folder (`results["run"]["out"]`,
    else the report's folder). A video no larger than `embed_video_bytes` is embedded, as
    long as the embedded ones stay under `embed_total_bytes` together; 0 embeds none."""
    path = Path(path)
    report_dir = path.resolve().parent
    out = (results.get("run") or {}).get("out")
    results_dir = Path(out).resolve() if out else report_dir
    videos = _Videos(results_dir, report_dir, embed_video_bytes, embed_total_bytes)
    page = _page(results, videos)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(page, encoding="utf-8")
    os.replace(tmp, path)
    return str(path)


class _Videos:
    """Where each episode's video is, as the report's `<video src>`."""

    def __init__(self, results_dir: Path, report_dir: Path, each: int, total: int) -> None:
        self.results_dir, self.report_dir = results_dir, report_dir
        self.each, self.left = each, total

    def src(self, relative: str) -> str:
        file = self.results_dir / relative
        if self.each > 0:
            try:
                size = file.stat().st_size
            except OSError:
                size = None
            if size is not None and size <= self.each and size <= self.left:
                self.left -= size
                return "data:video/mp4;base64," + base64.b64encode(file.read_bytes()).decode("ascii")
        return Path(os.path.relpath(file, self.report_dir)).as_posix()


# -- formatting --------------------------------------------------------------------------


def _e(value: Any) -> str:
    return html.escape("" if value is None else str(value), quote=True)


def _num(value: Any, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        return f"{value:,.{digits}f}"
    return _e(value)


def _pct(rate: Any) -> str:
    return "—" if rate is None else f"{100 * rate:.1f}%"


def _se(stderr: Any) -> str:
    return "" if stderr is None else f"± {100 * stderr:.1f}"


def _ci(interval: Any) -> str:
    """A Wilson 95 % interval in percent."""
    return "" if not interval else f"95% CI {100 * interval[0]:.1f}–{100 * interval[1]:.1f}%"


def _key(value: Any) -> str:
    """A cell's sort key: numbers as numbers, missing last."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(int(value))
    return _e(value)


def _compact(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (dict, list)):
        return json.dumps(value, separators=(", ", ": "), default=str)
    return "" if value is None else str(value)


def _outcome(episode: dict[str, Any]) -> tuple[str, str, int]:
    """(label, css class, sort rank): errors first, then failures, then successes."""
    if episode.get("error"):
        return "error", "err", 0
    if episode.get("success") is None:
        return "done", "none", 2
    return ("success", "ok", 3) if episode["success"] else ("failure", "fail", 1)


# -- the page ----------------------------------------------------------------------------


def _page(results: dict[str, Any], videos: _Videos) -> str:
    summary = results.get("summary") or {}
    bench = results.get("benchmark") or "evaluation"
    rule = ((results.get("protocol") or {}).get("success") or {}).get("rule")
    episodes = results.get("episodes") or []
    with_video = sum(1 for e in episodes if e.get("video"))
    title = f"{bench} — envhub eval"
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{_e(title)}</title>",
            f"<style>{_CSS}</style></head><body>",
            '<header class="top">',
            f'<div class="eyebrow">envhub eval · {_e(results.get("schema", ""))}</div>',
            f"<h1>{_e(bench)}</h1>",
            f'<p class="desc">{_e(results.get("description", ""))}</p>',
            _headline(summary, rule, results),
            "</header><main>",
            _axis_table(results, rule),
            _task_table(results, rule),
            '<section class="cards">',
            _card("Protocol", results.get("protocol") or {}),
            _card("Policy", results.get("policy") or {}),
            _card("Versions", _versions(results.get("versions") or {})),
            _card("Run", {k: v for k, v in (results.get("run") or {}).items() if k not in ("shards", "merged_from")}),
            "</section>",
            _shard_table(results),
            _episode_table(episodes, results, videos, with_video),
            "</main>",
            f"<footer>Written by envhub {_e((results.get('versions') or {}).get('envhub', ''))}. "
            "Rates are the share of successful episodes (an errored episode counts as a failure); "
            "± is one standard error, √(p(1−p)/n); 95% CI is the Wilson score interval.</footer>",
            f"<script>{_JS}</script>",
            "</body></html>",
        ]
    )


def _headline(summary: dict[str, Any], rule: Any, results: dict[str, Any]) -> str:
    stats = []
    if rule != "none":
        stats.append(
            (
                "Success rate",
                f"{_pct(summary.get('success_rate'))} <small>{_se(summary.get('stderr'))}</small>"
                f"<div class=\"ci\"><small>{_ci(summary.get('ci95'))}</small></div>",
                "big",
            )
        )
        stats.append(("Successes", f"{_num(summary.get('successes'))} / {_num(summary.get('episodes'))}", ""))
    else:
        stats.append(("Mean return", _num(summary.get("mean_return")), "big"))
        stats.append(("Episodes", _num(summary.get("episodes")), ""))
    stats.append(("Errors", _num(summary.get("errors")), "warn" if summary.get("errors") else ""))
    if rule != "none":
        stats.append(("Mean return", _num(summary.get("mean_return")), ""))
    stats += [
        ("Mean length", _num(summary.get("mean_length"), 1), ""),
        ("Episodes / min", _num(summary.get("episodes_per_minute"), 1), ""),
        ("Tasks", _num(len(results.get("tasks") or [])), ""),
    ]
    cells = "".join(
        f'<div class="stat {cls}"><div class="label">{_e(label)}</div><div class="value">{value}</div></div>'
        for label, value, cls in stats
    )
    return f'<div class="stats">{cells}</div>'


def _task_table(results: dict[str, Any], rule: Any) -> str:
    rows = []
    for row in results.get("per_task") or []:
        rate = row.get("success_rate")
        bar = (
            f'<div class="bar"><span style="width:{100 * rate:.1f}%"></span></div>'
            if rate is not None and rule != "none"
            else ""
        )
        rows.append(
            "<tr>"
            f'<td data-key="{_key(row.get("task"))}" class="mono">{_e(row.get("task"))}</td>'
            f'<td data-key="{_key(row.get("text"))}" class="text">{_e(row.get("text"))}</td>'
            f'<td data-key="{_key(row.get("episodes"))}" class="num">{_num(row.get("episodes"))}</td>'
            f'<td data-key="{_key(row.get("successes"))}" class="num">{_num(row.get("successes"))}</td>'
            f'<td data-key="{_key(row.get("errors"))}" class="num">{_num(row.get("errors"))}</td>'
            f'<td data-key="{_key(rate)}" class="rate">{bar}<b>{_pct(rate)}</b> '
            f"<small>{_se(row.get('stderr'))}</small><br><small>{_ci(row.get('ci95'))}</small></td>"
            f'<td data-key="{_key(row.get("mean_return"))}" class="num">{_num(row.get("mean_return"))}</td>'
            f'<td data-key="{_key(row.get("mean_length"))}" class="num">{_num(row.get("mean_length"), 1)}</td>'
            "</tr>"
        )
    head = _head(
        [
            ("Task", "text"),
            ("Instruction", "text"),
            ("Episodes", "num"),
            ("Successes", "num"),
            ("Errors", "num"),
            ("Success rate", "num"),
            ("Mean return", "num"),
            ("Mean length", "num"),
        ]
    )
    return (
        '<section><h2>Per task</h2><table id="tasks" class="sortable">'
        f"{head}<tbody>{''.join(rows)}</tbody></table></section>"
    )


def _axis_table(results: dict[str, Any], rule: Any) -> str:
    """The per-axis table of a perturbation benchmark (`axes.rows`); empty otherwise."""
    rows = []
    for row in axis_rows(results):
        rate = row.get("success_rate")
        bar = (
            f'<div class="bar"><span style="width:{100 * rate:.1f}%"></span></div>'
            if rate is not None and rule != "none"
            else ""
        )
        delta = row.get("vs_original")
        rows.append(
            "<tr>"
            f'<td data-key="{_key(row.get("axis"))}" class="mono" title="{_e(AXES.get(str(row.get("axis")), ""))}">'
            f"{_e(row.get('axis'))}</td>"
            f'<td data-key="{_key(row.get("tasks"))}" class="num">{_num(row.get("tasks"))}</td>'
            f'<td data-key="{_key(row.get("episodes"))}" class="num">{_num(row.get("episodes"))}</td>'
            f'<td data-key="{_key(row.get("successes"))}" class="num">{_num(row.get("successes"))}</td>'
            f'<td data-key="{_key(row.get("errors"))}" class="num">{_num(row.get("errors"))}</td>'
            f'<td data-key="{_key(rate)}" class="rate">{bar}<b>{_pct(rate)}</b> '
            f"<small>{_se(row.get('stderr'))}</small><br><small>{_ci(row.get('ci95'))}</small></td>"
            f'<td data-key="{_key(delta)}" class="num">'
            f"{'—' if delta is None else f'{100 * delta:+.1f} pts'}</td>"
            "</tr>"
        )
    if not rows:
        return ""
    head = _head(
        [
            ("Axis", "text"),
            ("Tasks", "num"),
            ("Episodes", "num"),
            ("Successes", "num"),
            ("Errors", "num"),
            ("Success rate", "num"),
            ("vs original", "num"),
        ]
    )
    return (
        '<section><h2>Per perturbation axis</h2><table id="axes" class="sortable">'
        f"{head}<tbody>{''.join(rows)}</tbody></table></section>"
    )


def _shard_table(results: dict[str, Any]) -> str:
    """A merged run's shards (`envhub eval merge`, `--ray`): host, episodes, attempts, time."""
    shards = (results.get("run") or {}).get("shards") or []
    if not shards:
        return ""
    rows = []
    for sh in shards:
        secs = sh.get("seconds")
        rate = sh["episodes"] / secs * 60 if secs else None
        rows.append(
            "<tr>"
            f'<td data-key="{_key(sh.get("shard"))}" class="mono">{_e(sh.get("shard"))}</td>'
            f'<td data-key="{_key(sh.get("host"))}" class="mono">{_e(sh.get("host"))}</td>'
            f'<td data-key="{_key(sh.get("episodes"))}" class="num">{_num(sh.get("episodes"))}</td>'
            f'<td data-key="{_key(sh.get("attempts"))}" class="num">{_num(sh.get("attempts"))}</td>'
            f'<td data-key="{_key(secs)}" class="num">{_num(secs, 1)}</td>'
            f'<td data-key="{_key(rate)}" class="num">{_num(rate, 1)}</td>'
            f'<td data-key="{_key(sh.get("started"))}" class="mono">{_e(sh.get("started"))}</td>'
            "</tr>"
        )
    head = _head([("Shard", "text"), ("Host", "text"), ("Episodes", "num"), ("Attempts", "num"), ("Seconds", "num"),
                  ("Episodes/min", "num"), ("Started", "text")])
    return (
        f'<section><h2>Shards <small class="muted">{len(shards)} merged</small></h2>'
        f'<table id="shards" class="sortable">{head}<tbody>{"".join(rows)}</tbody></table></section>'
    )


def _episode_table(
    episodes: list[dict[str, Any]], results: dict[str, Any], videos: _Videos, with_video: int
) -> str:
    texts = {t.get("id"): t.get("text", "") for t in results.get("tasks") or []}
    preload = "metadata" if with_video <= _PRELOAD_LIMIT else "none"
    rows = []
    for ep in episodes:
        label, cls, rank = _outcome(ep)
        video = ep.get("video")
        player = (
            f'<video controls muted playsinline preload="{preload}" src="{_e(videos.src(video))}"></video>'
            if video
            else '<span class="muted">—</span>'
        )
        error = ep.get("error")
        rows.append(
            f'<tr data-task="{_e(ep.get("task"))}" data-outcome="{label}">'
            f'<td data-key="{_key(ep.get("task"))}" class="mono" title="{_e(texts.get(ep.get("task"), ""))}">'
            f"{_e(ep.get('task'))}</td>"
            f'<td data-key="{_key(ep.get("index"))}" class="num">{_num(ep.get("index"))}</td>'
            f'<td data-key="{rank}"><span class="badge {cls}">{label}</span></td>'
            f'<td data-key="{_key(ep.get("return"))}" class="num">{_num(ep.get("return"))}</td>'
            f'<td data-key="{_key(ep.get("length"))}" class="num">{_num(ep.get("length"))}</td>'
            f'<td data-key="{_key(ep.get("seconds"))}" class="num">{_num(ep.get("seconds"), 1)}</td>'
            f'<td class="mono small">{_e(_compact(ep.get("init")))}</td>'
            f'<td class="video">{player}'
            + (f'<div class="error">{_e(error)}</div>' if error else "")
            + "</td></tr>"
        )
    head = _head(
        [
            ("Task", "text"),
            ("Episode", "num"),
            ("Outcome", "num"),
            ("Return", "num"),
            ("Length", "num"),
            ("Seconds", "num"),
            ("Initial condition", None),
            ("Video", None),
        ]
    )
    options = "".join(
        f'<option value="{_e(t.get("id"))}">{_e(t.get("id"))}</option>' for t in results.get("tasks") or []
    )
    failures = sum(1 for e in episodes if _outcome(e)[2] < 2)
    controls = (
        '<div class="controls">'
        f'<label><input type="checkbox" id="failures-only"> Failures only ({failures})</label>'
        f'<label>Task <select id="task-filter"><option value="">all tasks</option>{options}</select></label>'
        f'<span id="shown" class="muted">{len(episodes)} of {len(episodes)} episodes</span>'
        "</div>"
    )
    return (
        f'<section><h2>Episodes <small class="muted">{with_video} with video</small></h2>{controls}'
        f'<table id="episodes" class="sortable">{head}<tbody>{"".join(rows)}</tbody></table></section>'
    )


def _head(columns: list[tuple[str, str | None]]) -> str:
    cells = "".join(
        f'<th data-type="{kind}" tabindex="0" aria-sort="none">{_e(name)}<i></i></th>'
        if kind
        else f"<th>{_e(name)}</th>"
        for name, kind in columns
    )
    return f"<thead><tr>{cells}</tr></thead>"


def _versions(versions: dict[str, Any]) -> dict[str, Any]:
    flat = {k: v for k, v in versions.items() if k != "packages"}
    flat.update(versions.get("packages") or {})
    return flat


def _card(title: str, values: dict[str, Any]) -> str:
    rows = "".join(
        f'<tr><th>{_e(k)}</th><td class="mono">{_e(_compact(v)) or "<span class=muted>—</span>"}</td></tr>'
        for k, v in values.items()
    )
    return f'<div class="card"><h3>{_e(title)}</h3><table class="kv">{rows}</table></div>'


_CSS = """
:root{--fg:#1d2433;--muted:#6b7385;--line:#e3e6ec;--bg:#f6f7f9;--card:#fff;--accent:#2f5bd3;
--ok:#1a7f4b;--okbg:#e3f4ea;--fail:#b42318;--failbg:#fde8e6;--err:#9a5b00;--errbg:#fff1d6}
*{box-sizing:border-box}
body{margin:0;font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:var(--fg);background:var(--bg)}
.top{background:#fff;border-bottom:1px solid var(--line);padding:28px 40px 22px}
.eyebrow{font-size:12px;letter-spacing:.06em;text-transform:uppercase;color:var(--muted)}
h1{margin:4px 0 2px;font-size:26px}
.desc{margin:0 0 16px;color:var(--muted);max-width:70em}
main{padding:8px 40px 40px}
h2{font-size:17px;margin:28px 0 10px}
h3{font-size:13px;margin:0 0 8px;text-transform:uppercase;letter-spacing:.05em;color:var(--muted)}
small,.muted{color:var(--muted);font-weight:normal}
.stats{display:flex;flex-wrap:wrap;gap:10px}
.stat{background:var(--bg);border:1px solid var(--line);border-radius:8px;padding:10px 16px;min-width:120px}
.stat .label{font-size:12px;color:var(--muted)}
.stat .value{font-size:18px;font-weight:600}
.stat.big .value{font-size:28px;color:var(--accent)}
.stat.warn .value{color:var(--err)}
table{border-collapse:collapse;width:100%;background:var(--card)}
table.sortable{border:1px solid var(--line);border-radius:8px;overflow:hidden}
table.sortable th{position:sticky;top:0;background:#eef0f4;text-align:left;font-weight:600;padding:8px 10px;
border-bottom:1px solid var(--line);white-space:nowrap;user-select:none}
table.sortable th[data-type]{cursor:pointer}
table.sortable th[data-type]:hover{background:#e4e7ee}
th i{display:inline-block;width:1em;color:var(--accent);font-style:normal}
th[aria-sort=ascending] i:after{content:" ▲"}
th[aria-sort=descending] i:after{content:" ▼"}
td{padding:7px 10px;border-bottom:1px solid var(--line);vertical-align:middle}
tbody tr:nth-child(even){background:#fafbfc}
tbody tr:hover{background:#f1f4fb}
.num{text-align:right;font-variant-numeric:tabular-nums}
.mono{font-family:ui-monospace,SFMono-Regular,Menlo,Consolas,monospace;font-size:12.5px}
.small{font-size:11.5px;color:var(--muted)}
.text{max-width:36em}
.rate{white-space:nowrap;font-variant-numeric:tabular-nums}
.bar{display:inline-block;width:80px;height:8px;background:var(--failbg);border-radius:4px;margin-right:8px;
vertical-align:middle;overflow:hidden}
.bar span{display:block;height:100%;background:var(--ok)}
.badge{display:inline-block;padding:1px 9px;border-radius:10px;font-size:12px;font-weight:600}
.badge.ok{color:var(--ok);background:var(--okbg)}
.badge.fail{color:var(--fail);background:var(--failbg)}
.badge.err{color:var(--err);background:var(--errbg)}
.badge.none{color:var(--muted);background:var(--bg)}
video{width:192px;max-height:192px;border-radius:4px;background:#111;display:block}
.error{color:var(--fail);font-size:12px;max-width:40em;margin-top:4px;white-space:pre-wrap}
.cards{display:grid;grid-template-columns:repeat(auto-fit,minmax(320px,1fr));gap:14px;margin-top:28px}
.card{background:var(--card);border:1px solid var(--line);border-radius:8px;padding:14px 16px;overflow:auto}
table.kv th{text-align:left;font-weight:500;color:var(--muted);padding:3px 12px 3px 0;vertical-align:top;
white-space:nowrap;width:1%}
table.kv td{padding:3px 0;border:0;word-break:break-word}
.controls{display:flex;gap:18px;align-items:center;margin:0 0 10px}
select{font:inherit;padding:2px 4px}
footer{padding:0 40px 30px;color:var(--muted);font-size:12px}
"""

_JS = """
(function(){
  function sortBy(table, th){
    var col = Array.prototype.indexOf.call(th.parentNode.children, th);
    var numeric = th.dataset.type === 'num';
    var dir = th.getAttribute('aria-sort') === 'ascending' ? -1 : 1;
    table.querySelectorAll('th').forEach(function(h){ h.setAttribute('aria-sort', 'none'); });
    th.setAttribute('aria-sort', dir === 1 ? 'ascending' : 'descending');
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function(a, b){
      var x = a.cells[col].dataset.key, y = b.cells[col].dataset.key;
      if (x === '' && y !== '') return 1;
      if (y === '' && x !== '') return -1;
      var c = numeric ? parseFloat(x) - parseFloat(y) : x.localeCompare(y, undefined, {numeric: true});
      return c !== 0 ? dir * c : a._order - b._order;
    });
    rows.forEach(function(r){ body.appendChild(r); });
  }
  document.querySelectorAll('table.sortable').forEach(function(table){
    // Ties keep the rendered order (task, then episode index), whatever was sorted before.
    Array.prototype.forEach.call(table.tBodies[0].rows, function(r, i){ r._order = i; });
    table.querySelectorAll('th[data-type]').forEach(function(th){
      th.addEventListener('click', function(){ sortBy(table, th); });
      th.addEventListener('keydown', function(ev){ if (ev.key === 'Enter') sortBy(table, th); });
    });
  });
  var failures = document.getElementById('failures-only');
  var task = document.getElementById('task-filter');
  var shown = document.getElementById('shown');
  function filter(){
    var rows = document.querySelectorAll('#episodes tbody tr'), n = 0;
    rows.forEach(function(r){
      var hide = (failures.checked && (r.dataset.outcome === 'success' || r.dataset.outcome === 'done')) ||
                 (task.value && r.dataset.task !== task.value);
      r.hidden = hide;
      if (!hide) n++;
    });
    shown.textContent = n + ' of ' + rows.length + ' episodes';
  }
  if (failures) { failures.addEventListener('change', filter); task.addEventListener('change', filter); }
})();
"""
