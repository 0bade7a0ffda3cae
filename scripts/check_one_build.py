"""Checks that `make build` (what the demo and the Python package need, its arguments given
here) and `make lint`'s build of every target of the workspace compile each shared crate the
same way, so the second reuses the first.

Cargo resolves features per build: a feature that only a dev-dependency turns on changes that
crate, and every crate above it, in the build of the tests, and they are compiled twice
(crates/hub/Cargo.toml asks for those features in the normal build too). This compares the two unit
graphs (`cargo build --unit-graph`, unstable: RUSTC_BOOTSTRAP=1) and names each crate whose
features differ.

    python scripts/check_one_build.py -- --release -p envhub-hub -p envhub-worker -p envhub-python --features envhub-worker/mujoco
"""

import json
import os
import subprocess
import sys


def unit_features(args: list[str]) -> dict[tuple, set[tuple]]:
    env = dict(os.environ, RUSTC_BOOTSTRAP="1")
    out = subprocess.run(
        ["cargo", "build", *args, "--unit-graph", "-Z", "unstable-options"],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    units = json.loads(out)["units"]
    host = for_host(units)
    features: dict[tuple, set[tuple]] = {}
    for i, unit in enumerate(units):
        # A crate compiled for build scripts and proc macros and again for the binaries is two
        # units: each is compared with its own kind, else the host copy's features would hide
        # a target copy compiled twice.
        key = (unit["pkg_id"], unit["target"]["name"], unit["mode"], tuple(unit["target"]["kind"]), host[i])
        features.setdefault(key, set()).add(tuple(sorted(unit["features"])))
    return features


def for_host(units: list[dict]) -> list[bool]:
    """Whether each unit runs on the build machine: build scripts, proc macros and what they
    depend on (the unit graph's `platform` is null for both kinds without `--target`)."""
    host = [False] * len(units)
    stack = [
        i
        for i, u in enumerate(units)
        if "proc-macro" in u["target"]["kind"] or (u["target"]["kind"] == ["custom-build"] and u["mode"] == "build")
    ]
    while stack:
        i = stack.pop()
        if not host[i]:
            host[i] = True
            stack.extend(d["index"] for d in units[i]["dependencies"])
    return host


def without_packages(args: list[str]) -> list[str]:
    """`args` without its package selection (`-p NAME`, `--workspace`)."""
    kept, skip = [], False
    for arg in args:
        if skip:
            skip = False
        elif arg in ("-p", "--package"):
            skip = True
        elif arg != "--workspace" and not arg.startswith(("-p=", "--package=")):
            kept.append(arg)
    return kept


def main() -> int:
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    build = unit_features(args)
    every = unit_features([*without_packages(args), "--workspace", "--all-targets"])
    differ = []
    for key, features in sorted(build.items()):
        # A unit only the tests build is new there, not a second compile: only what the
        # build has and the tests' build has otherwise counts.
        if key in every and not features <= every[key]:
            differ.append(f"  {key[0].split('#')[-1]} ({key[1]}): build {sorted(features)}, tests {sorted(every[key] - features)}")
    if differ:
        print(
            "check_one_build: these crates are compiled with other features for the tests, so "
            "they and every crate above them are compiled twice; ask for the tests' features in "
            "crates/hub/Cargo.toml:\n" + "\n".join(differ),
            file=sys.stderr,
        )
        return 1
    print(f"one build: {len(build)} units of `make build` reused by the tests' build")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
