//! The client's reading of typed info columns: a schema a worker announced, checked
//! (`envhub_protocol::info_columns`) before Python lays numpy views over the slot with it.

use envhub_protocol::info_columns::{InfoSchema, ValueKind};
use numpy::{PyArrayDescr, PyArrayDescrMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

/// One checked column: `(key, dtype, shape, offset, mask offset, kind)`.
pub(crate) type ColumnTuple = (String, &'static str, Vec<usize>, usize, usize, &'static str);

/// The schema `text` (JSON, from a worker) checked for rows of `row_bytes`: its id and its
/// columns. Raises `ValueError` naming what is wrong.
#[pyfunction]
pub(crate) fn info_schema(text: &str, row_bytes: usize) -> PyResult<(u64, Vec<ColumnTuple>)> {
    let schema = InfoSchema::parse(text, row_bytes).map_err(invalid)?;
    Ok((schema.id, schema.columns.iter().map(column_tuple).collect()))
}

/// A checked schema made ready to lay Gymnasium's vector info over rows: each key's name,
/// its mask's name (`_key`) and its numpy dtype, made once.
pub(crate) struct ReadySchema {
    schema: InfoSchema,
    names: Vec<(Py<PyString>, Py<PyString>)>,
    dtypes: Vec<Py<PyArrayDescr>>,
    flag: Py<PyArrayDescr>,
}

/// Most schemas a session remembers; past it, the oldest is forgotten (a worker that keeps
/// re-learning gives up after 16, so a session has at most 16 per worker in use).
const MAX_SCHEMAS: usize = 256;

/// The schemas a session's workers announced, by id.
#[derive(Default)]
pub(crate) struct Schemas {
    by_id: HashMap<u64, Arc<ReadySchema>>,
    order: VecDeque<u64>,
}

fn invalid(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!(
        "a worker announced an invalid info-column schema: {e}\nhint: the worker runs another envhub version or misbehaves"
    ))
}

impl Schemas {
    /// Checks and remembers the schema `text` (from a worker) for rows of `row_bytes`.
    pub fn learn(&mut self, py: Python<'_>, text: &str, row_bytes: usize) -> PyResult<()> {
        let schema = InfoSchema::parse(text, row_bytes).map_err(invalid)?;
        if self.by_id.contains_key(&schema.id) {
            return Ok(());
        }
        let mut names = Vec::with_capacity(schema.columns.len());
        let mut dtypes = Vec::with_capacity(schema.columns.len());
        for c in &schema.columns {
            names.push((
                PyString::intern(py, &c.key).unbind(),
                PyString::new(py, &format!("_{}", c.key)).unbind(),
            ));
            dtypes.push(PyArrayDescr::new(py, c.dtype)?.unbind());
        }
        let ready = ReadySchema {
            names,
            dtypes,
            flag: PyArrayDescr::new(py, "|b1")?.unbind(),
            schema,
        };
        if self.order.len() >= MAX_SCHEMAS
            && let Some(old) = self.order.pop_front()
        {
            self.by_id.remove(&old);
        }
        self.order.push_back(ready.schema.id);
        self.by_id.insert(ready.schema.id, Arc::new(ready));
        Ok(())
    }

    pub fn get(&self, id: u64) -> Option<Arc<ReadySchema>> {
        self.by_id.get(&id).cloned()
    }

    /// The schema `id` as `info_schema` gives it, if announced.
    pub fn describe(&self, id: u64) -> Option<(u64, Vec<ColumnTuple>)> {
        self.by_id
            .get(&id)
            .map(|r| (id, r.schema.columns.iter().map(column_tuple).collect()))
    }
}

fn column_tuple(c: &envhub_protocol::info_columns::Column) -> ColumnTuple {
    let kind = match c.kind {
        ValueKind::Py => "py",
        ValueKind::Np => "np",
        ValueKind::Array => "array",
    };
    (
        c.key.clone(),
        c.dtype,
        c.shape.clone(),
        c.offset,
        c.mask,
        kind,
    )
}

/// The schema id every one of `n` rows of `row_bytes` at `rows` starts with; `None` when the
/// rows differ, or all say 0 (no columns).
///
/// # Safety
/// `rows` must be valid for reads of `n * row_bytes` bytes, `row_bytes >= 8`.
pub(crate) unsafe fn uniform_id(rows: *const u8, n: usize, row_bytes: usize) -> Option<u64> {
    let id_at = |k: usize| {
        let mut bytes = [0u8; 8];
        // SAFETY: row `k < n` starts `k * row_bytes` bytes in and has at least 8 bytes.
        unsafe { std::ptr::copy_nonoverlapping(rows.add(k * row_bytes), bytes.as_mut_ptr(), 8) };
        u64::from_le_bytes(bytes)
    };
    let first = id_at(0);
    (first != 0 && (1..n).all(|k| id_at(k) == first)).then_some(first)
}

/// Gymnasium's vector info of `n >= 1` rows of `row_bytes` at `rows`, all written with
/// `schema`: for each key present in some env, its values as a strided `[n, *shape]` view
/// of the rows and its `_key` mask as a `[n]` bool view, in Gymnasium's key order (by the
/// first env that has the key, then the env's own order). `base` keeps the rows alive.
///
/// # Safety
/// `rows` must be valid for `n * row_bytes` bytes, 8-byte aligned, that stay valid and are
/// written by no one else while `base` lives; `schema` must have been checked for
/// `row_bytes` (so every value and flag lies inside a row, aligned for its dtype).
pub(crate) unsafe fn vector_info<'py>(
    py: Python<'py>,
    schema: &ReadySchema,
    rows: *mut u8,
    n: usize,
    row_bytes: usize,
    base: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let columns = &schema.schema.columns;
    // SAFETY: every flag offset is inside a row (checked), rows are valid for reading.
    let flag = |k: usize, j: usize| unsafe { *rows.add(k * row_bytes + columns[j].mask) };
    let mut first_env: Vec<Option<usize>> = vec![None; columns.len()];
    for (j, first) in first_env.iter_mut().enumerate() {
        for k in 0..n {
            match flag(k, j) {
                0 => {}
                1 => {
                    first.get_or_insert(k);
                }
                other => {
                    return Err(PyValueError::new_err(format!(
                        "info columns hold a presence flag of {other} (key `{}`, env {k}); flags are 0 or 1\nhint: the worker misbehaves",
                        columns[j].key
                    )));
                }
            }
        }
    }
    let mut order: Vec<(usize, usize)> = first_env
        .iter()
        .enumerate()
        .filter_map(|(j, f)| f.map(|k| (k, j)))
        .collect();
    order.sort_unstable();
    let out = PyDict::new(py);
    let rows_stride = row_bytes as isize;
    for (_, j) in order {
        let c = &columns[j];
        let (key, mask_key) = &schema.names[j];
        let item = schema.dtypes[j].bind(py).itemsize() as isize;
        let mut dims = Vec::with_capacity(1 + c.shape.len());
        dims.push(n as isize);
        dims.extend(c.shape.iter().map(|&d| d as isize));
        // C order within a value, one row apart between envs.
        let mut strides = vec![0isize; dims.len()];
        let mut step = item;
        for d in (1..dims.len()).rev() {
            strides[d] = step;
            step *= dims[d];
        }
        strides[0] = rows_stride;
        // SAFETY: the checked schema puts this value inside each row, aligned for its dtype;
        // the caller guarantees the rows and that `base` keeps them.
        let values = unsafe {
            crate::arrays::strided_view(
                py,
                schema.dtypes[j].bind(py),
                &dims,
                &strides,
                rows.add(c.offset),
                base,
            )?
        };
        // SAFETY: the flag byte lies inside each row and holds 0 or 1 (checked above).
        let mask = unsafe {
            crate::arrays::strided_view(
                py,
                schema.flag.bind(py),
                &[n as isize],
                &[rows_stride],
                rows.add(c.mask),
                base,
            )?
        };
        out.set_item(key.bind(py), values)?;
        out.set_item(mask_key.bind(py), mask)?;
    }
    Ok(out)
}
