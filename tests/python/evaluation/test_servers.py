"""Policy servers through envhub's clients: a vla-eval model server written with vla-eval's
own base class and served by vla-eval, and an OpenPI-protocol server built as OpenPI's
`serve_policy.py` builds one (openpi-client's msgpack_numpy over websockets), both from
PyPI in their own environment (eval_peers.py), in subprocesses on 127.0.0.1.

- Each gives, over `VlaEvalPolicy` / `OpenPIPolicy`, exactly the actions of the same
  function called directly, for a fixed sequence of batched requests (several episodes per
  slot, vla-eval's server-side batching and chunking, OpenPI's chunks and replanning).
- A server that stalls, disconnects, answers something that is not an action, fails in its
  policy, or exits fails that slot's episode with a PolicyError saying so, within the
  timeout; the other slots go on, and the slot's next episode reconnects.

Without uv or PyPI these skip with the reason (a failure under ENVHUB_PYENV_REQUIRED=1).
"""

from __future__ import annotations

import os
import time

import eval_peers
import numpy as np
import pytest
from eval_peers import HORIZON, reference_action, reference_chunk
from harness import import_envhub
from policy_servers import (
    CHEETAH,
    Server,
    evaluate_or_skip,
    peers,  # noqa: F401 - a fixture
)

import_envhub()

from envhub.evaluation.policy import Episode, PolicyError, Request, Task  # noqa: E402
from envhub.evaluation.servers import OpenPIPolicy, VlaEvalPolicy, connect  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
VLA_FIELDS = {"images.agentview": "agentview_image", "states": "state"}
OPENPI_FIELDS = {"observation/image": "agentview_image", "observation/state": "state"}
STALL_TIMEOUT_S = 2.0


@pytest.fixture(scope="module")
def vla_server(peers):
    server = Server(peers, "vla-eval", "--batch", "4")
    yield server
    server.stop()


@pytest.fixture(scope="module")
def vla_chunk_server(peers):
    server = Server(peers, "vla-eval", "--chunk", "3")
    yield server
    server.stop()


@pytest.fixture(scope="module")
def openpi_server(peers):
    server = Server(peers, "openpi")
    yield server
    server.stop()


def task(i: int, text: str | None = None) -> Task:
    return Task("bench", f"bench/{i}", "bench-entry", text or f"put object {i} in the basket", i)


def observation(rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        "agentview_image": rng.integers(0, 256, (64, 48, 3), dtype=np.uint8),
        "state": rng.standard_normal(8),
    }


def direct(obs: dict[str, np.ndarray], episode: Episode) -> np.ndarray:
    return reference_action(obs["agentview_image"], obs["state"], episode.task.text)


def run_episodes(
    policy, expected, *, slots: int = 3, episodes: int = 2, steps: int = 12, every=lambda step: True
):
    """Runs `episodes` rounds of one episode per slot, `steps` steps each, asking the
    policy for a batch at each step where `every(step)`; checks each answer against
    `expected(obs, episode, step)`. Returns how many answers were compared."""
    rng = np.random.default_rng(5)
    compared = 0
    for round_ in range(episodes):
        batch = [Episode(task(slot + 10 * round_), round_, {"init_state": round_}) for slot in range(slots)]
        for slot, episode in enumerate(batch):
            policy.start(slot, episode)
        for step in range(steps):
            if not every(step):
                continue
            requests = [Request(slot, ep, step, observation(rng)) for slot, ep in enumerate(batch)]
            for request, answer in zip(requests, policy.act(requests)):
                want = expected(request.observation, request.episode, step)
                assert answer.dtype == want.dtype and answer.shape == want.shape, (answer, want)
                np.testing.assert_array_equal(answer, want)
                compared += 1
        for slot, episode in enumerate(batch):
            policy.end(slot, episode, {"success": True, "return": 1.0, "length": steps, "seconds": 0.1})
    return compared


def test_vla_eval_server_answers_as_the_function_does(vla_server) -> None:
    with VlaEvalPolicy(vla_server.url, fields=VLA_FIELDS, timeout=30) as policy:
        assert run_episodes(policy, lambda obs, ep, step: direct(obs, ep)) == 3 * 2 * 12
        described = policy.describe()
    assert described["kind"] == "server" and described["protocol"] == "vla-eval"
    assert described["url"] == vla_server.url
    assert described["server"]["model_server"] == "Reference"
    assert described["server"]["protocol_version"] == 1


def test_vla_eval_episode_start_carries_the_task(vla_server) -> None:
    """EPISODE_START's `task`: the text as `name`, `task_id`, `episode_idx`, the initial
    condition, and what `task_info` adds; the server's step count restarts each episode."""
    info = lambda episode: {"level": 10 + episode.task.index}  # noqa: E731
    with VlaEvalPolicy(vla_server.url, fields=VLA_FIELDS, timeout=30, task_info=info) as policy:
        rng = np.random.default_rng(0)
        for index in (4, 5):
            episode = Episode(
                Task("bench", "bench/3", "bench-entry", "echo the task", 3), index, {"init_state": index}
            )
            policy.start(1, episode)
            for step in range(2):
                (answer,) = policy.act([Request(1, episode, step, observation(rng))])
                np.testing.assert_array_equal(
                    answer, np.array([3, index, index, 13, 13, step, 0], np.float32)
                )
            policy.end(1, episode, {"success": False, "length": 2})


def test_vla_eval_server_side_chunks_replay_as_the_function_does(vla_chunk_server) -> None:
    """`PredictModelServer(chunk_size=3)` computes a chunk every 3rd observation of an
    episode and answers from its buffer in between; the buffer starts anew each episode."""
    chunks: dict[tuple[int, int], np.ndarray] = {}

    def expected(obs, episode, step):
        key = (episode.task.index, step // 3)
        if step % 3 == 0:
            chunks[key] = reference_chunk(obs["agentview_image"], obs["state"], episode.task.text, 3)
        return chunks[key][step % 3]

    with VlaEvalPolicy(vla_chunk_server.url, fields=VLA_FIELDS, timeout=30) as policy:
        assert run_episodes(policy, expected, steps=10) == 3 * 2 * 10


def test_openpi_server_chunks_as_the_function_does(openpi_server) -> None:
    replan = 3

    def expected(obs, episode, step):
        return reference_chunk(obs["agentview_image"], obs["state"], episode.task.text)[:replan]

    with OpenPIPolicy(openpi_server.url, fields=OPENPI_FIELDS, replan_steps=replan, timeout=30) as policy:
        assert run_episodes(policy, expected, every=lambda step: step % replan == 0) == 3 * 2 * 4
        described = policy.describe()
    assert described["server"] == {"policy": "reference", "action_horizon": HORIZON, "action_dim": 7}
    assert described["replan_steps"] == replan


def test_openpi_whole_chunk_without_replan(openpi_server) -> None:
    with connect("openpi", openpi_server.url, fields=OPENPI_FIELDS, timeout=30) as policy:
        episode = Episode(task(0), 0)
        obs = observation(np.random.default_rng(1))
        (chunk,) = policy.act([Request(0, episode, 0, obs)])
    np.testing.assert_array_equal(
        chunk, reference_chunk(obs["agentview_image"], obs["state"], episode.task.text)
    )


# What each misbehaviour's error says, per protocol.
FAILURES = {
    ("vla-eval", "stall"): f"sent no action within {STALL_TIMEOUT_S:g} s",
    ("vla-eval", "disconnect"): "closed the connection",
    ("vla-eval", "malformed"): "expected `actions` as a numeric array of shape (action_dim,)",
    (
        "vla-eval",
        "error",
    ): "answered ERROR: observation_failed: ValueError: the reference policy refuses this task",
    ("openpi", "stall"): f"sent no action within {STALL_TIMEOUT_S:g} s",
    ("openpi", "disconnect"): "closed the connection",
    ("openpi", "malformed"): "answered a dict with keys ['action']; expected a dict with `actions`",
    ("openpi", "error"): "failed: ValueError: the reference policy refuses this task",
}


@pytest.mark.parametrize("protocol,trouble", sorted(FAILURES))
def test_a_misbehaving_server_fails_that_episode_only(protocol, trouble, request) -> None:
    server = request.getfixturevalue("vla_server" if protocol == "vla-eval" else "openpi_server")
    fields = VLA_FIELDS if protocol == "vla-eval" else OPENPI_FIELDS
    want = reference_action if protocol == "vla-eval" else reference_chunk
    rng = np.random.default_rng(2)
    with connect(protocol, server.url, fields=fields, timeout=STALL_TIMEOUT_S) as policy:
        bad, good = Episode(task(0, f"please {trouble} now"), 0), Episode(task(1), 0)
        policy.start(0, bad)
        policy.start(1, good)
        started = time.monotonic()
        with pytest.raises(PolicyError) as caught:
            policy.act([Request(0, bad, 0, observation(rng)), Request(1, good, 0, observation(rng))])
        took = time.monotonic() - started
        message = str(caught.value)
        assert FAILURES[protocol, trouble] in message, message
        assert message.startswith("slot 0: ") and "slot 1" not in message, message
        assert caught.value.slots.keys() == {0}
        assert caught.value.answers[0] is None and caught.value.answers[1] is not None
        assert took < STALL_TIMEOUT_S + 3, took
        # The failed episode asks no more of its server; the other slot goes on.
        with pytest.raises(PolicyError, match="slot 0"):
            policy.act([Request(0, bad, 1, observation(rng))])
        obs = observation(rng)
        (answer,) = policy.act([Request(1, good, 1, obs)])
        np.testing.assert_array_equal(answer, want(obs["agentview_image"], obs["state"], good.task.text))
        policy.end(0, bad, {"success": False, "error": message})
        # The slot's next episode connects anew and works.
        fresh = Episode(task(2), 1)
        policy.start(0, fresh)
        obs = observation(rng)
        (answer,) = policy.act([Request(0, fresh, 0, obs)])
        np.testing.assert_array_equal(answer, want(obs["agentview_image"], obs["state"], fresh.task.text))


@pytest.mark.parametrize("protocol", ["vla-eval", "openpi"])
def test_a_server_that_exits_fails_its_episodes_and_nothing_hangs(protocol, peers) -> None:
    server = Server(peers, protocol)
    fields = VLA_FIELDS if protocol == "vla-eval" else OPENPI_FIELDS
    rng = np.random.default_rng(3)
    try:
        with connect(protocol, server.url, fields=fields, timeout=5) as policy:
            dying, other = Episode(task(0, "exit please"), 0), Episode(task(1), 0)
            policy.start(0, dying)
            policy.start(1, other)
            started = time.monotonic()
            with pytest.raises(PolicyError, match="closed the connection"):
                policy.act([Request(0, dying, 0, observation(rng))])
            server.proc.wait(timeout=10)
            # The server is gone: the other slot's connection is closed, and a new episode
            # cannot connect; both say so at once.
            with pytest.raises(PolicyError, match="closed the connection|could not connect"):
                policy.act([Request(1, other, 0, observation(rng))])
            policy.start(0, Episode(task(2), 1))
            with pytest.raises(
                PolicyError, match=f"could not connect to the {protocol} server at {server.url}"
            ):
                policy.act([Request(0, Episode(task(2), 1), 0, observation(rng))])
            assert time.monotonic() - started < 10
    finally:
        server.stop()


def test_an_unreachable_server_fails_within_the_timeout() -> None:
    with VlaEvalPolicy("127.0.0.1:9", timeout=2) as policy:
        started = time.monotonic()
        with pytest.raises(PolicyError, match="could not connect to the vla-eval server at ws://127.0.0.1:9"):
            policy.act([Request(0, Episode(task(0), 0), 0, {"state": np.zeros(3)})])
        assert time.monotonic() - started < 5


def test_a_missing_observation_key_names_the_ones_there(openpi_server) -> None:
    with OpenPIPolicy(openpi_server.url, fields={"observation/image": "camera"}, timeout=5) as policy:
        with pytest.raises(
            PolicyError,
            match=r"no key 'camera' \(for the server's 'observation/image'\); it has \['agentview_image', 'state'\]",
        ):
            policy.act([Request(0, Episode(task(0), 0), 0, observation(np.random.default_rng(0)))])


def test_the_default_layouts() -> None:
    """Without `fields`: vla-eval's `images.<camera>` and the task's text as
    `task_description`; OpenPI's `observation/<key>` and `prompt`."""
    obs = {"agentview_image": np.zeros((4, 4, 3), np.uint8), "state": np.zeros(3)}
    request = Request(0, Episode(task(0), 0), 0, obs)
    vla = VlaEvalPolicy.observation.__get__(_Bare(None, "task_description"))(request)
    assert set(vla) == {"images", "state", "task_description"} and set(vla["images"]) == {"agentview"}
    pi = OpenPIPolicy.observation.__get__(_Bare(None, "prompt"))(request)
    assert set(pi) == {"observation/agentview_image", "observation/state", "prompt"}
    assert pi["prompt"] == vla["task_description"] == "put object 0 in the basket"
    with pytest.raises(
        ValueError, match="unknown policy-server protocol 'grpc'; valid: \\['lerobot', 'openpi', 'vla-eval'\\]"
    ):
        connect("grpc", "ws://127.0.0.1:1")


class _Bare:
    def __init__(self, fields, text_key) -> None:
        self.fields, self.text_key, self.layout = fields, text_key, None


# -- through `envhub.evaluation.evaluate` --------------------------------------------------

def _episodes(results: dict) -> list[tuple]:
    return [
        (e["task"], e["index"], e["init"], e["return"], e["length"], e["error"]) for e in results["episodes"]
    ]


@pytest.mark.parametrize("protocol", ["vla-eval", "openpi"])
def test_eval_through_a_server_equals_the_callable(protocol, peers, tmp_path) -> None:
    """`envhub.evaluation.evaluate` with the policy behind a vla-eval model server (one
    action per observation) or an OpenPI server (4-action chunks) gives, episode for
    episode, the results of the same function passed as a Python callable, on a different
    number of envs."""
    evaluate = evaluate_or_skip()
    if protocol == "vla-eval":

        def function(observations, tasks):
            return [eval_peers.linear_action(o, 6) for o in observations]
    else:

        def function(observations, tasks):
            return [eval_peers.linear_chunk(o, 6) for o in observations]

    reference = evaluate(CHEETAH, function, num_envs=2, progress=False, out=tmp_path / "callable")
    server = Server(peers, protocol, "--batch", "4", "--action-dim", "6")
    try:
        policy = connect(protocol, server.url, timeout=30)
        served = evaluate(CHEETAH, policy, num_envs=3, progress=False, out=tmp_path / "served")
    finally:
        server.stop()
    assert _episodes(served) == _episodes(reference)
    assert all(e["error"] is None and e["length"] == 40 for e in served["episodes"])
    assert served["policy"]["protocol"] == protocol and served["policy"]["url"] == server.url
    if protocol == "vla-eval":
        assert served["policy"]["server"]["model_server"] == "Reference"
    else:
        assert served["policy"]["server"]["action_horizon"] == HORIZON
