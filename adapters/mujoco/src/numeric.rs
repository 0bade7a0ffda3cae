//! NumPy's arithmetic where a plain Rust loop would round differently.
//!
//! `np.sum` adds with pairwise summation (eight interleaved accumulators per block of 128), and
//! `np.sum(np.square(action))` of a float32 action stays in float32; a float64 `+=` loop would
//! differ from Gymnasium's reward in the last bits. These reproduce NumPy 2's
//! `pairwise_sum` exactly (checked against `np.sum` on thousands of arrays).

use std::ops::Add;

/// NumPy's pairwise sum of the `n` values `get(at..at + n)`, in the precision of `T`.
fn pairwise_sum<T: Copy + Add<Output = T>>(
    zero: T,
    at: usize,
    n: usize,
    values: &dyn Fn(usize) -> T,
) -> T {
    const BLOCK: usize = 128;
    let get = |i: usize| values(at + i);
    if n < 8 {
        (0..n).fold(zero, |acc, i| acc + get(i))
    } else if n <= BLOCK {
        let mut r = [zero; 8];
        for (j, slot) in r.iter_mut().enumerate() {
            *slot = get(j);
        }
        let whole = n - n % 8;
        let mut i = 8;
        while i < whole {
            for (j, slot) in r.iter_mut().enumerate() {
                *slot = *slot + get(i + j);
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for k in whole..n {
            res = res + get(k);
        }
        res
    } else {
        let half = n / 2;
        let half = half - half % 8;
        pairwise_sum(zero, at, half, values) + pairwise_sum(zero, at + half, n - half, values)
    }
}

/// `np.sum(np.square(a))` of a float32 array: float32 squares, float32 pairwise sum.
pub(crate) fn sum_squares_f32(a: &[f32]) -> f32 {
    pairwise_sum(0.0f32, 0, a.len(), &|i| a[i] * a[i])
}

/// `np.sum(np.square(a))` of a float64 array.
pub(crate) fn sum_squares(a: &[f64]) -> f64 {
    pairwise_sum(0.0f64, 0, a.len(), &|i| a[i] * a[i])
}

/// `np.sum(np.square(np.clip(a, lo, hi)))`.
pub(crate) fn sum_squares_clipped(a: &[f64], lo: f64, hi: f64) -> f64 {
    pairwise_sum(0.0f64, 0, a.len(), &|i| {
        let x = a[i].clamp(lo, hi);
        x * x
    })
}

/// `np.sum(a)`.
pub(crate) fn sum(a: &[f64]) -> f64 {
    pairwise_sum(0.0f64, 0, a.len(), &|i| a[i])
}

/// `np.linalg.norm(v)` of a short float64 vector (fewer than 16 elements): `sqrt(v.dot(v))`,
/// where OpenBLAS's `ddot` (as NumPy's wheels ship it, on any x86-64 CPU with FMA) accumulates
/// a short vector with one fused multiply-add per element.
pub(crate) fn norm(v: &[f64]) -> f64 {
    debug_assert!(
        v.len() < 16,
        "OpenBLAS sums longer vectors in another order"
    );
    v.iter().fold(0.0, |acc, x| x.mul_add(*x, acc)).sqrt()
}

/// Python's `x ** 2` on a float64 (NumPy scalar): the C library's `pow`, which is not always
/// the correctly rounded `x * x`. `black_box` keeps LLVM from rewriting it as `x * x`.
pub(crate) fn py_square(x: f64) -> f64 {
    x.powf(std::hint::black_box(2.0))
}

/// NumPy's `np.clip(x, lo, hi)` of one element.
pub(crate) fn clip(x: f64, lo: f64, hi: f64) -> f64 {
    x.max(lo).min(hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairwise_order() {
        // With 9 values the ninth is added after the eight accumulators are combined.
        let a: Vec<f64> = (1..=9).map(|i| 1.0 / i as f64).collect();
        let r: Vec<f64> = a[..8].to_vec();
        let want = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7])) + a[8];
        assert_eq!(sum(&a), want);
        assert_eq!(sum_squares_f32(&[3.0, 4.0]), 25.0);
        let long: Vec<f64> = (0..300).map(|i| (i as f64).sin()).collect();
        assert!((sum(&long) - long.iter().sum::<f64>()).abs() < 1e-12);
    }
}
