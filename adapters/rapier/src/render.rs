//! `render_mode="rgb_array"`: a small software ray caster over the rapier world itself.
//!
//! Every pixel casts one ray against every collider with parry's exact ray tests (boxes,
//! balls, capsules, cylinders, heightfields), so
//! whatever collides is drawn exactly as it collides, and nothing beyond `rapier3d` is needed:
//! no GPU, no windowing, no C library. Shading is Lambert with one directional light plus
//! ambient; a collider's colour is its `user_data` (see `physics::color`), floors and terrain
//! get a checker pattern so motion over them is visible, lighter where they are higher.
//! Colliders in no collision group (arm links, targets) are drawn too: every collider is
//! tested.
//!
//! The cost is one ray per pixel and collider: 16–40 ms for the default 240 × 240 frame on a
//! 2-core VM (`examples/rapier_speed.rs` measures it).

use crate::physics::CHECKER;
use envhub_core::{EnvError, ExtraKeys};
use rapier3d::prelude::*;

/// The `extra` keys rendering takes.
pub(crate) const OPTIONS: &[&str] = &["width", "height"];

/// Default frame size in pixels.
const DEFAULT_SIZE: u64 = 240;

/// The only render mode.
pub(crate) const RGB_ARRAY: &str = "rgb_array";

/// Frame size, from the env's options.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RenderOptions {
    width: usize,
    height: usize,
}

impl RenderOptions {
    /// `Some` for `render_mode="rgb_array"`, `None` without a render mode, an error for any
    /// other mode or a frame size outside `1..=4096`.
    pub(crate) fn from_config(
        env_id: &str,
        render_mode: Option<&str>,
        keys: &ExtraKeys<'_>,
    ) -> Result<Option<Self>, EnvError> {
        let size = |key: &str| -> Result<usize, EnvError> {
            let v = keys.u64(key, DEFAULT_SIZE)?;
            if (1..=4096).contains(&v) {
                Ok(v as usize)
            } else {
                Err(keys.error(key, format!("expected 1 to 4096 pixels, got {v}")))
            }
        };
        let (width, height) = (size("width")?, size("height")?);
        match render_mode {
            None => Ok(None),
            Some(RGB_ARRAY) => Ok(Some(RenderOptions { width, height })),
            Some(mode) => Err(EnvError::RenderMode {
                env_id: env_id.to_string(),
                mode: mode.to_string(),
                supported: vec![RGB_ARRAY.to_string()],
            }),
        }
    }
}

/// A perspective camera.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Camera {
    /// Where it is.
    pub(crate) eye: Vector,
    /// The point it looks at (the centre of the frame).
    pub(crate) target: Vector,
    /// Vertical field of view, degrees.
    pub(crate) fov_deg: f32,
}

/// Draws frames of a given size.
pub(crate) struct Renderer {
    options: RenderOptions,
}

/// Light direction (towards the light).
const LIGHT: Vector = Vector::new(0.4, 0.8, 0.3);

impl Renderer {
    /// A renderer for frames of `options`' size.
    pub(crate) fn new(options: RenderOptions) -> Self {
        Renderer { options }
    }

    /// One `(height, width, rgb)` frame of `world` seen from `camera`.
    pub(crate) fn render(&self, world: &PhysicsWorld, camera: &Camera) -> (usize, usize, Vec<u8>) {
        let RenderOptions { width, height } = self.options;
        let mut pixels = vec![0u8; width * height * 3];
        let forward = (camera.target - camera.eye).normalize();
        let right = forward.cross(Vector::Y).normalize();
        let up = right.cross(forward);
        let half_h = (camera.fov_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height as f32;
        let light = LIGHT.normalize();
        // Every collider is tested directly (tasks have a dozen): no dependence on the broad
        // phase, which is only built by the first physics step.
        let colliders: Vec<&Collider> = world.colliders.iter().map(|(_, c)| c).collect();
        for row in 0..height {
            let v = (1.0 - 2.0 * (row as f32 + 0.5) / height as f32) * half_h;
            for col in 0..width {
                let u = (2.0 * (col as f32 + 0.5) / width as f32 - 1.0) * half_w;
                let dir = (forward + right * u + up * v).normalize();
                let ray = Ray::new(camera.eye, dir);
                let nearest = colliders
                    .iter()
                    .filter_map(|c| {
                        c.shape()
                            .cast_ray_and_get_normal(c.position(), &ray, 100.0, true)
                            .map(|hit| (c, hit))
                    })
                    .min_by(|a, b| a.1.time_of_impact.total_cmp(&b.1.time_of_impact));
                let rgb = match nearest {
                    Some((collider, hit)) => {
                        let data = collider.user_data;
                        let mut base = [
                            ((data >> 16) & 0xff) as f32,
                            ((data >> 8) & 0xff) as f32,
                            (data & 0xff) as f32,
                        ];
                        if data & CHECKER != 0 {
                            let p = ray.point_at(hit.time_of_impact);
                            let cell = (p.x * 2.0).floor() as i64 + (p.z * 2.0).floor() as i64;
                            if cell.rem_euclid(2) == 0 {
                                base = base.map(|c| c * 0.8);
                            }
                            // Terrain: higher is lighter, so relief reads from above.
                            let lift = (1.0 + 1.5 * p.y).clamp(0.5, 1.6);
                            base = base.map(|c| c * lift);
                        }
                        let n = hit.normal;
                        let shade = 0.35 + 0.65 * n.dot(light).max(0.0);
                        base.map(|c| (c * shade).min(255.0) as u8)
                    }
                    None => {
                        let t = 0.5 * (dir.y + 1.0);
                        [
                            (170.0 + 60.0 * t) as u8,
                            (190.0 + 50.0 * t) as u8,
                            (215.0 + 40.0 * t) as u8,
                        ]
                    }
                };
                let i = (row * width + col) * 3;
                pixels[i..i + 3].copy_from_slice(&rgb);
            }
        }
        (height, width, pixels)
    }
}
