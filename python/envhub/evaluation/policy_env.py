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
import select
import signal
import subprocess
import sys
import time
from typing import Any, Sequence

import numpy as np

from .policy import Episode, PolicyError, PolicyLoadError, Request, policy_traceback

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


def _die_with_parent() -> None:
    """In the child before exec: SIGKILL when the evaluation's process ends, whatever ends it
    (a kill -9 leaves no policy process behind)."""
    import ctypes

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


class EnvPolicy:
    """A `Policy` whose callable (`module:function`) runs in another interpreter. Each call
    but the first `describe` (the environment's build and the policy's loading) has a
    deadline of `timeout` seconds: a process that misses one is killed (its process group),
    the call fails with a `PolicyError`, and the next call starts a new process, told of the
    episodes still running (`start` again)."""

    def __init__(
        self,
        spec: str,
        command: Sequence[str],
        per_task: bool = False,
        env_name: str | None = None,
        timeout: float | None = None,
    ) -> None:
        if timeout is not None and not timeout > 0:
            raise ValueError(f"the policy timeout must be a positive number of seconds, not {timeout!r}")
        self.spec, self.env_name, self.timeout = spec, env_name, timeout
        self.command, self.per_task = list(command), per_task
        from .arena import Arena

        self.arena = Arena()
        self.running: dict[int, Episode] = {}  # episodes started and not ended, by slot
        self.proc: subprocess.Popen | None = None
        self.gone = True  # no live process to call (none yet, or killed): the next call starts one
        self.killed = 0  # processes killed for a missed deadline
        self.info: dict[str, Any] = self._spawn()

    @property
    def name(self) -> str:
        return f"`{self.spec}` (in `{self.env_name}`, pid {self.proc.pid if self.proc else '-'})"

    def _spawn(self) -> dict[str, Any]:
        args = [*self.command, "-m", "envhub.evaluation.policy_env", self.spec, "--arena", str(self.arena.fd)]
        args += ["--per-task"] if self.per_task else []
        # `-m` puts the current folder first on the child's path: the policy's module is found
        # where `--policy` names it, as in this process. Its own process group, killed whole
        # on a missed deadline or a stop; the terminal's Ctrl-C reaches the evaluation, which
        # closes it.
        self.proc = subprocess.Popen(
            args,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            pass_fds=(self.arena.fd,),
            start_new_session=True,
            preexec_fn=_die_with_parent,
        )
        self.gone = False
        return self._call("describe", deadline=False)

    def kill(self) -> None:
        """Kills the policy's process and its group (its own children), and reaps it."""
        proc, self.gone = self.proc, True
        if proc is None or proc.returncode is not None:
            return
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            proc.kill()
        proc.wait()
        for pipe in (proc.stdin, proc.stdout):
            try:
                pipe.close()  # type: ignore[union-attr]
            except OSError:
                pass

    def _wait_reply(self, what: str) -> None:
        """Waits until the reply starts to arrive, `timeout` seconds at most."""
        assert self.proc is not None
        fd = self.proc.stdout.fileno()  # type: ignore[union-attr]
        deadline = time.monotonic() + self.timeout  # type: ignore[operator]
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                name = self.name
                self.kill()
                self.killed += 1
                raise PolicyError(
                    f"the policy {name} gave no answer to `{what}` within {self.timeout:g} s (--policy-timeout); "
                    "its process was killed (a new one starts for the next episodes)"
                )
            ready, _, _ = select.select([fd], [], [], left)
            if ready:
                return

    def _call(self, command: str, *args: Any, deadline: bool = True) -> Any:
        if self.gone:  # killed after a missed deadline: a new process, told of the running episodes
            self.info = self._spawn()
            for slot, episode in list(self.running.items()):
                self._call("start", slot, episode)
        proc = self.proc
        assert proc is not None
        try:
            pickle.dump((command, args), proc.stdin, protocol=5)  # type: ignore[arg-type]
            proc.stdin.flush()  # type: ignore[union-attr]
            if deadline and self.timeout is not None:
                self._wait_reply(command)
            ok, value = pickle.load(proc.stdout)  # type: ignore[arg-type]
        except KeyboardInterrupt:  # a stop mid-call: the pipe is out of step; the process goes
            self.kill()
            raise
        except (EOFError, BrokenPipeError, OSError, pickle.UnpicklingError) as e:
            code = proc.poll()
            raise PolicyError(
                f"the policy process ({self.spec} in `{self.env_name}`) is gone (exit {code}): {type(e).__name__}"
                "\nhint: its error is on stderr above"
            ) from None
        if not ok:
            if isinstance(value, tuple) and value[0] == "load":
                raise PolicyLoadError(value[1])
            raise PolicyError(value)
        return value

    def start(self, slot: int, episode: Episode) -> None:
        self._call("start", slot, episode)
        self.running[slot] = episode

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]:
        packed, size = self.arena.put(requests)
        try:
            return self._call("act", packed, size)
        except PolicyError:
            if self.gone:  # killed: the batch's episodes fail, the others go on in the next process
                for r in requests:
                    self.running.pop(r.slot, None)
            raise

    def end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None:
        if self.running.pop(slot, None) is None:  # its process was killed with its episode
            return
        self._call("end", slot, episode, result)

    def describe(self) -> dict[str, Any]:
        return {**self.info, "python_env": self.env_name}

    def close(self) -> None:
        proc = self.proc
        if proc is not None and not self.gone and proc.poll() is None:
            try:
                self._call("close")
            except PolicyError:
                pass
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
        self.kill()  # its group too: whatever the policy started
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
        pickle.dump((False, ("load", f"cannot load the policy `{spec}`: {type(e).__name__}: {e}")), reply)
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
        except Exception as e:  # the traceback travels: the evaluation's console and results show it
            pickle.dump((False, f"the policy raised {type(e).__name__}: {e}\n{policy_traceback(e)}"), reply)
        reply.flush()


def _arena_fd(argv: list[str]) -> int | None:
    return int(argv[argv.index("--arena") + 1]) if "--arena" in argv else None


if __name__ == "__main__":
    sys.exit(child(sys.argv[1], "--per-task" in sys.argv[2:], _arena_fd(sys.argv[2:])))
