//! A planar two-link arm on a fixed base, shared by the reaching and pushing tasks.
//!
//! The arm moves in the horizontal `x`–`z` plane at height `height`; both joints turn about
//! `-y`, so a positive angle turns the arm counter-clockwise seen from above in the `(x, z)`
//! plane. Torques are `action * max_torque` per joint. Links collide with nothing (only a
//! fingertip ball that the task may give a collision group), as in Reacher-v5.

use crate::physics::{self, Hinge, color};
use rapier3d::prelude::*;

/// The arm's dimensions and actuators.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ArmSpec {
    /// Upper and lower link lengths (m).
    pub(crate) lengths: [f32; 2],
    /// Link radius (m), for mass and drawing.
    pub(crate) radius: f32,
    /// Link masses (kg).
    pub(crate) masses: [f32; 2],
    /// Joint torque at action 1 (N m).
    pub(crate) max_torque: [f32; 2],
    /// Viscous joint damping (N m s / rad).
    pub(crate) damping: f32,
    /// Height of the arm plane (m).
    pub(crate) height: f32,
    /// Fingertip ball radius (m) and its collision groups.
    pub(crate) tip_radius: f32,
    /// Collision groups of the fingertip.
    pub(crate) tip_groups: InteractionGroups,
}

/// A built arm.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Arm {
    spec: ArmSpec,
    links: [RigidBodyHandle; 2],
    joints: [Hinge; 2],
}

const AXIS: Vector = Vector::NEG_Y;

fn planar(angle: f32, length: f32) -> (f32, f32) {
    (length * angle.cos(), length * angle.sin())
}

impl Arm {
    /// Builds the arm at joint angles `q` with joint velocities `qd`.
    pub(crate) fn build(world: &mut PhysicsWorld, spec: ArmSpec, q: [f32; 2], qd: [f32; 2]) -> Arm {
        let h = spec.height;
        let base =
            world.insert_body(RigidBodyBuilder::fixed().translation(Vector::new(0.0, h, 0.0)));
        world.insert_collider(
            ColliderBuilder::cylinder(h * 0.5 + 0.01, spec.radius * 1.6)
                .translation(Vector::new(0.0, -h * 0.5, 0.0))
                .collision_groups(physics::no_collisions())
                .user_data(color(60, 60, 70)),
            Some(base),
        );
        let mut links = [base; 2];
        let mut parent = base;
        let mut start = Vector::new(0.0, h, 0.0);
        let mut angle = 0.0;
        let mut joints = Vec::with_capacity(2);
        for i in 0..2 {
            angle += q[i];
            let (dx, dz) = planar(angle, spec.lengths[i]);
            let body = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .pose(Pose::from_parts(
                        start,
                        Rotation::from_axis_angle(AXIS, angle),
                    ))
                    .angvel(AXIS * (qd[..=i].iter().sum::<f32>())),
            );
            // In the link's own frame the link lies along +x from its joint.
            let l = spec.lengths[i];
            world.insert_collider(
                ColliderBuilder::capsule_x(l * 0.5, spec.radius)
                    .translation(Vector::new(l * 0.5, 0.0, 0.0))
                    .mass(spec.masses[i])
                    .collision_groups(physics::no_collisions())
                    .user_data(color(230, 150, 40)),
                Some(body),
            );
            if i == 1 {
                world.insert_collider(
                    ColliderBuilder::ball(spec.tip_radius)
                        .translation(Vector::new(l, 0.0, 0.0))
                        .mass(1e-3)
                        .friction(0.3)
                        .collision_groups(spec.tip_groups)
                        .user_data(color(200, 40, 40)),
                    Some(body),
                );
            }
            // Both frames share the rotation about the joint axis only, so the axis is `AXIS`
            // in each and the joint's zero is the straight arm.
            joints.push(physics::hinge(world, parent, body, start, AXIS, None));
            links[i] = body;
            parent = body;
            start += Vector::new(dx, 0.0, dz);
        }
        Arm {
            spec,
            links,
            joints: [joints[0], joints[1]],
        }
    }

    /// Joint angles.
    pub(crate) fn q(&self, world: &PhysicsWorld) -> [f32; 2] {
        self.joints.map(|j| j.angle(world))
    }

    /// Joint velocities.
    pub(crate) fn qd(&self, world: &PhysicsWorld) -> [f32; 2] {
        self.joints.map(|j| j.velocity(world))
    }

    /// The fingertip in the arm plane, `(x, z)`.
    pub(crate) fn tip(&self, world: &PhysicsWorld) -> [f32; 2] {
        let body = &world.bodies[self.links[1]];
        let p = body
            .position()
            .transform_point(Vector::new(self.spec.lengths[1], 0.0, 0.0));
        [p.x, p.z]
    }

    /// Applies the torques of `action` (and joint damping) for the coming physics steps.
    pub(crate) fn actuate(&self, world: &mut PhysicsWorld, action: &[f32]) {
        for (i, joint) in self.joints.iter().enumerate() {
            let damping = -self.spec.damping * joint.velocity(world);
            joint.apply_torque(world, action[i] * self.spec.max_torque[i] + damping);
        }
    }

    /// Drives the arm with `action` for `frames` physics steps — forces cleared before each,
    /// as rapier keeps them between steps — and returns the control cost `Σ a²`.
    pub(crate) fn drive(&self, world: &mut PhysicsWorld, action: &[f32], frames: usize) -> f64 {
        for _ in 0..frames {
            physics::clear_forces(world);
            self.actuate(world, action);
            world.step();
        }
        action.iter().map(|a| f64::from(a * a)).sum()
    }
}
