"""The folder where envhub's Python side keeps files of its own (caches a suite's adapter makes
once per user): the same folder, and the same checks, as the Rust side's
`crates/core/src/private_dir.rs` — `$XDG_RUNTIME_DIR/envhub`, else
`$XDG_CACHE_HOME/envhub/run`, else `~/.cache/envhub/run`; never a predictable name in the
shared temporary folder, which another user could make first (and fill with pickles).

Every component of the path is checked with `lstat` before use: owned by this user or root,
writable by no one else unless sticky (as `/tmp`), a link followed only if this user or root
made it; the folder itself this user's, mode 0700, not a link. Missing components are made
with mode 0700. A folder that fails raises `PrivateDirError`, naming it and the fix.
"""

from __future__ import annotations

import os
import stat


class PrivateDirError(OSError):
    """A folder envhub cannot trust with its files: another user's, open to others, or a link."""


def _base() -> str:
    run = os.environ.get("XDG_RUNTIME_DIR")
    if run:
        return os.path.join(run, "envhub")
    cache = os.environ.get("XDG_CACHE_HOME") or (
        os.path.join(os.environ["HOME"], ".cache") if os.environ.get("HOME") else ""
    )
    if not cache:
        raise PrivateDirError(
            "no folder of this user's for envhub's files: `XDG_RUNTIME_DIR`, `XDG_CACHE_HOME` and `HOME` "
            "are all unset\nhint: set `XDG_RUNTIME_DIR` to a folder only you can enter"
        )
    return os.path.join(cache, "envhub", "run")


def _check(path: str, st: os.stat_result, own: bool) -> None:
    uid = os.getuid()
    hint = "set `XDG_RUNTIME_DIR` to a folder of your own"
    if not stat.S_ISDIR(st.st_mode):
        raise PrivateDirError(f"`{path}` is not a folder\nhint: remove it, or {hint}")
    if st.st_uid != uid and (own or st.st_uid != 0):
        raise PrivateDirError(
            f"`{path}` belongs to uid {st.st_uid}, not to this user (uid {uid}) or root; another user may "
            f"have made it first\nhint: remove it (as root: `rm -r {path}`), or {hint}"
        )
    mode = stat.S_IMODE(st.st_mode)
    if own and mode & 0o077:
        raise PrivateDirError(
            f"`{path}` has mode {mode:o}: other users could enter or change what is in it\nhint: `chmod 700 {path}`"
        )
    if not own and mode & 0o022 and not mode & stat.S_ISVTX:
        raise PrivateDirError(
            f"`{path}` has mode {mode:o}: other users could replace what is in it\nhint: `chmod go-w {path}`"
        )


def ensure(path: str) -> str:
    """Makes `path`'s missing components (mode 0700) and checks every one; returns `path`."""
    path = os.path.abspath(path)
    parts = [p for p in path.split(os.sep) if p]
    at = os.sep
    _check(at, os.lstat(at), own=False)
    for i, name in enumerate(parts):
        last = i == len(parts) - 1
        nxt = os.path.join(at, name)
        try:
            st = os.lstat(nxt)
        except FileNotFoundError:
            try:
                os.mkdir(nxt, 0o700)
                # The mode exactly: the umask is process-wide, and a library in another
                # thread may have narrowed it for a moment (0o177 made this folder 0600).
                fd = os.open(nxt, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
                try:
                    os.fchmod(fd, 0o700)
                finally:
                    os.close(fd)
            except FileExistsError:
                pass
            st = os.lstat(nxt)
        if stat.S_ISLNK(st.st_mode):
            if last or st.st_uid not in (0, os.getuid()):
                raise PrivateDirError(
                    f"`{nxt}` is a symbolic link (owned by uid {st.st_uid}); envhub does not write through "
                    f"links it does not trust\nhint: remove the link (`rm {nxt}`), or set `XDG_RUNTIME_DIR` "
                    "to a folder of your own"
                )
            target = os.path.realpath(nxt)
            walked = os.sep
            for part in [p for p in target.split(os.sep) if p]:
                walked = os.path.join(walked, part)
                _check(walked, os.lstat(walked), own=False)
            at = target
            continue
        _check(nxt, st, own=last)
        at = nxt
    return path


def runtime_dir(sub: str) -> str:
    """`sub` inside this user's private folder for envhub, made and checked."""
    base = ensure(_base())
    return ensure(os.path.join(base, sub))
