"""Fails a cargo build that printed any warning: clippy's `-D warnings` for a build whose
workspace crates are compiled by clippy-driver (the Makefile's `RUSTC_WORKSPACE_WRAPPER`).

Reads `cargo build --message-format=json-diagnostic-rendered-ansi` on stdin and prints each
diagnostic as cargo would. cargo replays the diagnostics of crates it does not recompile, so a
warning fails every run until it is fixed, not only the run that compiled it.

    cargo build ... --message-format=json-diagnostic-rendered-ansi | python scripts/deny_warnings.py
"""

import json
import re
import sys

# rustc's own tally ("3 warnings emitted"): not a diagnostic of its own.
TALLY = re.compile(r"^\d+ warnings? emitted$|^aborting due to")


def main() -> int:
    warnings = errors = 0
    finished = None
    for line in sys.stdin:
        try:
            msg = json.loads(line)
        except json.JSONDecodeError:
            sys.stdout.write(line)  # a build script's or cargo's own text
            continue
        reason = msg.get("reason")
        if reason == "build-finished":
            finished = msg.get("success")
        if reason != "compiler-message":
            continue
        diagnostic = msg["message"]
        if TALLY.match(diagnostic.get("message", "")):
            continue
        sys.stderr.write(diagnostic.get("rendered") or diagnostic.get("message", ""))
        level = diagnostic.get("level", "")
        if level == "warning":
            warnings += 1
        elif level.startswith("error"):
            errors += 1
    if finished is None:
        print("deny_warnings: the build ended without cargo's summary (see above)", file=sys.stderr)
        return 1
    if warnings:
        print(
            f"deny_warnings: {warnings} warning(s) from rustc or clippy (the build denies them; "
            "fix them or allow the lint with a reason)",
            file=sys.stderr,
        )
        return 1
    return 0 if finished and not errors else 1


if __name__ == "__main__":
    raise SystemExit(main())
