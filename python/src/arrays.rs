//! numpy arrays of a space's dtype: read-only views of shared memory kept alive by an owner
//! object, and fresh arrays that results are copied into.

use envhub_core::DType;
use numpy::ndarray::{ArrayViewD, IxDyn};
use numpy::npyffi::{
    _PyArray_GET_ITEM_DATA, NPY_ARRAY_WRITEABLE, NpyTypes, PY_ARRAY_API, get_type_object,
};
use numpy::{PyArray, PyArrayDescr, PyArrayDescrMethods, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// Calls `$body` with `$t` bound to the Rust type of `$dtype` (`u8` for raw bytes).
macro_rules! with_dtype {
    ($dtype:expr, $t:ident => $body:expr) => {
        match $dtype {
            Some(DType::Float32) => {
                type $t = f32;
                $body
            }
            Some(DType::Float64) => {
                type $t = f64;
                $body
            }
            Some(DType::Int8) => {
                type $t = i8;
                $body
            }
            Some(DType::Int32) => {
                type $t = i32;
                $body
            }
            Some(DType::Int64) => {
                type $t = i64;
                $body
            }
            Some(DType::Bool) => {
                type $t = bool;
                $body
            }
            Some(DType::Uint8) | None => {
                type $t = u8;
                $body
            }
        }
    };
}

/// How a batch of values of one space looks as an array: a leaf's dtype and shape, or raw
/// bytes per value (`dtype` `None`) for a `Dict`/`Tuple`, split into leaves in Python.
#[derive(Clone, Debug)]
pub(crate) struct ArrayLayout {
    pub dtype: Option<DType>,
    /// Shape of one value (`[byte_len]` for raw bytes).
    pub shape: Vec<usize>,
    /// Bytes of one value.
    pub bytes: usize,
}

impl ArrayLayout {
    pub fn of(space: &envhub_hub::Space) -> ArrayLayout {
        let bytes = space.byte_len();
        match (space.dtype(), space.shape()) {
            (Some(dtype), Some(shape)) => ArrayLayout {
                dtype: Some(dtype),
                shape,
                bytes,
            },
            _ => ArrayLayout {
                dtype: None,
                shape: vec![bytes],
                bytes,
            },
        }
    }

    /// `[n, *shape]`, or `shape` alone for `None`.
    fn batch_shape(&self, n: Option<usize>) -> Vec<usize> {
        n.into_iter().chain(self.shape.iter().copied()).collect()
    }
}

/// Rewards as arrays see them: one `float64` per env.
pub(crate) const REWARDS: ArrayLayout = ArrayLayout {
    dtype: Some(DType::Float64),
    shape: Vec::new(),
    bytes: 8,
};

/// Done flags as arrays see them: one `bool` per env.
pub(crate) const FLAGS: ArrayLayout = ArrayLayout {
    dtype: Some(DType::Bool),
    shape: Vec::new(),
    bytes: 1,
};

/// A writeable array of `n` values (one value without a leading axis when `n` is `None`)
/// viewing the memory at `ptr`, with `owner` as its base: the memory must stay valid, and
/// written by no one else, as long as `owner` lives.
///
/// # Safety
/// `ptr` must point to `n.unwrap_or(1) * layout.bytes` bytes, aligned for the dtype, holding
/// valid values of it, that stay valid and are neither read nor written by anyone else while
/// `owner` is alive.
pub(crate) unsafe fn view<'py>(
    layout: &ArrayLayout,
    n: Option<usize>,
    ptr: *const u8,
    owner: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let shape = layout.batch_shape(n);
    with_dtype!(layout.dtype, T => {
        // SAFETY: the caller guarantees the memory; the shape covers exactly those bytes.
        let view = unsafe { ArrayViewD::<T>::from_shape_ptr(IxDyn(&shape), ptr.cast::<T>()) };
        // SAFETY: `owner` keeps the memory alive for as long as the array (its base) lives.
        let array = unsafe { PyArray::<T, IxDyn>::borrow_from_array(&view, owner) };
        Ok(array.into_any())
    })
}

/// A fresh, writeable array of `n` values, and the address of its data.
pub(crate) fn empty<'py>(
    py: Python<'py>,
    layout: &ArrayLayout,
    n: Option<usize>,
) -> (Bound<'py, PyAny>, usize) {
    let shape = layout.batch_shape(n);
    with_dtype!(layout.dtype, T => {
        // SAFETY: every element is written (`copy_into`) before the array reaches Python.
        let array = unsafe { PyArray::<T, IxDyn>::new(py, IxDyn(&shape), false) };
        let ptr = array.data() as usize;
        (array.into_any(), ptr)
    })
}

/// A fresh array of `n` values holding a copy of `bytes`.
pub(crate) fn copy<'py>(
    py: Python<'py>,
    layout: &ArrayLayout,
    n: Option<usize>,
    bytes: &[u8],
) -> Bound<'py, PyAny> {
    let (array, ptr) = empty(py, layout, n);
    assert_eq!(
        bytes.len(),
        n.unwrap_or(1) * layout.bytes,
        "bytes for the shape"
    );
    // SAFETY: the array was allocated for exactly this many bytes and nothing else sees it yet.
    unsafe { copy_into(ptr, bytes) };
    array
}

/// Copies `bytes` to the address `dst` (from [`empty`], of at least that many bytes).
///
/// # Safety
/// `dst` must be valid for `bytes.len()` bytes of writes and not be read meanwhile.
pub(crate) unsafe fn copy_into(dst: usize, bytes: &[u8]) {
    // SAFETY: as the caller guarantees; `bytes` cannot overlap a fresh allocation.
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), dst as *mut u8, bytes.len()) };
}

/// The bytes of a C-contiguous array, copied (actions: small, and copying keeps another
/// Python thread from changing them while the GIL is released).
pub(crate) fn bytes_of(array: &Bound<'_, numpy::PyUntypedArray>) -> Option<Vec<u8>> {
    if !array.is_c_contiguous() {
        return None;
    }
    let len = array.len() * numpy::PyUntypedArrayMethods::dtype(array).itemsize();
    // SAFETY: a C-contiguous array's data holds `len` bytes; we hold the GIL while copying.
    let data = unsafe { (*_PyArray_GET_ITEM_DATA(array.as_array_ptr())).data };
    if len == 0 {
        return Some(Vec::new());
    }
    // SAFETY: as above.
    Some(unsafe { std::slice::from_raw_parts(data.cast::<u8>(), len) }.to_vec())
}

/// The numpy dtype of a layout's values (`uint8` for raw bytes).
pub(crate) fn dtype_of<'py>(
    py: Python<'py>,
    layout: &ArrayLayout,
) -> Bound<'py, numpy::PyArrayDescr> {
    with_dtype!(layout.dtype, T => numpy::dtype::<T>(py))
}

/// A writeable array of `descr`'s dtype with shape `dims` and byte `strides`, viewing the
/// memory at `ptr`, with `base` as its base object.
///
/// # Safety
/// Every element the shape and strides reach from `ptr` must be valid memory, aligned for
/// the dtype and holding valid values of it, that stays valid and is written by no one else
/// while `base` lives.
pub(crate) unsafe fn strided_view<'py>(
    py: Python<'py>,
    descr: &Bound<'py, PyArrayDescr>,
    dims: &[isize],
    strides: &[isize],
    ptr: *mut u8,
    base: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    assert_eq!(dims.len(), strides.len(), "a stride per dimension");
    let mut dims = dims.to_vec();
    let mut strides = strides.to_vec();
    // SAFETY: the descr reference is stolen by the call (hence `into_dtype_ptr`, a new
    // reference); dims and strides outlive it; the caller guarantees the memory.
    let array = unsafe {
        PY_ARRAY_API.PyArray_NewFromDescr(
            py,
            get_type_object(py, NpyTypes::PyArray_Type),
            descr.clone().into_dtype_ptr(),
            dims.len() as std::ffi::c_int,
            dims.as_mut_ptr(),
            strides.as_mut_ptr(),
            ptr.cast(),
            NPY_ARRAY_WRITEABLE,
            std::ptr::null_mut(),
        )
    };
    if array.is_null() {
        return Err(PyErr::fetch(py));
    }
    // SAFETY: `array` is a new reference to an array we own.
    let array = unsafe { Bound::from_owned_ptr(py, array) };
    // SAFETY: `array` is an ndarray without a base; the call steals the new reference to
    // `base`.
    if unsafe {
        PY_ARRAY_API.PyArray_SetBaseObject(py, array.as_ptr().cast(), base.clone().into_ptr())
    } != 0
    {
        return Err(PyErr::fetch(py));
    }
    Ok(array)
}

/// The address of an array's data.
pub(crate) fn data_ptr(array: &Bound<'_, numpy::PyUntypedArray>) -> *mut u8 {
    // SAFETY: reads the data pointer of a live array while holding the GIL.
    unsafe { (*_PyArray_GET_ITEM_DATA(array.as_array_ptr())).data.cast() }
}

/// `bytes` copied into 8-byte words (so views of any dtype over them are aligned), the last
/// word zero-padded.
pub(crate) fn words_of(bytes: &[u8]) -> Vec<u64> {
    let mut words = vec![0u64; bytes.len().div_ceil(8)];
    // SAFETY: `words` holds at least `bytes.len()` bytes, and a fresh allocation cannot
    // overlap `bytes`.
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), words.as_mut_ptr().cast(), bytes.len())
    };
    words
}

/// An array of `n` values of `layout` (one value without a leading axis when `n` is `None`)
/// over `words` (from [`words_of`]), which the array takes over: no copy.
pub(crate) fn owned<'py>(
    py: Python<'py>,
    layout: &ArrayLayout,
    n: Option<usize>,
    words: Vec<u64>,
) -> PyResult<Bound<'py, PyAny>> {
    assert!(
        words.len() * 8 >= n.unwrap_or(1) * layout.bytes,
        "words for the shape"
    );
    let base = numpy::PyArray1::<u64>::from_vec(py, words).into_any();
    let ptr = data_ptr(base.cast::<numpy::PyUntypedArray>()?);
    // SAFETY: `base` owns the words, which hold the shape's bytes, 8-byte aligned, and
    // nothing else reads or writes them; the values are the bytes a worker wrote for this
    // dtype, as a view of the slot has them.
    unsafe { view(layout, n, ptr, base) }
}
