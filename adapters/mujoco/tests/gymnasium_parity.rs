//! Parity with Gymnasium itself (envpool's `*_align_test.py` idea, driven from Rust).
//!
//! `tests/python/support/mujoco_reference.py` records trajectories of Gymnasium's own v5 envs: the
//! seeded initial state, then per step the random action, the observation, reward, `terminated`
//! and `truncated` (Gymnasium's `TimeLimit`), and a fresh initial state whenever an episode ends
//! (reset without a seed). This test replays them: the same seed must give the same initial
//! state (NumPy's generator is reproduced bit for bit), and the same actions the same
//! observations and rewards within 1e-6 relative, and the same flags. Some runs start from a
//! state set through `MujocoEnv.set_state`, which the Rust env takes as `qpos`/`qvel` reset
//! options. Each run's `metadata["render_fps"]` (`int(np.round(1 / dt))`, so it follows
//! `frame_skip`) must be the env's `render_fps`.
//!
//! Some runs (Ant, HalfCheetah, Hopper) scale the actions three times beyond the action space:
//! Gymnasium sets `data.ctrl` to them, MuJoCo clamps `ctrl` to `ctrlrange`, and the control
//! cost uses the action as given. Their steps must match bit for bit, info included.
//!
//! Both sides step the same libmujoco build, so the simulator state is expected to stay
//! bit-identical; what can differ in the last bits is NumPy's own arithmetic (its SIMD `sin`,
//! `einsum`, BLAS norms) in observations and rewards. The summary printed with `--nocapture`
//! counts the steps that are not bit-identical.
//!
//! Python: `$ENVHUB_PYTHON`, else `<repo>/.venv/bin/python` (`make test` creates it). If it
//! cannot import gymnasium the test fails, unless `ENVHUB_SKIP_PYTHON_TESTS=1`.

use envhub_conformance::{close, floats, gymnasium_version, python_reference, scaled_diff};
use envhub_core::{Env, EnvConfig, Info, InfoValue, ResetOptions};
use envhub_mujoco::Mujoco;
use serde_json::Value;
use std::collections::BTreeMap;

/// Observations and rewards, relative (absolute near 0).
const TOL: f64 = 1e-6;

/// What the runs of one env showed, for the summary.
#[derive(Default)]
struct Tally {
    steps: usize,
    terminations: usize,
    truncations: usize,
    /// Steps whose observation or reward is not bit-identical to Gymnasium's.
    inexact: usize,
    max_diff: f64,
    /// Steps with an action beyond the action space's bounds.
    beyond_bounds: usize,
}

/// Infos Gymnasium computes with `np.linalg.norm`, whose dot product is OpenBLAS's kernel for
/// this CPU (with or without fused multiply-adds, by CPU and `OPENBLAS_CORETYPE`): equal to a
/// few units in the last place, while the positions they are computed from are checked bit
/// for bit.
const NORMS: &[&str] = &["distance_from_origin"];
const NORM_ULPS: u64 = 4;

/// Checks a step's info against Gymnasium's, bit for bit (the norms in `NORMS` to
/// `NORM_ULPS`): the same keys, the same numbers.
fn check_info(info: &Info, want: &Value, what: &str) {
    let want = want.as_object().expect("info is an object");
    let got: BTreeMap<&str, f64> = info
        .iter()
        .map(|(k, v)| match v {
            InfoValue::Float(x) => (k, *x),
            InfoValue::Int(n) => (k, *n as f64),
            InfoValue::Bool(b) => (k, f64::from(u8::from(*b))),
            other => panic!("{what}: info[{k:?}] = {other:?} is not a number"),
        })
        .collect();
    let mut want_keys: Vec<&str> = want.keys().map(String::as_str).collect();
    want_keys.sort_unstable();
    assert_eq!(
        got.keys().copied().collect::<Vec<_>>(),
        want_keys,
        "{what}: info keys"
    );
    for (k, w) in want {
        let w = w.as_f64().expect("a number");
        if NORMS.contains(&k.as_str()) {
            let ulps = (got[k.as_str()].to_bits() as i64 - w.to_bits() as i64).unsigned_abs();
            assert!(
                ulps <= NORM_ULPS,
                "{what}: info[{k:?}] = {} != {w} ({ulps} ulps)",
                got[k.as_str()]
            );
            continue;
        }
        assert_eq!(
            got[k.as_str()].to_bits(),
            w.to_bits(),
            "{what}: info[{k:?}] = {} != {w}",
            got[k.as_str()]
        );
    }
}

fn obs_f64(obs: &[u8]) -> Vec<f64> {
    obs.chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// Checks an observation; returns the largest scaled difference (0 when bit-identical).
fn check_obs(obs: &[u8], want: &Value, what: &str) -> f64 {
    let got = obs_f64(obs);
    let want = floats(want);
    assert_eq!(got.len(), want.len(), "{what}: observation length");
    let mut worst = 0.0f64;
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(
            close(*g, *w, TOL),
            "{what}: obs[{i}] = {g} != {w}\n got {got:?}\nwant {want:?}"
        );
        worst = worst.max(scaled_diff(*g, *w));
    }
    worst
}

#[test]
fn matches_gymnasium() {
    let script = "tests/python/support/mujoco_reference.py";
    let needs = "gymnasium 1.4 and mujoco 3.17";
    let Some(reference) = python_reference(script, &["gymnasium", "mujoco"], needs) else {
        return;
    };
    let version = gymnasium_version(&reference, "1.4");

    let adapter = Mujoco::default();
    let mut tallies: BTreeMap<String, Tally> = BTreeMap::new();
    for run in reference["runs"].as_array().unwrap() {
        let env_id = run["env_id"].as_str().unwrap();
        let seed = run["seed"].as_u64().unwrap();
        let at = format!("{env_id} seed {seed} kwargs {}", run["kwargs"]);
        let config = EnvConfig {
            extra: serde_json::from_value(run["kwargs"].clone()).unwrap(),
            ..EnvConfig::default()
        };
        let options: ResetOptions = match run.get("options") {
            Some(o) => serde_json::from_value(o.clone()).unwrap(),
            None => ResetOptions::new(),
        };
        let limit = run["max_episode_steps"].as_u64().map(|n| n as u32);
        let scaled = run["action_scale"].as_f64().is_some_and(|s| s != 1.0);
        let tally = tallies.entry(env_id.to_string()).or_default();

        // Truncation as `TimeLimit` applies it (counted here, to keep the state accessors).
        let mut env = adapter.make_mujoco(env_id, &config).unwrap();
        let mut elapsed = 0u32;
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();

        env.reset(Some(seed), &options, &mut obs, &mut info)
            .unwrap();
        let state = |env: &envhub_mujoco::MujocoEnv| (env.qpos().to_vec(), env.qvel().to_vec());
        let (qpos, qvel) = state(&env);
        assert_eq!(qpos, floats(&run["reset_qpos"]), "{at}: initial qpos");
        assert_eq!(qvel, floats(&run["reset_qvel"]), "{at}: initial qvel");
        check_obs(&obs, &run["reset_obs"], &format!("{at}: reset"));
        assert_eq!(
            env.render_fps(),
            run["render_fps"].as_f64(),
            "{at}: metadata[\"render_fps\"]"
        );

        for (i, step) in run["steps"].as_array().unwrap().iter().enumerate() {
            let at = format!("{at} step {i}");
            let action: Vec<u8> = floats(&step["action"])
                .iter()
                .flat_map(|a| (*a as f32).to_le_bytes())
                .collect();
            let beyond = !env.action_space().contains(&action);
            tally.beyond_bounds += usize::from(beyond);
            info.clear();
            let mut t = env.step(&action, &mut obs, &mut info).unwrap();
            elapsed += 1;
            t.truncated |= limit.is_some_and(|l| elapsed >= l);
            let diff = check_obs(&obs, &step["obs"], &at);
            let reward = step["reward"].as_f64().unwrap();
            assert!(
                close(t.reward, reward, TOL),
                "{at}: reward {} != {reward}",
                t.reward
            );
            let diff = diff.max(scaled_diff(t.reward, reward));
            tally.inexact += usize::from(diff > 0.0);
            tally.max_diff = tally.max_diff.max(diff);
            if scaled {
                assert_eq!(diff, 0.0, "{at}: scaled actions, not bit-identical");
                check_info(&info, &step["info"], &at);
            }
            assert_eq!(
                t.terminated,
                step["terminated"].as_bool().unwrap(),
                "{at}: terminated"
            );
            assert_eq!(
                t.truncated,
                step["truncated"].as_bool().unwrap(),
                "{at}: truncated"
            );
            tally.steps += 1;
            tally.terminations += usize::from(t.terminated);
            tally.truncations += usize::from(t.truncated && !t.terminated);

            if step.get("reset_obs").is_some() {
                elapsed = 0;
                env.reset(None, &ResetOptions::new(), &mut obs, &mut info)
                    .unwrap();
                let (qpos, qvel) = state(&env);
                assert_eq!(qpos, floats(&step["reset_qpos"]), "{at}: qpos after reset");
                assert_eq!(qvel, floats(&step["reset_qvel"]), "{at}: qvel after reset");
                check_obs(&obs, &step["reset_obs"], &format!("{at}: reset"));
            }
        }
    }

    println!("gymnasium {version} parity:");
    for (env_id, t) in &tallies {
        println!(
            "  {env_id}: {} steps ({} not bit-identical, max diff {:e}; {} with actions beyond \
             the bounds), {} terminations, {} truncations",
            t.steps, t.inexact, t.max_diff, t.beyond_bounds, t.terminations, t.truncations
        );
    }
    assert_eq!(tallies.len(), 11, "every v5 env has reference runs");
    for (env_id, t) in &tallies {
        assert!(t.steps >= 1000, "{env_id}");
        assert!(
            t.terminations + t.truncations > 0,
            "{env_id}: no episode ended"
        );
        if ["Ant-v5", "HalfCheetah-v5", "Hopper-v5"].contains(&env_id.as_str()) {
            assert!(
                t.beyond_bounds >= 200,
                "{env_id}: {} steps with actions beyond the bounds",
                t.beyond_bounds
            );
        }
    }
}
