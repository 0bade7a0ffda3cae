//! The `Env` contract, checked through random rollouts of one env.

use envhub_core::{DType, Env, EnvAdapter, EnvConfig, Info, ResetOptions, Space, TimeLimit};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// One entry of a rollout: the observation after a reset (reward 0, no flags) or after a step.
#[derive(Debug, PartialEq)]
struct Step {
    obs: Vec<u8>,
    reward: f64,
    terminated: bool,
    truncated: bool,
}

impl Step {
    fn reset(obs: &[u8]) -> Self {
        Step {
            obs: obs.to_vec(),
            reward: 0.0,
            terminated: false,
            truncated: false,
        }
    }
}

/// Checks `env_id` of `adapter`, made with `config`, against the `Env` contract; panics with the
/// env id on the first violation.
///
/// - The env's spaces are the ones its spec announces.
/// - Over `steps` random steps (resetting after each end, so over several episodes): every
///   sampled action is in the action space, every observation in the observation space and
///   every reward finite, and some episode ends (give an env with long episodes a short
///   `max_episode_steps` in `config`).
/// - The same seed gives the same trajectory, both from a fresh env and from the same env
///   reseeded; another seed gives another.
/// - Continuous actions three times the sampled ones, most beyond the `Box` bounds (envhub
///   passes them to the env as Gymnasium does), step like any other: no error, observations in
///   the space, rewards finite. (Whether the env clips them as its original does is for a
///   parity test to show.)
/// - `TimeLimit` truncates at exactly the episode limit (the config's `max_episode_steps`, else
///   the env's default; one of them must be set) and at a short limit of 5 steps, unless the
///   episode terminates first.
#[track_caller]
pub fn check_env(adapter: &dyn EnvAdapter, env_id: &str, config: &EnvConfig, steps: usize) {
    let spec = adapter
        .spec(env_id, config)
        .unwrap_or_else(|e| panic!("{env_id}: spec: {e}"));
    let limit = config
        .episode_limit(spec.max_episode_steps)
        .unwrap_or_else(|| {
            panic!(
                "{env_id}: no episode limit to check\nhint: set `max_episode_steps` in the config"
            )
        });
    let make = |limit| {
        let env = adapter
            .make(env_id, config)
            .unwrap_or_else(|e| panic!("{env_id}: make: {e}"));
        TimeLimit::new(env, Some(limit))
    };

    let mut env = make(limit);
    assert_eq!(env.observation_space(), &spec.observation_space, "{env_id}");
    assert_eq!(env.action_space(), &spec.action_space, "{env_id}");

    // Observations stay in the space over several episodes, with resets after each end.
    let a = rollout(env_id, &mut env, 7, steps);
    assert!(
        a.iter().any(|s| s.terminated || s.truncated),
        "{env_id}: no episode ended in {steps} steps"
    );

    // Continuous actions beyond the bounds are the env's to clip.
    if env
        .action_space()
        .leaves()
        .iter()
        .any(|(_, _, leaf)| is_float(leaf))
    {
        rollout_scaled(env_id, &mut make(limit), 9, steps, 3.0);
    }

    // Same seed, same trajectory (a fresh env, and the same env reseeded).
    let fresh = rollout(env_id, &mut make(limit), 7, steps);
    assert_same(&a, &fresh, &format!("{env_id}: fresh env"));
    let reseeded = rollout(env_id, &mut env, 7, steps);
    assert_same(&a, &reseeded, &format!("{env_id}: reseeded env"));
    assert!(
        a != rollout(env_id, &mut env, 8, steps),
        "{env_id}: other seed, same trajectory"
    );

    // Truncation at exactly the limit, whether the env's own (or the config's) or a short one.
    for limit in [limit, 5] {
        let mut env = make(limit);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        env.reset(Some(3), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap_or_else(|e| panic!("{env_id}: reset: {e}"));
        for step in 1..=limit {
            let action = env.action_space().sample(&mut rng);
            let t = env
                .step(&action, &mut obs, &mut info)
                .unwrap_or_else(|e| panic!("{env_id}: step {step}: {e}"));
            assert_eq!(t.truncated, step == limit, "{env_id}: step {step}/{limit}");
            if t.terminated {
                break;
            }
        }
    }
}

/// Steps `env` with `steps` random actions drawn from `seed`, after a reset with `seed`
/// and resetting (without a seed) whenever an episode ends; returns every observation, reward
/// and end flag. Panics if an action, observation or reward breaks the contract.
#[track_caller]
fn rollout(env_id: &str, env: &mut dyn Env, seed: u64, steps: usize) -> Vec<Step> {
    rollout_scaled(env_id, env, seed, steps, 1.0)
}

fn is_float(leaf: &Space) -> bool {
    matches!(leaf.dtype(), Some(DType::Float32 | DType::Float64))
}

/// Multiplies every float element of `action` by `scale`.
fn scale_floats(space: &Space, action: &mut [u8], scale: f64) {
    for (_, offset, leaf) in space.leaves() {
        let data = &mut action[offset..offset + leaf.byte_len()];
        match leaf.dtype() {
            Some(DType::Float32) => data.chunks_exact_mut(4).for_each(|c| {
                let v = f32::from_le_bytes(c.try_into().unwrap()) * scale as f32;
                c.copy_from_slice(&v.to_le_bytes());
            }),
            Some(DType::Float64) => data.chunks_exact_mut(8).for_each(|c| {
                let v = f64::from_le_bytes(c.try_into().unwrap()) * scale;
                c.copy_from_slice(&v.to_le_bytes());
            }),
            _ => {}
        }
    }
}

/// [`rollout`] with every float element of the sampled actions multiplied by `scale`.
#[track_caller]
fn rollout_scaled(
    env_id: &str,
    env: &mut dyn Env,
    seed: u64,
    steps: usize,
    scale: f64,
) -> Vec<Step> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    let mut info = Info::default();
    let options = ResetOptions::new();
    env.reset(Some(seed), &options, &mut obs, &mut info)
        .unwrap_or_else(|e| panic!("{env_id}: reset with seed {seed}: {e}"));
    assert_in_space(env, &obs, &format!("{env_id}: reset with seed {seed}"));
    let mut out = vec![Step::reset(&obs)];
    for i in 0..steps {
        let mut at = format!("{env_id}: seed {seed}, step {i}");
        if scale != 1.0 {
            at += &format!(", actions × {scale}");
        }
        let mut action = env.action_space().sample(&mut rng);
        assert!(env.action_space().contains(&action), "{at}: sampled action");
        if scale != 1.0 {
            scale_floats(env.action_space(), &mut action, scale);
        }
        let t = env
            .step(&action, &mut obs, &mut info)
            .unwrap_or_else(|e| panic!("{at}: {e}"));
        assert_in_space(env, &obs, &at);
        assert!(t.reward.is_finite(), "{at}: reward {}", t.reward);
        out.push(Step {
            obs: obs.clone(),
            reward: t.reward,
            terminated: t.terminated,
            truncated: t.truncated,
        });
        if t.terminated || t.truncated {
            env.reset(None, &options, &mut obs, &mut info)
                .unwrap_or_else(|e| panic!("{at}: reset: {e}"));
            assert_in_space(env, &obs, &format!("{at}: reset"));
            out.push(Step::reset(&obs));
        }
    }
    out
}

#[track_caller]
fn assert_in_space(env: &dyn Env, obs: &[u8], at: &str) {
    if let Err(e) = env.observation_space().validate(obs) {
        panic!("{at}: observation outside the space: {e}");
    }
}

/// Panics at the first entry where two trajectories differ.
#[track_caller]
fn assert_same(want: &[Step], got: &[Step], what: &str) {
    let first = (0..want.len().max(got.len())).find(|&i| want.get(i) != got.get(i));
    if let Some(i) = first {
        panic!(
            "{what}: trajectory differs at entry {i}\nwant {:?}\n got {:?}",
            want.get(i),
            got.get(i)
        );
    }
}
