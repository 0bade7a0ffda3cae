//! Seeded rolling terrain: a heightfield made of a few random plane waves, flattened around
//! the start, with a bilinear height lookup for observations.

use envhub_core::NumpyRng;

/// Grid points per side.
const POINTS: usize = 81;

/// A square heightfield centred on the origin.
pub(crate) struct Terrain {
    /// Side length (m).
    pub(crate) size: f32,
    /// Heights, row `i` along `z`, column `j` along `x` (rapier's layout), `POINTS²` values.
    pub(crate) heights: Vec<f32>,
}

impl Terrain {
    /// The number of grid points per side.
    pub(crate) const POINTS: usize = POINTS;

    /// Random terrain of side `size`: six waves of wavelengths 4–14 m whose summed amplitude
    /// is `roughness * 0.3` m, blended to flat within 1.5 m of the origin.
    pub(crate) fn random(rng: &mut NumpyRng, size: f32, roughness: f32) -> Terrain {
        let waves: Vec<[f32; 4]> = (0..6)
            .map(|_| {
                let wavelength = rng.uniform(4.0, 14.0) as f32;
                let heading = rng.uniform(0.0, std::f64::consts::TAU) as f32;
                let phase = rng.uniform(0.0, std::f64::consts::TAU) as f32;
                let amplitude = rng.uniform(0.5, 1.0) as f32;
                [
                    std::f32::consts::TAU / wavelength,
                    heading,
                    phase,
                    amplitude,
                ]
            })
            .collect();
        let total: f32 = waves.iter().map(|w| w[3]).sum();
        let scale = roughness * 0.3 / total;
        let mut heights = Vec::with_capacity(POINTS * POINTS);
        for i in 0..POINTS {
            for j in 0..POINTS {
                let (x, z) = (Self::coord(size, j), Self::coord(size, i));
                let h: f32 = waves
                    .iter()
                    .map(|&[k, heading, phase, a]| {
                        a * (k * (x * heading.cos() + z * heading.sin()) + phase).sin()
                    })
                    .sum();
                let r = (x * x + z * z).sqrt();
                let blend = ((r - 0.5) / 1.0).clamp(0.0, 1.0);
                heights.push(h * scale * blend * blend * (3.0 - 2.0 * blend));
            }
        }
        Terrain { size, heights }
    }

    fn coord(size: f32, index: usize) -> f32 {
        -size * 0.5 + size * index as f32 / (POINTS - 1) as f32
    }

    /// The height at `(x, z)`, bilinear between grid points, clamped to the edge.
    pub(crate) fn height(&self, x: f32, z: f32) -> f32 {
        let cell = self.size / (POINTS - 1) as f32;
        let fx = ((x + self.size * 0.5) / cell).clamp(0.0, (POINTS - 1) as f32 - 1e-3);
        let fz = ((z + self.size * 0.5) / cell).clamp(0.0, (POINTS - 1) as f32 - 1e-3);
        let (j, i) = (fx as usize, fz as usize);
        let (tx, tz) = (fx - j as f32, fz - i as f32);
        let h = |i: usize, j: usize| self.heights[i * POINTS + j];
        let top = h(i, j) * (1.0 - tx) + h(i, j + 1) * tx;
        let bottom = h(i + 1, j) * (1.0 - tx) + h(i + 1, j + 1) * tx;
        top * (1.0 - tz) + bottom * tz
    }
}
