//! Small helpers over rapier's `PhysicsWorld`: a world with the crate's conventions (y up,
//! fixed step), joint angles and velocities read from body poses, and torque actuation.
//!
//! Joints are rapier impulse joints. Torque control is applied as equal and opposite external
//! torques on the two bodies a joint connects (what a motor between them does), so an action
//! is a torque, as in MuJoCo's `<motor>` actuators, not a velocity or position target.

use rapier3d::prelude::*;

/// Solver iterations, rapier's default, stated here because it shapes every task: 8 made the
/// tasks 1.5× slower and changed none of the scripted controllers' success rates.
const SOLVER_ITERATIONS: usize = 4;

/// An empty world with gravity along `-y` and a physics step of `dt` seconds.
pub(crate) fn new_world(dt: f32) -> PhysicsWorld {
    let mut world = PhysicsWorld::new();
    world.integration_parameters.dt = dt;
    world.integration_parameters.num_solver_iterations = SOLVER_ITERATIONS;
    world
}

/// The collision groups of a collider that is drawn but never touches anything.
pub(crate) fn no_collisions() -> InteractionGroups {
    InteractionGroups::new(Group::NONE, Group::NONE, InteractionTestMode::And)
}

/// Collision groups: member of `member`, collides with `filter`.
pub(crate) fn groups(member: Group, filter: Group) -> InteractionGroups {
    InteractionGroups::new(member, filter, InteractionTestMode::And)
}

/// A revolute joint about `axis` (the same in both bodies' frames, which must have the same
/// orientation when the joint is built) through the world point `anchor`.
pub(crate) fn hinge(
    world: &mut PhysicsWorld,
    parent: RigidBodyHandle,
    child: RigidBodyHandle,
    anchor: Vector,
    axis: Vector,
    limits: Option<[f32; 2]>,
) -> Hinge {
    let p = *world.bodies[parent].position();
    let c = *world.bodies[child].position();
    let mut builder = RevoluteJointBuilder::new(axis)
        .local_anchor1(p.inverse_transform_point(anchor))
        .local_anchor2(c.inverse_transform_point(anchor))
        .contacts_enabled(false);
    if let Some(limits) = limits {
        builder = builder.limits(limits);
    }
    world.insert_impulse_joint(parent, child, builder);
    Hinge {
        parent,
        child,
        axis,
    }
}

/// A revolute joint between two bodies, described by what is needed to read and drive it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Hinge {
    /// The body the joint hangs from.
    pub(crate) parent: RigidBodyHandle,
    /// The body it moves.
    pub(crate) child: RigidBodyHandle,
    /// The axis in the parent's frame.
    pub(crate) axis: Vector,
}

impl Hinge {
    /// The joint angle: the twist of the child relative to the parent about the axis, in
    /// `(-pi, pi]`, zero in the pose the joint was built in.
    pub(crate) fn angle(&self, world: &PhysicsWorld) -> f32 {
        let p = world.bodies[self.parent].rotation();
        let c = world.bodies[self.child].rotation();
        let rel = p.inverse() * *c;
        let twist = Vector::new(rel.x, rel.y, rel.z).dot(self.axis);
        let a = 2.0 * twist.atan2(rel.w);
        wrap_angle(a)
    }

    /// The axis in world coordinates.
    pub(crate) fn world_axis(&self, world: &PhysicsWorld) -> Vector {
        *world.bodies[self.parent].rotation() * self.axis
    }

    /// The joint's angular velocity (child relative to parent, about the axis).
    pub(crate) fn velocity(&self, world: &PhysicsWorld) -> f32 {
        let axis = self.world_axis(world);
        let rel = world.bodies[self.child].angvel() - world.bodies[self.parent].angvel();
        rel.dot(axis)
    }

    /// Adds `torque` about the axis: on the child, and its reaction on the parent.
    pub(crate) fn apply_torque(&self, world: &mut PhysicsWorld, torque: f32) {
        let t = self.world_axis(world) * torque;
        world.bodies[self.child].add_torque(t, true);
        world.bodies[self.parent].add_torque(-t, true);
    }
}

/// Removes the external forces and torques of every body (rapier keeps them between steps).
pub(crate) fn clear_forces(world: &mut PhysicsWorld) {
    for (_, body) in world.bodies.iter_mut() {
        body.reset_forces(false);
        body.reset_torques(false);
    }
}

/// `a` wrapped into `(-pi, pi]`.
pub(crate) fn wrap_angle(a: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI { w + TAU } else { w }
}

/// A colour as stored in a collider's `user_data`, which the renderer reads.
pub(crate) fn color(r: u8, g: u8, b: u8) -> u128 {
    (u128::from(r) << 16) | (u128::from(g) << 8) | u128::from(b)
}

/// `user_data` flag: draw this collider with a checker pattern (floors, terrain).
pub(crate) const CHECKER: u128 = 1 << 24;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hinge_reads_the_angle_it_was_turned_by() {
        let mut world = new_world(0.01);
        let a = world.insert_body(RigidBodyBuilder::fixed());
        let b = world.insert_body(RigidBodyBuilder::dynamic());
        let hinge = hinge(&mut world, a, b, Vector::ZERO, Vector::Y, None);
        for angle in [-3.0f32, -1.0, 0.0, 0.5, 3.1] {
            world.bodies[b].set_rotation(Rotation::from_rotation_y(angle), false);
            assert!((hinge.angle(&world) - angle).abs() < 1e-5, "{angle}");
        }
        assert!((wrap_angle(3.0 * std::f32::consts::PI) - std::f32::consts::PI).abs() < 1e-5);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-6);
    }
}
