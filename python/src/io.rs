//! Image files from Python: EXR read and written as float32 RGBA (what the `softvk` command
//! line writes and reads), PNG read as float32 RGB and written as 8 bits; a file written
//! appears whole or not at all ([`AtomicFile`]).

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use softvk::atomic_file::AtomicFile;
use softvk::exr_io::{encode_rgba, read_rgba};

use crate::convert::checked;
use crate::error::{to_py, value_error};

/// `read_exr(path)`: the first RGBA layer of an EXR (what `softvk render --out X.exr` writes)
/// as float32 `[H, W, 4]`, row 0 at the top; missing channels read as 0.
#[pyfunction]
pub(crate) fn read_exr<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
) -> PyResult<Bound<'py, PyAny>> {
    let (width, height, pixels) = py.detach(|| read_rgba(&path)).map_err(to_py)?;
    let flat = pixels.into_flattened();
    Ok(flat
        .into_pyarray(py)
        .reshape([height as usize, width as usize, 4])?
        .into_any())
}

/// `write_exr(path, image)`: float32 `[H, W, 4]` RGBA (row 0 at the top) as a lossless EXR, the
/// format `softvk grad --weights` reads; the file appears whole or not at all.
#[pyfunction]
pub(crate) fn write_exr(
    path: std::path::PathBuf,
    image: PyReadonlyArrayDyn<'_, f32>,
) -> PyResult<()> {
    let (data, shape) = checked("image", &image, &[None, None, Some(4)])?;
    let too_large = || value_error(format!("image of shape {shape:?} is too large"));
    let width = u32::try_from(shape[1]).map_err(|_| too_large())?;
    let height = u32::try_from(shape[0]).map_err(|_| too_large())?;
    let bytes = encode_rgba(bytemuck::cast_slice(data), width, height)
        .map_err(|e| value_error(format!("{}: {e}", path.display())))?;
    AtomicFile::create(&path)
        .and_then(|file| file.commit(&bytes))
        .map_err(to_py)
}

/// `read_rgb(path)`: an image (PNG, 8 or 16 bits, any colour type) as float32 `[H, W, 3]` in
/// [0, 1], row 0 at the top: grey replicated to RGB, alpha dropped, as SoftRas reads textures.
#[pyfunction]
pub(crate) fn read_rgb<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
) -> PyResult<Bound<'py, PyAny>> {
    let image = py
        .detach(|| image::open(&path).map(|i| i.to_rgb32f()))
        .map_err(|e| value_error(format!("{}: cannot read the image: {e}", path.display())))?;
    let (width, height) = image.dimensions();
    Ok(image
        .into_raw()
        .into_pyarray(py)
        .reshape([height as usize, width as usize, 3])?
        .into_any())
}

/// `write_png(path, image)`: uint8 `[H, W]`, `[H, W, 1]`, `[H, W, 3]` or `[H, W, 4]` as an 8-bit
/// PNG; the file appears whole or not at all.
#[pyfunction]
pub(crate) fn write_png(
    path: std::path::PathBuf,
    image: PyReadonlyArrayDyn<'_, u8>,
) -> PyResult<()> {
    use image::ImageEncoder;
    let shape = image.shape().to_vec();
    let channels = match shape.as_slice() {
        [_, _] => 1,
        [_, _, c] => *c,
        _ => 0,
    };
    let color = match channels {
        1 => image::ExtendedColorType::L8,
        3 => image::ExtendedColorType::Rgb8,
        4 => image::ExtendedColorType::Rgba8,
        _ => {
            return Err(value_error(format!(
                "a PNG needs [H, W] or [H, W, 1 | 3 | 4] bytes, got shape {shape:?}"
            )));
        }
    };
    let data = image
        .as_slice()
        .map_err(|_| value_error("the image is not C-contiguous".into()))?;
    let too_large = || value_error(format!("image of shape {shape:?} is too large"));
    let width = u32::try_from(shape[1]).map_err(|_| too_large())?;
    let height = u32::try_from(shape[0]).map_err(|_| too_large())?;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(data, width, height, color)
        .map_err(|e| value_error(format!("{}: cannot encode PNG: {e}", path.display())))?;
    AtomicFile::create(&path)
        .and_then(|file| file.commit(&bytes))
        .map_err(to_py)
}
