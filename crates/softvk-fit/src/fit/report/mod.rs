//! What a fit shows a person: a contact sheet of predicted against target silhouettes
//! ([`contact_sheet`], and [`labelled_contact_sheet`] with each view's IoU), renders side by
//! side ([`side_by_side`]), a loss plot ([`loss_plot`]), an animated GIF of the progress
//! ([`GifWriter`]), and atomic PNG writing ([`write_png`]). All CPU, all deterministic: the same
//! inputs give the same pixels.
//!
//! The whole module is behind the `plots` feature (which the command line enables), so the
//! engine library alone pulls no plotting, font or GIF crate. Text and plots are drawn by
//! `plotters` in DejaVu Sans, embedded through the `dejavu` crate and registered with plotters'
//! `ab_glyph` engine, so no system font is looked up. Still hand-written, because no crate does
//! it: the contact sheet's per-pixel colouring (a few loops over the silhouettes), and the GIF
//! writer's atomic temporary file around the `gif` crate's encoder.

mod animation;
mod plot;
mod sheets;

#[cfg(test)]
mod tests;

pub use animation::GifWriter;
pub use plot::{PLOT_BACKGROUND, Series, loss_plot};
pub use sheets::{
    BOTH, GAP, IOU_BAR_HEIGHT, IOU_EMPTY, IOU_FILL, NEITHER, PREDICTED_ONLY, TARGET_ONLY,
    contact_sheet, labelled_contact_sheet, side_by_side,
};

use std::path::Path;

use image::RgbImage;
use image::{EncodableLayout, ImageBuffer, PixelWithColorType, Rgb};

use crate::error::Result;
use crate::io::AtomicFile;

/// Behind the labels of [`labelled_contact_sheet`] and [`side_by_side`].
pub const LABEL_BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);
/// The labels' ink.
pub const LABEL_INK: Rgb<u8> = Rgb([235, 235, 235]);

/// The typeface of every picture's text: DejaVu Sans, embedded in the binary by the `dejavu`
/// crate and registered once with plotters' `ab_glyph` engine, so nothing depends on the
/// machine's fonts (CI images have none) and every machine draws the same pixels.
fn typeface() -> &'static str {
    const NAME: &str = "softvk-dejavu-sans";
    static REGISTERED: std::sync::Once = std::sync::Once::new();
    REGISTERED.call_once(|| {
        let registered = plotters::style::register_font(
            NAME,
            plotters::style::FontStyle::Normal,
            dejavu::sans::regular(),
        );
        assert!(
            registered.is_ok(),
            "the embedded DejaVu Sans is a TrueType font"
        );
    });
    NAME
}

/// Draws `(x, y, text)` labels (top-left corners) onto `img` in [`LABEL_INK`], `px` pixels tall.
fn draw_labels(img: &mut RgbImage, labels: &[(u32, u32, String)], px: u32) {
    use plotters::prelude::*;
    let (w, h) = img.dimensions();
    let root = BitMapBackend::with_buffer(img, (w, h)).into_drawing_area();
    let ink = RGBColor(LABEL_INK[0], LABEL_INK[1], LABEL_INK[2]);
    let style = (typeface(), f64::from(px)).into_font().color(&ink);
    for (x, y, text) in labels {
        // Drawing into memory fails only for text past the image, which is clipped.
        let _ = root.draw_text(text, &style, (*x as i32, *y as i32));
    }
    let _ = root.present();
}

/// Writes an 8-bit (or 16-bit) image as PNG, atomically: a failed write leaves no file.
pub fn write_png<P>(path: &Path, image: &ImageBuffer<P, Vec<P::Subpixel>>) -> Result<()>
where
    P: PixelWithColorType,
    [P::Subpixel]: EncodableLayout,
{
    let file = AtomicFile::create(path)?;
    let bytes = crate::io::encode_png(
        image.as_raw().as_bytes(),
        image.width(),
        image.height(),
        P::COLOR_TYPE,
        path,
    )?;
    file.commit(&bytes)
}

/// |render − target| as a heat map: the mean absolute difference over R, G, B, A per pixel,
/// black (0) → red → yellow → white (1), opaque.
pub fn error_map(render: &[[f32; 4]], target: &[[f32; 4]]) -> Vec<[f32; 4]> {
    render
        .iter()
        .zip(target)
        .map(|(r, t)| {
            let e = (0..4).map(|k| (r[k] - t[k]).abs()).sum::<f32>() / 4.0;
            let x = e.clamp(0.0, 1.0) * 3.0;
            [
                x.min(1.0),
                (x - 1.0).clamp(0.0, 1.0),
                (x - 2.0).clamp(0.0, 1.0),
                1.0,
            ]
        })
        .collect()
}
