//! NumPy's `default_rng`: `SeedSequence` seeding a `PCG64`, so a seed gives Gymnasium's draws.
//!
//! Gymnasium seeds an env with `np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed)))`
//! and draws initial states with `Generator.uniform` and `Generator.standard_normal`.
//! Reproducing those pieces bit for bit (a few hundred lines and NumPy's ziggurat tables) makes
//! `reset(Some(seed))` of a native env return the very state Gymnasium returns for the same seed,
//! which no general-purpose generator would. Shared by every adapter that re-implements a
//! Gymnasium env (classic control, MuJoCo).

mod ziggurat;

use rand::TryRngCore;

/// NumPy's `np.random.Generator(np.random.PCG64(seed_sequence))`, reduced to what Gymnasium's
/// envs draw: uniform doubles and standard normals.
#[derive(Clone, Debug)]
pub struct NumpyRng {
    state: u128,
    inc: u128,
}

/// `PCG_DEFAULT_MULTIPLIER_128` of NumPy's `pcg64.h`.
const PCG_MULTIPLIER: u128 = 0x2360_ED05_1FC6_5DA4_4385_DF64_9FCC_F645;

impl NumpyRng {
    /// `default_rng(seed)` for a non-negative integer seed, as Gymnasium's `np_random(seed)`.
    pub fn seeded(seed: u64) -> Self {
        // `_int_to_uint32_array`: little-endian 32-bit words, at least one.
        let words: &[u32] = &[seed as u32, (seed >> 32) as u32];
        let used = if seed >> 32 == 0 { 1 } else { 2 };
        Self::from_entropy_words(&words[..used])
    }

    /// `default_rng(None)`: 128 bits from the operating system, as `SeedSequence()` draws.
    pub fn from_os_entropy() -> Self {
        let mut bytes = [0u8; 16];
        rand::rngs::OsRng
            .try_fill_bytes(&mut bytes)
            .expect("the operating system has no entropy source");
        let words: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        Self::from_entropy_words(&words)
    }

    fn from_entropy_words(entropy: &[u32]) -> Self {
        let words = seed_sequence_state(entropy);
        let word = |i: usize| (words[2 * i] as u64) | ((words[2 * i + 1] as u64) << 32);
        let init_state = ((word(0) as u128) << 64) | word(1) as u128;
        let init_seq = ((word(2) as u128) << 64) | word(3) as u128;
        // `pcg_setseq_128_srandom_r`.
        let mut rng = NumpyRng {
            state: 0,
            inc: (init_seq << 1) | 1,
        };
        rng.step();
        rng.state = rng.state.wrapping_add(init_state);
        rng.step();
        rng
    }

    fn step(&mut self) {
        self.state = self
            .state
            .wrapping_mul(PCG_MULTIPLIER)
            .wrapping_add(self.inc);
    }

    /// PCG XSL-RR 128/64: advance, then output from the new state.
    fn next_u64(&mut self) -> u64 {
        self.step();
        let rot = (self.state >> 122) as u32;
        (((self.state >> 64) as u64) ^ (self.state as u64)).rotate_right(rot)
    }

    /// `Generator.random()`: a double in `[0, 1)` with 53 random bits.
    pub fn random(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }

    /// `Generator.uniform(low, high)`: `low + (high - low) * random()`, in that order.
    pub fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.random()
    }

    /// `Generator.uniform(low, high, size=out.len())`: one draw per element, in order.
    pub fn uniform_fill(&mut self, low: f64, high: f64, out: &mut [f64]) {
        for x in out {
            *x = self.uniform(low, high);
        }
    }

    /// `Generator.standard_normal()`: NumPy's 256-layer ziggurat (`random_standard_normal`).
    pub fn standard_normal(&mut self) -> f64 {
        const R: f64 = 3.654_152_885_361_009;
        const INV_R: f64 = 0.273_661_237_329_758_3;
        loop {
            let r = self.next_u64();
            let idx = (r & 0xff) as usize;
            let r = r >> 8;
            let negative = r & 1 == 1;
            let rabs = (r >> 1) & 0x000f_ffff_ffff_ffff;
            let x = rabs as f64 * f64::from_bits(ziggurat::WI[idx]);
            let x = if negative { -x } else { x };
            if rabs < ziggurat::KI[idx] {
                return x; // 99.3% of draws
            }
            if idx == 0 {
                // The tail beyond R (NumPy draws `1 - U` to avoid `log(0)`).
                loop {
                    let xx = -INV_R * (-self.random()).ln_1p();
                    let yy = -(-self.random()).ln_1p();
                    if yy + yy > xx * xx {
                        return if (rabs >> 8) & 1 == 1 {
                            -(R + xx)
                        } else {
                            R + xx
                        };
                    }
                }
            }
            let (f_lo, f_hi) = (
                f64::from_bits(ziggurat::FI[idx]),
                f64::from_bits(ziggurat::FI[idx - 1]),
            );
            if (f_hi - f_lo) * self.random() + f_lo < (-0.5 * x * x).exp() {
                return x;
            }
        }
    }

    /// `Generator.standard_normal(size=out.len())`: one draw per element, in order.
    pub fn standard_normal_fill(&mut self, out: &mut [f64]) {
        for x in out {
            *x = self.standard_normal();
        }
    }

    /// Gymnasium's `Env.reset(seed=...)` seeding of the generator in `slot`: a seed replaces
    /// it, no seed keeps it, and the first reset without one seeds from the operating system.
    pub fn reseed(slot: &mut Option<NumpyRng>, seed: Option<u64>) -> &mut NumpyRng {
        if let Some(seed) = seed {
            *slot = Some(NumpyRng::seeded(seed));
        }
        slot.get_or_insert_with(NumpyRng::from_os_entropy)
    }
}

/// `SeedSequence(entropy).generate_state(4, np.uint64)` as eight 32-bit words (pool size 4,
/// no spawn key).
fn seed_sequence_state(entropy: &[u32]) -> [u32; 8] {
    const INIT_A: u32 = 0x43b0_d7e5;
    const MULT_A: u32 = 0x931e_8875;
    const INIT_B: u32 = 0x8b51_f9dd;
    const MULT_B: u32 = 0x58f3_8ded;
    const MIX_MULT_L: u32 = 0xca01_f9dd;
    const MIX_MULT_R: u32 = 0x4973_f715;
    const XSHIFT: u32 = 16;
    const POOL: usize = 4;

    let mut hash_const = INIT_A;
    let mut hashmix = |value: u32| {
        let mut value = value ^ hash_const;
        hash_const = hash_const.wrapping_mul(MULT_A);
        value = value.wrapping_mul(hash_const);
        value ^ (value >> XSHIFT)
    };
    let mix = |x: u32, y: u32| {
        let r = MIX_MULT_L
            .wrapping_mul(x)
            .wrapping_sub(MIX_MULT_R.wrapping_mul(y));
        r ^ (r >> XSHIFT)
    };

    let mut pool = [0u32; POOL];
    for (i, slot) in pool.iter_mut().enumerate() {
        *slot = hashmix(entropy.get(i).copied().unwrap_or(0));
    }
    for src in 0..POOL {
        for dst in 0..POOL {
            if src != dst {
                pool[dst] = mix(pool[dst], hashmix(pool[src]));
            }
        }
    }
    for &extra in entropy.iter().skip(POOL) {
        for slot in pool.iter_mut() {
            *slot = mix(*slot, hashmix(extra));
        }
    }

    let mut hash_const = INIT_B;
    let mut out = [0u32; 8];
    for (i, word) in out.iter_mut().enumerate() {
        let mut v = pool[i % POOL] ^ hash_const;
        hash_const = hash_const.wrapping_mul(MULT_B);
        v = v.wrapping_mul(hash_const);
        *word = v ^ (v >> XSHIFT);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    // Reference values from NumPy 2.4:
    // `np.random.SeedSequence(s).generate_state(4, np.uint64)` and
    // `np.random.Generator(np.random.PCG64(s)).random()`.
    #[test]
    fn seed_sequence_matches_numpy() {
        let state = |seed: u64| {
            let words = [seed as u32, (seed >> 32) as u32];
            let w = seed_sequence_state(if seed >> 32 == 0 {
                &words[..1]
            } else {
                &words[..]
            });
            (0..4)
                .map(|i| (w[2 * i] as u64) | ((w[2 * i + 1] as u64) << 32))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            state(0),
            [
                0xdb2cd7e7b0f478be,
                0xabf4641a2c71ba49,
                0x20c6ed6d9d7b8d41,
                0x2c4099de223c39d4
            ]
        );
        assert_eq!(
            state(4_294_967_301),
            [
                0xf9c15bd6e249d9ac,
                0xb2021b4036320ed7,
                0x9388b47fe6dcf739,
                0x5eeba8d9ad6439e1
            ]
        );
    }

    #[test]
    fn draws_match_numpy() {
        let cases: [(u64, [f64; 3], f64); 4] = [
            (
                0,
                [0.6369616873214543, 0.2697867137638703, 0.04097352393619469],
                -0.04834723644714709,
            ),
            (
                42,
                [0.7739560485559633, 0.4388784397520523, 0.8585979199113825],
                0.019736802905936393,
            ),
            (
                4_294_967_301,
                [0.7742041803738812, 0.47072268318809307, 0.6958803443421149],
                0.03165376458429718,
            ),
            (
                u64::MAX,
                [0.6800266789616931, 0.8453117585624743, 0.007403081599260064],
                0.039456812643914735,
            ),
        ];
        for (seed, randoms, uniform) in cases {
            let mut rng = NumpyRng::seeded(seed);
            for r in randoms {
                assert_eq!(rng.random(), r, "seed {seed}");
            }
            assert_eq!(rng.uniform(-0.05, 0.05), uniform, "seed {seed}");
        }
    }

    // `np.random.default_rng(s).standard_normal(6)`, and 100 000 draws that take the wedge
    // and tail paths too.
    #[test]
    fn standard_normal_matches_numpy() {
        let cases: [(u64, [f64; 6]); 2] = [
            (
                0,
                [
                    0.1257302210933933,
                    -0.1321048632913019,
                    0.6404226504432821,
                    0.10490011715303971,
                    -0.535669373161111,
                    0.36159505490948474,
                ],
            ),
            (
                42,
                [
                    0.30471707975443135,
                    -1.0399841062404955,
                    0.7504511958064572,
                    0.9405647163912139,
                    -1.9510351886538364,
                    -1.302179506862318,
                ],
            ),
        ];
        for (seed, want) in cases {
            let mut rng = NumpyRng::seeded(seed);
            let mut got = [0.0; 6];
            rng.standard_normal_fill(&mut got);
            assert_eq!(got, want, "seed {seed}");
        }
        let mut rng = NumpyRng::seeded(3);
        rng.random();
        assert_eq!(rng.standard_normal(), -2.5556650313141818);

        let mut rng = NumpyRng::seeded(123);
        let draws: Vec<f64> = (0..100_000).map(|_| rng.standard_normal()).collect();
        assert_eq!(draws[99_999], -0.5802057682474822);
        assert_eq!(
            draws.iter().fold(0.0f64, |m, x| m.max(x.abs())),
            4.4176134326121055
        );
    }

    #[test]
    fn os_entropy_differs() {
        let a = NumpyRng::from_os_entropy().random();
        let b = NumpyRng::from_os_entropy().random();
        assert_ne!(a, b);
    }
}
