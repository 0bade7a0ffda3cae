//! Rollout helpers shared by the tests.

use envhub_core::{Env, EnvAdapter, EnvConfig, Info, InfoValue, ResetOptions, TimeLimit};
use envhub_rapier::Rapier;

/// A boxed policy made per episode (a controller may keep state, such as a gait clock).
pub type Controller = Box<dyn FnMut(&[f32], &mut [f32])>;

/// A policy: observation in, action out (both `float32`).
pub type Policy<'a> = &'a mut dyn FnMut(&[f32], &mut [f32]);

/// One finished episode.
#[derive(Debug, PartialEq)]
pub struct Episode {
    /// `info["is_success"]` at the last step.
    pub success: bool,
    /// Sum of rewards.
    pub ret: f64,
    /// Steps taken.
    pub steps: usize,
    /// Every observation, as raw bytes (reset first).
    pub obs: Vec<Vec<u8>>,
    /// The info of the last step.
    pub info: Info,
}

pub fn make(env_id: &str, config: &EnvConfig) -> TimeLimit<Box<dyn Env>> {
    let adapter = Rapier;
    let limit = adapter.spec(env_id, config).unwrap().max_episode_steps;
    TimeLimit::new(
        adapter.make(env_id, config).unwrap(),
        config.episode_limit(limit),
    )
}

pub fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// Runs one episode of `env` from `seed` with `policy`.
pub fn episode(
    env: &mut TimeLimit<Box<dyn Env>>,
    seed: u64,
    policy: Policy<'_>,
    keep_obs: bool,
) -> Episode {
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    let mut info = Info::default();
    env.reset(Some(seed), &ResetOptions::new(), &mut obs, &mut info)
        .unwrap();
    let n_act = env.action_space().num_elements();
    let mut action = vec![0f32; n_act];
    let mut action_bytes = vec![0u8; n_act * 4];
    let mut all = Vec::new();
    if keep_obs {
        all.push(obs.clone());
    }
    let mut ret = 0.0;
    let mut steps = 0;
    loop {
        policy(&floats(&obs), &mut action);
        for (b, a) in action_bytes.chunks_exact_mut(4).zip(&action) {
            b.copy_from_slice(&a.clamp(-1.0, 1.0).to_le_bytes());
        }
        let t = env.step(&action_bytes, &mut obs, &mut info).unwrap();
        ret += t.reward;
        steps += 1;
        if keep_obs {
            all.push(obs.clone());
        }
        if t.terminated || t.truncated {
            let success = matches!(info.get("is_success"), Some(InfoValue::Bool(true)));
            return Episode {
                success,
                ret,
                steps,
                obs: all,
                info,
            };
        }
    }
}

/// A uniform random policy from a small deterministic generator.
pub fn random_policy(seed: u64) -> impl FnMut(&[f32], &mut [f32]) {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    move |_obs, action| {
        for a in action.iter_mut() {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *a = ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0;
        }
    }
}

/// Success rate of `make_policy(seed)` over `seeds`.
pub fn success_rate(
    env_id: &str,
    config: &EnvConfig,
    seeds: std::ops::Range<u64>,
    mut make_policy: impl FnMut(u64) -> Controller,
) -> f64 {
    let mut env = make(env_id, config);
    let n = seeds.end - seeds.start;
    let wins = seeds
        .filter(|&seed| episode(&mut env, seed, &mut *make_policy(seed), false).success)
        .count();
    wins as f64 / n as f64
}
