//! `AntRun-v0`: a four-legged robot running forward (+x), modelled on Gymnasium's Ant-v5 and
//! built in code with the proportions of Gymnasium's `ant.xml` (torso sphere of radius 0.25,
//! four legs on the diagonals, each a hip about the vertical and an ankle that lifts the
//! shin, with `ant.xml`'s joint ranges: hips ±30°, ankles 30°–70° below the horizontal).
//! Masses and torque scales are rapier's own (`ant.xml`'s gear 150 assumes MuJoCo's joint
//! armature, which rapier has no equivalent of). It is not loaded through `rapier3d-mjcf`,
//! so the env needs neither the asset file nor Python.
//!
//! - Action `Box(-1, 1, (8,))`: torques of (hip, ankle) for the front-left, front-right,
//!   back-left and back-right legs, `20 N m` at 1.
//! - Observation (27, Ant-v5 without contact forces and without the torso's x, z):
//!   torso height, torso orientation quaternion `(w, x, y, z)`, the 8 joint angles, torso
//!   linear and angular velocity (world frame), the 8 joint velocities.
//! - Reward (Ant-v5's terms): `forward_reward_weight * vx + healthy_reward
//!   - ctrl_cost_weight * |a|²`.
//! - Terminated when the torso's height leaves `healthy_z_range` (`[0.2, 1.0]` m) or the
//!   torso turns upside down (unless `terminate_when_unhealthy` is false). Success: the torso
//!   at least 3 m ahead of where it started, still healthy.

use crate::physics::{self, Hinge, color, groups};
use crate::render::Camera;
use crate::task::{StepResult, Task};
use envhub_core::{EnvConfig, EnvError, ExtraKeys, Info, NumpyRng};
use rapier3d::prelude::*;

/// The env id.
pub(crate) const ID: &str = "AntRun-v0";
/// The options it takes besides rendering ones.
pub(crate) const OPTIONS: &[&str] = &[
    "forward_reward_weight",
    "ctrl_cost_weight",
    "healthy_reward",
    "terminate_when_unhealthy",
    "healthy_z_range",
];
/// Ant-v5's limit.
pub(crate) const MAX_EPISODE_STEPS: u32 = 1000;

/// Forward distance (m) that counts as success.
pub(crate) const SUCCESS_DISTANCE: f32 = 3.0;

const PHYSICS_DT: f32 = 0.01;
const FRAME_SKIP: usize = 5;
const MAX_TORQUE: f32 = 20.0;
const JOINT_DAMPING: f32 = 0.3;

const ROBOT: Group = Group::GROUP_1;
const GROUND: Group = Group::GROUP_2;

/// Thigh and shin lengths and the limb radius, as in `ant.xml`.
const HIP_OFFSET: f32 = 0.2 * std::f32::consts::SQRT_2;
const THIGH: f32 = 0.2 * std::f32::consts::SQRT_2;
const SHIN: f32 = 0.4 * std::f32::consts::SQRT_2;
const LIMB_RADIUS: f32 = 0.08;
/// The shin's rest angle below the horizontal, the middle of `ant.xml`'s 30°–70° range.
const SHIN_REST: f32 = 50.0 * std::f32::consts::PI / 180.0;
const ANKLE_RANGE: f32 = 20.0 * std::f32::consts::PI / 180.0;
const HIP_RANGE: f32 = 30.0 * std::f32::consts::PI / 180.0;

/// Leg directions: front-left, front-right, back-left, back-right (forward +x, left −z).
const LEGS: [[f32; 2]; 4] = [[1.0, -1.0], [1.0, 1.0], [-1.0, -1.0], [-1.0, 1.0]];

/// The task.
pub(crate) struct Ant {
    forward_weight: f64,
    ctrl_weight: f64,
    healthy_reward: f64,
    terminate_when_unhealthy: bool,
    healthy_z: (f64, f64),
    world: PhysicsWorld,
    torso: RigidBodyHandle,
    joints: Vec<Hinge>,
    start_x: f32,
}

impl Ant {
    /// Reads the options.
    pub(crate) fn new(_config: &EnvConfig, keys: &ExtraKeys<'_>) -> Result<Self, EnvError> {
        Ok(Ant {
            forward_weight: keys.f64("forward_reward_weight", 1.0)?,
            ctrl_weight: keys.f64("ctrl_cost_weight", 0.5)?,
            healthy_reward: keys.f64("healthy_reward", 1.0)?,
            terminate_when_unhealthy: keys.bool("terminate_when_unhealthy", true)?,
            healthy_z: keys.range("healthy_z_range", (0.2, 1.0))?,
            world: physics::new_world(PHYSICS_DT),
            torso: RigidBodyHandle::invalid(),
            joints: Vec::new(),
            start_x: 0.0,
        })
    }

    fn is_healthy(&self) -> bool {
        let torso = &self.world.bodies[self.torso];
        let y = f64::from(torso.translation().y);
        let up = *torso.rotation() * Vector::Y;
        self.healthy_z.0 <= y && y <= self.healthy_z.1 && up.y > 0.0
    }

    fn progress(&self) -> f32 {
        self.world.bodies[self.torso].translation().x - self.start_x
    }
}

impl Task for Ant {
    fn obs_dim(&self) -> usize {
        27
    }

    fn act_dim(&self) -> usize {
        8
    }

    fn dt(&self) -> f64 {
        f64::from(PHYSICS_DT) * FRAME_SKIP as f64
    }

    fn reset(&mut self, rng: &mut NumpyRng) {
        let mut world = physics::new_world(PHYSICS_DT);
        let ground = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            ColliderBuilder::cuboid(60.0, 0.1, 60.0)
                .translation(Vector::new(0.0, -0.1, 0.0))
                .friction(1.0)
                .collision_groups(groups(GROUND, ROBOT))
                .user_data(color(150, 170, 150) | physics::CHECKER),
            Some(ground),
        );
        let robot = groups(ROBOT, GROUND);
        let height = SHIN * SHIN_REST.sin() + LIMB_RADIUS + 0.02;
        let center = Vector::new(0.0, height, 0.0);
        // Ant-v5 adds uniform noise of ±0.1 to the joint positions and N(0, 0.1) to the
        // velocities; here the torso's starting velocities carry the noise.
        let mut noise = [0.0; 6];
        rng.standard_normal_fill(&mut noise);
        let noise = noise.map(|x| (0.1 * x) as f32);
        let torso = world.insert_body(
            RigidBodyBuilder::dynamic()
                .translation(center)
                .linvel(Vector::new(noise[0], noise[1], noise[2]))
                .angvel(Vector::new(noise[3], noise[4], noise[5])),
        );
        world.insert_collider(
            ColliderBuilder::ball(0.25)
                .mass(2.5)
                .collision_groups(robot)
                .user_data(color(200, 160, 60)),
            Some(torso),
        );
        let mut joints = Vec::with_capacity(8);
        for leg in LEGS {
            let d = Vector::new(leg[0], 0.0, leg[1]).normalize();
            world.insert_collider(
                ColliderBuilder::capsule_from_endpoints(Vector::ZERO, d * HIP_OFFSET, LIMB_RADIUS)
                    .mass(0.1)
                    .collision_groups(robot)
                    .user_data(color(200, 160, 60)),
                Some(torso),
            );
            let hip = center + d * HIP_OFFSET;
            let thigh = world.insert_body(RigidBodyBuilder::dynamic().translation(hip));
            world.insert_collider(
                ColliderBuilder::capsule_from_endpoints(Vector::ZERO, d * THIGH, LIMB_RADIUS)
                    .mass(0.3)
                    .collision_groups(robot)
                    .user_data(color(210, 130, 50)),
                Some(thigh),
            );
            joints.push(physics::hinge(
                &mut world,
                torso,
                thigh,
                hip,
                Vector::Y,
                Some([-HIP_RANGE, HIP_RANGE]),
            ));
            let knee = hip + d * THIGH;
            let shin = world.insert_body(RigidBodyBuilder::dynamic().translation(knee));
            let foot = (d * SHIN_REST.cos() - Vector::Y * SHIN_REST.sin()) * SHIN;
            world.insert_collider(
                ColliderBuilder::capsule_from_endpoints(Vector::ZERO, foot, LIMB_RADIUS)
                    .mass(0.4)
                    .friction(1.0)
                    .collision_groups(robot)
                    .user_data(color(220, 100, 40)),
                Some(shin),
            );
            // About d × y, a positive angle lifts the shin.
            joints.push(physics::hinge(
                &mut world,
                thigh,
                shin,
                knee,
                d.cross(Vector::Y),
                Some([-ANKLE_RANGE, ANKLE_RANGE]),
            ));
        }
        self.start_x = world.bodies[torso].translation().x;
        self.world = world;
        self.torso = torso;
        self.joints = joints;
    }

    fn step(&mut self, action: &[f32], info: &mut Info) -> StepResult {
        let x0 = self.world.bodies[self.torso].translation().x;
        for _ in 0..FRAME_SKIP {
            physics::clear_forces(&mut self.world);
            for (joint, a) in self.joints.iter().zip(action) {
                let damping = -JOINT_DAMPING * joint.velocity(&self.world);
                joint.apply_torque(&mut self.world, a * MAX_TORQUE + damping);
            }
            self.world.step();
        }
        let x1 = self.world.bodies[self.torso].translation().x;
        let vx = f64::from(x1 - x0) / self.dt();
        let healthy = self.is_healthy();
        let forward = self.forward_weight * vx;
        let healthy_reward = if healthy || !self.terminate_when_unhealthy {
            self.healthy_reward
        } else {
            0.0
        };
        let ctrl: f64 = action.iter().map(|a| f64::from(a * a)).sum();
        let ctrl_cost = self.ctrl_weight * ctrl;
        info.set_f64("reward_forward", forward);
        info.set_f64("reward_ctrl", -ctrl_cost);
        info.set_f64("reward_survive", healthy_reward);
        info.set_f64("x_position", f64::from(x1));
        info.set_f64("x_velocity", vx);
        info.set_f64("distance_from_origin", f64::from(self.progress()));
        StepResult {
            reward: forward + healthy_reward - ctrl_cost,
            terminated: self.terminate_when_unhealthy && !healthy,
        }
    }

    fn observe(&self, obs: &mut [f32]) {
        let torso = &self.world.bodies[self.torso];
        let r = torso.rotation();
        let v = torso.linvel();
        let w = torso.angvel();
        obs[0] = torso.translation().y;
        obs[1..5].copy_from_slice(&[r.w, r.x, r.y, r.z]);
        for (i, joint) in self.joints.iter().enumerate() {
            obs[5 + i] = joint.angle(&self.world);
            obs[19 + i] = joint.velocity(&self.world);
        }
        obs[13..16].copy_from_slice(&[v.x, v.y, v.z]);
        obs[16..19].copy_from_slice(&[w.x, w.y, w.z]);
    }

    fn is_success(&self) -> bool {
        !self.joints.is_empty() && self.is_healthy() && self.progress() >= SUCCESS_DISTANCE
    }

    fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    fn camera(&self) -> Camera {
        let p = self.world.bodies[self.torso].translation();
        let target = Vector::new(p.x, 0.3, p.z);
        Camera {
            eye: target + Vector::new(-1.5, 1.6, 2.6),
            target,
            fov_deg: 45.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaving_the_healthy_range_terminates() {
        let config = EnvConfig::default();
        let keys = config.extra_keys(ID, OPTIONS).unwrap();
        let mut ant = Ant::new(&config, &keys).unwrap();
        ant.reset(&mut NumpyRng::seeded(0));
        let mut info = Info::default();
        let result = ant.step(&[0.0; 8], &mut info);
        assert!(!result.terminated, "a fresh ant is healthy");
        // Lift the whole ant 2 m: above `healthy_z_range`.
        for (_, body) in ant.world.bodies.iter_mut() {
            if body.is_dynamic() {
                let p = body.translation() + Vector::new(0.0, 2.0, 0.0);
                body.set_translation(p, true);
            }
        }
        let result = ant.step(&[0.0; 8], &mut info);
        assert!(result.terminated);
        assert_eq!(
            info.get("reward_survive"),
            Some(&envhub_core::InfoValue::Float(0.0))
        );
    }
}
