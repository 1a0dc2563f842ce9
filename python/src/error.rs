//! softvk's errors as Python exceptions ([`to_py`]), and the `ValueError` of input this module
//! refuses itself ([`value_error`]).

use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use softvk::Error;

/// softvk's errors as Python exceptions: bad input is a `ValueError`, an allocation the device
/// cannot hold a `MemoryError`, the rest (no driver, no device, a device limit) `RuntimeError`;
/// the message is the engine's one line.
pub(crate) fn to_py(e: Error) -> PyErr {
    let message = format!("softvk: {e}");
    match e {
        Error::Input(_) | Error::Mesh(_) | Error::Render(_) | Error::Parse { .. } => {
            PyValueError::new_err(message)
        }
        // An input too large for the device (an image, a batch): refused before any work, as
        // the input's fault, the same ValueError as any other bad input.
        Error::Limit(_) | Error::DeviceLimit { .. } | Error::BufferTooLarge { .. } => {
            PyValueError::new_err(message)
        }
        Error::Allocation { .. } => PyMemoryError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

pub(crate) fn value_error(message: String) -> PyErr {
    PyValueError::new_err(format!("softvk: {message}"))
}
