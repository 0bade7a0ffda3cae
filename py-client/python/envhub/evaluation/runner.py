"""The episode loop: a task's episodes over the envs of one session, batched policy calls.

Each env (slot) runs one episode at a time: a reset with the episode's initial condition,
the settling steps with the protocol's fixed action, then policy steps (an action chunk is
executed one action per step before the slot asks again) until success (when the rule stops
there), the env's own end, or the horizon. Only envs with an episode are stepped (`send` to
those ids, `recv` until all are back), so an env never runs past its episode. An episode's
result depends on its initial condition and the policy's answers alone: the same with 1 env
or 16, local or remote.
"""

from __future__ import annotations

import json
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .benchmarks import Benchmark, TaskSpec
from .policy import Episode, Policy, PolicyError, Request, Task
from .protocol import ActionError, Observer, check_actions

__all__ = ["Runner", "EvaluationStopped"]


class EvaluationStopped(RuntimeError):
    """`fail_fast`: an episode failed, and the evaluation stopped there."""


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
    error: str | None = None
    ended: bool = False
    frames: bool = False


def _row(obs: Any, j: int) -> Any:
    if isinstance(obs, dict):
        return {k: _row(v, j) for k, v in obs.items()}
    return obs[j]


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
    """Runs `bench`'s episodes with `policy`; `record(result)` gets each finished episode."""

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
    ) -> None:
        self.bench, self.policy, self.record = bench, policy, record
        self.num_envs, self.workers, self.hubs, self.registry = num_envs, workers, hubs, registry
        self.step_timeout, self.fail_fast, self.replan, self.videos = step_timeout, fail_fast, replan, videos
        self.env_steps = 0
        self.tasks: dict[str, Task] = {}
        self._slots: list[_Slot] = []
        self._started: set[int] = set()

    # Tasks --------------------------------------------------------------------------------

    def run(self, skip: set[str]) -> None:
        """Every episode of every task, but those in `skip` (`<task id>#<index>`)."""
        for spec in self.bench.tasks:
            todo = [k for k in range(self.bench.episodes_per_task) if f"{spec.id}#{k}" not in skip]
            if todo:
                self._run_task(spec, todo)

    def _run_task(self, spec: TaskSpec, todo: list[int]) -> None:
        from .. import EnvHubError, make_vec

        failures = 0
        while todo:
            n = min(self.num_envs, len(todo))
            try:
                envs = make_vec(
                    spec.entry,
                    n,
                    self.workers,
                    "disabled",
                    max_episode_steps=self.bench.settle_steps + self.bench.horizon,
                    registry=self.registry,
                    step_timeout=self.step_timeout,
                    hubs=self.hubs,
                    **self.bench.env_options(spec),
                )
            except EnvHubError as e:
                # The task cannot run here: each of its episodes fails with the reason.
                task = self.tasks.get(spec.id) or self.bench.task(spec)
                for k in todo:
                    self._fail_unstarted(Episode(task, k, self.bench.episode_init(k)), f"{type(e).__name__}: {e}")
                return
            try:
                done_before = len(todo)
                todo = self._run_session(envs, spec, todo)
            except EnvHubError as e:
                # The session broke (a worker died, a step timed out): its running episodes
                # failed, and the rest of the task goes on in a new session.
                for i, slot in enumerate(self._slots):
                    if slot.episode is not None and not slot.ended:
                        self._finish(slot, i, error=f"{type(e).__name__}: {e}")
                todo = [k for k in todo if k not in self._started]
                failures = failures + 1 if len(todo) == done_before else 0
                if failures >= 2:
                    task = self.tasks.get(spec.id) or self.bench.task(spec)
                    for k in todo:
                        self._fail_unstarted(Episode(task, k, self.bench.episode_init(k)), f"{type(e).__name__}: {e}")
                    return
            finally:
                envs.close()

    # One session --------------------------------------------------------------------------

    def _run_session(self, envs: Any, spec: TaskSpec, todo: list[int]) -> list[int]:
        n = envs.num_envs
        self._space = envs.single_action_space
        self.observer = Observer(self.bench.observation, envs.single_observation_space)
        self._slots = [_Slot() for _ in range(n)]
        self._started: set[int] = set()
        queue = list(todo)
        self._spec = spec
        assign = {i: queue.pop(0) for i in range(n)}
        self._reset(envs, assign, full=True)
        while any(s.episode is not None for s in self._slots):
            self._ask_policy()
            self._step(envs)
            ended = [i for i, s in enumerate(self._slots) if s.episode is not None and s.ended]
            for i in ended:
                self._slots[i] = _Slot()
            assign = {i: queue.pop(0) for i in ended if queue}
            if assign:
                self._reset(envs, assign, full=False)
        return []

    def _reset(self, envs: Any, assign: dict[int, int], full: bool) -> None:
        """Resets the slots in `assign` for their episodes (grouped by reset options: the
        session's reset takes one set of options for the envs it resets)."""
        n = envs.num_envs
        inits = {i: self.bench.episode_init(k) for i, k in assign.items()}
        seeds: list[int | None] = [None] * n
        groups: dict[str, list[int]] = {}
        for i, init in inits.items():
            seeds[i] = init.get("seed")
            options = {k: v for k, v in init.items() if k != "seed"}
            groups.setdefault(json.dumps(options, sort_keys=True), []).append(i)
        batches = list(groups.items())
        t0 = time.perf_counter()
        for g, (key, ids) in enumerate(batches):
            options = json.loads(key)
            if full and g == 0:
                obs, info = envs.reset(seed=seeds, options=options or None)
            else:
                mask = np.zeros(n, dtype=np.bool_)
                mask[ids] = True
                obs, info = envs.reset(seed=seeds, options={**options, "reset_mask": mask})
            texts, has = info.get("language"), info.get("_language")
            for i in ids:
                # A language-conditioned suite says the task's instruction in its reset info.
                if texts is not None and (has is None or has[i]) and isinstance(texts[i], str):
                    if self._spec.id not in self.tasks:
                        self.tasks[self._spec.id] = self.bench.task(self._spec, texts[i])
                slot = self._slots[i] = _Slot(obs=_row(obs, i), t0=t0, settle_left=self.bench.settle_steps)
        task = self.tasks.setdefault(self._spec.id, self.bench.task(self._spec))
        for i, k in assign.items():
            slot = self._slots[i]
            slot.episode = Episode(task, k, inits[i])
            self._started.add(k)
            try:
                self.policy.start(i, slot.episode)
            except Exception as e:
                self._finish(slot, i, error=f"policy start failed: {type(e).__name__}: {e}")
                continue
            if slot.settle_left == 0:
                self._frame(i, slot)

    def _ask_policy(self) -> None:
        need = [
            i
            for i, s in enumerate(self._slots)
            if s.episode is not None and not s.ended and s.settle_left == 0 and (s.chunk is None or s.pos >= len(s.chunk))
        ]
        if not need:
            return
        requests = [Request(i, self._slots[i].episode, self._slots[i].t, self.observer(self._slots[i].obs)) for i in need]  # type: ignore[arg-type]
        try:
            answers = self.policy.act(requests)
            if len(answers) != len(requests):
                raise PolicyError(f"the policy answered {len(answers)} times for {len(requests)} requests")
        except Exception as e:
            per_slot = getattr(e, "slots", None)
            if isinstance(e, PolicyError) and isinstance(per_slot, dict) and getattr(e, "answers", None) is not None:
                # A server that failed some slots only (`slots`: slot -> message) answered the others.
                answers = list(e.answers)  # type: ignore[attr-defined]
                for i in need:
                    if i in per_slot:
                        self._finish(self._slots[i], i, error=str(per_slot[i]))
            else:
                message = str(e) if isinstance(e, PolicyError) else f"the policy raised {type(e).__name__}: {e}"
                if not isinstance(e, PolicyError):
                    message += "\n" + "".join(traceback.format_exception(e)[-3:]).rstrip()
                for i in need:
                    self._finish(self._slots[i], i, error=message)
                return
        for i, answer in zip(need, answers, strict=True):
            slot = self._slots[i]
            if slot.ended:
                continue
            try:
                chunk = check_actions(answer, self._space, self.bench.action.get("sign"))
            except ActionError as e:
                self._finish(slot, i, error=str(e))
                continue
            slot.chunk = chunk[: self.replan] if self.replan else chunk
            slot.pos = 0

    def _step(self, envs: Any) -> None:
        ids = [i for i, s in enumerate(self._slots) if s.episode is not None and not s.ended]
        if not ids:
            return
        actions = np.empty((len(ids), *self._space.shape), dtype=self._space.dtype)
        for j, i in enumerate(ids):
            slot = self._slots[i]
            if slot.settle_left:
                actions[j] = self.bench.settle_action  # type: ignore[assignment]
            else:
                actions[j] = slot.chunk[slot.pos]  # type: ignore[index]
                slot.pos += 1
        envs.send(actions, ids)
        waiting = set(ids)
        while waiting:
            obs, rewards, terminated, truncated, info = envs.recv()
            got = [int(i) for i in info["env_id"]]
            for j, i in enumerate(got):
                waiting.discard(i)
                self._after_step(i, _row(obs, j), float(rewards[j]), bool(terminated[j]), bool(truncated[j]), info, j)
        self.env_steps += len(ids)

    def _after_step(self, i: int, obs: Any, reward: float, terminated: bool, truncated: bool, info: Any, j: int) -> None:
        slot = self._slots[i]
        slot.obs = obs
        if slot.settle_left:
            slot.settle_left -= 1
            if terminated or truncated:
                self._finish(slot, i, error=None, success=False)
            elif slot.settle_left == 0:
                self._frame(i, slot)
            return
        slot.t += 1
        slot.ret += reward
        self._frame(i, slot)
        rule = self.bench.rule
        flag = _flag(info, self.bench.success_key, j) if rule != "none" else None
        if rule == "any_step" and flag:
            slot.success = True
        elif rule == "last_step":
            slot.success = bool(flag)
        elif rule == "any_step" and slot.success is None:
            slot.success = False
        if (slot.success and rule == "any_step" and self.bench.stop_on_success) or terminated or truncated:
            self._finish(slot, i)
        elif slot.t >= self.bench.horizon:
            self._finish(slot, i)

    # Episode ends -------------------------------------------------------------------------

    def _frame(self, i: int, slot: _Slot) -> None:
        if self.videos is None:
            return
        frame = self.observer.frame(slot.obs)
        if frame is not None:
            self.videos.frame(i, frame)
            slot.frames = True

    def _finish(self, slot: _Slot, i: int, error: str | None = None, success: bool | None = None) -> None:
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
        if self.videos is not None and i >= 0:
            if error is None and slot.frames:
                result["video"] = self.videos.finish(i, ep, bool(slot.success))
            else:
                self.videos.discard(i)
        if i >= 0:
            try:
                self.policy.end(i, ep, result)
            except Exception as e:  # the episode's result stands; the policy's trouble is said
                result["error"] = result["error"] or f"policy end failed: {type(e).__name__}: {e}"
        self.record(result)
        if error is not None and self.fail_fast:
            raise EvaluationStopped(f"episode {ep.key} failed: {error}")

    def _fail_unstarted(self, episode: Episode, error: str) -> None:
        slot = _Slot(episode=episode, t0=time.perf_counter())
        self._finish(slot, -1, error=error)
