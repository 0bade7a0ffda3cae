"""One commit of a dataset, on disk: staged files fsynced, placed by rename, and the whole of
`meta/` swapped in by one atomic exchange, the commit point.

Data and video files a commit places are new files, named after every file there (`_files.py`),
so placing them first changes nothing a loader reads through `meta/`. The
new `meta/` is built beside the old one (unchanged files hard-linked, changed ones written
anew, never through a link) and exchanged with it by `renameat2(RENAME_EXCHANGE)`: `info.json`,
`stats.json`, `tasks.parquet` and the episodes files change together. Where the file system
cannot exchange, the files are renamed one by one, `info.json` last.
"""

from __future__ import annotations

import ctypes
import os
import shutil
from collections.abc import Callable
from pathlib import Path

#: Called with the path (relative to the dataset) before each rename of a commit; a test sets
#: it to simulate a crash between two renames.
rename_hook: Callable[[str], None] | None = None

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swaps the paths `a` and `b`; `False` where the system or file system cannot."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    done = renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if done == 0:
        return True
    errno = ctypes.get_errno()
    if errno in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: not supported here
        return False
    raise OSError(errno, os.strerror(errno), str(b))


def link_or_copy(src: str, dst: str) -> None:
    """A hard link (nothing copied), or a copy where the file system has none."""
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _hook(rel: str) -> None:
    if rename_hook is not None:
        rename_hook(rel)


class Commit:
    """The files of one commit, staged in `staging` (inside the dataset, so renames stay on
    its file system) until `apply`."""

    def __init__(self, root: Path, staging: Path) -> None:
        self.root, self.staging = root, staging
        self.meta = staging / "meta"
        shutil.rmtree(self.meta, ignore_errors=True)
        if (root / "meta").is_dir():
            shutil.copytree(root / "meta", self.meta, copy_function=link_or_copy)
        else:
            self.meta.mkdir(parents=True)
        self._renames: list[tuple[Path, str]] = []
        self._written: list[Path] = []
        self._serial = 0
        self._staged: list[Path] = []
        self._removed: list[str] = []
        #: False once `meta/` had to change file by file (no atomic exchange here).
        self.exchanged = True

    def staged(self, name: str) -> Path:
        """A fresh path in the staging folder."""
        self._serial += 1
        path = self.staging / f"c{self._serial}-{name}"
        self._staged.append(path)
        return path

    def discard(self) -> None:
        """Removes what this commit staged (one that will not apply)."""
        for path in self._staged:
            path.unlink(missing_ok=True)
        shutil.rmtree(self.meta, ignore_errors=True)

    def place(self, tmp: Path, rel: str) -> None:
        """Puts `tmp` at `rel` (under the dataset) when the commit applies, before `meta/`."""
        self._renames.append((tmp, rel))

    def meta_file(self, rel: str) -> Path:
        """The path to write `meta/<rel>` of the new `meta/` to (a new file: an unchanged one
        is a hard link to the committed file, which must not change)."""
        path = self.meta / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.unlink(missing_ok=True)
        self._written.append(path)
        return path

    def remove_meta_file(self, rel: str) -> None:
        """`meta/<rel>` is not part of the new `meta/` (removed after the files written)."""
        (self.meta / rel).unlink()
        self._removed.append(rel)

    def apply(self) -> None:
        for tmp, _ in self._renames:
            fsync_file(tmp)
        for path in self._written:
            fsync_file(path)
        for dirpath, _, _ in os.walk(self.meta):
            fsync_dir(Path(dirpath))
        dirs: set[Path] = set()
        for tmp, rel in self._renames:
            final = self.root / rel
            final.parent.mkdir(parents=True, exist_ok=True)
            _hook(rel)
            os.replace(tmp, final)
            for parent in Path(rel).parents:  # the file's folder, and any folder made for it
                dirs.add(self.root / parent)
        for d in sorted(dirs, key=lambda p: -len(p.parts)):
            fsync_dir(d)
        old = self.root / "meta"
        _hook("meta")
        if not old.exists():
            os.rename(self.meta, old)
        elif not _exchange(self.meta, old):
            self.exchanged = False
            self._rename_one_by_one(old)
        fsync_dir(self.root)
        shutil.rmtree(self.meta, ignore_errors=True)  # the previous `meta/`, after an exchange

    def _rename_one_by_one(self, old: Path) -> None:
        """Without an atomic exchange: every changed file into `meta/`, `info.json` (whose
        totals say which episodes exist) last."""
        info = self.meta / "info.json"
        for path in [p for p in self._written if p != info] + [info]:
            rel = path.relative_to(self.meta)
            (old / rel).parent.mkdir(parents=True, exist_ok=True)
            _hook(f"meta/{rel}")
            os.replace(path, old / rel)
            fsync_dir((old / rel).parent)
        for rel in self._removed:
            (old / rel).unlink(missing_ok=True)
            fsync_dir((old / rel).parent)
