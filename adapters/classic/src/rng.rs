//! NumPy's generator, as Gymnasium seeds it: moved to `envhub_core::NumpyRng`, which the MuJoCo
//! adapter shares; these names keep the env files unchanged.

pub(crate) use envhub_core::NumpyRng;

/// Gymnasium's `Env.reset(seed=...)` seeding (see [`NumpyRng::reseed`]).
pub(crate) fn reseed(rng: &mut Option<NumpyRng>, seed: Option<u64>) -> &mut NumpyRng {
    NumpyRng::reseed(rng, seed)
}
