"""The episode loop: a benchmark's episodes over sessions of envs, batched policy calls.

A task runs in a session of its entry (the task is a make option, so one session holds one
task); sessions of several tasks run at once while the env budget (`num_envs`) allows: a
task with fewer episodes left than free envs leaves the rest to the next tasks. A benchmark
whose adapter switches tasks on reset (`task_reset_option`) runs every task in one session
instead (a session's start, workers that import the suite, is paid once): its episodes queue
task by task in turn (each task's first, then each task's second, ...), so the first envs
start on different tasks, and an env whose episode ends takes the next episode of the task
it runs while there is one (a task's env is made once per env that runs it, as Meta-World's
own MT10 vector env has one env per task), else the queue's first. Every env
(slot, numbered across sessions) runs one episode at a time: a reset with the episode's
initial condition, the settling steps with the protocol's fixed action, then policy steps
(an action chunk is executed one action per step before the slot asks again) until success
(when the rule stops there), the env's own end, or the horizon. One policy call per step
gathers every slot whose turn it is, whatever its task. Only envs with an episode are stepped
(`send` to those ids), so an env never runs past its episode. The runner takes the envs that
are ready: each round receives what the session's first workers answered and asks the policy
for those envs while the other workers still step, so a slow worker holds back its own envs
only; an env whose episode ended is reset alone (`send_reset`) as soon as its worker is back,
while the other workers step (a suite's reset costs tens of steps), and `recv` returns its
first observation like a step's. (A session whose videos come from `render()` waits for
every env instead: one `render()` shows the whole session.) An
episode's result depends on its initial condition and the policy's answers alone: the same
with 1 env or 16, local or remote, whatever order the envs come back in. For benchmarking,
`Runner(ready_envs=False)` or `ENVHUB_EVAL_READY_ENVS=0` (read when a `Runner` is made, so
`envhub eval` takes it from its environment) runs the synchronous loop instead: every round
waits for every env out, and ended envs reset together once all are back; the same results.
"""

from __future__ import annotations

import json
import os
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..wire.cores import usable_cores
from .benchmarks import Benchmark, TaskSpec
from .policy import Episode, Policy, PolicyError, Request, Task, policy_traceback
from .protocol import ActionError, Observer, check_actions

__all__ = ["Runner", "EvaluationStopped"]

# Sessions of a task that break without finishing an episode before its episodes are failed.
MAX_BROKEN = 2


class EvaluationStopped(RuntimeError):
    """`fail_fast`: an episode failed, and the evaluation stopped there."""


#: An episode to run: its task and index.
Job = tuple[TaskSpec, int]


@dataclass
class _Slot:
    episode: Episode | None = None
    settle_left: int = 0
    t: int = 0
    ret: float = 0.0
    success: bool | None = None
    chunk: np.ndarray | None = None
    pos: int = 0
    t0: float = 0.0
    obs: Any = None
    action: Any = None  # the last action the env got (a row of the batch sent)
    ended: bool = False
    frames: bool = False

    @property
    def running(self) -> bool:
        return self.episode is not None and not self.ended


class _Session:
    """A session: its envs, their slots (global ids `ids[i]` for env `i`), and the episodes
    not started yet (one task's, or every task's where envs switch tasks on reset)."""

    def __init__(self, envs: Any, ids: list[int], queue: deque[Job], bench: Benchmark, broken: int) -> None:
        self.envs, self.ids, self.queue = envs, ids, queue
        self.space = envs.single_action_space
        self.observer = Observer(bench.observation, envs.single_observation_space)
        self.slots = [_Slot() for _ in ids]
        self.tasks: list[str | None] = [None] * len(ids)  # the task each env last ran (its id)
        self.finished = 0  # episodes that ended without an error
        self.broken = broken  # sessions of these episodes that broke before this one
        self.waiting: set[int] = set()  # envs sent whose results have not been received
        # Env i's worker: one request goes to a worker, so an env goes out only when the
        # other envs of its worker are back.
        self.worker_of = [0] * len(ids)
        for w, (lo, hi) in enumerate(getattr(envs, "worker_envs", [(0, len(ids))])):
            self.worker_of[lo:hi] = [w] * (hi - lo)
        # Envs whose next episode is assigned and whose reset waits for their worker, and
        # those whose reset is out (`send_reset`): job, initial condition, start time.
        self.deferred: dict[int, Job] = {}
        self.resetting: dict[int, tuple[Job, dict[str, Any], float]] = {}
        self.first = True
        # Videos of envs with no image observation: frames from `render()`, once per step of
        # the session (every env rendered), kept per env until the runner takes them.
        self.render = getattr(envs, "render_mode", None) == "rgb_array" and self.observer.video is None
        self.rendered: Any = None

    def busy_workers(self) -> set[int]:
        return {self.worker_of[i] for i in self.waiting}

    def active(self) -> bool:
        """Whether an episode runs or is about to (its reset waits or is out)."""
        return bool(self.deferred or self.resetting) or any(x.episode is not None for x in self.slots)


def _row(obs: Any, j: int) -> Any:
    if isinstance(obs, dict):
        return {k: _row(v, j) for k, v in obs.items()}
    return obs[j]


def _copy(obs: Any) -> Any:
    if isinstance(obs, dict):
        return {k: _copy(v) for k, v in obs.items()}
    return np.array(obs)


def _info_row(info: dict[str, Any], j: int) -> dict[str, Any]:
    """Env `j`'s part of a batch's info, as a batch of one (what `_flag` reads at index 0)."""
    out: dict[str, Any] = {}
    for key, values in info.items():
        try:
            out[key] = np.array(np.asarray(values)[j : j + 1])
        except Exception:
            continue
    return out


def _flag(info: dict[str, Any], key: str, j: int) -> bool | None:
    """The env `j`'s value of info `key` (Gymnasium's vector layout), or None if absent."""
    values = info.get(key)
    if values is None:
        return None
    mask = info.get(f"_{key}")
    if mask is not None and not mask[j]:
        return None
    return bool(values[j])


class Runner:
    """Runs `bench`'s episodes with `policy`; `record(result)` gets each finished episode.

    `ready_envs`: each round takes the envs the first workers answered (True), or waits for
    every env out (False: the synchronous runner, for benchmarks); None reads
    `ENVHUB_EVAL_READY_ENVS` (`0` for False; True by default). The results are the same.
    """

    def __init__(
        self,
        bench: Benchmark,
        policy: Policy,
        record: Callable[[dict[str, Any]], None],
        *,
        num_envs: int = 1,
        workers: int | None = None,
        hubs: Any = None,
        registry: Any = None,
        step_timeout: float | None = None,
        fail_fast: bool = False,
        replan: int | None = None,
        videos: Any = None,
        dataset: Any = None,
        ready_envs: bool | None = None,
    ) -> None:
        self.bench, self.policy, self.record = bench, policy, record
        self.num_envs, self.workers, self.hubs, self.registry = num_envs, workers, hubs, registry
        self.step_timeout, self.fail_fast, self.replan, self.videos = step_timeout, fail_fast, replan, videos
        self.dataset = dataset
        if ready_envs is None:
            ready_envs = os.environ.get("ENVHUB_EVAL_READY_ENVS", "1").strip() != "0"
        self.ready_envs = ready_envs
        self.env_steps = 0
        self.tasks: dict[str, Task] = {}
        self.sessions: list[_Session] = []

    # Sessions -----------------------------------------------------------------------------

    def run(self, skip: set[str]) -> None:
        """Every episode of every task, but those in `skip` (`<task id>#<index>`)."""
        from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

        from ..wire.errors import EnvHubError

        # Episodes that share sessions, with the count of their sessions that broke.
        pending: deque[tuple[deque[Job], int]] = deque()
        for spec in self.bench.tasks:
            todo = deque((spec, k) for k in range(self.bench.episodes_per_task) if f"{spec.id}#{k}" not in skip)
            if todo:
                pending.append((todo, 0))
        if self.bench.task_reset_option is not None and pending:
            # One session for every task, the tasks in turn.
            jobs = [(k, spec.index, (spec, k)) for todo, _ in pending for spec, k in todo]
            pending = deque([(deque(job for _, _, job in sorted(jobs, key=lambda j: j[:2])), 0)])
        free = list(range(self.num_envs))
        # Sessions start (workers spawn, suites import) and stop in threads while the others
        # step: a start takes seconds. Two at a time, so a small machine is not swamped.
        pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="envhub-eval-start")
        self._stops = ThreadPoolExecutor(max_workers=2, thread_name_prefix="envhub-eval-stop")
        starting: dict[Any, tuple[deque[Job], list[int], int]] = {}
        try:
            while pending or self.sessions or starting:
                while pending and free:
                    todo, broken = pending.popleft()
                    n = min(len(free), len(todo))
                    ids, free = free[:n], free[n:]
                    # Env i made with the task of the episode it runs first.
                    first = [spec for spec, _ in list(todo)[:n]]
                    starting[pool.submit(self._make, first, n)] = (todo, ids, broken)
                if not self.sessions:  # nothing to step: wait for a start
                    wait(list(starting), return_when=FIRST_COMPLETED)
                for future in [f for f in starting if f.done()]:
                    todo, ids, broken = starting.pop(future)
                    started = self._started_session(future, todo, ids, broken)
                    if started is not True:
                        free = sorted(free + ids)
                        if started is not False:
                            pending.appendleft(started)
                for s in list(self.sessions):
                    try:
                        self._tick(s)
                    except EnvHubError as e:
                        requeue = self._broken(s, e)
                        if requeue is not None:
                            pending.appendleft(requeue)
                    if s not in self.sessions or not s.active():
                        if s in self.sessions:
                            self._close(s)
                        free = sorted(free + s.ids)
                self._ask_policy()
                self._send_all()
        finally:
            for s in list(self.sessions):
                self._close(s)
            for future in starting:  # sessions that start after all: stopped unused
                future.add_done_callback(lambda f: f.cancelled() or f.exception() is not None or f.result().close())
            pool.shutdown(wait=True, cancel_futures=True)
            self._stops.shutdown(wait=True)

    def _make(self, specs: list[TaskSpec], n: int) -> Any:
        from ..client.factory import make_vec

        # By default a session gets the share of the cores its envs are of `num_envs` (at least
        # one worker): sessions run side by side, and every worker is an interpreter to start.
        workers = self.workers or max(1, min(n, usable_cores() * n // self.num_envs))
        render = {"render_mode": "rgb_array"} if self.videos is not None and self._needs_render(specs[0]) else {}
        return make_vec(
            specs[0].entry,
            n,
            workers,
            "disabled",
            max_episode_steps=self.bench.settle_steps + self.bench.horizon,
            registry=self.registry,
            step_timeout=self.step_timeout,
            hubs=self.hubs,
            **render,
            **self.bench.session_options(specs),
        )

    def _needs_render(self, spec: TaskSpec) -> bool:
        """A video needs `render()` frames: the protocol names no video key and the entry's
        observation holds no image."""
        if self.bench.observation.get("video"):
            return False
        try:
            obs_type = self.registry.get(spec.entry).obs_type if self.registry is not None else "state"
        except Exception:
            return False
        return "image" not in obs_type and "pixel" not in obs_type

    def _started_session(
        self, future: Any, todo: deque[Job], ids: list[int], broken: int
    ) -> bool | tuple[deque[Job], int]:
        """The session a start gave, with its first episodes reset: True; False where the
        task cannot run (its episodes failed with the reason); or the task to start again
        when its first reset broke the session."""
        from ..wire.errors import EnvHubError

        try:
            envs = future.result()
        except EnvHubError as e:
            self._fail_all(todo, f"{type(e).__name__}: {e}")
            return False
        if self.dataset is not None:
            try:
                self.dataset.session(envs, todo[0][0].id)
            except BaseException:
                envs.close()
                raise
        s = _Session(envs, ids, todo, self.bench, broken)
        self.sessions.append(s)
        first = {i: s.queue.popleft() for i in range(len(ids))}
        s.tasks = [spec.id for spec, _ in first.values()]  # as the envs were made
        try:
            self._reset(s, first)
        except EnvHubError as e:
            requeue = self._broken(s, e)
            return False if requeue is None else requeue
        return True

    def _close(self, s: _Session) -> None:
        """Stops a session's workers in the background (its results are all in)."""
        self.sessions.remove(s)

        def close() -> None:
            try:
                s.envs.close()
            except Exception:
                pass

        self._stops.submit(close)

    def _broken(self, s: _Session, e: Exception) -> tuple[deque[Job], int] | None:
        """A session that broke (a worker died, a step timed out): its running episodes fail;
        its other episodes go on in a new session, unless sessions of them keep breaking with
        no episode finished."""
        for i, slot in enumerate(s.slots):
            if slot.running:
                self._finish(s, i, error=f"{type(e).__name__}: {e}")
        # Episodes assigned whose reset had not come back never started: they run again.
        unstarted = [job for job, _, _ in s.resetting.values()] + list(s.deferred.values())
        s.queue.extendleft(reversed(unstarted))
        s.resetting.clear()
        s.deferred.clear()
        self._close(s)
        broken = 0 if s.finished else s.broken + 1
        if not s.queue:
            return None
        if broken >= MAX_BROKEN:
            self._fail_all(s.queue, f"{type(e).__name__}: {e}")
            return None
        return s.queue, broken

    def _fail_all(self, jobs: deque[Job], error: str) -> None:
        """Fails episodes that never started (their sessions could not start or kept breaking)."""
        for spec, k in jobs:
            task = self.tasks.get(spec.id) or self.bench.task(spec)
            self._fail_unstarted(Episode(task, k, self.bench.episode_init(k)), error)

    # Resets -------------------------------------------------------------------------------

    def _reset(self, s: _Session, assign: dict[int, Job]) -> None:
        """Resets the envs in `assign` for their episodes (grouped by reset options: one
        reset takes one set of options for the envs it resets; the options pick the
        episode's initial condition and, in a session of every task, its task)."""
        n = len(s.slots)
        inits = {i: self.bench.episode_init(k) for i, (_, k) in assign.items()}
        seeds: list[int | None] = [None] * n
        groups = self._reset_groups(s, assign, inits)
        for i, init in inits.items():
            seeds[i] = init.get("seed")
        t0 = time.perf_counter()
        for key, group in groups.items():
            options = json.loads(key)
            if s.first:  # a session's first reset is a full one
                obs, info = s.envs.reset(seed=seeds, options=options or None)
                s.first = False
            else:
                mask = np.zeros(n, dtype=np.bool_)
                mask[group] = True
                obs, info = s.envs.reset(seed=seeds, options={**options, "reset_mask": mask})
            for i in group:
                self._reset_landed(s, i, assign[i], _row(obs, i), info, i, t0)
        if s.render:
            s.rendered = s.envs.render()
        for i, job in assign.items():
            self._start(s, i, job, inits[i])

    def _reset_groups(
        self, s: _Session, assign: dict[int, Job], inits: dict[int, dict[str, Any]]
    ) -> dict[str, list[int]]:
        """The envs of `assign` by their reset options (JSON): the episode's initial
        condition and, for an env that switches tasks, the task's options."""
        groups: dict[str, list[int]] = {}
        for i, init in inits.items():
            options = {k: v for k, v in init.items() if k != "seed"}
            if s.tasks[i] != assign[i][0].id:  # switch the env's task
                options.update(self.bench.reset_options(assign[i][0]))
            groups.setdefault(json.dumps(options, sort_keys=True), []).append(i)
        return groups

    def _start(self, s: _Session, i: int, job: Job, init: dict[str, Any]) -> None:
        """Env `i`, reset, starts episode `job` (its slot holds the first observation)."""
        spec, k = job
        s.tasks[i] = spec.id
        task = self.tasks.setdefault(spec.id, self.bench.task(spec))
        slot = s.slots[i]
        slot.episode = Episode(task, k, init)
        try:
            self.policy.start(s.ids[i], slot.episode)
        except Exception as e:
            self._finish(s, i, error=f"policy start failed: {type(e).__name__}: {e}")
            return
        if slot.settle_left == 0:
            self._frame(s, i)

    def _send_resets(self, s: _Session) -> None:
        """Sends the resets of deferred envs whose worker has nothing out, one reset per
        worker and set of options; the rest wait for their worker."""
        if not s.deferred:
            return
        out = s.busy_workers()
        ready = {i: job for i, job in s.deferred.items() if s.worker_of[i] not in out}
        inits = {i: self.bench.episode_init(k) for i, (_, k) in ready.items()}
        busy: set[int] = set()
        for key, group in self._reset_groups(s, ready, inits).items():
            ids = [i for i in group if s.worker_of[i] not in busy]
            if not ids:
                continue
            options = json.loads(key)
            s.envs.send_reset(ids, seed=[inits[i].get("seed") for i in ids], options=options or None)
            t0 = time.perf_counter()
            for i in ids:
                s.resetting[i] = (s.deferred.pop(i), inits[i], t0)
                s.waiting.add(i)
            busy.update(s.worker_of[i] for i in ids)

    def _reset_arrived(self, s: _Session, i: int, obs: Any, info: dict[str, Any], j: int) -> None:
        """Env `i`'s reset (sent alone) came back as row `j`: its episode starts."""
        job, init, t0 = s.resetting.pop(i)
        self._reset_landed(s, i, job, obs, info, j, t0)
        self._start(s, i, job, init)

    def _reset_landed(
        self, s: _Session, i: int, job: Job, obs: Any, info: dict[str, Any], j: int, t0: float
    ) -> None:
        """Env `i`, reset for `job` at `t0`, came back as row `j` of `info`: its slot holds
        the first observation `obs`."""
        spec = job[0]
        texts, has = info.get("language"), info.get("_language")
        # A language-conditioned suite says the task's instruction in its reset info.
        if texts is not None and (has is None or has[j]) and isinstance(texts[j], str):
            if spec.id not in self.tasks:
                self.tasks[spec.id] = self.bench.task(spec, texts[j])
        s.slots[i] = _Slot(obs=obs, t0=t0, settle_left=self.bench.settle_steps)

    def _next_job(self, s: _Session, i: int) -> Job:
        """The next episode for env `i`: in a session of every task, the next one of the task
        the env runs while there is one (no other task's env to make), else the queue's first."""
        current = s.tasks[i]
        if current is not None:
            for n, job in enumerate(s.queue):
                if job[0].id == current:
                    del s.queue[n]
                    return job
        return s.queue.popleft()

    def _tick(self, s: _Session) -> None:
        """Receives what the session's first workers answered (if envs are out; every env
        out without `ready_envs`), then starts the next episodes on the envs whose episode
        ended: with `ready_envs`, each reset goes out as soon as its worker is back, while
        the other workers step (`send_reset`); else once every env is back, as one reset."""
        if s.waiting:
            self._recv(s, all_back=s.render or not self.ready_envs)
        alone = self.ready_envs and not s.render
        ended = [i for i, slot in enumerate(s.slots) if slot.episode is not None and slot.ended]
        if ended and s.queue and s.waiting and not alone:
            self._recv(s, all_back=True)
            ended = [i for i, slot in enumerate(s.slots) if slot.episode is not None and slot.ended]
        for i in ended:
            s.slots[i] = _Slot()
        assign: dict[int, Job] = {}
        for i in ended:
            if not s.queue:
                break
            assign[i] = self._next_job(s, i)
        if alone:
            s.deferred.update(assign)
            self._send_resets(s)
        elif assign:
            self._reset(s, assign)

    # Policy and steps ---------------------------------------------------------------------

    def _ask_policy(self) -> None:
        need = [
            (s, i)
            for s in self.sessions
            for i, slot in enumerate(s.slots)
            if slot.running
            and i not in s.waiting
            and slot.settle_left == 0
            and (slot.chunk is None or slot.pos >= len(slot.chunk))
        ]
        if not need:
            return
        requests = [
            Request(s.ids[i], s.slots[i].episode, s.slots[i].t, s.observer(s.slots[i].obs))  # type: ignore[arg-type]
            for s, i in need
        ]
        try:
            answers = self.policy.act(requests)
            if len(answers) != len(requests):
                raise PolicyError(f"the policy answered {len(answers)} times for {len(requests)} requests")
        except Exception as e:
            per_slot = getattr(e, "slots", None)
            if isinstance(e, PolicyError) and isinstance(per_slot, dict) and getattr(e, "answers", None) is not None:
                # A server that failed some slots only (`slots`: slot -> message) answered the others.
                answers = list(e.answers)  # type: ignore[attr-defined]
                for s, i in need:
                    if s.ids[i] in per_slot:
                        self._finish(s, i, error=str(per_slot[s.ids[i]]))
            else:
                message = str(e) if isinstance(e, PolicyError) else f"the policy raised {type(e).__name__}: {e}"
                if not isinstance(e, PolicyError):
                    message += "\n" + policy_traceback(e)
                for s, i in need:
                    self._finish(s, i, error=message)
                return
        sign = self.bench.action.get("sign")
        for (s, i), answer in zip(need, answers, strict=True):
            slot = s.slots[i]
            if slot.ended:
                continue
            try:
                chunk = check_actions(answer, s.space, sign)
            except ActionError as e:
                self._finish(s, i, error=str(e))
                continue
            slot.chunk = chunk[: self.replan] if self.replan else chunk
            slot.pos = 0

    def _send_all(self) -> None:
        for s in list(self.sessions):
            busy = s.busy_workers()
            ids = [
                i
                for i, slot in enumerate(s.slots)
                if slot.running and i not in s.waiting and s.worker_of[i] not in busy
            ]
            if not ids:
                continue
            actions = np.empty((len(ids), *s.space.shape), dtype=s.space.dtype)
            for j, i in enumerate(ids):
                slot = s.slots[i]
                if slot.settle_left:
                    actions[j] = self.bench.settle_action  # type: ignore[assignment]
                else:
                    actions[j] = slot.chunk[slot.pos]  # type: ignore[index]
                    slot.action = actions[j]
                    slot.pos += 1
            s.envs.send(actions, ids)
            s.waiting.update(ids)

    def _recv(self, s: _Session, all_back: bool) -> None:
        """Receives the results of the first workers to answer, or (`all_back`) of every env
        out."""
        later = []  # with `render()` frames: the results, taken once every env is back and rendered
        while s.waiting:
            obs, rewards, terminated, truncated, info = s.envs.recv()
            ids = info["env_id"].tolist()
            self.env_steps += sum(i not in s.resetting for i in ids)
            for j, i in enumerate(ids):
                s.waiting.discard(i)
                if i in s.resetting:
                    self._reset_arrived(s, i, _row(obs, j), info, j)
                    continue
                step = (s, i, _row(obs, j), float(rewards[j]), bool(terminated[j]), bool(truncated[j]), info, j)
                if s.render:
                    later.append((*step[:2], _copy(step[2]), *step[3:6], _info_row(info, j), 0))
                else:
                    self._after_step(*step)
            if not all_back:
                break
        if later:
            s.rendered = s.envs.render()
            for step in later:
                self._after_step(*step)

    def _after_step(
        self, s: _Session, i: int, obs: Any, reward: float, terminated: bool, truncated: bool, info: Any, j: int
    ) -> None:
        slot = s.slots[i]
        slot.obs = obs
        if slot.settle_left:
            # A `done` while settling is ignored, as the references' loops ignore it.
            slot.settle_left -= 1
            if slot.settle_left == 0:
                self._frame(s, i)
            return
        slot.t += 1
        slot.ret += reward
        if self.dataset is not None:
            self.dataset.step(s.ids[i], slot.action, reward, terminated)
        self._frame(s, i)
        rule = self.bench.rule
        if rule == "any_step":
            if _flag(info, self.bench.success_key, j):
                slot.success = True
            elif slot.success is None:
                slot.success = False
        elif rule == "last_step":
            slot.success = bool(_flag(info, self.bench.success_key, j))
        if (slot.success and rule == "any_step" and self.bench.stop_on_success) or terminated or truncated:
            self._finish(s, i)
        elif slot.t >= self.bench.horizon:
            self._finish(s, i)

    # Episode ends -------------------------------------------------------------------------

    def _frame(self, s: _Session, i: int) -> None:
        """Env `i` shows its policy a new observation (after settling, after each step)."""
        if self.dataset is not None:
            self.dataset.observe(s.ids[i], s.slots[i].obs)
        if self.videos is None:
            return
        if s.render:
            frame = None if s.rendered is None else s.rendered[i]
        else:
            frame = s.observer.frame(s.slots[i].obs)
        if frame is not None:
            self.videos.frame(s.ids[i], frame)
            s.slots[i].frames = True

    def _finish(self, s: _Session | None, i: int, error: str | None = None, success: bool | None = None) -> None:
        slot = s.slots[i] if s is not None else self._unstarted
        if slot.ended or slot.episode is None:
            return
        slot.ended = True
        if success is not None:
            slot.success = success
        ep = slot.episode
        rule = self.bench.rule
        result = {
            "task": ep.task.id,
            "index": ep.index,
            "init": ep.init,
            "success": None if rule == "none" or error is not None else bool(slot.success),
            "return": slot.ret,
            "length": slot.t,
            "seconds": round(time.perf_counter() - slot.t0, 3),
            "error": error,
            "video": None,
        }
        if s is not None:
            s.finished += error is None
            slot_id = s.ids[i]
            if self.videos is not None:
                if error is None and slot.frames:
                    result["video"] = self.videos.finish(slot_id, ep, bool(slot.success))
                else:
                    self.videos.discard(slot_id)
            if self.dataset is not None:
                if error is None:
                    self.dataset.finish(slot_id, ep.task.text or ep.task.id, result["success"])
                else:
                    self.dataset.discard(slot_id)
            try:
                self.policy.end(slot_id, ep, result)
            except Exception as e:  # the episode's result stands; the policy's trouble is said
                result["error"] = result["error"] or f"policy end failed: {type(e).__name__}: {e}"
        self.record(result)
        if error is not None and self.fail_fast:
            raise EvaluationStopped(f"episode {ep.key} failed: {error}")

    def _fail_unstarted(self, episode: Episode, error: str) -> None:
        self._unstarted = _Slot(episode=episode, t0=time.perf_counter())
        self._finish(None, -1, error=error)
