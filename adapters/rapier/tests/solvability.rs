//! Per task: a scripted controller that reads only the observation succeeds in at least 90 %
//! of seeded episodes, uniform random actions in at most 10 % (success as `docs/design/rapier.md`
//! defines it, reported by `info["is_success"]` at the episode's last step).

use crate::common::{Controller, random_policy, success_rate};
use envhub_core::EnvConfig;

const SEEDS: std::ops::Range<u64> = 0..30;

fn check(env_id: &str, scripted: fn() -> Controller) {
    check_with(env_id, &EnvConfig::default(), scripted);
}

fn check_with(env_id: &str, config: &EnvConfig, scripted: fn() -> Controller) {
    let good = success_rate(env_id, config, SEEDS, |_| scripted());
    let random = success_rate(env_id, config, SEEDS, |seed| Box::new(random_policy(seed)));
    eprintln!("{env_id}: scripted {good:.2}, random {random:.2}");
    assert!(
        good >= 0.9,
        "{env_id}: scripted controller succeeded in {good}"
    );
    assert!(
        random <= 0.1,
        "{env_id}: random actions succeeded in {random}"
    );
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
fn reach_pd() -> Controller {
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

/// Jacobian-transpose task-space PD: the torques (as actions) that pull a two-link arm's
/// fingertip at `tip` towards `want`.
fn tip_pd(
    q: [f32; 2],
    qd: [f32; 2],
    tip: [f32; 2],
    want: [f32; 2],
    lengths: [f32; 2],
    gains: (f32, f32, [f32; 2]),
) -> [f32; 2] {
    let (kp, kd, max_torque) = gains;
    let (s1, c1) = q[0].sin_cos();
    let (s12, c12) = (q[0] + q[1]).sin_cos();
    let j = [
        [-lengths[0] * s1 - lengths[1] * s12, -lengths[1] * s12],
        [lengths[0] * c1 + lengths[1] * c12, lengths[1] * c12],
    ];
    let v = [
        j[0][0] * qd[0] + j[0][1] * qd[1],
        j[1][0] * qd[0] + j[1][1] * qd[1],
    ];
    let f = [
        kp * (want[0] - tip[0]) - kd * v[0],
        kp * (want[1] - tip[1]) - kd * v[1],
    ];
    [
        (j[0][0] * f[0] + j[1][0] * f[1]) / max_torque[0],
        (j[0][1] * f[0] + j[1][1] * f[1]) / max_torque[1],
    ]
}

/// Push: bring the fingertip behind the puck (going around it), push it along the line to the
/// goal while correcting for drift, then hold back.
fn push_scripted() -> Controller {
    const R: f32 = 0.05 + 0.03;
    Box::new(|obs, action| {
        let q = [obs[2].atan2(obs[0]), obs[3].atan2(obs[1])];
        let qd = [obs[4], obs[5]];
        let tip = [obs[6], obs[7]];
        let puck = [obs[8], obs[9]];
        let goal = [obs[12], obs[13]];
        let d = [goal[0] - puck[0], goal[1] - puck[1]];
        let dist = d[0].hypot(d[1]);
        let u = [d[0] / dist.max(1e-6), d[1] / dist.max(1e-6)];
        let rel = [tip[0] - puck[0], tip[1] - puck[1]];
        let along = rel[0] * u[0] + rel[1] * u[1];
        let across = -rel[0] * u[1] + rel[1] * u[0];
        let behind = [puck[0] - u[0] * (R + 0.01), puck[1] - u[1] * (R + 0.01)];
        let want = if dist < 0.015 {
            // Done: back off along the line so as not to nudge it.
            [puck[0] - u[0] * (R + 0.06), puck[1] - u[1] * (R + 0.06)]
        } else if along < -R * 0.7 && across.abs() < 0.02 {
            // Aligned behind: push towards the goal, steering the contact point.
            let push = dist.min(0.12);
            let n = [-u[1], u[0]];
            [
                puck[0] + u[0] * (push - R) - n[0] * across,
                puck[1] + u[1] * (push - R) - n[1] * across,
            ]
        } else if along < -R * 0.7 {
            // Behind it but off the line: slide sideways onto the line.
            behind
        } else {
            // In front of or beside it: go round on the side it is on, to a point beside and
            // a little behind it.
            let side = if across >= 0.0 { 1.0 } else { -1.0 };
            let n = [-u[1], u[0]];
            [
                puck[0] + n[0] * side * (R + 0.05) - u[0] * (R + 0.03),
                puck[1] + n[1] * side * (R + 0.05) - u[1] * (R + 0.03),
            ]
        };
        let a = tip_pd(q, qd, tip, want, [0.4, 0.4], (40.0, 4.0, [4.0, 3.0]));
        action.copy_from_slice(&a);
    })
}

#[test]
fn arm_push() {
    check("ArmPush-v0", push_scripted);
}

/// Ant: a trot (diagonal legs in phase, 0.5 s period) tracked by joint PD, with the stride of
/// the left and right legs adjusted to hold the heading. Hips swing a foot forward while its
/// ankle lifts it, then sweep it back on the ground. The PD gains are low on purpose: the
/// controller acts every 0.05 s, and a higher derivative gain on the light shins is unstable
/// at that rate.
fn ant_trot() -> Controller {
    use std::f32::consts::{PI, TAU};
    // Per leg (FL, FR, BL, BR): the hip angle's sign for a forward swing, and the phase.
    const FORWARD: [f32; 4] = [1.0, -1.0, 1.0, -1.0];
    const PHASE: [f32; 4] = [0.0, PI, PI, 0.0];
    const PERIOD: f32 = 0.5;
    const HIP: f32 = 0.4;
    const LIFT: f32 = 0.35;
    const PRESS: f32 = -0.2;
    const KP: f32 = 16.0;
    const KD: f32 = 0.4;
    const KYAW: f32 = 1.0;
    const MAX_TORQUE: f32 = 20.0;
    let mut t = 0.0f32;
    Box::new(move |obs, action| {
        let (w, x, y, z) = (obs[1], obs[2], obs[3], obs[4]);
        let yaw = (-2.0 * (x * z - w * y)).atan2(1.0 - 2.0 * (y * y + z * z));
        for leg in 0..4 {
            let phi = TAU / PERIOD * t + PHASE[leg];
            let side = if leg % 2 == 0 { 1.0 } else { -1.0 };
            let stride = (HIP * (1.0 + side * KYAW * yaw)).clamp(0.0, 0.5);
            let hip_target = FORWARD[leg] * stride * -phi.cos();
            let ankle_target = if phi.sin() > 0.0 {
                LIFT * phi.sin()
            } else {
                PRESS
            };
            let (hip, ankle) = (obs[5 + 2 * leg], obs[6 + 2 * leg]);
            let (hip_v, ankle_v) = (obs[19 + 2 * leg], obs[20 + 2 * leg]);
            action[2 * leg] = (KP * (hip_target - hip) - KD * hip_v) / MAX_TORQUE;
            action[2 * leg + 1] = (KP * (ankle_target - ankle) - KD * ankle_v) / MAX_TORQUE;
        }
        t += 0.05;
    })
}

#[test]
fn ant_run() {
    // 300 steps (15 s) instead of the default 1000 keeps the test short; the trot covers the
    // 3 m in about 5 s.
    let config = EnvConfig {
        max_episode_steps: Some(300),
        ..EnvConfig::default()
    };
    check_with("AntRun-v0", &config, ant_trot);
}

/// Rover: steer towards the goal (heading error from the goal vector in the base frame),
/// slowing down for sharp turns and when close.
fn rover_steer() -> Controller {
    Box::new(|obs, action| {
        let (forward, right) = (obs[0], obs[2]);
        let heading_error = right.atan2(forward);
        let distance = forward.hypot(right);
        let speed = (heading_error.cos().max(0.0) * (distance / 1.5).min(1.0)).max(0.2);
        // Yaw rate (about +y, i.e. turning left) damps the turn.
        let turn = (0.8 * heading_error + 0.15 * obs[7]).clamp(-0.6, 0.6);
        action[0] = (speed + turn).clamp(-1.0, 1.0);
        action[1] = (speed - turn).clamp(-1.0, 1.0);
    })
}

#[test]
fn rover_terrain() {
    check("RoverTerrain-v0", rover_steer);
}
