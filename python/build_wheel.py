"""Assembles the `envhub` wheel from the binaries `make build` already compiled.

    python python/build_wheel.py --out dist    (what `make wheel` runs)

Why not `maturin build`: maturin compiles the extension in its own target folder with its own
flags, so CI would compile the whole dependency tree (iceoryx2, mujoco-rs, rapier, pyo3) a
second time, and it would not build the `envhub` and worker binaries the wheel must carry. A
wheel is a zip file with a `.dist-info` folder (PEP 427), so this script writes one from the
single release build: the pure-Python package, `target/release/lib_envhub.so` as the
extension module, and the `envhub`, `envhub-worker`, `envhub-worker-mujoco`, `envhub-worker-rapier` binaries in
`envhub/bin/`. Metadata comes from `pyproject.toml` (the one maturin reads too) and the
version from the workspace's `Cargo.toml`.

The binaries are copied without their debug sections (`strip --strip-debug`, when binutils is
there): a wheel of about a quarter the size, with symbols kept for backtraces. The wheel is
refused if a binary carries an RPATH/RUNPATH or a path of this machine (see `leaks`): it must
run wherever pip puts it, and finds libmujoco through the `mujoco` wheel at run time.
"""

from __future__ import annotations

import argparse
import base64
import csv
import hashlib
import io
import os
import shutil
import stat
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "python" / "envhub"
BINARIES = ("envhub", "envhub-worker", "envhub-worker-mujoco", "envhub-worker-rapier")
# Zip entries get a fixed date, so the same build gives the same wheel (SOURCE_DATE_EPOCH wins).
EPOCH = (1980, 1, 1, 0, 0, 0)


#: The oldest CPython the extension module supports: it is built for the stable ABI of this
#: version (pyo3's `abi3-py39`, python/Cargo.toml), so one wheel serves every later one.
ABI3_FROM = "cp39"


def wheel_tag() -> str:
    """`cp39-abi3-linux_x86_64`: the module uses only the stable ABI of CPython 3.9, so the
    wheel installs into any CPython from 3.9 on (the Python environments envhub builds for
    suites included). A plain `linux_*` tag, not manylinux: the binaries link the build
    machine's glibc and are not audited for older ones."""
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{ABI3_FROM}-abi3-{platform}"


def version() -> str:
    cargo = tomllib.loads((ROOT / "Cargo.toml").read_text())
    return cargo["workspace"]["package"]["version"]


def metadata(project: dict, ver: str) -> str:
    lines = [
        "Metadata-Version: 2.1",
        f"Name: {project['name']}",
        f"Version: {ver}",
        f"Summary: {project['description']}",
        f"License: {project['license']['text']}",
        f"Requires-Python: {project['requires-python']}",
    ]
    lines += [f"Requires-Dist: {dep}" for dep in project.get("dependencies", [])]
    for extra, deps in project.get("optional-dependencies", {}).items():
        lines.append(f"Provides-Extra: {extra}")
        lines += [f'Requires-Dist: {dep}; extra == "{extra}"' for dep in deps]
    readme = ROOT / "python" / "README.md"
    body = readme.read_text() if readme.is_file() else ""
    if body:
        lines.append("Description-Content-Type: text/markdown")
    return "\n".join(lines) + "\n\n" + body


def entry_points(project: dict) -> str:
    scripts = project.get("scripts", {})
    return "[console_scripts]\n" + "".join(f"{k} = {v}\n" for k, v in scripts.items())


def leaks(path: Path) -> list[str]:
    """Why `path` (a binary) would not run elsewhere, or carries where it was built: an
    RPATH/RUNPATH, or the repository's, target folder's or cargo home's absolute path."""
    found = []
    dynamic = subprocess.run(["readelf", "-d", str(path)], capture_output=True, text=True, check=True).stdout
    found += [line.strip() for line in dynamic.splitlines() if "RPATH" in line or "RUNPATH" in line]
    data = path.read_bytes()
    cargo_home = Path(os.environ.get("CARGO_HOME", Path.home() / ".cargo"))
    for needle in {str(ROOT), str(ROOT.resolve()), str(cargo_home), str(cargo_home.resolve())}:
        if needle.encode() in data:
            found.append(f"contains `{needle}`")
    return found


def stripped(src: Path, tmp: Path) -> Path:
    """A copy of `src` without debug sections, or `src` itself without binutils' `strip`."""
    if shutil.which("strip") is None:
        return src
    out = tmp / src.name
    subprocess.run(["strip", "--strip-debug", "-o", str(out), str(src)], check=True)
    return out


def build(target: Path, out: Path) -> Path:
    project = tomllib.loads((ROOT / "python" / "pyproject.toml").read_text())["project"]
    ver = version()
    tag = wheel_tag()
    name = project["name"]
    ext_suffix = ".abi3.so"
    dist_info = f"{name}-{ver}.dist-info"

    missing = [str(target / f) for f in ("lib_envhub.so", *BINARIES) if not (target / f).is_file()]
    if missing:
        sys.exit(
            f"error: not built: {', '.join(missing)}\n"
            "hint: run `make wheel` (it runs `make build` first, with the `mujoco` feature)"
        )

    # (path in the wheel, file on disk, executable)
    files: list[tuple[str, Path, bool]] = []
    for src in sorted(PACKAGE.rglob("*")):
        rel = src.relative_to(PACKAGE)
        if src.is_dir() or rel.parts[0] == "bin" or "__pycache__" in rel.parts:
            continue
        if src.suffix in (".so", ".pyc"):  # the dev install's copy of the module; added below
            continue
        files.append((f"envhub/{rel.as_posix()}", src, False))

    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        compiled = [(f"envhub/_envhub{ext_suffix}", stripped(target / "lib_envhub.so", tmp), False)]
        compiled += [(f"envhub/bin/{b}", stripped(target / b, tmp), True) for b in BINARIES]
        problems = [f"{arc}: {why}" for arc, path, _ in compiled for why in leaks(path)]
        if problems:
            sys.exit(
                "error: a binary carries a path of this machine:\n  "
                + "\n  ".join(problems)
                + "\nhint: build through the Makefile (its RUSTFLAGS remap source paths; no rpath is set)"
            )
        files += compiled

        out.mkdir(parents=True, exist_ok=True)
        wheel = out / f"{name}-{ver}-{tag}.whl"
        generated = {
            f"{dist_info}/METADATA": metadata(project, ver),
            f"{dist_info}/WHEEL": (
                "Wheel-Version: 1.0\nGenerator: envhub build_wheel.py\n"
                f"Root-Is-Purelib: false\nTag: {tag}\n"
            ),
            f"{dist_info}/entry_points.txt": entry_points(project),
        }
        record = io.StringIO()
        writer = csv.writer(record, lineterminator="\n")
        partial = wheel.with_suffix(".tmp")
        with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as zf:

            def add(arc: str, data: bytes, executable: bool) -> None:
                info = zipfile.ZipInfo(arc, date_time=EPOCH)
                info.compress_type = zipfile.ZIP_DEFLATED
                # A regular file's mode: pip makes it executable only with S_IFREG set.
                info.external_attr = (stat.S_IFREG | (0o755 if executable else 0o644)) << 16
                zf.writestr(info, data)
                digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
                writer.writerow([arc, f"sha256={digest.decode()}", len(data)])

            for arc, path, executable in files:
                add(arc, path.read_bytes(), executable)
            for arc, text in generated.items():
                add(arc, text.encode(), False)
            writer.writerow([f"{dist_info}/RECORD", "", ""])
            info = zipfile.ZipInfo(f"{dist_info}/RECORD", date_time=EPOCH)
            info.external_attr = (stat.S_IFREG | 0o644) << 16
            zf.writestr(info, record.getvalue())
        partial.replace(wheel)
    return wheel


def main() -> None:
    global EPOCH
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", type=Path, default=ROOT / "target" / "release", help="cargo's release folder")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="where the wheel goes")
    args = parser.parse_args()
    if "SOURCE_DATE_EPOCH" in os.environ:
        import time

        EPOCH = time.gmtime(max(int(os.environ["SOURCE_DATE_EPOCH"]), 315532800))[:6]
    print(build(args.target, args.out))


if __name__ == "__main__":
    main()
