//! `RoverTerrain-v0`: a differential-drive base (two driven wheels, two frictionless caster
//! balls) driving to a goal over rolling heightfield terrain that is new for every seed.
//!
//! - Action `Box(-1, 1, (2,))`: target speeds of the left and right wheels (velocity motors
//!   with a torque limit), `12 rad/s` (about 1.6 m/s) at 1.
//! - Observation (37): the goal in the base frame `(forward, up, right)` (3), the base's
//!   linear and angular velocity in the base frame (3 + 3), gravity's direction in the base
//!   frame (3), and a 5 × 5 patch of terrain heights relative to the base, 0.5 m apart,
//!   centred under it and turned with its heading (row by row from front to back, left to
//!   right).
//! - Reward: progress towards the goal (`progress_weight` × metres gained this step)
//!   − `ctrl_cost_weight` × `|a|²`; `+goal_reward` on reaching the goal, `−flip_penalty` on
//!   flipping over.
//! - Terminated at the goal (the base's centre within 0.5 m of it horizontally: success), when
//!   the base turns over (its up axis more than ~80° from vertical) or when it drives off the
//!   24 m square of terrain (penalised as a flip).

use super::terrain::Terrain;
use crate::physics::{self, color, groups};
use crate::render::Camera;
use crate::task::{StepResult, Task};
use envhub_core::{EnvConfig, EnvError, ExtraKeys, Info, InfoValue, NumpyRng};
use rapier3d::parry::utils::Array2;
use rapier3d::prelude::*;

/// The env id.
pub(crate) const ID: &str = "RoverTerrain-v0";
/// The options it takes besides rendering ones.
pub(crate) const OPTIONS: &[&str] = &[
    "terrain_roughness",
    "goal_distance_range",
    "progress_weight",
    "ctrl_cost_weight",
    "goal_reward",
    "flip_penalty",
];
/// 25 s of driving.
pub(crate) const MAX_EPISODE_STEPS: u32 = 500;

/// Horizontal distance (m) at which the goal counts as reached.
pub(crate) const GOAL_RADIUS: f32 = 0.5;

const PHYSICS_DT: f32 = 0.01;
const FRAME_SKIP: usize = 5;
const TERRAIN_SIZE: f32 = 24.0;
const MAX_WHEEL_SPEED: f32 = 12.0;
const WHEEL_TORQUE: f32 = 8.0;
const WHEEL_RADIUS: f32 = 0.13;
/// `up.y` below this is a flip (about 80° of tilt).
const FLIPPED_UP_Y: f32 = 0.17;
const PATCH: usize = 5;
const PATCH_SPACING: f32 = 0.5;

const BODY: Group = Group::GROUP_1;
const GROUND: Group = Group::GROUP_2;

/// Drive wheel positions in the chassis frame: left, right (forward +x, right +z).
const WHEELS: [[f32; 3]; 2] = [[0.0, -0.06, -0.33], [0.0, -0.06, 0.33]];
/// Frictionless caster balls under the chassis, front and back: (x, y, radius). They sit 2 cm
/// higher than the wheels, so on flat ground the wheels carry the weight and the base rocks
/// onto a caster only when it pitches.
const CASTERS: [[f32; 3]; 2] = [[0.28, -0.10, 0.07], [-0.28, -0.10, 0.07]];

/// The task.
pub(crate) struct Rover {
    roughness: f32,
    goal_range: (f64, f64),
    progress_weight: f64,
    ctrl_weight: f64,
    goal_reward: f64,
    flip_penalty: f64,
    world: PhysicsWorld,
    terrain: Option<Terrain>,
    chassis: RigidBodyHandle,
    wheels: Vec<ImpulseJointHandle>,
    goal: [f32; 2],
    distance: f32,
}

impl Rover {
    /// Reads the options.
    pub(crate) fn new(_config: &EnvConfig, keys: &ExtraKeys<'_>) -> Result<Self, EnvError> {
        let roughness = keys.f64("terrain_roughness", 1.0)?;
        if !(0.0..=3.0).contains(&roughness) {
            return Err(keys.error(
                "terrain_roughness",
                format!("expected 0 (flat) to 3, got {roughness}"),
            ));
        }
        let goal_range = keys.range("goal_distance_range", (4.0, 7.0))?;
        if !(1.0 <= goal_range.0 && goal_range.0 <= goal_range.1 && goal_range.1 <= 10.0) {
            return Err(keys.error(
                "goal_distance_range",
                format!("expected `[low, high]` with 1 <= low <= high <= 10 m, got {goal_range:?}"),
            ));
        }
        Ok(Rover {
            roughness: roughness as f32,
            goal_range,
            progress_weight: keys.f64("progress_weight", 1.0)?,
            ctrl_weight: keys.f64("ctrl_cost_weight", 0.01)?,
            goal_reward: keys.f64("goal_reward", 10.0)?,
            flip_penalty: keys.f64("flip_penalty", 10.0)?,
            world: physics::new_world(PHYSICS_DT),
            terrain: None,
            chassis: RigidBodyHandle::invalid(),
            wheels: Vec::new(),
            goal: [0.0; 2],
            distance: f32::INFINITY,
        })
    }

    fn horizontal_distance(&self) -> f32 {
        let p = self.world.bodies[self.chassis].translation();
        (self.goal[0] - p.x).hypot(self.goal[1] - p.z)
    }

    fn is_flipped(&self) -> bool {
        let up = *self.world.bodies[self.chassis].rotation() * Vector::Y;
        up.y < FLIPPED_UP_Y
    }

    /// Whether the base has driven off the edge of the terrain.
    fn off_terrain(&self) -> bool {
        let p = self.world.bodies[self.chassis].translation();
        let edge = TERRAIN_SIZE * 0.5 - 0.5;
        p.x.abs() > edge || p.z.abs() > edge
    }

    fn reached(&self) -> bool {
        self.terrain.is_some() && self.horizontal_distance() < GOAL_RADIUS
    }
}

impl Task for Rover {
    fn obs_dim(&self) -> usize {
        12 + PATCH * PATCH
    }

    fn act_dim(&self) -> usize {
        2
    }

    fn dt(&self) -> f64 {
        f64::from(PHYSICS_DT) * FRAME_SKIP as f64
    }

    fn reset(&mut self, rng: &mut NumpyRng) {
        let terrain = Terrain::random(rng, TERRAIN_SIZE, self.roughness);
        let heading = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI) as f32;
        let goal_angle = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
        let goal_distance = rng.uniform(self.goal_range.0, self.goal_range.1);
        let goal = [
            (goal_distance * goal_angle.cos()) as f32,
            (goal_distance * goal_angle.sin()) as f32,
        ];

        let mut world = physics::new_world(PHYSICS_DT);
        let n = Terrain::POINTS;
        // rapier's `Array2` is column-major: element (i, j) at `i + j * nrows`.
        let mut column_major = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                column_major[i + j * n] = terrain.heights[i * n + j];
            }
        }
        let ground = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            ColliderBuilder::heightfield_with_flags(
                Array2::new(n, n, column_major),
                Vector::new(TERRAIN_SIZE, 1.0, TERRAIN_SIZE),
                HeightFieldFlags::FIX_INTERNAL_EDGES,
            )
            .friction(1.0)
            .collision_groups(groups(GROUND, BODY))
            .user_data(color(120, 150, 100) | physics::CHECKER),
            Some(ground),
        );
        world.insert_collider(
            ColliderBuilder::cylinder(0.6, 0.08)
                .translation(Vector::new(
                    goal[0],
                    terrain.height(goal[0], goal[1]) + 0.6,
                    goal[1],
                ))
                .collision_groups(physics::no_collisions())
                .user_data(color(230, 60, 60)),
            Some(ground),
        );

        let spawn = Vector::new(0.0, terrain.height(0.0, 0.0) + 0.25, 0.0);
        let rotation = Rotation::from_rotation_y(heading);
        let chassis =
            world.insert_body(RigidBodyBuilder::dynamic().pose(Pose::from_parts(spawn, rotation)));
        world.insert_collider(
            ColliderBuilder::cuboid(0.35, 0.08, 0.22)
                .mass(6.0)
                .friction(0.5)
                .collision_groups(groups(BODY, GROUND))
                .user_data(color(60, 90, 200)),
            Some(chassis),
        );
        for [x, y, r] in CASTERS {
            world.insert_collider(
                ColliderBuilder::ball(r)
                    .translation(Vector::new(x, y, 0.0))
                    .mass(0.2)
                    .friction(0.0)
                    .friction_combine_rule(CoefficientCombineRule::Min)
                    .collision_groups(groups(BODY, GROUND))
                    .user_data(color(90, 90, 90)),
                Some(chassis),
            );
        }
        let mut wheels = Vec::with_capacity(2);
        for w in WHEELS {
            let local = Vector::new(w[0], w[1], w[2]);
            let wheel = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .pose(Pose::from_parts(spawn + rotation * local, rotation)),
            );
            world.insert_collider(
                ColliderBuilder::ball(WHEEL_RADIUS)
                    .mass(0.5)
                    .friction(1.5)
                    .collision_groups(groups(BODY, GROUND))
                    .user_data(color(40, 40, 40)),
                Some(wheel),
            );
            // About -z (the chassis' left), so a positive speed rolls the base forward.
            let joint = RevoluteJointBuilder::new(Vector::NEG_Z)
                .local_anchor1(local)
                .local_anchor2(Vector::ZERO)
                .contacts_enabled(false)
                .motor_velocity(0.0, 50.0)
                .motor_max_force(WHEEL_TORQUE);
            wheels.push(world.insert_impulse_joint(chassis, wheel, joint));
        }
        // Nothing pushes the bodies awake (the motors act through joints): wake them.
        world.wake_up_all(true);
        self.world = world;
        self.terrain = Some(terrain);
        self.chassis = chassis;
        self.wheels = wheels;
        self.goal = goal;
        self.distance = self.horizontal_distance();
    }

    fn step(&mut self, action: &[f32], info: &mut Info) -> StepResult {
        for (i, &handle) in self.wheels.iter().enumerate() {
            let speed = action[i] * MAX_WHEEL_SPEED;
            if let Some(joint) = self.world.impulse_joints.get_mut(handle, true) {
                joint.data.set_motor_velocity(JointAxis::AngX, speed, 50.0);
            }
        }
        for _ in 0..FRAME_SKIP {
            self.world.step();
        }
        let distance = self.horizontal_distance();
        let progress = f64::from(self.distance - distance);
        self.distance = distance;
        let ctrl: f64 = action.iter().map(|a| f64::from(a * a)).sum();
        let reached = self.reached();
        let flipped = self.is_flipped();
        let off_terrain = self.off_terrain();
        let mut reward = self.progress_weight * progress - self.ctrl_weight * ctrl;
        if reached {
            reward += self.goal_reward;
        } else if flipped || off_terrain {
            reward -= self.flip_penalty;
        }
        info.set_f64("reward_progress", self.progress_weight * progress);
        info.set_f64("reward_ctrl", -self.ctrl_weight * ctrl);
        info.set_f64("distance", f64::from(distance));
        info.insert("flipped", InfoValue::Bool(flipped));
        info.insert("off_terrain", InfoValue::Bool(off_terrain));
        StepResult {
            reward,
            terminated: reached || flipped || off_terrain,
        }
    }

    fn observe(&self, obs: &mut [f32]) {
        let body = &self.world.bodies[self.chassis];
        let pose = body.position();
        let p = body.translation();
        let terrain = self.terrain.as_ref().expect("reset before observe");
        let goal_world = Vector::new(
            self.goal[0],
            terrain.height(self.goal[0], self.goal[1]),
            self.goal[1],
        );
        let goal = pose.inverse_transform_point(goal_world);
        let v = pose.inverse_transform_vector(body.linvel());
        let w = pose.inverse_transform_vector(body.angvel());
        let g = pose.inverse_transform_vector(Vector::NEG_Y);
        obs[..12].copy_from_slice(&[
            goal.x, goal.y, goal.z, v.x, v.y, v.z, w.x, w.y, w.z, g.x, g.y, g.z,
        ]);
        // The heading (forward axis projected on the ground) orients the patch.
        let forward = pose.rotation * Vector::X;
        let f = Vector::new(forward.x, 0.0, forward.z).normalize_or(Vector::X);
        let right = Vector::new(-f.z, 0.0, f.x);
        let half = (PATCH as f32 - 1.0) * 0.5;
        for r in 0..PATCH {
            for c in 0..PATCH {
                let ahead = (half - r as f32) * PATCH_SPACING;
                let side = (c as f32 - half) * PATCH_SPACING;
                let q = p + f * ahead + right * side;
                obs[12 + r * PATCH + c] = terrain.height(q.x, q.z) - p.y;
            }
        }
    }

    fn is_success(&self) -> bool {
        self.reached()
    }

    fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    fn camera(&self) -> Camera {
        let p = self.world.bodies[self.chassis].translation();
        let target = Vector::new((p.x + self.goal[0]) * 0.5, p.y, (p.z + self.goal[1]) * 0.5);
        let span = ((p.x - self.goal[0]).hypot(p.z - self.goal[1])).max(2.0);
        Camera {
            eye: target + Vector::new(0.0, 1.1 * span + 2.0, 0.9 * span + 1.5),
            target,
            fov_deg: 50.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rover(seed: u64) -> Rover {
        let config = EnvConfig::default();
        let keys = config.extra_keys(ID, OPTIONS).unwrap();
        let mut rover = Rover::new(&config, &keys).unwrap();
        rover.reset(&mut NumpyRng::seeded(seed));
        rover
    }

    #[test]
    fn flipping_over_terminates_with_the_penalty() {
        let mut rover = rover(0);
        let mut info = Info::default();
        let upside_down = Rotation::from_rotation_x(std::f32::consts::PI);
        let p = rover.world.bodies[rover.chassis].translation() + Vector::new(0.0, 0.5, 0.0);
        for (_, body) in rover.world.bodies.iter_mut() {
            if body.is_dynamic() {
                let local = body.translation() - p;
                body.set_position(Pose::from_parts(p + upside_down * local, upside_down), true);
            }
        }
        let result = rover.step(&[0.0, 0.0], &mut info);
        assert!(result.terminated);
        assert!(result.reward < -5.0, "{}", result.reward);
        assert_eq!(info.get("flipped"), Some(&InfoValue::Bool(true)));
        assert!(!rover.is_success());
    }

    #[test]
    fn reaching_the_goal_terminates_with_the_bonus() {
        let mut rover = rover(1);
        let mut info = Info::default();
        // Put the goal under the base.
        let p = rover.world.bodies[rover.chassis].translation();
        rover.goal = [p.x + 0.1, p.z];
        let result = rover.step(&[0.0, 0.0], &mut info);
        assert!(result.terminated && rover.is_success());
        assert!(result.reward > 5.0, "{}", result.reward);
    }

    #[test]
    fn driving_off_the_terrain_terminates() {
        let mut rover = rover(2);
        let mut info = Info::default();
        let shift = Vector::new(TERRAIN_SIZE * 0.5, 0.0, 0.0);
        for (_, body) in rover.world.bodies.iter_mut() {
            if body.is_dynamic() {
                body.set_translation(body.translation() + shift, true);
            }
        }
        assert!(rover.step(&[0.0, 0.0], &mut info).terminated);
        assert_eq!(info.get("off_terrain"), Some(&InfoValue::Bool(true)));
    }

    #[test]
    fn terrain_changes_with_the_seed_and_the_patch_sees_it() {
        let (a, b) = (rover(0), rover(1));
        let (ta, tb) = (a.terrain.as_ref().unwrap(), b.terrain.as_ref().unwrap());
        assert_ne!(ta.heights, tb.heights);
        // Flat at the start, rough away from it.
        assert_eq!(ta.height(0.0, 0.0), 0.0);
        let spread = ta.heights.iter().fold(0.0f32, |m, h| m.max(h.abs()));
        assert!(spread > 0.05, "{spread}");
        let mut obs = vec![0.0; a.obs_dim()];
        a.observe(&mut obs);
        let g = &obs[9..12];
        assert!(
            (g[1] + 1.0).abs() < 1e-3,
            "gravity points down in the base frame: {g:?}"
        );
    }
}
