//! Per task: a scripted controller that reads only the observation succeeds in at least 90 %
//! of seeded episodes, uniform random actions in at most 10 % (success as `docs/rapier.md`
//! defines it, reported by `info["is_success"]` at the episode's last step).

use crate::common::{random_policy, success_rate};
use envhub_core::EnvConfig;

const SEEDS: std::ops::Range<u64> = 0..20;

fn check(env_id: &str, scripted: fn() -> Box<dyn FnMut(&[f32], &mut [f32])>) {
    let config = EnvConfig::default();
    let good = success_rate(env_id, &config, SEEDS, |_| scripted());
    let random = success_rate(env_id, &config, SEEDS, |seed| Box::new(random_policy(seed)));
    eprintln!("{env_id}: scripted {good:.2}, random {random:.2}");
    assert!(good >= 0.9, "{env_id}: scripted controller succeeded in {good}");
    assert!(random <= 0.1, "{env_id}: random actions succeeded in {random}");
}

/// Two-link inverse kinematics for the fingertip at `(x, z)`, on the elbow side of `q2`.
fn ik(l1: f32, l2: f32, x: f32, z: f32, elbow_sign: f32) -> [f32; 2] {
    let d2 = x * x + z * z;
    let c2 = ((d2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)).clamp(-1.0, 1.0);
    let q2 = elbow_sign * c2.acos();
    let q1 = z.atan2(x) - (l2 * q2.sin()).atan2(l1 + l2 * q2.cos());
    [q1, q2]
}

fn wrap(a: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    (a + PI).rem_euclid(TAU) - PI
}

/// Reach: inverse kinematics to the target, then joint-space PD.
fn reach_pd() -> Box<dyn FnMut(&[f32], &mut [f32])> {
    Box::new(|obs, action| {
        let q = [obs[2].atan2(obs[0]), obs[3].atan2(obs[1])];
        let qd = [obs[6], obs[7]];
        let sign = if q[1] >= 0.0 { 1.0 } else { -1.0 };
        let qt = ik(0.1, 0.11, obs[4], obs[5], sign);
        for i in 0..2 {
            action[i] = 4.0 * wrap(qt[i] - q[i]) - 0.3 * qd[i];
        }
    })
}

#[test]
fn arm_reach() {
    check("ArmReach-v0", reach_pd);
}
