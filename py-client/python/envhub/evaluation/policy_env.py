"""A callable policy run in a catalog Python environment (`--policy-env NAME`): a child
process of that environment's interpreter loads the policy, and the two speak a small pipe
protocol: pickled `(command, args)` messages on the child's stdin, pickled replies on its
stdout (the child's prints go to stderr). Observations' arrays travel through shared memory
(`arena.py`: written once into a memory file the child maps); the pipe carries
where they are.

    python -m envhub.evaluation.policy_env SPEC --arena FD [--per-task]   # the child, run by EnvPolicy
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from typing import Any, Sequence

import numpy as np

from .policy import Episode, PolicyError, Request

__all__ = ["EnvPolicy", "env_command"]


def env_command(name: str, registry: Any = None) -> list[str]:
    """The command that runs the rest of its arguments in the catalog's Python environment
    `name` as its workers run (`envhub env run NAME --`): built first where it is not, its
    interpreter importing this install's `envhub`, the environment held while it runs."""
    from .._cli import BINARY

    files: list[str] = []
    for source in getattr(registry, "sources", None) or []:
        files += ["--registry", "@default" if source.endswith("(@default)") else source]
    return [str(BINARY), *files, "env", "run", name, "--"]


class EnvPolicy:
    """A `Policy` whose callable (`module:function`) runs in another interpreter."""

    def __init__(self, spec: str, command: Sequence[str], per_task: bool = False, env_name: str | None = None) -> None:
        self.spec, self.env_name = spec, env_name
        from .arena import Arena

        self.arena = Arena()
        args = [*command, "-m", "envhub.evaluation.policy_env", spec, "--arena", str(self.arena.fd)]
        args += ["--per-task"] if per_task else []
        # `-m` puts the current folder first on the child's path: the policy's module is found
        # where `--policy` names it, as in this process.
        self.proc = subprocess.Popen(
            args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, pass_fds=(self.arena.fd,)
        )
        self.info: dict[str, Any] = self._call("describe")

    def _call(self, command: str, *args: Any) -> Any:
        try:
            pickle.dump((command, args), self.proc.stdin, protocol=5)  # type: ignore[arg-type]
            self.proc.stdin.flush()  # type: ignore[union-attr]
            ok, value = pickle.load(self.proc.stdout)  # type: ignore[arg-type]
        except (EOFError, BrokenPipeError, OSError) as e:
            code = self.proc.poll()
            raise PolicyError(
                f"the policy process ({self.spec} in `{self.env_name}`) is gone (exit {code}): {type(e).__name__}"
                "\nhint: its error is on stderr above"
            ) from None
        if not ok:
            raise PolicyError(value)
        return value

    def start(self, slot: int, episode: Episode) -> None:
        self._call("start", slot, episode)

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]:
        packed, size = self.arena.put(requests)
        return self._call("act", packed, size)

    def end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None:
        self._call("end", slot, episode, result)

    def describe(self) -> dict[str, Any]:
        return {**self.info, "python_env": self.env_name}

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self._call("close")
            except PolicyError:
                pass
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.arena.close()


def child(spec: str, per_task: bool, arena: int | None) -> int:
    reply = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    requests = sys.stdin.buffer
    from .arena import ArenaView
    from .callable import CallablePolicy, PerTask, load

    view = ArenaView(arena) if arena is not None else None

    try:
        target = load(spec)
        policy = CallablePolicy(PerTask(target) if per_task else target, name=spec)
    except Exception as e:
        pickle.dump((False, f"cannot load the policy `{spec}`: {type(e).__name__}: {e}"), reply)
        reply.flush()
        return 1
    while True:
        try:
            command, args = pickle.load(requests)
        except EOFError:
            return 0
        try:
            if command == "describe":
                value: Any = policy.describe()
            elif command == "act":
                batch = view.take(args[0], args[1]) if view is not None and len(args) > 1 else args[0]
                value = [np.asarray(a) for a in policy.act(batch)]
            elif command == "start":
                value = policy.start(*args)
            elif command == "end":
                value = policy.end(*args)
            elif command == "close":
                policy.close()
                pickle.dump((True, None), reply)
                reply.flush()
                return 0
            else:
                raise ValueError(f"unknown command {command!r}")
            pickle.dump((True, value), reply, protocol=5)
        except Exception as e:
            pickle.dump((False, f"{type(e).__name__}: {e}"), reply)
        reply.flush()


def _arena_fd(argv: list[str]) -> int | None:
    return int(argv[argv.index("--arena") + 1]) if "--arena" in argv else None


if __name__ == "__main__":
    sys.exit(child(sys.argv[1], "--per-task" in sys.argv[2:], _arena_fd(sys.argv[2:])))
