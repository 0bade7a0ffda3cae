//! NumPy's `default_rng`: `SeedSequence` seeding a `PCG64`, so a seed gives Gymnasium's draws.
//!
//! Gymnasium seeds an env with `np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed)))`
//! and draws initial states with `Generator.uniform`. Reproducing those three pieces bit for bit
//! (about a hundred lines) makes `reset(Some(seed))` return the very state Gymnasium returns for
//! the same seed, which no general-purpose generator would.

use rand::TryRngCore;

/// NumPy's `np.random.Generator(np.random.PCG64(seed_sequence))`, reduced to what the
/// classic-control envs draw: uniform doubles.
#[derive(Clone, Debug)]
pub(crate) struct NumpyRng {
    state: u128,
    inc: u128,
}

/// `PCG_DEFAULT_MULTIPLIER_128` of NumPy's `pcg64.h`.
const PCG_MULTIPLIER: u128 = 0x2360_ED05_1FC6_5DA4_4385_DF64_9FCC_F645;

impl NumpyRng {
    /// `default_rng(seed)` for a non-negative integer seed, as Gymnasium's `np_random(seed)`.
    pub(crate) fn seeded(seed: u64) -> Self {
        // `_int_to_uint32_array`: little-endian 32-bit words, at least one.
        let words: &[u32] = &[seed as u32, (seed >> 32) as u32];
        let used = if seed >> 32 == 0 { 1 } else { 2 };
        Self::from_entropy_words(&words[..used])
    }

    /// `default_rng(None)`: 128 bits from the operating system, as `SeedSequence()` draws.
    pub(crate) fn from_os_entropy() -> Self {
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
    pub(crate) fn random(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }

    /// `Generator.uniform(low, high)`: `low + (high - low) * random()`, in that order.
    pub(crate) fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.random()
    }
}

/// Gymnasium's `Env.reset(seed=...)` seeding: a seed replaces the generator, no seed keeps it,
/// and the first reset without one seeds from the operating system.
pub(crate) fn reseed(rng: &mut Option<NumpyRng>, seed: Option<u64>) -> &mut NumpyRng {
    if let Some(seed) = seed {
        *rng = Some(NumpyRng::seeded(seed));
    }
    rng.get_or_insert_with(NumpyRng::from_os_entropy)
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

    #[test]
    fn os_entropy_differs() {
        let a = NumpyRng::from_os_entropy().random();
        let b = NumpyRng::from_os_entropy().random();
        assert_ne!(a, b);
    }
}
