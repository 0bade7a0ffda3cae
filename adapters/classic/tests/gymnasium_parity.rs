//! Parity with Gymnasium itself (envpool's `*_align_test.py` idea, driven from Rust).
//!
//! `tests/python/support/classic_reference.py` records trajectories of Gymnasium's own envs: for each
//! run the seeded initial state, then per step the state before it, the action, and the
//! observation, reward and `terminated` after it, with a fresh initial state whenever an
//! episode ends. This test replays them: the same seed must give the same initial states (NumPy's
//! generator is reproduced bit for bit), and the same actions the same observations (within
//! float32 rounding), rewards (within 1e-9 relative) and terminations; `render_fps` must be the
//! env's `metadata["render_fps"]`.
//!
//! Some runs scale the continuous actions three times beyond the action space (Gymnasium passes
//! them to the env, which clips them as it was written to): their steps must match too, and each
//! continuous env must have stepped with hundreds of them.
//!
//! With the same C library as NumPy (glibc on Linux), every step is bit-identical (the summary
//! printed with `--nocapture` counts any that are not); the tolerances leave room for another
//! libm. The envs run free from the seeded initial state. Where Rust's and NumPy's `sin`/`cos` differ
//! in the last bit, the state before a step may differ by a rounding error; the test checks it
//! is one, then copies Gymnasium's state in (`set_state`) so chaotic envs (Acrobot) cannot
//! amplify it over hundreds of steps.
//!
//! Python: `$ENVHUB_PYTHON`, else `<repo>/.venv/bin/python` (`make test` creates it). If it
//! cannot import gymnasium the test fails, unless `ENVHUB_SKIP_PYTHON_TESTS=1`.

use envhub_classic::ClassicControl;
use envhub_conformance::{close, floats, gymnasium_version, python_reference, scaled_diff};
use envhub_core::{EnvConfig, Info, ResetOptions};
use serde_json::Value;
use std::collections::BTreeMap;

/// Observations: float32 rounding.
const OBS_TOL: f64 = 1e-6;
/// Rewards, relative (absolute for rewards near 0).
const REWARD_TOL: f64 = 1e-9;
/// The state before a step, where a last-bit difference in `sin`/`cos` may have crept in.
const STATE_TOL: f64 = 1e-9;

/// What one run of one env showed, for the summary.
#[derive(Default)]
struct Tally {
    steps: usize,
    terminations: usize,
    resets: usize,
    resyncs: usize,
    max_state_diff: f64,
    /// Steps whose observation or reward is not bit-identical to Gymnasium's.
    inexact: usize,
    /// Steps with an action beyond the action space's bounds.
    beyond_bounds: usize,
}

#[test]
fn matches_gymnasium() {
    let script = "tests/python/support/classic_reference.py";
    let Some(reference) = python_reference(script, &["gymnasium"], "gymnasium 1.4") else {
        return;
    };
    let version = gymnasium_version(&reference, "1.4");

    let mut tallies: BTreeMap<String, Tally> = BTreeMap::new();
    for run in reference["runs"].as_array().unwrap() {
        let env_id = run["env_id"].as_str().unwrap();
        let seed = run["seed"].as_u64().unwrap();
        let at = format!("{env_id} seed {seed} kwargs {}", run["kwargs"]);
        let config = EnvConfig {
            extra: serde_json::from_value(run["kwargs"].clone()).unwrap(),
            ..EnvConfig::default()
        };
        let options: ResetOptions = serde_json::from_value(run["options"].clone()).unwrap();
        let tally = tallies.entry(env_id.to_string()).or_default();

        let mut env = ClassicControl.make_classic(env_id, &config).unwrap();
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        // Checks an observation; returns whether it is bit-identical.
        let check_obs = |obs: &[u8], want: &Value, what: &str| {
            let got: Vec<f64> = obs
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64)
                .collect();
            let want = floats(want);
            assert_eq!(got.len(), want.len(), "{what}");
            for (g, w) in got.iter().zip(&want) {
                assert!(close(*g, *w, OBS_TOL), "{what}: obs {got:?} != {want:?}");
            }
            got == want
        };

        env.reset(Some(seed), &options, &mut obs, &mut info)
            .unwrap();
        assert_eq!(
            env.state(),
            floats(&run["reset_state"]),
            "{at}: seeded initial state"
        );
        check_obs(&obs, &run["reset_obs"], &format!("{at}: reset"));
        assert_eq!(
            env.render_fps(),
            run["render_fps"].as_f64(),
            "{at}: metadata[\"render_fps\"]"
        );

        for (i, step) in run["steps"].as_array().unwrap().iter().enumerate() {
            let at = format!("{at} step {i}");
            let want_state = floats(&step["state"]);
            if env.state() != want_state {
                let diff = env
                    .state()
                    .iter()
                    .zip(&want_state)
                    .map(|(g, w)| scaled_diff(*g, *w))
                    .fold(0.0, f64::max);
                assert!(
                    diff <= STATE_TOL,
                    "{at}: state {:?} != {want_state:?}",
                    env.state()
                );
                // MountainCarContinuous's float32 arithmetic is reproduced exactly.
                assert_ne!(
                    step["state_dtype"], "float32",
                    "{at}: float32 state differs"
                );
                tally.max_state_diff = tally.max_state_diff.max(diff);
                tally.resyncs += 1;
                env.set_state(&want_state).unwrap();
            }

            let action: Vec<u8> = match &step["action"] {
                Value::Number(n) => n.as_i64().unwrap().to_le_bytes().to_vec(),
                list => floats(list)
                    .iter()
                    .flat_map(|a| (*a as f32).to_le_bytes())
                    .collect(),
            };
            tally.beyond_bounds += usize::from(!env.action_space().contains(&action));
            let t = env.step(&action, &mut obs, &mut info).unwrap();
            let exact_obs = check_obs(&obs, &step["obs"], &at);
            let reward = step["reward"].as_f64().unwrap();
            tally.inexact += (!exact_obs || t.reward != reward) as usize;
            assert!(
                close(t.reward, reward, REWARD_TOL),
                "{at}: reward {} != {reward}",
                t.reward
            );
            assert_eq!(
                t.terminated,
                step["terminated"].as_bool().unwrap(),
                "{at}: terminated"
            );
            tally.steps += 1;
            tally.terminations += t.terminated as usize;

            if let Some(reset_state) = step.get("reset_state") {
                env.reset(None, &options, &mut obs, &mut info).unwrap();
                assert_eq!(
                    env.state(),
                    floats(reset_state),
                    "{at}: initial state after reset(seed=None)"
                );
                check_obs(&obs, &step["reset_obs"], &format!("{at}: reset"));
                tally.resets += 1;
            }
        }
    }

    println!("gymnasium {version} parity:");
    for (env_id, t) in &tallies {
        println!(
            "  {env_id}: {} steps ({} not bit-identical, {} with actions beyond the bounds), \
             {} terminations, {} resets, {} states resynced (max diff {:e})",
            t.steps,
            t.inexact,
            t.beyond_bounds,
            t.terminations,
            t.resets,
            t.resyncs,
            t.max_state_diff
        );
    }
    assert_eq!(tallies.len(), 5, "every env has reference runs");
    for (env_id, t) in &tallies {
        assert!(t.steps >= 300, "{env_id}");
        if env_id != "Pendulum-v1" {
            assert!(t.terminations > 0, "{env_id}: no termination exercised");
        }
        if ["Pendulum-v1", "MountainCarContinuous-v0"].contains(&env_id.as_str()) {
            assert!(
                t.beyond_bounds >= 300,
                "{env_id}: {} steps with actions beyond the bounds",
                t.beyond_bounds
            );
        }
    }
}
