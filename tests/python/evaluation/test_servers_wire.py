"""What envhub sends a policy server is what the server's own harness sends.

- The state conversions of the benchmarks' `servers:` layouts (quaternion to axis-angle in
  vla-eval's two conventions and OpenPI's example's, vla-eval's matrix to quaternion) give
  the references' bits, computed by vla-eval 0.8.0 itself in the peers' environment.
- A vla-eval model server's HELLO chooses what it is sent: a logging `PredictModelServer`
  that asks for `send_wrist_image` and `send_state` gets both cameras, the 8-D `states`
  and `controller_states`; a param envhub's benchmark does not support is an error naming
  it and the supported ones, before any episode runs.
- A server that stops answering fails its batch's episodes after the policy timeout, with an
  error naming the server and the wait; the run goes on, or stops with fail_fast.

LIBERO end to end, against vla-eval's and OpenPI's own clients: evaluation/test_servers_libero.py.

Skips with the reason where uv or PyPI are missing; failures instead under
ENVHUB_PYENV_REQUIRED=1.
"""

from __future__ import annotations

import os
import pickle
import subprocess

import numpy as np
import peer_servers
import pytest
from harness import REPO_ROOT, SUPPORT, import_envhub
from policy_servers import (
    BOTH,
    CHEETAH,
    Server,
    assert_same,
    evaluate_or_skip,
    logging_server,
    peers,  # noqa: F401 - a fixture
    read_log,
)

envhub = import_envhub()

from envhub.evaluation.benchmarks import BenchmarkError, parse  # noqa: E402
from envhub.evaluation.catalog import Catalog  # noqa: E402
from envhub.evaluation.policy import Episode, Request, Task  # noqa: E402
from envhub.evaluation.servers import OpenPIPolicy, VlaEvalPolicy, connect  # noqa: E402
from envhub.evaluation.servers.layout import LayoutError, axis_angle, quat_of_matrix  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))


def libero_spatial():
    """The checkout's libero-spatial (its registry file as written, not the catalog built into
    the extension at its last build)."""
    registry = REPO_ROOT / "configs" / "env_registry.yaml"
    return parse("libero-spatial", dict(Catalog([str(registry)]).declared["libero-spatial"]))


# -- the conversions against vla-eval's own ------------------------------------------------

REFERENCE_CONVERSIONS = """
import pickle, sys
import numpy as np
from vla_eval.rotation import matrix_to_quat, quat_to_axisangle
from vla_eval.benchmarks.libero.benchmark import _quat_to_axisangle_robosuite
sys.path.insert(0, sys.argv[2])
from peer_servers import quat2axisangle
quats, mats = pickle.load(open(sys.argv[1], "rb"))
out = {
    "antipodal": [quat_to_axisangle(q) for q in quats],
    "robosuite": [_quat_to_axisangle_robosuite(q) for q in quats],
    "robosuite64": [quat2axisangle(q.copy()) for q in quats],
    "matrix": [matrix_to_quat(m) for m in mats],
}
pickle.dump(out, open(sys.argv[1], "wb"))
"""


def test_state_conversions_give_the_references_bits(peers, tmp_path) -> None:
    rng = np.random.default_rng(11)
    quats = [q / np.linalg.norm(q) for q in rng.standard_normal((300, 4))]
    quats += [np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, -1.0]), np.array([1e-9, 0, 0, 1.0])]
    mats = []
    for q in quats[:300]:
        x, y, z, w = q
        m = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        mats.append(m.astype(np.float32))  # as vla-eval reads the controller's matrix
    path = tmp_path / "conversions.pkl"
    path.write_bytes(pickle.dumps((quats, mats)))
    done = subprocess.run(
        [peers, "-c", REFERENCE_CONVERSIONS, str(path), str(SUPPORT)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    ref = pickle.loads(path.read_bytes())
    for convention in ("antipodal", "robosuite", "robosuite64"):
        for q, want in zip(quats, ref[convention]):
            assert_same(axis_angle(q.copy(), convention), want, f"{convention} {q}")
    for m, want in zip(mats, ref["matrix"]):
        assert_same(quat_of_matrix(m), want, f"matrix {m}")


# -- the HELLO's observation params ------------------------------------------------------


def libero_observation(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """An observation with LIBERO's keys (what the benchmark shows a policy, with the
    controller's pose that `send_state` asks the env for)."""
    q = rng.standard_normal(4)
    return {
        "agentview_image": rng.integers(0, 256, (256, 256, 3), dtype=np.uint8),
        "robot0_eye_in_hand_image": rng.integers(0, 256, (256, 256, 3), dtype=np.uint8),
        "robot0_eef_pos": rng.standard_normal(3),
        "robot0_eef_quat": q / np.linalg.norm(q),
        "robot0_gripper_qpos": rng.standard_normal(2),
        "robot0_controller_ee_pos": rng.standard_normal(3),
        "robot0_controller_ee_ori_mat": np.eye(3)[[1, 2, 0]],
    }


def test_the_hello_chooses_what_a_vla_eval_server_is_sent(peers, tmp_path) -> None:
    log = tmp_path / "seen.pkl"
    server = logging_server(peers, log, BOTH)
    try:
        with VlaEvalPolicy(server.url, timeout=30) as policy:
            bench = libero_spatial()
            bound = policy.bind(bench)
            # What the env must give for `send_state`: the controller's pose.
            assert bound.kwargs == {**bench.kwargs, "controller_state": True}
            assert bound.observation["keys"][-2:] == ["robot0_controller_ee_pos", "robot0_controller_ee_ori_mat"]
            assert bench.kwargs.get("controller_state") is None  # the catalog's own is unchanged
            obs = libero_observation(np.random.default_rng(3))
            task = Task("libero-spatial", "libero-spatial/0", "libero-spatial", "pick up the bowl", 0)
            episode = Episode(task, 0, {"init_state": 0})
            policy.start(0, episode)
            (action,) = policy.act([Request(0, episode, 0, obs)])
            policy.end(0, episode, {"success": False, "length": 1})
            described = policy.describe()
    finally:
        server.stop()
    np.testing.assert_array_equal(action, peer_servers.fixed_action(0))
    (seen,) = read_log(log)
    want_state = np.concatenate(
        [obs["robot0_eef_pos"], axis_angle(obs["robot0_eef_quat"], "antipodal"), obs["robot0_gripper_qpos"]]
    )
    controller = np.concatenate(
        [
            obs["robot0_controller_ee_pos"].astype(np.float32),
            axis_angle(quat_of_matrix(obs["robot0_controller_ee_ori_mat"].astype(np.float32)), "antipodal"),
            obs["robot0_gripper_qpos"].astype(np.float32),
        ]
    )
    want = {
        "images": {"agentview": obs["agentview_image"], "wrist": obs["robot0_eye_in_hand_image"]},
        "task_description": "pick up the bowl",
        "states": want_state,
        "controller_states": controller,
    }
    assert_same(seen, want)
    assert described["layout"]["params"] == BOTH


@pytest.mark.parametrize(
    "params,message",
    [
        (
            {"send_state": True, "absolute_action": True},
            "asks for the observation param `absolute_action` = True, which envhub's `libero-spatial` does not "
            "support; supported: `send_wrist_image`, `send_state`, `quat_no_antipodal`, `seed`, `env_seed`, "
            "`num_steps_wait`",
        ),
        ({"env_seed": 0}, "asks for `env_seed` = 0; envhub's `libero-spatial` runs with `env_seed` = 7"),
    ],
)
def test_an_unsupported_ask_is_an_error_naming_the_supported(peers, tmp_path, params, message) -> None:
    from envhub.evaluation import evaluate

    server = logging_server(peers, tmp_path / "seen.pkl", params)
    try:
        with VlaEvalPolicy(server.url, timeout=30) as policy:
            with pytest.raises(LayoutError) as caught:
                policy.bind(libero_spatial())
        # Through `evaluate` (`envhub eval`): a usage error (exit status 2) before any env starts.
        decl = {**Catalog().declared["libero-spatial"], "name": "libero-spatial"}
        with pytest.raises(BenchmarkError) as usage:
            evaluate(decl, connect("vla-eval", server.url, timeout=30), progress=False, out=tmp_path / "run")
    finally:
        server.stop()
    assert message in str(caught.value), str(caught.value)
    assert message in str(usage.value), str(usage.value)
    assert not (tmp_path / "seen.pkl").exists()


def test_an_ask_on_a_benchmark_without_a_layout_is_an_error(peers, tmp_path) -> None:
    server = logging_server(peers, tmp_path / "seen.pkl", {"send_state": True})
    try:
        with VlaEvalPolicy(server.url, timeout=30) as policy:
            with pytest.raises(LayoutError, match="declares no `servers.vla-eval` layout"):
                policy.bind(parse("cheetah-short", {k: v for k, v in CHEETAH.items() if k != "name"}))
    finally:
        server.stop()


def test_openpi_on_libero_sends_the_examples_keys() -> None:
    """OpenPI's LIBERO layout: the example's keys, 224x224 images, the 8-D float64 state."""
    policy = OpenPIPolicy("ws://127.0.0.1:9", timeout=5)
    try:
        policy.bind(libero_spatial())
        obs = libero_observation(np.random.default_rng(4))
        task = Task("libero-spatial", "libero-spatial/0", "libero-spatial", "open the drawer", 0)
        sent = policy.observation(Request(0, Episode(task, 0), 0, obs))
        assert policy.replan() == 5  # the example's replan_steps, unless the caller gives one
        assert OpenPIPolicy("ws://127.0.0.1:9", timeout=5, replan_steps=2).replan() == 2
    finally:
        policy.close()
    assert list(sent) == ["observation/image", "observation/wrist_image", "observation/state", "prompt"]
    assert sent["observation/image"].shape == (224, 224, 3) and sent["observation/image"].dtype == np.uint8
    state = peer_servers.quat2axisangle(obs["robot0_eef_quat"].copy())
    assert_same(
        sent["observation/state"],
        np.concatenate([obs["robot0_eef_pos"], state, obs["robot0_gripper_qpos"]]),
    )
    assert sent["prompt"] == "open the drawer"


# -- a server that stops answering ---------------------------------------------------------


@pytest.mark.parametrize("protocol", ["vla-eval", "openpi"])
@pytest.mark.parametrize("fail_fast", [False, True])
def test_a_server_that_stops_answering_fails_its_episodes(protocol, fail_fast, peers, tmp_path) -> None:
    """A server that answers one observation, then hangs (alive, connected): its episodes
    fail after the policy timeout with an error naming the server and the wait; the run
    goes on to the other episodes (each failing the same way), or stops at the first."""
    from envhub.evaluation import evaluate

    evaluate_or_skip()
    server = Server(peers, protocol, "--action-dim", "6", "--hang-after", "1")
    try:
        policy = connect(protocol, server.url, timeout=1.5)
        decl = dict(CHEETAH, name="cheetah-hang", episodes_per_task=2, horizon=8)
        if fail_fast:
            from envhub.evaluation.runner import EvaluationStopped

            with pytest.raises(EvaluationStopped) as caught:
                evaluate(decl, policy, num_envs=1, progress=False, out=tmp_path / "run", fail_fast=True)
            errors = [str(caught.value)]
        else:
            results = evaluate(decl, policy, num_envs=1, progress=False, out=tmp_path / "run")
            errors = [e["error"] for e in results["episodes"]]
            assert results["summary"]["errors"] == 2 and all(errors), errors
    finally:
        server.stop()
    want = f"the {protocol} server at {server.url} sent no action within 1.5 s (--policy-timeout"
    assert all(want in e for e in errors), errors


@pytest.mark.parametrize(
    "servers,message",
    [
        ({"grpc": {"send": {"x": "y"}}}, "unknown server protocol `grpc` in `servers`; valid: vla-eval, openpi"),
        ({"openpi": {"send": {"a": {"rotate": "b"}}}}, "a source is an observation key, `$text`, or one of"),
        (
            {"vla-eval": {"send": {"a": "b"}, "params": {"send_state": {"add": {"s": "k"}, "sends": 1}}}},
            "unknown field `sends`; valid: `add`, `replace`, `env`, `equals`",
        ),
        (
            {"openpi": {"send": {"a": {"axis_angle": "q", "convention": "scipy"}}}},
            "unknown axis-angle convention `scipy`; valid: antipodal, robosuite, robosuite64",
        ),
        (
            {"vla-eval": {"send": {"a": "b"}, "params": {"seed": {"equals": "$init.sed"}}}},
            "unknown protocol value `$init.sed`; valid: $init.seed, $settle.steps",
        ),
    ],
)
def test_a_bad_servers_declaration_is_a_benchmark_error(servers, message) -> None:
    decl = {k: v for k, v in CHEETAH.items() if k != "name"}
    with pytest.raises(BenchmarkError) as caught:
        parse("cheetah-short", {**decl, "servers": servers})
    assert message in str(caught.value), str(caught.value)


def test_equals_follows_the_runs_own_protocol() -> None:
    """`seed: {equals: $init.seed}`: a server's `seed` must be the seed the run resets with
    (7, or 7 + k under `--seeds`); the settling steps likewise."""
    from envhub.evaluation.servers.layout import layout_for

    decl = libero_spatial().raw["servers"]
    assert layout_for(decl, "vla-eval", {"seed": 7, "num_steps_wait": 10}, "b", {"init.seed": 7, "settle.steps": 10})
    assert layout_for(decl, "vla-eval", {"env_seed": 8}, "b", {"init.seed": 8, "settle.steps": 10})
    with pytest.raises(LayoutError, match="asks for `seed` = 7; envhub's `b` runs with `seed` = 8"):
        layout_for(decl, "vla-eval", {"seed": 7}, "b", {"init.seed": 8, "settle.steps": 10})
    with pytest.raises(LayoutError, match="asks for `num_steps_wait` = 0; envhub's `b` runs with `num_steps_wait` = 10"):
        layout_for(decl, "vla-eval", {"num_steps_wait": 0}, "b", {"init.seed": 7, "settle.steps": 10})
