//! `ArmPush-v0`: a two-joint planar arm pushing a puck across a table to a goal, modelled on
//! Gymnasium's Pusher-v5 (episode length, `dt`, the three reward terms); the arm is planar
//! with two joints instead of Pusher's seven, and the object a puck that slides on the table
//! with friction and is moved only through contact with the fingertip ball.
//!
//! - Action `Box(-1, 1, (2,))`: joint torques (`4` and `3 N m` at 1).
//! - Observation (14): `cos q` (2), `sin q` (2), `q̇` (2), fingertip `(x, z)` (2),
//!   puck `(x, z)` (2), puck velocity `(x, z)` (2), goal `(x, z)` (2).
//! - Reward: `-reward_near_weight * |tip − puck| - reward_dist_weight * |puck − goal|
//!   - reward_control_weight * |a|²` (Pusher-v5's defaults 0.5, 1, 0.1).
//! - Never terminates (100-step episodes). Success: the puck's centre within 5 cm of the goal.

use super::arm::{Arm, ArmSpec};
use crate::physics::{self, color, groups};
use crate::render::Camera;
use crate::task::{StepResult, Task};
use envhub_core::{EnvConfig, EnvError, ExtraKeys, Info, NumpyRng};
use rapier3d::prelude::*;

/// The env id.
pub(crate) const ID: &str = "ArmPush-v0";
/// The options it takes besides rendering ones.
pub(crate) const OPTIONS: &[&str] = &[
    "reward_near_weight",
    "reward_dist_weight",
    "reward_control_weight",
];
/// Pusher-v5's limit.
pub(crate) const MAX_EPISODE_STEPS: u32 = 100;

/// Puck-to-goal distance (m) under which the task counts as solved.
pub(crate) const SUCCESS_DISTANCE: f32 = 0.05;

const PHYSICS_DT: f32 = 0.01;
const FRAME_SKIP: usize = 5;

/// The table, the puck and the fingertip: the only colliders that touch.
const TABLE: Group = Group::GROUP_1;
const PUCK: Group = Group::GROUP_2;
const TIP: Group = Group::GROUP_3;

const PUCK_RADIUS: f32 = 0.05;
const PUCK_HALF_HEIGHT: f32 = 0.03;

const SPEC: ArmSpec = ArmSpec {
    lengths: [0.4, 0.4],
    radius: 0.025,
    masses: [0.5, 0.5],
    max_torque: [4.0, 3.0],
    damping: 0.3,
    height: PUCK_HALF_HEIGHT,
    tip_radius: 0.03,
    tip_groups: InteractionGroups::new(TIP, PUCK, InteractionTestMode::And),
};

/// The task.
pub(crate) struct Push {
    near_weight: f64,
    dist_weight: f64,
    ctrl_weight: f64,
    world: PhysicsWorld,
    arm: Option<Arm>,
    puck: RigidBodyHandle,
    goal: [f32; 2],
}

/// A point at a radius in `[r0, r1]` and an angle in `[a0, a1]` (radians) around the base.
fn polar(rng: &mut NumpyRng, r: (f64, f64), a: (f64, f64)) -> [f32; 2] {
    let radius = rng.uniform(r.0, r.1);
    let angle = rng.uniform(a.0, a.1);
    [(radius * angle.cos()) as f32, (radius * angle.sin()) as f32]
}

impl Push {
    /// Reads the options.
    pub(crate) fn new(_config: &EnvConfig, keys: &ExtraKeys<'_>) -> Result<Self, EnvError> {
        Ok(Push {
            near_weight: keys.f64("reward_near_weight", 0.5)?,
            dist_weight: keys.f64("reward_dist_weight", 1.0)?,
            ctrl_weight: keys.f64("reward_control_weight", 0.1)?,
            world: physics::new_world(PHYSICS_DT),
            arm: None,
            puck: RigidBodyHandle::invalid(),
            goal: [0.0; 2],
        })
    }

    fn puck_xz(&self) -> [f32; 2] {
        let p = self.world.bodies[self.puck].translation();
        [p.x, p.z]
    }

    fn puck_to_goal(&self) -> f32 {
        let p = self.puck_xz();
        (p[0] - self.goal[0]).hypot(p[1] - self.goal[1])
    }
}

impl Task for Push {
    fn obs_dim(&self) -> usize {
        14
    }

    fn act_dim(&self) -> usize {
        2
    }

    fn dt(&self) -> f64 {
        f64::from(PHYSICS_DT) * FRAME_SKIP as f64
    }

    fn reset(&mut self, rng: &mut NumpyRng) {
        use std::f64::consts::FRAC_PI_2;
        // The arm starts folded near its home pose (q = (-pi/2, pi/2) puts the fingertip at
        // (0.4, -0.4) m); the puck in front of the base, the goal 0.2–0.35 m from the puck,
        // both in the arm's reach and away from the base.
        let q = [
            (-FRAC_PI_2 + rng.uniform(-0.1, 0.1)) as f32,
            (FRAC_PI_2 + rng.uniform(-0.1, 0.1)) as f32,
        ];
        let puck = polar(rng, (0.4, 0.6), (-0.6, 0.9));
        let goal = loop {
            let g = polar(rng, (0.3, 0.7), (-0.9, 1.2));
            let d = (g[0] - puck[0]).hypot(g[1] - puck[1]);
            if (0.2..=0.35).contains(&d) {
                break g;
            }
        };
        let mut world = physics::new_world(PHYSICS_DT);
        let table = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            ColliderBuilder::cuboid(1.0, 0.02, 1.0)
                .translation(Vector::new(0.2, -0.02, 0.0))
                .friction(0.5)
                .collision_groups(groups(TABLE, PUCK))
                .user_data(color(160, 120, 80) | physics::CHECKER),
            Some(table),
        );
        world.insert_collider(
            ColliderBuilder::cylinder(0.001, SUCCESS_DISTANCE)
                .translation(Vector::new(goal[0], 0.001, goal[1]))
                .collision_groups(physics::no_collisions())
                .user_data(color(60, 180, 80)),
            Some(table),
        );
        let puck_body = world.insert_body(
            RigidBodyBuilder::dynamic()
                .translation(Vector::new(puck[0], PUCK_HALF_HEIGHT, puck[1]))
                // The puck slides and spins but does not tip over.
                .enabled_rotations(false, true, false)
                .linear_damping(0.5)
                .angular_damping(1.0),
        );
        world.insert_collider(
            ColliderBuilder::cylinder(PUCK_HALF_HEIGHT, PUCK_RADIUS)
                .mass(0.3)
                .friction(0.5)
                .collision_groups(groups(PUCK, TABLE | TIP))
                .user_data(color(50, 90, 200)),
            Some(puck_body),
        );
        self.arm = Some(Arm::build(&mut world, SPEC, q, [0.0; 2]));
        self.world = world;
        self.puck = puck_body;
        self.goal = goal;
    }

    fn step(&mut self, action: &[f32], info: &mut Info) -> StepResult {
        let arm = self.arm.expect("reset before step");
        let ctrl = arm.drive(&mut self.world, action, FRAME_SKIP);
        let tip = arm.tip(&self.world);
        let puck = self.puck_xz();
        let near = f64::from((tip[0] - puck[0]).hypot(tip[1] - puck[1]));
        let dist = f64::from(self.puck_to_goal());
        let reward_near = -self.near_weight * near;
        let reward_dist = -self.dist_weight * dist;
        let reward_ctrl = -self.ctrl_weight * ctrl;
        info.set_f64("reward_near", reward_near);
        info.set_f64("reward_dist", reward_dist);
        info.set_f64("reward_ctrl", reward_ctrl);
        info.set_f64("distance", dist);
        StepResult {
            reward: reward_near + reward_dist + reward_ctrl,
            terminated: false,
        }
    }

    fn observe(&self, obs: &mut [f32]) {
        let arm = self.arm.expect("reset before observe");
        let q = arm.q(&self.world);
        let qd = arm.qd(&self.world);
        let tip = arm.tip(&self.world);
        let puck = self.puck_xz();
        let v = self.world.bodies[self.puck].linvel();
        obs.copy_from_slice(&[
            q[0].cos(),
            q[1].cos(),
            q[0].sin(),
            q[1].sin(),
            qd[0],
            qd[1],
            tip[0],
            tip[1],
            puck[0],
            puck[1],
            v.x,
            v.z,
            self.goal[0],
            self.goal[1],
        ]);
    }

    fn is_success(&self) -> bool {
        self.arm.is_some() && self.puck_to_goal() < SUCCESS_DISTANCE
    }

    fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    fn camera(&self) -> Camera {
        Camera {
            eye: Vector::new(0.35, 1.6, 0.9),
            target: Vector::new(0.35, 0.0, 0.1),
            fov_deg: 45.0,
        }
    }
}
