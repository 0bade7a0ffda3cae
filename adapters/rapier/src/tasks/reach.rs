//! `ArmReach-v0`: a two-joint planar arm moving its fingertip to a random target, modelled on
//! Gymnasium's Reacher-v5 (same link lengths, target disc, episode length, `dt` and
//! observation layout; rapier dynamics, torque actuators of its own).
//!
//! - Action `Box(-1, 1, (2,))`: joint torques, `0.05` and `0.03 N m` at 1.
//! - Observation (10): `cos q` (2), `sin q` (2), target `(x, z)` (2), `q̇` (2),
//!   fingertip − target `(x, z)` (2).
//! - Reward: `-reward_dist_weight * |fingertip − target| - reward_control_weight * |a|²`.
//! - Never terminates (50-step episodes). Success: the fingertip within 2 cm of the target.

use super::arm::{Arm, ArmSpec};
use crate::physics::{self, color};
use crate::render::Camera;
use crate::task::{StepResult, Task};
use envhub_core::{EnvConfig, EnvError, ExtraKeys, Info, NumpyRng};
use rapier3d::prelude::*;

/// The env id.
pub(crate) const ID: &str = "ArmReach-v0";
/// The options it takes besides rendering ones.
pub(crate) const OPTIONS: &[&str] = &["reward_dist_weight", "reward_control_weight"];
/// Gymnasium's limit for Reacher-v5.
pub(crate) const MAX_EPISODE_STEPS: u32 = 50;

/// Fingertip distance (m) under which the target counts as reached.
pub(crate) const SUCCESS_DISTANCE: f32 = 0.02;

const PHYSICS_DT: f32 = 0.01;
const FRAME_SKIP: usize = 2;

const SPEC: ArmSpec = ArmSpec {
    lengths: [0.1, 0.11],
    radius: 0.01,
    masses: [0.05, 0.05],
    max_torque: [0.05, 0.03],
    damping: 0.004,
    height: 0.02,
    tip_radius: 0.012,
    tip_groups: InteractionGroups::new(Group::NONE, Group::NONE, InteractionTestMode::And),
};

/// The task.
pub(crate) struct Reach {
    dist_weight: f64,
    ctrl_weight: f64,
    world: PhysicsWorld,
    arm: Option<Arm>,
    target: [f32; 2],
}

impl Reach {
    /// Reads the options.
    pub(crate) fn new(_config: &EnvConfig, keys: &ExtraKeys<'_>) -> Result<Self, EnvError> {
        Ok(Reach {
            dist_weight: keys.f64("reward_dist_weight", 1.0)?,
            ctrl_weight: keys.f64("reward_control_weight", 0.1)?,
            world: physics::new_world(PHYSICS_DT),
            arm: None,
            target: [0.0; 2],
        })
    }

    fn distance(&self) -> f32 {
        let Some(arm) = &self.arm else {
            return f32::INFINITY;
        };
        let tip = arm.tip(&self.world);
        ((tip[0] - self.target[0]).powi(2) + (tip[1] - self.target[1]).powi(2)).sqrt()
    }
}

impl Task for Reach {
    fn obs_dim(&self) -> usize {
        10
    }

    fn act_dim(&self) -> usize {
        2
    }

    fn dt(&self) -> f64 {
        f64::from(PHYSICS_DT) * FRAME_SKIP as f64
    }

    fn reset(&mut self, rng: &mut NumpyRng) {
        // As Reacher-v5: joint angles and velocities uniform in ±0.1 and ±0.005, the target
        // uniform in the 0.2 m disc (rejection from the square).
        let q = [rng.uniform(-0.1, 0.1) as f32, rng.uniform(-0.1, 0.1) as f32];
        let target = loop {
            let t = [rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2)];
            if t[0].hypot(t[1]) < 0.2 {
                break t.map(|x| x as f32);
            }
        };
        let qd = [
            rng.uniform(-0.005, 0.005) as f32,
            rng.uniform(-0.005, 0.005) as f32,
        ];
        let mut world = physics::new_world(PHYSICS_DT);
        let floor = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            ColliderBuilder::cuboid(0.3, 0.005, 0.3)
                .translation(Vector::new(0.0, -0.005, 0.0))
                .user_data(color(200, 200, 190) | physics::CHECKER),
            Some(floor),
        );
        world.insert_collider(
            ColliderBuilder::ball(0.009)
                .translation(Vector::new(target[0], SPEC.height, target[1]))
                .collision_groups(physics::no_collisions())
                .user_data(color(40, 160, 60)),
            Some(floor),
        );
        self.arm = Some(Arm::build(&mut world, SPEC, q, qd));
        self.world = world;
        self.target = target;
    }

    fn step(&mut self, action: &[f32], info: &mut Info) -> StepResult {
        let arm = self.arm.expect("reset before step");
        let ctrl = arm.drive(&mut self.world, action, FRAME_SKIP);
        let dist = f64::from(self.distance());
        let reward_dist = -self.dist_weight * dist;
        let reward_ctrl = -self.ctrl_weight * ctrl;
        info.set_f64("reward_dist", reward_dist);
        info.set_f64("reward_ctrl", reward_ctrl);
        info.set_f64("distance", dist);
        StepResult {
            reward: reward_dist + reward_ctrl,
            terminated: false,
        }
    }

    fn observe(&self, obs: &mut [f32]) {
        let arm = self.arm.expect("reset before observe");
        let q = arm.q(&self.world);
        let qd = arm.qd(&self.world);
        let tip = arm.tip(&self.world);
        obs.copy_from_slice(&[
            q[0].cos(),
            q[1].cos(),
            q[0].sin(),
            q[1].sin(),
            self.target[0],
            self.target[1],
            qd[0],
            qd[1],
            tip[0] - self.target[0],
            tip[1] - self.target[1],
        ]);
    }

    fn is_success(&self) -> bool {
        self.distance() < SUCCESS_DISTANCE
    }

    fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    fn camera(&self) -> Camera {
        Camera {
            eye: Vector::new(0.0, 0.55, 0.25),
            target: Vector::new(0.0, 0.0, 0.0),
            fov_deg: 45.0,
        }
    }
}
