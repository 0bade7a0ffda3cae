//! Python and NumPy scalar arithmetic where Rust's plain operators would round differently.

/// Python's `x ** 2` on a float64 (a Python float or a NumPy scalar): the C library's `pow`,
/// which is not always the correctly rounded `x * x` (glibc's differs in the last bit for about
/// one value in a thousand). Gymnasium's Acrobot integrates these squares, so over a few hundred
/// chaotic steps that bit matters.
///
/// The exponent goes through `black_box` because LLVM would otherwise rewrite `pow(x, 2.0)` as
/// `x * x`.
#[inline]
pub(crate) fn py_square(x: f64) -> f64 {
    x.powf(std::hint::black_box(2.0))
}

/// NumPy's `x ** 2` on a float32 scalar: the C library's `powf`, likewise not always the
/// correctly rounded `x * x` (Pendulum's torque cost).
#[inline]
pub(crate) fn py_square_f32(x: f32) -> f32 {
    x.powf(std::hint::black_box(2.0))
}

/// A Python float meeting a float32 NumPy scalar: NumPy (NEP 50) casts it to float32 first.
#[inline]
pub(crate) const fn as_f32(v: f64) -> f32 {
    v as f32
}
