//! The Python worker (`python -m envhub.worker`) driven through the Rust hub: Gymnasium envs
//! pinned to it step bit for bit like the native adapters, and a Python exception or a
//! killed Python worker reaches the client as an error while the hub goes on.
//!
//! Each test skips (with the reason) when the interpreter the hub uses cannot import the
//! compiled `envhub._envhub`, unless `ENVHUB_PY_REQUIRED` is set.

use envhub_e2e::{PATIENCE, PyModule, TestHub, kill_worker_expect_died, python_worker_available};
use envhub_hub::env_vars::{ENVHUB_ADAPTERS, ENVHUB_DESCRIBE_TIMEOUT};
use envhub_hub::{EnvConfig, HubError, Registry, VecEnv};
use rand::SeedableRng;
use std::sync::mpsc;
use std::time::Duration;

/// Entries pinned to the Python host, beside the built-in (native) ones.
const REGISTRY: &str = "
environments:
  - id: py-cartpole
    name: CartPole in the Python worker
    framework: gymnasium
    env_id: CartPole-v1
    adapter: gymnasium
    robot_type: custom
    env_type: floor
  - id: py-half-cheetah
    name: HalfCheetah in the Python worker
    framework: gymnasium
    env_id: HalfCheetah-v5
    adapter: gymnasium
    robot_type: biped
    env_type: floor
  - id: py-stuck
    name: An env whose worker hangs on exit after failing to make it
    framework: e2e_stuck
    env_id: Stuck-v0
    robot_type: custom
    env_type: floor
  - id: py-boom
    name: An env that raises in step
    framework: e2e_boom
    env_id: Boom-v0
    robot_type: custom
    env_type: floor
";

/// A user adapter whose env raises in `step` on action 1.
const BOOM_ADAPTER: &str = r#"
import gymnasium as gym
import numpy as np

import envhub


class BoomEnv(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (1,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(1, np.float32), {}

    def step(self, action):
        self.t += 1
        if int(action) == 1:
            raise ValueError(f"boom: action 1 at step {self.t}")
        return np.array([self.t], np.float32), 1.0, False, False, {}


class BoomAdapter(envhub.EnvAdapter):
    name = "e2e_boom"
    frameworks = ["e2e_boom"]
    requires = ["gymnasium"]
    description = "raises in step on action 1"

    def make(self, env_id, config):
        return BoomEnv()
"#;

/// A user adapter module that blocks at import.
const HANG_AT_IMPORT: &str = "import time\n\ntime.sleep(3600)\n";

/// A user adapter that cannot make its env and then hangs in its worker's exit; it leaves
/// its worker's pid in `worker.pid` beside its module.
const STUCK_ADAPTER: &str = r#"
import atexit
import os
import time

import envhub


class StuckAdapter(envhub.EnvAdapter):
    name = "e2e_stuck"
    frameworks = ["e2e_stuck"]
    requires = []
    description = "fails to make its env, then hangs on exit"

    def make(self, env_id, config):
        with open(os.path.join(os.path.dirname(__file__), "worker.pid"), "w") as f:
            f.write(str(os.getpid()))
        atexit.register(time.sleep, 3600)
        raise RuntimeError("cannot make Stuck-v0 on purpose")
"#;

fn hub(name: &str) -> TestHub {
    let mut registry = Registry::builtin();
    registry
        .add_yaml(REGISTRY, "python_worker.yaml", &std::env::temp_dir())
        .unwrap();
    TestHub::over(name, registry, |_| {})
}

fn workers(n: usize) -> EnvConfig {
    EnvConfig {
        workers: Some(n),
        ..EnvConfig::default()
    }
}

/// Steps `native` and `python` with the same seeds and random actions and asserts every
/// observation byte, reward and flag is equal; returns the episodes that ended.
fn assert_same_rollout(mut native: VecEnv, mut python: VecEnv, steps: usize) -> usize {
    let id = python.id().to_string();
    assert_eq!(python.route().adapter, "gymnasium", "{id} runs in Python");
    assert_ne!(native.route().adapter, "gymnasium", "{id}'s twin is native");
    assert_eq!(python.num_workers(), 2);
    assert_eq!(native.action_space(), python.action_space(), "{id}");
    let n = native.num_envs();
    let ob = native.observation_space().byte_len();
    assert_eq!(python.observation_space().byte_len(), ob, "{id}");
    let same_obs = |a: &[u8], b: &[u8], when: &str| {
        for i in 0..n {
            assert_eq!(
                a[i * ob..(i + 1) * ob],
                b[i * ob..(i + 1) * ob],
                "{id}: obs of env {i} {when}"
            );
        }
    };
    let a = native.reset(Some(42)).unwrap().obs.to_vec();
    same_obs(&a, python.reset(Some(42)).unwrap().obs, "after reset");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut episodes = 0;
    for step in 0..steps {
        let actions = native.sample_actions(&mut rng);
        let a = native.step(&actions).unwrap();
        let b = python.step(&actions).unwrap();
        same_obs(a.obs, b.obs, &format!("at step {step}"));
        assert_eq!(a.rewards, b.rewards, "{id}: rewards at step {step}");
        assert_eq!(
            a.terminated, b.terminated,
            "{id}: terminated at step {step}"
        );
        assert_eq!(a.truncated, b.truncated, "{id}: truncated at step {step}");
        episodes += a.terminated.iter().filter(|d| **d).count();
    }
    native.close();
    python.close();
    episodes
}

#[test]
fn gymnasium_envs_in_the_python_worker_match_the_native_adapters() {
    if !python_worker_available(
        "python_worker::gymnasium_envs_in_the_python_worker_match_the_native_adapters",
    ) {
        return;
    }
    let t = hub("pymatch");
    let native = t.hub.make_vec("gym-cartpole", 4, &workers(2)).unwrap();
    let python = t.hub.make_vec("py-cartpole", 4, &workers(2)).unwrap();
    // Episodes end, so the autoreset of both hosts is compared too.
    assert!(assert_same_rollout(native, python, 300) > 0);
    let native = t
        .hub
        .make_vec("mujoco-half-cheetah", 2, &workers(2))
        .unwrap();
    let python = t.hub.make_vec("py-half-cheetah", 2, &workers(2)).unwrap();
    assert_same_rollout(native, python, 200);
}

#[test]
fn a_python_exception_names_the_env_and_carries_the_traceback() {
    if !python_worker_available(
        "python_worker::a_python_exception_names_the_env_and_carries_the_traceback",
    ) {
        return;
    }
    let module = PyModule::write("pyboom", "e2e_boom_adapter", BOOM_ADAPTER);
    // The hub passes its own environment to the workers it starts; no other test in this
    // process (nextest runs each in its own) reads it while it changes.
    unsafe {
        std::env::set_var(ENVHUB_ADAPTERS, "e2e_boom_adapter:BoomAdapter");
        std::env::set_var("PYTHONPATH", module.pythonpath());
    }
    envhub_hub::refresh_adapters();
    let t = hub("pyboom");
    let mut other = t.hub.make_vec("py-cartpole", 2, &workers(1)).unwrap();
    other.reset(Some(0)).unwrap();
    let mut env = t.hub.make_vec("py-boom", 2, &workers(1)).unwrap();
    assert_eq!(env.route().adapter, "e2e_boom");
    env.reset(Some(0)).unwrap();
    env.step_i64(&[0, 0]).unwrap();
    let err = env.step_i64(&[0, 1]).unwrap_err();
    let HubError::EnvFailed {
        worker: 0,
        envs,
        message,
    } = &err
    else {
        panic!("expected EnvFailed from worker 0, got {err}");
    };
    assert_eq!(envs, &[1], "only the env that raised failed");
    for needle in [
        "`Boom-v0`",
        "raised in `step`",
        "Traceback (most recent call last)",
        "e2e_boom_adapter.py",
        "ValueError: boom: action 1 at step 2",
    ] {
        assert!(message.contains(needle), "no {needle:?} in: {message}");
    }
    // Env 0 stepped: its result is there. Env 1 must be reset before it steps again.
    let partial = env.last_batch().unwrap();
    assert_eq!(partial.env_ids, &[0, 1]);
    assert!(!partial.terminated[0] && !partial.truncated[0]);
    let refused = env.step_i64(&[0, 0]).unwrap_err().to_string();
    assert!(refused.contains("must be reset"), "{refused}");
    env.reset_with(&[None, Some(5)], Some(&[false, true]), &Default::default())
        .unwrap();
    // The worker outlives the exception; the other session and new ones go on.
    env.step_i64(&[0, 0]).unwrap();
    other.step_i64(&[1, 0]).unwrap();
    let mut fresh = t.hub.make_vec("py-boom", 1, &workers(1)).unwrap();
    fresh.reset(Some(1)).unwrap();
    assert_eq!(fresh.step_i64(&[0]).unwrap().rewards, [1.0]);
}

#[test]
fn a_killed_python_worker_is_worker_died() {
    if !python_worker_available("python_worker::a_killed_python_worker_is_worker_died") {
        return;
    }
    let t = hub("pykill");
    let mut env = t.hub.make_vec("py-cartpole", 4, &workers(2)).unwrap();
    let mut other = t.hub.make_vec("py-cartpole", 2, &workers(1)).unwrap();
    other.reset(Some(0)).unwrap();
    env.reset(Some(0)).unwrap();
    let actions = [0i64, 1, 1, 0];
    for _ in 0..20 {
        env.step_i64(&actions).unwrap();
    }
    let victim = env.worker_pids()[1];
    let (_, why) = kill_worker_expect_died(1, victim, || env.step_i64(&actions).map(drop));
    assert!(why.contains("signal: 9"), "{why}");
    assert!(matches!(
        env.step_i64(&actions),
        Err(HubError::Closed { .. })
    ));
    other.step_i64(&[0, 1]).unwrap();
}

#[test]
fn an_adapter_that_hangs_at_import_is_named_and_stalls_nothing_else() {
    if !python_worker_available(
        "python_worker::an_adapter_that_hangs_at_import_is_named_and_stalls_nothing_else",
    ) {
        return;
    }
    let module = PyModule::write("pyhang", "e2e_hang_adapter", HANG_AT_IMPORT);
    // As above: this process's environment is the workers' (nextest runs each test alone).
    // The describe's bound is far above a native make on a slow, busy machine, so the make
    // below is done while the describe still hangs; the import itself hangs for an hour.
    unsafe {
        std::env::set_var(ENVHUB_ADAPTERS, "e2e_hang_adapter:HangAdapter");
        std::env::set_var("PYTHONPATH", module.pythonpath());
        std::env::set_var(ENVHUB_DESCRIBE_TIMEOUT, "10");
    }
    let bound = Duration::from_secs(10);
    envhub_hub::refresh_adapters();
    let t = std::sync::Arc::new(hub("pyhang"));
    // Resolved first, as every session of a native env does; Python is not asked for it.
    t.hub.make_vec("gym-cartpole", 1, &workers(1)).unwrap();

    // A Python env: asking the Python worker what it hosts hangs in the import.
    let (tx, python) = mpsc::channel();
    let hub_a = t.clone();
    std::thread::spawn(move || {
        let _ = tx.send(hub_a.hub.make_vec("py-cartpole", 1, &workers(1)).map(drop));
    });
    std::thread::sleep(Duration::from_millis(300));

    // Meanwhile a native env is made and steps, without waiting for the hang: the hanging
    // describe has not returned when it is done.
    let mut native = t.hub.make_vec("gym-cartpole", 2, &workers(1)).unwrap();
    native.reset(Some(0)).unwrap();
    native.step_i64(&[0, 1]).unwrap();
    assert!(
        python.try_recv().is_err(),
        "the native make returned only after the hanging describe did"
    );
    // And the catalog, which needs the Python worker too, waits about the bound, not the
    // hour of the import (nor behind the hanging describe).
    let (tx, catalog) = mpsc::channel();
    let hub_b = t.clone();
    std::thread::spawn(move || {
        let _ = tx.send(hub_b.hub.adapters());
    });
    let listed = catalog
        .recv_timeout(bound + PATIENCE)
        .expect("the catalog waits at most the bound, not behind the hanging describe")
        .unwrap();
    let gymnasium = listed.iter().find(|a| a.name == "gymnasium").unwrap();
    assert!(!gymnasium.availability.is_available(), "{gymnasium:?}");

    let result = python
        .recv_timeout(bound + PATIENCE)
        .expect("the make that hit the hanging import returns");
    let err = result.unwrap_err();
    let HubError::Unavailable { reason, hint, .. } = &err else {
        panic!("expected Unavailable, got {err:?}");
    };
    // Ended by its bound: the describe was killed after the 10 s it was given.
    for needle in [
        "envhub.worker describe",
        "did not finish within 10 s",
        "e2e_hang_adapter:HangAdapter",
    ] {
        assert!(reason.contains(needle), "no {needle:?} in: {reason}");
    }
    assert!(hint.contains("ENVHUB_DESCRIBE_TIMEOUT"), "{hint}");
}

#[test]
fn a_worker_that_hangs_after_reporting_an_error_is_killed() {
    if !python_worker_available(
        "python_worker::a_worker_that_hangs_after_reporting_an_error_is_killed",
    ) {
        return;
    }
    let module = PyModule::write("pystuck", "e2e_stuck_adapter", STUCK_ADAPTER);
    unsafe {
        std::env::set_var(ENVHUB_ADAPTERS, "e2e_stuck_adapter:StuckAdapter");
        std::env::set_var("PYTHONPATH", module.pythonpath());
    }
    envhub_hub::refresh_adapters();
    let t = std::sync::Arc::new(hub("pystuck"));
    let (tx, made) = mpsc::channel();
    let hub_a = t.clone();
    std::thread::spawn(move || {
        let _ = tx.send(hub_a.hub.make_vec("py-stuck", 1, &workers(1)).map(drop));
    });
    // Its exit would take an hour: the hub gives it a few seconds after its error line
    // (`EXIT_AFTER_ERROR`, 5 s), then kills it.
    let Ok(made) = made.recv_timeout(Duration::from_secs(5) + PATIENCE) else {
        panic!("the make waited on the worker that hangs on exit");
    };
    let Err(err) = made else {
        panic!("py-stuck was made");
    };
    assert!(
        matches!(&err, HubError::MakeFailed(m) if m.contains("cannot make Stuck-v0 on purpose")),
        "{err:?}"
    );
    // Killed and reaped, not left behind hanging: its pid is gone.
    let pid = std::fs::read_to_string(module.dir.join("worker.pid")).expect("the worker ran make");
    assert!(
        !std::path::Path::new(&format!("/proc/{}", pid.trim())).exists(),
        "the worker {pid} that hung on exit still runs"
    );
}

#[test]
fn a_render_mode_the_native_adapter_lacks_runs_gymnasiums_own_env() {
    if !python_worker_available(
        "python_worker::a_render_mode_the_native_adapter_lacks_runs_gymnasiums_own_env",
    ) {
        return;
    }
    let t = hub("pyrender");
    let drawn = EnvConfig {
        render_mode: Some("rgb_array".into()),
        ..workers(2)
    };
    // The native classic-control adapter draws nothing: the unpinned entry goes to the
    // Gymnasium-hosted adapter, whose frames are Gymnasium's.
    let mut python = t.hub.make_vec("gym-cartpole", 4, &drawn).unwrap();
    python.reset(Some(0)).unwrap();
    let frames = python.render().unwrap();
    assert_eq!(frames.len(), 4);
    for frame in frames {
        let frame = frame.expect("a frame per env");
        assert_eq!(
            (frame.height, frame.width, frame.rgb.len()),
            (400, 600, 400 * 600 * 3)
        );
    }
    python.close();
    // Its trajectory is the native one's, bit for bit.
    let native = t.hub.make_vec("gym-cartpole", 4, &workers(2)).unwrap();
    let python = t.hub.make_vec("gym-cartpole", 4, &drawn).unwrap();
    assert!(assert_same_rollout(native, python, 300) > 0);
    // An entry pinned to the native adapter keeps its pin, which refuses the mode.
    let mut registry = Registry::builtin();
    registry
        .add_yaml(
            "environments:\n  - {id: pinned-cartpole, name: CartPole, framework: gymnasium, env_id: CartPole-v1, adapter: classic_control, robot_type: custom, env_type: floor}\n",
            "pinned.yaml",
            &std::env::temp_dir(),
        )
        .unwrap();
    let pinned = TestHub::over("pyrender-pin", registry, |_| {});
    let err = pinned
        .hub
        .make_vec("pinned-cartpole", 2, &drawn)
        .err()
        .expect("the pinned adapter refuses the mode")
        .to_string();
    assert!(
        err.contains("render mode `rgb_array` is not supported by `CartPole-v1`"),
        "{err}"
    );
}
