//! Spaces as in `gymnasium.spaces`, plus the flat byte layout that moves through shared memory.
//!
//! Every space has a fixed byte length. A leaf is stored as a dense little-endian array of its
//! dtype; a `Dict` or `Tuple` is its children one after another, each starting on an 8-byte
//! boundary so that every leaf can be viewed in place as a typed array.

use rand::Rng;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Element type of a space, named as numpy names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DType {
    /// `float32`
    Float32,
    /// `float64`
    Float64,
    /// `int8`
    Int8,
    /// `int32`
    Int32,
    /// `int64`
    Int64,
    /// `uint8`
    Uint8,
    /// `bool` (one byte, 0 or 1)
    Bool,
}

impl DType {
    /// Size of one element in bytes.
    pub fn size(self) -> usize {
        match self {
            DType::Float64 | DType::Int64 => 8,
            DType::Float32 | DType::Int32 => 4,
            DType::Int8 | DType::Uint8 | DType::Bool => 1,
        }
    }

    /// The numpy name (`float32`, `int64`, ...).
    pub fn name(self) -> &'static str {
        match self {
            DType::Float32 => "float32",
            DType::Float64 => "float64",
            DType::Int8 => "int8",
            DType::Int32 => "int32",
            DType::Int64 => "int64",
            DType::Uint8 => "uint8",
            DType::Bool => "bool",
        }
    }

    fn is_float(self) -> bool {
        matches!(self, DType::Float32 | DType::Float64)
    }

    /// Reads element `i` of a dense array of this dtype as `f64`.
    fn read(self, bytes: &[u8], i: usize) -> f64 {
        let at = i * self.size();
        let b = &bytes[at..at + self.size()];
        match self {
            DType::Float32 => f32::from_le_bytes(b.try_into().unwrap()) as f64,
            DType::Float64 => f64::from_le_bytes(b.try_into().unwrap()),
            DType::Int8 => i8::from_le_bytes([b[0]]) as f64,
            DType::Int32 => i32::from_le_bytes(b.try_into().unwrap()) as f64,
            DType::Int64 => i64::from_le_bytes(b.try_into().unwrap()) as f64,
            DType::Uint8 | DType::Bool => b[0] as f64,
        }
    }

    /// Writes `v` (already in range for the dtype) as element `i`.
    fn write(self, bytes: &mut [u8], i: usize, v: f64) {
        let at = i * self.size();
        let b = &mut bytes[at..at + self.size()];
        match self {
            DType::Float32 => b.copy_from_slice(&(v as f32).to_le_bytes()),
            DType::Float64 => b.copy_from_slice(&v.to_le_bytes()),
            DType::Int8 => b.copy_from_slice(&(v as i8).to_le_bytes()),
            DType::Int32 => b.copy_from_slice(&(v as i32).to_le_bytes()),
            DType::Int64 => b.copy_from_slice(&(v as i64).to_le_bytes()),
            DType::Uint8 | DType::Bool => b[0] = v as u8,
        }
    }
}

impl fmt::Display for DType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A Gymnasium space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Space {
    /// A box in R^n: one `low`/`high` bound per element (row-major), infinite bounds allowed.
    Box {
        /// Element type.
        dtype: DType,
        /// Array shape.
        shape: Vec<usize>,
        /// Lower bound of every element.
        #[serde(with = "bounds")]
        low: Vec<f64>,
        /// Upper bound of every element.
        #[serde(with = "bounds")]
        high: Vec<f64>,
    },
    /// `{start, ..., start + n - 1}`, stored as one `int64`.
    Discrete {
        /// Number of values.
        n: i64,
        /// Smallest value.
        start: i64,
    },
    /// A vector of discrete values, stored as `int64`.
    MultiDiscrete {
        /// Number of values of each element, in row-major order.
        nvec: Vec<i64>,
        /// Smallest value of each element.
        start: Vec<i64>,
        /// The array shape of `nvec` when it is not 1-D (Gymnasium's `MultiDiscrete([[2, 3],
        /// [4, 5]])`); `None`: `[nvec.len()]`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        shape: Option<Vec<usize>>,
    },
    /// Binary array, stored as `int8` as Gymnasium does.
    MultiBinary {
        /// Array shape.
        shape: Vec<usize>,
    },
    /// Named sub-spaces in a fixed order.
    Dict {
        /// Keys and spaces, in layout order.
        spaces: Vec<(String, Space)>,
    },
    /// Ordered sub-spaces.
    Tuple {
        /// Spaces, in layout order.
        spaces: Vec<Space>,
    },
}

/// How far a check holds values to a space's bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BoundsCheck {
    /// Every element lies within its bounds, as `gymnasium.Space.contains` requires.
    #[default]
    Strict,
    /// Elements of a float `Box` need only be finite: a value beyond the bounds passes, as
    /// Gymnasium passes it to the env, which clips it as it was written to (Pendulum clips the
    /// torque, MuJoCo clamps `ctrl` to `ctrlrange`). NaN and infinities are still errors, and
    /// so are integer values out of range (`Discrete`, `MultiDiscrete`, `MultiBinary`, an
    /// integer `Box`): Gymnasium's envs fail on those too.
    FiniteFloats,
}

/// Why a value does not belong to a space.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SpaceError {
    /// The value has the wrong number of bytes for the space.
    #[error("expected {expected} bytes for {space}, got {got}")]
    Length {
        /// The space, described.
        space: String,
        /// Bytes expected.
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// An element is outside the space.
    #[error("element {index}{path} = {value} is outside {space} (valid range [{low}, {high}])")]
    OutOfRange {
        /// Flat index of the element in its leaf.
        index: usize,
        /// Where the leaf sits in a `Dict`/`Tuple` (`["key"]`, `[0]`), empty for a leaf.
        path: String,
        /// The value found.
        value: f64,
        /// The space, described.
        space: String,
        /// Smallest valid value of the element.
        low: f64,
        /// Largest valid value of the element.
        high: f64,
    },
    /// A float element is NaN or infinite (whatever the bounds, and whatever the
    /// [`BoundsCheck`]).
    #[error("element {index}{path} is {value}, which no policy should send")]
    NotFinite {
        /// Flat index of the element in its leaf.
        index: usize,
        /// Where the leaf sits in a `Dict`/`Tuple`.
        path: String,
        /// The value found.
        value: f64,
    },
    /// The space itself is malformed (sent by another process: a worker, a hub): a size
    /// that overflows or exceeds the limit, bounds that do not match the shape, too deep.
    #[error("malformed space: {0}")]
    Malformed(String),
}

/// Most bytes one value of a space may take (1 GiB: far above any simulator's observation,
/// far below what overflows a batch's size arithmetic).
pub const MAX_VALUE_BYTES: usize = 1 << 30;

/// Deepest nesting of `Dict`/`Tuple` a space may have.
pub const MAX_DEPTH: usize = 32;

const ALIGN: usize = 8;

/// Most dimensions of a multi-discrete space's shape.
const MAX_DIMS: usize = 32;

fn align_up(n: usize) -> usize {
    n.div_ceil(ALIGN) * ALIGN
}

impl Space {
    /// A `float32` box with the same bound for every element.
    pub fn box_f32(shape: &[usize], low: f64, high: f64) -> Space {
        let n = shape.iter().product();
        Space::Box {
            dtype: DType::Float32,
            shape: shape.to_vec(),
            low: vec![low; n],
            high: vec![high; n],
        }
    }

    /// A `float32` box with per-element bounds.
    pub fn box_f32_bounds(low: Vec<f64>, high: Vec<f64>) -> Space {
        assert_eq!(low.len(), high.len(), "low and high differ in length");
        Space::Box {
            dtype: DType::Float32,
            shape: vec![low.len()],
            low,
            high,
        }
    }

    /// `Discrete(n)` starting at 0.
    pub fn discrete(n: i64) -> Space {
        Space::Discrete { n, start: 0 }
    }

    /// Number of scalar elements in a leaf space (sum over children for `Dict`/`Tuple`).
    pub fn num_elements(&self) -> usize {
        match self {
            Space::Box { shape, .. } | Space::MultiBinary { shape } => shape.iter().product(),
            Space::Discrete { .. } => 1,
            Space::MultiDiscrete { nvec, .. } => nvec.len(),
            Space::Dict { spaces } => spaces.iter().map(|(_, s)| s.num_elements()).sum(),
            Space::Tuple { spaces } => spaces.iter().map(Space::num_elements).sum(),
        }
    }

    /// The dtype of a leaf space; `None` for `Dict`/`Tuple`.
    pub fn dtype(&self) -> Option<DType> {
        match self {
            Space::Box { dtype, .. } => Some(*dtype),
            Space::Discrete { .. } | Space::MultiDiscrete { .. } => Some(DType::Int64),
            Space::MultiBinary { .. } => Some(DType::Int8),
            Space::Dict { .. } | Space::Tuple { .. } => None,
        }
    }

    /// The array shape of a leaf space (`[]` for `Discrete`); `None` for `Dict`/`Tuple`.
    pub fn shape(&self) -> Option<Vec<usize>> {
        match self {
            Space::Box { shape, .. } | Space::MultiBinary { shape } => Some(shape.clone()),
            Space::Discrete { .. } => Some(vec![]),
            Space::MultiDiscrete { nvec, shape, .. } => {
                Some(shape.clone().unwrap_or_else(|| vec![nvec.len()]))
            }
            Space::Dict { .. } | Space::Tuple { .. } => None,
        }
    }

    /// Checks a space that another process sent before any size of it is used: every size
    /// computed with checked arithmetic and at most [`MAX_VALUE_BYTES`], bounds as long as
    /// the shape, `start` as long as `nvec`, positive counts, at most [`MAX_DEPTH`] levels.
    /// Returns [`byte_len`](Self::byte_len), which is then safe to compute.
    pub fn check(&self) -> Result<usize, SpaceError> {
        self.check_at(0)
    }

    fn check_at(&self, depth: usize) -> Result<usize, SpaceError> {
        let bad = |m: String| SpaceError::Malformed(m);
        let too_big = || {
            bad(format!(
                "a value takes more than {MAX_VALUE_BYTES} bytes (the limit)"
            ))
        };
        if depth > MAX_DEPTH {
            return Err(bad(format!("nested deeper than {MAX_DEPTH} levels")));
        }
        let children: &mut dyn Iterator<Item = &Space> = match self {
            Space::Dict { spaces } => &mut spaces.iter().map(|(_, s)| s),
            Space::Tuple { spaces } => &mut spaces.iter(),
            Space::Box {
                dtype,
                shape,
                low,
                high,
            } => {
                let n = shape
                    .iter()
                    .try_fold(1usize, |n, &d| n.checked_mul(d))
                    .ok_or_else(too_big)?;
                if low.len() != n || high.len() != n {
                    return Err(bad(format!(
                        "a box of shape {shape:?} ({n} elements) with {} low and {} high bounds",
                        low.len(),
                        high.len()
                    )));
                }
                let bytes = n.checked_mul(dtype.size()).ok_or_else(too_big)?;
                return (bytes <= MAX_VALUE_BYTES)
                    .then_some(bytes)
                    .ok_or_else(too_big);
            }
            Space::MultiBinary { shape } => {
                let n = shape
                    .iter()
                    .try_fold(1usize, |n, &d| n.checked_mul(d))
                    .ok_or_else(too_big)?;
                return (n <= MAX_VALUE_BYTES).then_some(n).ok_or_else(too_big);
            }
            Space::Discrete { n, .. } => {
                if *n <= 0 {
                    return Err(bad(format!("a discrete space of {n} values")));
                }
                return Ok(8);
            }
            Space::MultiDiscrete { nvec, start, shape } => {
                if nvec.len() != start.len() || nvec.iter().any(|&n| n <= 0) {
                    return Err(bad(format!(
                        "a multi-discrete space with nvec {nvec:?} and start {start:?} (one positive count and one start per element)"
                    )));
                }
                if let Some(shape) = shape {
                    let elements = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
                    if shape.len() > MAX_DIMS || elements != Some(nvec.len()) {
                        return Err(bad(format!(
                            "a multi-discrete space of shape {shape:?} with {} counts (the shape's elements, at most {MAX_DIMS} dimensions)",
                            nvec.len()
                        )));
                    }
                }
                let bytes = nvec.len().checked_mul(8).ok_or_else(too_big)?;
                return (bytes <= MAX_VALUE_BYTES)
                    .then_some(bytes)
                    .ok_or_else(too_big);
            }
        };
        let mut total = 0usize;
        for child in children {
            let bytes = child.check_at(depth + 1)?;
            total = bytes
                .checked_next_multiple_of(ALIGN)
                .and_then(|b| total.checked_add(b))
                .filter(|&t| t <= MAX_VALUE_BYTES)
                .ok_or_else(too_big)?;
        }
        Ok(total)
    }

    /// Bytes one value of this space takes in the flat layout.
    pub fn byte_len(&self) -> usize {
        match self {
            Space::Dict { spaces } => spaces.iter().map(|(_, s)| align_up(s.byte_len())).sum(),
            Space::Tuple { spaces } => spaces.iter().map(|s| align_up(s.byte_len())).sum(),
            leaf => leaf.num_elements() * leaf.dtype().map_or(0, DType::size),
        }
    }

    /// Leaves in layout order with their byte offset and a path (`["observation"]`, `[1]`).
    pub fn leaves(&self) -> Vec<(String, usize, &Space)> {
        let mut out = Vec::new();
        self.collect_leaves(String::new(), 0, &mut out);
        out
    }

    fn collect_leaves<'a>(
        &'a self,
        path: String,
        offset: usize,
        out: &mut Vec<(String, usize, &'a Space)>,
    ) {
        let children: Vec<(String, &Space)> = match self {
            Space::Dict { spaces } => spaces
                .iter()
                .map(|(k, s)| (format!("{path}[\"{k}\"]"), s))
                .collect(),
            Space::Tuple { spaces } => spaces
                .iter()
                .enumerate()
                .map(|(i, s)| (format!("{path}[{i}]"), s))
                .collect(),
            leaf => {
                out.push((path, offset, leaf));
                return;
            }
        };
        let mut at = offset;
        for (p, s) in children {
            s.collect_leaves(p, at, out);
            at += align_up(s.byte_len());
        }
    }

    /// Checks that `bytes` is a value of this space: right length, every element in range,
    /// and no NaN or infinity in a float box (whatever its bounds: a policy that emits NaN is
    /// broken, and stepping a simulator with it only hides the bug).
    pub fn validate(&self, bytes: &[u8]) -> Result<(), SpaceError> {
        self.validate_with(bytes, BoundsCheck::Strict)
    }

    /// [`Space::validate`], holding float `Box` elements to their bounds only if `check` is
    /// [`BoundsCheck::Strict`]; the length, NaN, infinities and integer ranges are always
    /// checked.
    pub fn validate_with(&self, bytes: &[u8], check: BoundsCheck) -> Result<(), SpaceError> {
        let expected = self.byte_len();
        if bytes.len() != expected {
            return Err(SpaceError::Length {
                space: self.to_string(),
                expected,
                got: bytes.len(),
            });
        }
        if let Some(dtype) = self.dtype() {
            // A leaf: the common case on the hot path, checked without allocating.
            return self.validate_leaf(dtype, bytes, check, String::new);
        }
        for (path, offset, leaf) in self.leaves() {
            let dtype = leaf.dtype().expect("leaves have a dtype");
            leaf.validate_leaf(
                dtype,
                &bytes[offset..offset + leaf.byte_len()],
                check,
                || path.clone(),
            )?;
        }
        Ok(())
    }

    fn validate_leaf(
        &self,
        dtype: DType,
        data: &[u8],
        check: BoundsCheck,
        path: impl Fn() -> String,
    ) -> Result<(), SpaceError> {
        let bounded = !(dtype.is_float() && check == BoundsCheck::FiniteFloats);
        for i in 0..self.num_elements() {
            let v = dtype.read(data, i);
            if dtype.is_float() && !v.is_finite() {
                return Err(SpaceError::NotFinite {
                    index: i,
                    path: path(),
                    value: v,
                });
            }
            if !bounded {
                continue;
            }
            let (low, high) = self.bounds(i);
            // Bounds are checked at the dtype's precision: a float32 box of [-2, 2] must
            // accept the float32 nearest to 2.0.
            let (lo, hi) = if dtype == DType::Float32 {
                (low as f32 as f64, high as f32 as f64)
            } else {
                (low, high)
            };
            if v < lo || v > hi {
                return Err(SpaceError::OutOfRange {
                    index: i,
                    path: path(),
                    value: v,
                    space: self.to_string(),
                    low,
                    high,
                });
            }
        }
        Ok(())
    }

    /// Validates `bytes` as `count` values of this space back to back, as a batch of actions
    /// arrives, holding float `Box` elements to their bounds as `check` says
    /// ([`Space::validate_with`]). Returns the index of the first bad value with the reason.
    /// Discrete spaces and `float32` boxes, the common action spaces, are checked in one tight
    /// loop.
    pub fn validate_batch(
        &self,
        bytes: &[u8],
        count: usize,
        check: BoundsCheck,
    ) -> Result<(), (usize, SpaceError)> {
        let each = self.byte_len();
        if bytes.len() != each * count {
            return Err((
                0,
                SpaceError::Length {
                    space: format!("{count} × {self}"),
                    expected: each * count,
                    got: bytes.len(),
                },
            ));
        }
        let first_bad = match self {
            Space::Discrete { n, start } => bytes.chunks_exact(8).position(|b| {
                let v = i64::from_le_bytes(b.try_into().expect("8 bytes"));
                v < *start || v >= start + n
            }),
            Space::Box {
                dtype: DType::Float32,
                low,
                ..
            } if check == BoundsCheck::FiniteFloats => {
                let k = low.len().max(1);
                bytes
                    .chunks_exact(4)
                    .position(|b| !f32::from_le_bytes(b.try_into().expect("4 bytes")).is_finite())
                    .map(|elem| elem / k)
            }
            Space::Box {
                dtype: DType::Float32,
                low,
                high,
                ..
            } => {
                let k = low.len().max(1);
                let lo: Vec<f32> = low.iter().map(|&x| x as f32).collect();
                let hi: Vec<f32> = high.iter().map(|&x| x as f32).collect();
                bytes
                    .chunks_exact(4)
                    .enumerate()
                    .position(|(i, b)| {
                        let v = f32::from_le_bytes(b.try_into().expect("4 bytes"));
                        !(v.is_finite() && v >= lo[i % k] && v <= hi[i % k])
                    })
                    .map(|elem| elem / k)
            }
            _ => (0..count).find(|&i| {
                self.validate_with(&bytes[i * each..(i + 1) * each], check)
                    .is_err()
            }),
        };
        match first_bad {
            None => Ok(()),
            Some(i) => Err((
                i,
                self.validate_with(&bytes[i * each..(i + 1) * each], check)
                    .expect_err("the fast check and the full check agree"),
            )),
        }
    }

    /// Whether `bytes` is a value of this space.
    pub fn contains(&self, bytes: &[u8]) -> bool {
        self.validate(bytes).is_ok()
    }

    /// Inclusive bounds of element `i` of a leaf.
    fn bounds(&self, i: usize) -> (f64, f64) {
        match self {
            Space::Box { low, high, .. } => (low[i], high[i]),
            Space::Discrete { n, start } => (*start as f64, (start + n - 1) as f64),
            Space::MultiDiscrete { nvec, start, .. } => {
                (start[i] as f64, (start[i] + nvec[i] - 1) as f64)
            }
            Space::MultiBinary { .. } => (0.0, 1.0),
            Space::Dict { .. } | Space::Tuple { .. } => unreachable!("bounds of a composite"),
        }
    }

    /// Writes a uniformly random value of this space into `out` (as `Space::sample` in
    /// Gymnasium: unbounded box sides draw from a normal or exponential distribution).
    pub fn sample_into(&self, rng: &mut impl Rng, out: &mut [u8]) {
        assert_eq!(
            out.len(),
            self.byte_len(),
            "sample buffer has the wrong length"
        );
        for (_, offset, leaf) in self.leaves() {
            let dtype = leaf.dtype().expect("leaves have a dtype");
            let data = &mut out[offset..offset + leaf.byte_len()];
            for i in 0..leaf.num_elements() {
                let (lo, hi) = leaf.bounds(i);
                let v = if dtype.is_float() {
                    sample_interval(rng, lo, hi)
                } else {
                    rng.random_range(lo as i64..=hi as i64) as f64
                };
                dtype.write(data, i, v);
            }
        }
    }

    /// A random value of this space as a fresh buffer.
    pub fn sample(&self, rng: &mut impl Rng) -> Vec<u8> {
        let mut out = vec![0; self.byte_len()];
        self.sample_into(rng, &mut out);
        out
    }
}

fn sample_interval(rng: &mut impl Rng, lo: f64, hi: f64) -> f64 {
    let normal = |rng: &mut dyn rand::RngCore| -> f64 {
        // Box-Muller; enough for random exploration, not a statistics library.
        let u1: f64 = 1.0 - rand::Rng::random::<f64>(rng);
        let u2: f64 = rand::Rng::random::<f64>(rng);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let exp = |rng: &mut dyn rand::RngCore| -> f64 { -(1.0 - rand::Rng::random::<f64>(rng)).ln() };
    match (lo.is_finite(), hi.is_finite()) {
        (true, true) => lo + (hi - lo) * rng.random::<f64>(),
        (true, false) => lo + exp(rng),
        (false, true) => hi - exp(rng),
        (false, false) => normal(rng),
    }
}

impl fmt::Display for Space {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Space::Box {
                dtype,
                shape,
                low,
                high,
            } => {
                let uniform = |v: &[f64]| v.iter().all(|x| x == &v[0]);
                if !low.is_empty() && uniform(low) && uniform(high) {
                    write!(f, "Box({}, {}, {shape:?}, {dtype})", low[0], high[0])
                } else {
                    write!(f, "Box({shape:?}, {dtype})")
                }
            }
            Space::Discrete { n, start: 0 } => write!(f, "Discrete({n})"),
            Space::Discrete { n, start } => write!(f, "Discrete({n}, start={start})"),
            Space::MultiDiscrete { nvec, .. } => write!(f, "MultiDiscrete({nvec:?})"),
            Space::MultiBinary { shape } => write!(f, "MultiBinary({shape:?})"),
            Space::Dict { spaces } => {
                f.write_str("Dict(")?;
                for (i, (k, s)) in spaces.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "'{k}': {s}")?;
                }
                f.write_str(")")
            }
            Space::Tuple { spaces } => {
                f.write_str("Tuple(")?;
                for (i, s) in spaces.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{s}")?;
                }
                f.write_str(")")
            }
        }
    }
}

/// JSON has no infinity: bounds travel as numbers, or the strings `inf` / `-inf`.
mod bounds {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(untagged)]
    enum Bound {
        Num(f64),
        Text(String),
    }

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        v.iter()
            .map(|x| match *x {
                x if x == f64::INFINITY => Bound::Text("inf".into()),
                x if x == f64::NEG_INFINITY => Bound::Text("-inf".into()),
                x => Bound::Num(x),
            })
            .collect::<Vec<_>>()
            .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        Vec::<Bound>::deserialize(d)?
            .into_iter()
            .map(|b| match b {
                Bound::Num(x) => Ok(x),
                Bound::Text(t) => match t.as_str() {
                    "inf" | "+inf" => Ok(f64::INFINITY),
                    "-inf" => Ok(f64::NEG_INFINITY),
                    other => Err(serde::de::Error::custom(format!(
                        "invalid bound `{other}`; expected a number, `inf` or `-inf`"
                    ))),
                },
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rng() -> rand_chacha::ChaCha8Rng {
        rand_chacha::ChaCha8Rng::seed_from_u64(7)
    }

    fn goal_dict() -> Space {
        Space::Dict {
            spaces: vec![
                ("achieved_goal".into(), Space::box_f32(&[3], -1.0, 1.0)),
                (
                    "observation".into(),
                    Space::box_f32(&[5], f64::NEG_INFINITY, f64::INFINITY),
                ),
                ("flag".into(), Space::discrete(3)),
            ],
        }
    }

    #[test]
    fn a_multi_discrete_shape_must_hold_its_counts() {
        let md = |shape| Space::MultiDiscrete {
            nvec: vec![2; 6],
            start: vec![0; 6],
            shape,
        };
        assert_eq!(md(Some(vec![2, 3])).check().unwrap(), 48);
        assert_eq!(md(Some(vec![2, 3])).shape(), Some(vec![2, 3]));
        assert_eq!(md(None).shape(), Some(vec![6]));
        for bad in [vec![4, 2], vec![usize::MAX, 2], vec![1; 40]] {
            assert!(md(Some(bad.clone())).check().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn samples_are_contained() {
        let spaces = [
            Space::box_f32(&[4], -2.0, 2.0),
            Space::box_f32(&[2, 3], f64::NEG_INFINITY, f64::INFINITY),
            Space::Discrete { n: 5, start: -2 },
            Space::MultiDiscrete {
                nvec: vec![2, 3, 4],
                start: vec![0, 0, 1],
                shape: None,
            },
            Space::MultiDiscrete {
                nvec: vec![2, 3, 4, 5],
                start: vec![0, 0, 1, 1],
                shape: Some(vec![2, 2]),
            },
            Space::MultiBinary { shape: vec![6] },
            goal_dict(),
            Space::Tuple {
                spaces: vec![Space::discrete(2), Space::box_f32(&[1], 0.0, 1.0)],
            },
        ];
        let mut rng = rng();
        for space in spaces {
            for _ in 0..200 {
                let v = space.sample(&mut rng);
                assert!(space.contains(&v), "{space}: {:?}", space.validate(&v));
            }
        }
    }

    #[test]
    fn composite_layout_is_aligned() {
        let space = goal_dict();
        // 12 bytes -> 16, 20 -> 24, 8
        assert_eq!(space.byte_len(), 16 + 24 + 8);
        let offsets: Vec<usize> = space.leaves().iter().map(|l| l.1).collect();
        assert_eq!(offsets, vec![0, 16, 40]);
        assert_eq!(space.leaves()[1].0, "[\"observation\"]");
    }

    #[test]
    fn rejects_bad_values_with_reasons() {
        let discrete = Space::discrete(2);
        let err = discrete.validate(&5i64.to_le_bytes()).unwrap_err();
        assert!(err.to_string().contains("outside Discrete(2)"), "{err}");
        let err = discrete.validate(&[0u8; 4]).unwrap_err();
        assert!(matches!(
            err,
            SpaceError::Length {
                expected: 8,
                got: 4,
                ..
            }
        ));

        let pend = Space::box_f32(&[1], -2.0, 2.0);
        let nan = bytemuck::bytes_of(&f32::NAN).to_vec();
        assert!(matches!(
            pend.validate(&nan),
            Err(SpaceError::NotFinite { .. })
        ));
        let edge = bytemuck::bytes_of(&2.0f32).to_vec();
        assert!(pend.contains(&edge));
        let over = bytemuck::bytes_of(&2.5f32).to_vec();
        assert!(!pend.contains(&over));
    }

    #[test]
    fn batch_validation_finds_the_bad_value() {
        let d = Space::discrete(3);
        let ok: Vec<u8> = [0i64, 2, 1].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(d.validate_batch(&ok, 3, BoundsCheck::Strict).is_ok());
        let bad: Vec<u8> = [0i64, 3, 1].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(matches!(
            d.validate_batch(&bad, 3, BoundsCheck::Strict),
            Err((1, SpaceError::OutOfRange { .. }))
        ));
        let b = Space::box_f32_bounds(vec![-1.0, 0.0], vec![1.0, 5.0]);
        let ok: Vec<u8> = [0.5f32, 5.0, -1.0, 0.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert!(b.validate_batch(&ok, 2, BoundsCheck::Strict).is_ok());
        let bad: Vec<u8> = [0.5f32, 5.0, -1.0, f32::NAN]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert!(matches!(
            b.validate_batch(&bad, 2, BoundsCheck::Strict),
            Err((1, SpaceError::NotFinite { .. }))
        ));
        assert!(matches!(
            b.validate_batch(&ok[..12], 2, BoundsCheck::Strict),
            Err((0, SpaceError::Length { .. }))
        ));
    }

    fn f32_bytes(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    #[test]
    fn finite_floats_pass_float_boxes_beyond_their_bounds() {
        let finite = BoundsCheck::FiniteFloats;
        let b = Space::box_f32_bounds(vec![-1.0, 0.0], vec![1.0, 5.0]);
        let beyond = f32_bytes(&[3.0, -15.0, -1e30, 6.0]);
        assert!(b.validate_batch(&beyond, 2, finite).is_ok());
        let err = b
            .validate_batch(&beyond, 2, BoundsCheck::Strict)
            .unwrap_err();
        assert!(matches!(
            err,
            (
                0,
                SpaceError::OutOfRange {
                    index: 0,
                    low: -1.0,
                    high: 1.0,
                    ..
                }
            )
        ));
        assert!(
            err.1
                .to_string()
                .contains("element 0 = 3 is outside Box([2], float32) (valid range [-1, 1])"),
            "{}",
            err.1
        );
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let values = f32_bytes(&[0.0, 1.0, 9.0, bad]);
            assert!(matches!(
                b.validate_batch(&values, 2, finite),
                Err((1, SpaceError::NotFinite { index: 1, .. }))
            ));
        }
        // The general path (float64, composite) agrees with the float32 fast path.
        let f64_box = Space::Box {
            dtype: DType::Float64,
            shape: vec![1],
            low: vec![-2.0],
            high: vec![2.0],
        };
        let values: Vec<u8> = [7.0f64, f64::NAN]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert!(f64_box.validate_with(&values[..8], finite).is_ok());
        assert!(!f64_box.contains(&values[..8]));
        assert!(matches!(
            f64_box.validate_batch(&values, 2, finite),
            Err((1, SpaceError::NotFinite { .. }))
        ));
        let goal = goal_dict();
        let mut value = vec![0u8; goal.byte_len()];
        value[..4].copy_from_slice(&4.0f32.to_le_bytes());
        assert!(goal.validate_with(&value, finite).is_ok());
        assert!(goal.validate(&value).is_err());
    }

    #[test]
    fn out_of_range_names_the_bounds_as_declared() {
        let humanoid = Space::box_f32(&[2], -0.4, 0.4);
        let err = humanoid.validate(&f32_bytes(&[0.0, 0.5])).unwrap_err();
        assert!(
            err.to_string().ends_with(
                "element 1 = 0.5 is outside Box(-0.4, 0.4, [2], float32) (valid range [-0.4, 0.4])"
            ),
            "{err}"
        );
    }

    #[test]
    fn finite_floats_still_check_integer_spaces() {
        let finite = BoundsCheck::FiniteFloats;
        let d = Space::discrete(3);
        let bad: Vec<u8> = [0i64, 3].iter().flat_map(|v| v.to_le_bytes()).collect();
        let err = d.validate_batch(&bad, 2, finite).unwrap_err();
        assert!(matches!(err, (1, SpaceError::OutOfRange { .. })));
        assert!(
            err.1
                .to_string()
                .contains("outside Discrete(3) (valid range [0, 2])"),
            "{}",
            err.1
        );
        let md = Space::MultiDiscrete {
            nvec: vec![2, 3],
            start: vec![0, 0],
            shape: None,
        };
        let bad: Vec<u8> = [1i64, 3].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(md.validate_with(&bad, finite).is_err());
        let mb = Space::MultiBinary { shape: vec![2] };
        assert!(mb.validate_with(&[1, 2], finite).is_err());
        let int_box = Space::Box {
            dtype: DType::Uint8,
            shape: vec![1],
            low: vec![0.0],
            high: vec![10.0],
        };
        assert!(int_box.validate_with(&[11], finite).is_err());
        // Wrong length stays an error.
        assert!(matches!(
            Space::box_f32(&[1], -2.0, 2.0).validate_batch(&[0; 6], 2, finite),
            Err((0, SpaceError::Length { .. }))
        ));
    }

    #[test]
    fn serializes_infinite_bounds() {
        let space = goal_dict();
        let json = serde_json::to_string(&space).unwrap();
        assert!(json.contains("\"-inf\""), "{json}");
        let back: Space = serde_json::from_str(&json).unwrap();
        assert_eq!(back, space);
    }

    #[test]
    fn displays_like_gymnasium() {
        assert_eq!(Space::discrete(2).to_string(), "Discrete(2)");
        assert_eq!(
            Space::box_f32(&[1], -2.0, 2.0).to_string(),
            "Box(-2, 2, [1], float32)"
        );
    }
}
