//! RGBA images as OpenEXR, the lossless float format `softvk render` writes and `softvk grad`
//! reads its weights from (and the Python package's `read_exr` / `write_exr`).

use std::io::Cursor;
use std::path::Path;

use crate::error::{Error, Result};

/// The first RGBA layer of an EXR: `(width, height, pixels)`, row-major, row 0 at the top.
/// Missing channels read as 0 (alpha too: a weight map for colour only may omit A).
pub fn read_rgba(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    use exr::prelude::{ReadChannels, ReadLayers, Vec2, read};
    if !path.exists() {
        return Err(Error::Input(format!("{}: no such file", path.display())));
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |size, _| (size.width(), vec![[0f32; 4]; size.area()]),
            |(w, px): &mut (usize, Vec<[f32; 4]>),
             p: Vec2<usize>,
             (r, g, b, a): (f32, f32, f32, f32)| {
                px[p.y() * *w + p.x()] = [r, g, b, a];
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| Error::Input(format!("{}: not a readable RGBA EXR: {e}", path.display())))?;
    let size = image.layer_data.size;
    let (_, pixels) = image.layer_data.channel_data.pixels;
    Ok((size.width() as u32, size.height() as u32, pixels))
}

/// The bytes of an EXR of `width` × `height` RGBA float pixels (row-major, row 0 at the top):
/// ZIP over scan lines, lossless for f32 (unlike PXR24 or B44) and readable by every OpenEXR
/// reader (some small ones skip tiled files). The error is the encoder's message.
pub fn encode_rgba(
    pixels: &[[f32; 4]],
    width: u32,
    height: u32,
) -> std::result::Result<Vec<u8>, String> {
    use exr::prelude::*;
    let w = width as usize;
    if pixels.len() != w * height as usize {
        return Err(format!(
            "{} pixels for a {width}x{height} image",
            pixels.len()
        ));
    }
    let channels = SpecificChannels::rgba(|p: Vec2<usize>| {
        let [r, g, b, a] = pixels[p.y() * w + p.x()];
        (r, g, b, a)
    });
    let image =
        Image::from_encoded_channels((w, height as usize), Encoding::SMALL_LOSSLESS, channels);
    let mut out = Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut out)
        .map_err(|e| format!("cannot encode EXR: {e}"))?;
    Ok(out.into_inner())
}
