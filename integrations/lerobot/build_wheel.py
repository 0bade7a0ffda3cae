"""Writes the `lerobot_env_envhub` wheel (pure Python) from this folder, without a build
backend or a download: `make wheel` runs it beside the envhub wheel.

    python integrations/lerobot/build_wheel.py --out dist

LeRobot finds plugins by the distribution's `Name` in its metadata, which must start with
`lerobot_env_` as written (underscores): the name is written as `pyproject.toml` spells it.
"""

from __future__ import annotations

import argparse
import base64
import csv
import hashlib
import io
import stat
import sys
import zipfile
from pathlib import Path

import tomllib

HERE = Path(__file__).resolve().parent
EPOCH = (1980, 1, 1, 0, 0, 0)


def build(out: Path) -> Path:
    config = tomllib.loads((HERE / "pyproject.toml").read_text())
    project = config["project"]
    name, version = project["name"], project["version"]
    if not name.startswith("lerobot_env_"):
        sys.exit(f"error: the distribution's name `{name}` must start with `lerobot_env_` for LeRobot to load it")
    package = HERE / name
    data = set(config["tool"]["setuptools"]["package-data"][name])
    files = sorted(
        p for p in package.iterdir() if p.is_file() and (p.suffix == ".py" or p.name in data)
    )
    missing = sorted(data - {p.name for p in files})
    if missing:
        sys.exit(f"error: package data missing in {package}: {', '.join(missing)}")
    dist_info = f"{name}-{version}.dist-info"
    meta = [
        "Metadata-Version: 2.1",
        f"Name: {name}",
        f"Version: {version}",
        f"Summary: {project['description']}",
        f"License: {project['license']['text']}",
        f"Requires-Python: {project['requires-python']}",
        *(f"Requires-Dist: {d}" for d in project["dependencies"]),
    ]
    generated = {
        f"{dist_info}/METADATA": "\n".join(meta) + "\n",
        f"{dist_info}/WHEEL": "Wheel-Version: 1.0\nGenerator: envhub build_wheel.py\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
    }
    out.mkdir(parents=True, exist_ok=True)
    wheel = out / f"{name}-{version}-py3-none-any.whl"
    record = io.StringIO()
    writer = csv.writer(record, lineterminator="\n")
    partial = wheel.with_suffix(".tmp")
    with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as zf:

        def add(arc: str, content: bytes) -> None:
            info = zipfile.ZipInfo(arc, date_time=EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (stat.S_IFREG | 0o644) << 16
            zf.writestr(info, content)
            digest = base64.urlsafe_b64encode(hashlib.sha256(content).digest()).rstrip(b"=").decode()
            writer.writerow([arc, f"sha256={digest}", len(content)])

        for path in files:
            add(f"{name}/{path.name}", path.read_bytes())
        for arc, text in generated.items():
            add(arc, text.encode())
        writer.writerow([f"{dist_info}/RECORD", "", ""])
        info = zipfile.ZipInfo(f"{dist_info}/RECORD", date_time=EPOCH)
        info.external_attr = (stat.S_IFREG | 0o644) << 16
        zf.writestr(info, record.getvalue())
    partial.replace(wheel)
    return wheel


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HERE.parent.parent / "dist", help="where the wheel goes")
    print(build(parser.parse_args().out))


if __name__ == "__main__":
    main()
