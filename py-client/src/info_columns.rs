//! The client's reading of typed info columns: a schema a worker announced, checked
//! (`envhub_protocol::info_columns`) before Python lays numpy views over the slot with it.

use envhub_protocol::info_columns::{InfoSchema, ValueKind};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// One checked column: `(key, dtype, shape, offset, mask offset, kind)`.
type ColumnTuple = (String, &'static str, Vec<usize>, usize, usize, &'static str);

/// The schema `text` (JSON, from a worker) checked for rows of `row_bytes`: its id and its
/// columns. Raises `ValueError` naming what is wrong.
#[pyfunction]
pub(crate) fn info_schema(text: &str, row_bytes: usize) -> PyResult<(u64, Vec<ColumnTuple>)> {
    let schema = InfoSchema::parse(text, row_bytes).map_err(|e| {
        PyValueError::new_err(format!(
            "a worker announced an invalid info-column schema: {e}\nhint: the worker runs another envhub version or misbehaves"
        ))
    })?;
    let columns = schema
        .columns
        .into_iter()
        .map(|c| {
            let kind = match c.kind {
                ValueKind::Py => "py",
                ValueKind::Np => "np",
                ValueKind::Array => "array",
            };
            (c.key, c.dtype, c.shape, c.offset, c.mask, kind)
        })
        .collect();
    Ok((schema.id, columns))
}
