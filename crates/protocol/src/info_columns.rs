//! Typed info columns: the schema a Python worker announces for the info rows it writes in
//! the batch slot, and its validation.
//!
//! A worker whose session asked for info columns (`SessionOptions::info_row_bytes`) learns a
//! schema from its envs' infos (keys, and for each the dtype and shape of its value) and
//! writes every info that fits it as one row of the slot's column block: a `u64` schema id
//! at offset 0 (0: this env's info went as JSON instead), each key's value at its offset,
//! and one presence byte per key (Gymnasium's `_key` mask). The reader views each key as a
//! strided `[n, *shape]` array over the rows, in place. The schema itself travels once, as
//! JSON text in the info of the first env whose row uses it ([`SCHEMA_KEY`]):
//!
//! `{"id": 7, "keys": [{"key": "x", "dtype": "<f8", "shape": [], "offset": 8, "mask": 16,
//! "kind": "py"}]}`
//!
//! The text comes from another process (user code runs there), so [`InfoSchema::parse`]
//! checks every offset, size and count against the row with checked arithmetic before a
//! reader lays a view over the slot with it: every value and mask lies inside the row,
//! values are aligned for their dtype, nothing overlaps, keys are unique and none starts
//! with `_`, so none collides with a mask's name.

use serde::Deserialize;

/// The info key that carries a newly announced schema (JSON text).
pub const SCHEMA_KEY: &str = "__envhub_schema__";

/// Most keys a schema may have.
pub const MAX_KEYS: usize = 1024;
/// Most dimensions of a value.
pub const MAX_DIMS: usize = 8;

/// The dtypes a column may have (numpy's `dtype.str`, little-endian), with their item size.
const DTYPES: &[(&str, usize)] = &[
    ("|b1", 1),
    ("|i1", 1),
    ("|u1", 1),
    ("<i2", 2),
    ("<u2", 2),
    ("<f2", 2),
    ("<i4", 4),
    ("<u4", 4),
    ("<f4", 4),
    ("<i8", 8),
    ("<u8", 8),
    ("<f8", 8),
];

/// What an env's value was, so a reader that rebuilds one env's info dict gives back the
/// same Python type: a Python scalar (`bool`, `int`, `float`), a numpy scalar, an array.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ValueKind {
    /// A Python `bool`, `int` or `float`.
    Py,
    /// A numpy scalar (`np.float32(...)`).
    Np,
    /// A numpy array of the column's shape.
    Array,
}

/// One key of a schema, checked.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Column {
    /// The info key.
    pub key: String,
    /// numpy's `dtype.str` of the values.
    pub dtype: &'static str,
    /// Shape of one env's value (`[]` for a scalar).
    pub shape: Vec<usize>,
    /// Byte offset of the value in a row.
    pub offset: usize,
    /// Bytes of one env's value.
    pub nbytes: usize,
    /// Byte offset of the presence flag in a row.
    pub mask: usize,
    /// The Python type the values had.
    pub kind: ValueKind,
}

/// A checked schema: where each key's value and flag lie in a row of `row_bytes`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InfoSchema {
    /// Its id, as written at the start of each row that uses it (never 0).
    pub id: u64,
    /// The keys, in the order the worker learned them.
    pub columns: Vec<Column>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSchema {
    id: u64,
    keys: Vec<RawColumn>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawColumn {
    key: String,
    dtype: String,
    shape: Vec<u64>,
    offset: u64,
    mask: u64,
    kind: ValueKind,
}

impl InfoSchema {
    /// Parses and checks a schema for rows of `row_bytes`. The error says what is wrong.
    pub fn parse(text: &str, row_bytes: usize) -> Result<InfoSchema, String> {
        let raw: RawSchema =
            serde_json::from_str(text).map_err(|e| format!("not a schema: {e}"))?;
        if raw.id == 0 {
            return Err("schema id 0 (it means \"no columns\")".into());
        }
        if raw.keys.len() > MAX_KEYS {
            return Err(format!("{} keys, more than {MAX_KEYS}", raw.keys.len()));
        }
        // Byte ranges taken in the row; the id takes the first 8.
        let mut taken: Vec<(usize, usize)> = vec![(0, 8)];
        let mut columns = Vec::with_capacity(raw.keys.len());
        let mut names = std::collections::HashSet::new();
        for c in raw.keys {
            let bad = |what: String| format!("key `{}`: {what}", c.key);
            if c.key.is_empty() || c.key.starts_with('_') || c.key == SCHEMA_KEY {
                return Err(bad("not a column key (empty, or starts with `_`)".into()));
            }
            if !names.insert(c.key.clone()) {
                return Err(bad("appears twice".into()));
            }
            let &(dtype, item) = DTYPES
                .iter()
                .find(|(d, _)| *d == c.dtype)
                .ok_or_else(|| bad(format!("dtype `{}` is not a column dtype", c.dtype)))?;
            if c.shape.len() > MAX_DIMS {
                return Err(bad(format!(
                    "{} dimensions, more than {MAX_DIMS}",
                    c.shape.len()
                )));
            }
            if c.kind != ValueKind::Array && !c.shape.is_empty() {
                return Err(bad("a scalar with a shape".into()));
            }
            let mut shape = Vec::with_capacity(c.shape.len());
            let mut nbytes = item;
            for &d in &c.shape {
                let d = usize::try_from(d).map_err(|_| bad(format!("dimension {d}")))?;
                nbytes = nbytes
                    .checked_mul(d)
                    .filter(|&b| b <= row_bytes)
                    .ok_or_else(|| bad(format!("shape {:?} does not fit a row", c.shape)))?;
                shape.push(d);
            }
            let offset = usize::try_from(c.offset).map_err(|_| bad("offset".into()))?;
            let end = offset
                .checked_add(nbytes)
                .filter(|&e| e <= row_bytes)
                .ok_or_else(|| bad(format!("value at {offset} past a row of {row_bytes} bytes")))?;
            if !offset.is_multiple_of(item) {
                return Err(bad(format!(
                    "value at {offset}, not aligned to {item} bytes"
                )));
            }
            let mask = usize::try_from(c.mask)
                .ok()
                .filter(|&m| m < row_bytes)
                .ok_or_else(|| {
                    bad(format!(
                        "flag at {} past a row of {row_bytes} bytes",
                        c.mask
                    ))
                })?;
            if nbytes > 0 {
                taken.push((offset, end));
            }
            taken.push((mask, mask + 1));
            columns.push(Column {
                key: c.key,
                dtype,
                shape,
                offset,
                nbytes,
                mask,
                kind: c.kind,
            });
        }
        taken.sort_unstable();
        if let Some(w) = taken.windows(2).find(|w| w[1].0 < w[0].1) {
            return Err(format!(
                "bytes {}..{} and {}..{} of a row overlap",
                w[0].0, w[0].1, w[1].0, w[1].1
            ));
        }
        Ok(InfoSchema {
            id: raw.id,
            columns,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(key: &str, dtype: &str, shape: &str, offset: u64, mask: u64, kind: &str) -> String {
        format!(
            r#"{{"id": 3, "keys": [{{"key": "{key}", "dtype": "{dtype}", "shape": {shape}, "offset": {offset}, "mask": {mask}, "kind": "{kind}"}}]}}"#
        )
    }

    #[test]
    fn a_schema_that_fits_its_row_is_read() {
        let text = r#"{"id": 9, "keys": [
            {"key": "x", "dtype": "<f8", "shape": [], "offset": 8, "mask": 40, "kind": "py"},
            {"key": "v", "dtype": "<f4", "shape": [2, 3], "offset": 16, "mask": 41, "kind": "array"}]}"#;
        let s = InfoSchema::parse(text, 48).unwrap();
        assert_eq!(s.id, 9);
        assert_eq!(s.columns[1].nbytes, 24);
        assert_eq!(s.columns[1].shape, vec![2, 3]);
        assert_eq!(s.columns[0].kind, ValueKind::Py);
    }

    #[test]
    fn what_does_not_fit_or_overlaps_is_refused_with_the_reason() {
        let cases = [
            (one("x", "<f8", "[]", 8, 16, "py"), 16, "past a row"),
            (one("x", "<f8", "[]", 12, 20, "py"), 32, "not aligned"),
            (one("x", "<f8", "[]", 0, 20, "py"), 32, "overlap"),
            (one("x", "<f8", "[]", 8, 10, "py"), 32, "overlap"),
            (one("x", "<f8", "[]", 8, 32, "py"), 32, "flag at 32"),
            (one("x", "|O", "[]", 8, 20, "py"), 32, "not a column dtype"),
            (
                one("x", "<f8", "[2]", 8, 30, "np"),
                32,
                "scalar with a shape",
            ),
            (
                one("x", "<f8", "[4611686018427387904, 4]", 8, 30, "array"),
                32,
                "does not fit",
            ),
            (
                one("x", "<f8", "[18446744073709551615]", 8, 30, "array"),
                32,
                "does not fit",
            ),
            (
                one("x", "<f8", "[]", 18446744073709551615, 30, "py"),
                32,
                "past a row",
            ),
            (one("_x", "<f8", "[]", 8, 30, "py"), 32, "starts with"),
            (one("x", "<f8", "[]", 8, 30, "what"), 32, "not a schema"),
            (r#"{"id": 0, "keys": []}"#.to_string(), 32, "id 0"),
        ];
        for (text, row, want) in cases {
            let err = InfoSchema::parse(&text, row).unwrap_err();
            assert!(err.contains(want), "{text}: {err}");
        }
        let twice = r#"{"id": 1, "keys": [
            {"key": "x", "dtype": "|u1", "shape": [], "offset": 8, "mask": 10, "kind": "np"},
            {"key": "x", "dtype": "|u1", "shape": [], "offset": 9, "mask": 11, "kind": "np"}]}"#;
        assert!(InfoSchema::parse(twice, 16).unwrap_err().contains("twice"));
    }
}
