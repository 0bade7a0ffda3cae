"""Fails when a target that Cargo.toml marks `test = false` has tests in its sources.

Targets without unit tests are marked `test = false` (and `bench = false`) so that `make
lint`'s build of every target does not compile a test harness of them for nothing (a whole
crate again, cfg(test)). A test added to such a target later would never be built or run:
this names it. A library's folder is read whole; a binary's file alone (its library holds the
code).

    python scripts/check_untested_targets.py
"""

import json
import re
import subprocess
import sys
from pathlib import Path

MARKERS = re.compile(r"#\[(?:tokio::)?test\b|#\[cfg\(test\)\]|\bproptest!")


def main() -> int:
    meta = json.loads(
        subprocess.run(
            ["cargo", "metadata", "--no-deps", "--format-version", "1"], check=True, capture_output=True, text=True
        ).stdout
    )
    bad = []
    for package in meta["packages"]:
        for target in package["targets"]:
            if target.get("test", True):
                continue
            src = Path(target["src_path"])
            files = sorted(src.parent.rglob("*.rs")) if "lib" in target["kind"] or "cdylib" in target["kind"] else [src]
            for f in files:
                for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
                    if MARKERS.search(line):
                        bad.append(f"{f}:{n}: a test in `{package['name']}`'s {target['kind'][0]} `{target['name']}`, "
                                   "which Cargo.toml marks `test = false`")
    for line in bad:
        print(line, file=sys.stderr)
    if bad:
        print("hint: remove `test = false` (and `bench = false`) from that target in its Cargo.toml", file=sys.stderr)
        return 1
    print("untested targets ok: no test in a target marked `test = false`")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
