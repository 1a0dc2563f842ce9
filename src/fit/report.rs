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

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use image::{DynamicImage, RgbImage};
use image::{EncodableLayout, ImageBuffer, PixelWithColorType, Rgb, Rgba, RgbaImage};

use crate::error::{Error, Result};
use crate::io::AtomicFile;

/// Contact sheet: a pixel inside both the prediction and the target.
pub const BOTH: Rgba<u8> = Rgba([255, 255, 255, 255]);
/// Contact sheet: a pixel inside the prediction only (the mesh covers too much).
pub const PREDICTED_ONLY: Rgba<u8> = Rgba([230, 40, 40, 255]);
/// Contact sheet: a pixel inside the target only (the mesh covers too little).
pub const TARGET_ONLY: Rgba<u8> = Rgba([0, 190, 210, 255]);
/// Contact sheet: a pixel inside neither.
pub const NEITHER: Rgba<u8> = Rgba([24, 24, 24, 255]);
/// Contact sheet: the 1-pixel gaps between tiles and around the sheet.
pub const GAP: Rgba<u8> = Rgba([90, 90, 90, 255]);
/// Contact sheet: the filled part of an IoU bar.
pub const IOU_FILL: Rgba<u8> = Rgba([80, 200, 110, 255]);
/// Contact sheet: the unfilled part of an IoU bar.
pub const IOU_EMPTY: Rgba<u8> = Rgba([50, 50, 50, 255]);
/// Height of the IoU bar under each tile, in pixels (below a 1-pixel gap).
pub const IOU_BAR_HEIGHT: u32 = 3;

/// A contact sheet of `views` silhouettes, predicted against target, `columns` tiles per row
/// (clamped to `1..=views`), every pixel coloured by where it is: [`BOTH`], [`PREDICTED_ONLY`],
/// [`TARGET_ONLY`] or [`NEITHER`]. A predicted value is a soft alpha, inside when > 0.5; a
/// target value likewise (targets are 0 or 1).
///
/// `pred` and `target` are view-major, row-major, `width × height` per view (the layout of the
/// silhouette losses); only the first `views` views are read. With `iou`, a bar of
/// [`IOU_BAR_HEIGHT`] pixels under each tile is filled in proportion to that view's IoU
/// (clamped to [0, 1]; NaN leaves it empty).
///
/// Layout: tiles and bars are separated from each other and from the border by 1-pixel
/// [`GAP`]s, so view `v`'s tile starts at `(1 + (v % c)(width + 1), 1 + (v / c)(cell + 1))` with
/// `c` the columns and `cell` = `height`, or `height + 1 + IOU_BAR_HEIGHT` with bars. Opaque
/// throughout, so it can be a GIF frame.
///
/// # Panics
/// When `pred` or `target` hold fewer than `views · width · height` values, or `iou` fewer than
/// `views`: a caller's bug, not a user's input.
pub fn contact_sheet(
    pred: &[f32],
    target: &[f32],
    views: usize,
    width: u32,
    height: u32,
    columns: u32,
    iou: Option<&[f32]>,
) -> RgbaImage {
    let pixels = width as usize * height as usize;
    assert!(
        pred.len() >= views * pixels && target.len() >= views * pixels,
        "contact_sheet: {} predicted and {} target values for {views} views of {width}×{height}",
        pred.len(),
        target.len()
    );
    if let Some(iou) = iou {
        assert!(
            iou.len() >= views,
            "contact_sheet: {} IoUs for {views} views",
            iou.len()
        );
    }
    let (columns, rows, cell_w, cell_h) = sheet_grid(views, width, height, columns, iou.is_some());
    let mut sheet = RgbaImage::from_pixel(1 + columns * (cell_w + 1), 1 + rows * (cell_h + 1), GAP);
    for v in 0..views {
        let (x0, y0) = tile_origin(v, columns, cell_w, cell_h);
        let p = &pred[v * pixels..(v + 1) * pixels];
        let t = &target[v * pixels..(v + 1) * pixels];
        for y in 0..height {
            for x in 0..width {
                let i = (y * width + x) as usize;
                let colour = match (p[i] > 0.5, t[i] > 0.5) {
                    (true, true) => BOTH,
                    (true, false) => PREDICTED_ONLY,
                    (false, true) => TARGET_ONLY,
                    (false, false) => NEITHER,
                };
                sheet.put_pixel(x0 + x, y0 + y, colour);
            }
        }
        if let Some(iou) = iou {
            let value = if iou[v].is_nan() {
                0.0
            } else {
                iou[v].clamp(0.0, 1.0)
            };
            let filled = (f64::from(value) * f64::from(width)).round() as u32;
            for y in 0..IOU_BAR_HEIGHT {
                for x in 0..width {
                    let colour = if x < filled { IOU_FILL } else { IOU_EMPTY };
                    sheet.put_pixel(x0 + x, y0 + height + 1 + y, colour);
                }
            }
        }
    }
    sheet
}

/// The final contact sheet of a fit, for people to read: every view's tile `scale` times the
/// view's size (nearest neighbour: a silhouette's pixels stay visible), coloured as
/// [`contact_sheet`]'s, with a label under it, `"<v>: IoU <iou>"` (IoU to three decimals), in
/// the plots' typeface (larger from a scale of 3 up). `columns` as [`contact_sheet`]'s; opaque.
///
/// # Panics
/// As [`contact_sheet`] (a caller's bug), or for a zero scale.
#[allow(clippy::too_many_arguments)]
pub fn labelled_contact_sheet(
    pred: &[f32],
    target: &[f32],
    ious: &[f32],
    views: usize,
    width: u32,
    height: u32,
    columns: u32,
    scale: u32,
) -> RgbImage {
    assert!(scale >= 1, "labelled_contact_sheet: scale 0");
    let small = contact_sheet(pred, target, views, width, height, columns, None);
    let text_px = if scale >= 3 { 15 } else { 11 };
    let label_h = text_px + 7;
    let (columns, rows, _, _) = sheet_grid(views, width, height, columns, false);
    let (tile_w, tile_h) = (width * scale, height * scale);
    let (cell_w, cell_h) = (tile_w, tile_h + label_h);
    let gap = Rgb([GAP[0], GAP[1], GAP[2]]);
    let mut sheet = RgbImage::from_pixel(1 + columns * (cell_w + 1), 1 + rows * (cell_h + 1), gap);
    let mut labels = Vec::with_capacity(views);
    for (v, iou) in ious.iter().enumerate().take(views) {
        let (sx, sy) = tile_origin(v, columns, width, height);
        let (x0, y0) = tile_origin(v, columns, cell_w, cell_h);
        for y in 0..tile_h {
            for x in 0..tile_w {
                let p = small.get_pixel(sx + x / scale, sy + y / scale);
                sheet.put_pixel(x0 + x, y0 + y, Rgb([p[0], p[1], p[2]]));
            }
        }
        for y in tile_h..cell_h {
            for x in 0..cell_w {
                sheet.put_pixel(x0 + x, y0 + y, LABEL_BACKGROUND);
            }
        }
        labels.push((x0 + 3, y0 + tile_h + 3, format!("{v}: IoU {iou:.3}")));
    }
    draw_labels(&mut sheet, &labels, text_px);
    sheet
}

/// Renders placed side by side, each `width × height` RGBA (row 0 at the top, values in [0, 1],
/// composited over black) with its name above it in the plots' typeface: one frame of a
/// turntable, or a before/after.
///
/// # Panics
/// When an image holds fewer than `width · height` pixels (a caller's bug).
pub fn side_by_side(images: &[(&str, &[[f32; 4]])], width: u32, height: u32) -> RgbaImage {
    let text_px = 11;
    let label_h = text_px + 3;
    let n = images.len().max(1) as u32;
    let mut frame =
        RgbImage::from_pixel(n * width + (n + 1), height + label_h + 1, LABEL_BACKGROUND);
    let mut labels = Vec::with_capacity(images.len());
    for (i, (name, pixels)) in images.iter().enumerate() {
        assert!(
            pixels.len() >= (width * height) as usize,
            "side_by_side: {} pixels for {width}×{height}",
            pixels.len()
        );
        let x0 = 1 + i as u32 * (width + 1);
        for y in 0..height {
            for x in 0..width {
                let p = pixels[(y * width + x) as usize];
                let c = |v: f32| (v.clamp(0.0, 1.0) * p[3].clamp(0.0, 1.0) * 255.0).round() as u8;
                frame.put_pixel(x0 + x, label_h + y, Rgb([c(p[0]), c(p[1]), c(p[2])]));
            }
        }
        labels.push((x0 + 2, 1, (*name).to_string()));
    }
    draw_labels(&mut frame, &labels, text_px);
    DynamicImage::ImageRgb8(frame).to_rgba8()
}

/// Behind the labels of [`labelled_contact_sheet`] and [`side_by_side`].
pub const LABEL_BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);
/// The labels' ink.
pub const LABEL_INK: Rgb<u8> = Rgb([235, 235, 235]);

/// Columns (clamped to `1..=views`), rows, and a cell's width and height (tile, and bar).
fn sheet_grid(
    views: usize,
    width: u32,
    height: u32,
    columns: u32,
    bars: bool,
) -> (u32, u32, u32, u32) {
    let views = u32::try_from(views).unwrap_or(u32::MAX);
    let columns = columns.clamp(1, views.max(1));
    let rows = views.div_ceil(columns);
    let cell_h = if bars {
        height + 1 + IOU_BAR_HEIGHT
    } else {
        height
    };
    (columns, rows, width, cell_h)
}

/// Top-left pixel of view `v`'s tile.
fn tile_origin(v: usize, columns: u32, cell_w: u32, cell_h: u32) -> (u32, u32) {
    let v = v as u32;
    (
        1 + (v % columns) * (cell_w + 1),
        1 + (v / columns) * (cell_h + 1),
    )
}

/// One line of a [`loss_plot`].
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Shown in the legend beside a swatch of `color`.
    pub name: String,
    /// `(iteration, value)` pairs, in drawing order. A pair with a non-finite (or beyond
    /// ±1e300) coordinate, or on a log axis a value ≤ 0, is left out and breaks the line there.
    pub points: Vec<(f64, f64)>,
    /// The line's colour.
    pub color: [u8; 3],
}

/// The plot's background.
pub const PLOT_BACKGROUND: Rgb<u8> = Rgb([255, 255, 255]);

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

/// A line chart of loss curves, drawn by plotters: `value` against `iteration` for each series
/// on a white background, with a labelled grid (`iteration` on x, `loss` on y) and a legend of
/// the series that have a drawable point.
///
/// With `log_y` the y axis is logarithmic: values ≤ 0 cannot be placed and are left out,
/// breaking the line there, and the axis spans whole decades around the positive values.
/// Non-finite values (and any beyond ±1e300) are left out on either axis. A point with no
/// drawable neighbour is drawn as a small square, so a single value still shows. Series may be
/// empty; with no drawable point at all the axes span [0, 1] (1 to 10 with `log_y`). Too small
/// an image gives what fits, never a panic.
pub fn loss_plot(series: &[Series], width: u32, height: u32, log_y: bool) -> RgbImage {
    let (w, h) = (width.max(1), height.max(1));
    let mut img = RgbImage::from_pixel(w, h, PLOT_BACKGROUND);
    let drawable = |&(x, y): &(f64, f64)| {
        x.is_finite()
            && y.is_finite()
            && x.abs() <= 1e300
            && y.abs() <= 1e300
            && (!log_y || y > 0.0)
    };
    // Each series as runs of consecutive drawable points.
    let runs: Vec<Vec<Vec<(f64, f64)>>> = series
        .iter()
        .map(|s| {
            s.points
                .split(|p| !drawable(p))
                .filter(|run| !run.is_empty())
                .map(<[(f64, f64)]>::to_vec)
                .collect()
        })
        .collect();
    let all = runs.iter().flatten().flatten();
    let span = |values: &mut dyn Iterator<Item = f64>| {
        values.fold(None, |r: Option<(f64, f64)>, v| {
            Some(r.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))))
        })
    };
    let (x0, x1) = widen(span(&mut all.clone().map(|p| p.0)).unwrap_or((0.0, 1.0)));
    let ys = span(&mut all.map(|p| p.1));
    let font = typeface();
    let root = plotters::prelude::IntoDrawingArea::into_drawing_area(
        plotters::prelude::BitMapBackend::with_buffer(&mut img, (w, h)),
    );
    // Drawing into memory fails only where the image is too small for the layout: what fits
    // is kept.
    let _ = if log_y {
        let (lo, hi) = ys.unwrap_or((1.0, 10.0));
        let (lo, hi) = (
            10f64.powf(lo.log10().floor()),
            10f64.powf(hi.log10().ceil()),
        );
        let hi = if hi > lo { hi } else { lo * 10.0 };
        draw_chart(
            &root,
            font,
            x0..x1,
            plotters::prelude::IntoLogRange::log_scale(lo..hi),
            series,
            &runs,
        )
    } else {
        let (lo, hi) = widen(ys.unwrap_or((0.0, 1.0)));
        draw_chart(&root, font, x0..x1, lo..hi, series, &runs)
    };
    let _ = root.present();
    drop(root);
    img
}

/// A range with room: a single value becomes ±0.5 (or ±5 % of it) around it.
fn widen((lo, hi): (f64, f64)) -> (f64, f64) {
    if hi > lo {
        (lo, hi)
    } else {
        let d = if lo == 0.0 { 0.5 } else { 0.05 * lo.abs() };
        (lo - d, hi + d)
    }
}

type Area<'a> =
    plotters::drawing::DrawingArea<plotters::prelude::BitMapBackend<'a>, plotters::coord::Shift>;

/// [`loss_plot`]'s chart over either kind of y axis.
fn draw_chart<Y>(
    root: &Area<'_>,
    font: &'static str,
    x: std::ops::Range<f64>,
    y: Y,
    series: &[Series],
    runs: &[Vec<Vec<(f64, f64)>>],
) -> std::result::Result<(), Box<dyn std::error::Error>>
where
    Y: plotters::coord::ranged1d::AsRangedCoord<Value = f64>,
    Y::CoordDescType: plotters::coord::ranged1d::ValueFormatter<f64>,
{
    use plotters::prelude::*;
    let mut chart = ChartBuilder::on(root)
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc("iteration")
        .y_desc("loss")
        .x_label_formatter(&|v| format!("{v}"))
        .label_style((font, 13.0))
        .axis_desc_style((font, 14.0))
        .draw()?;
    let mut legend = false;
    for (s, runs) in series.iter().zip(runs) {
        let color = RGBColor(s.color[0], s.color[1], s.color[2]);
        for (k, run) in runs.iter().enumerate() {
            let drawn = if run.len() == 1 {
                chart.draw_series(run.iter().map(|&p| {
                    EmptyElement::at(p) + Rectangle::new([(-2, -2), (2, 2)], color.filled())
                }))?
            } else {
                chart.draw_series(LineSeries::new(run.iter().copied(), color.stroke_width(2)))?
            };
            if k == 0 {
                legend = true;
                drawn.label(s.name.as_str()).legend(move |(x, y)| {
                    Rectangle::new([(x, y - 3), (x + 16, y + 3)], color.filled())
                });
            }
        }
    }
    if legend {
        chart
            .configure_series_labels()
            .label_font((font, 13.0))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
    }
    Ok(())
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

/// An animated GIF of a fit's progress, written frame by frame into a temporary file beside
/// the target and renamed into place by [`GifWriter::finish`]. Dropped unfinished (an error, an
/// interrupted fit), it leaves nothing behind.
///
/// Frames loop forever. A frame with at most 256 colours (a contact sheet has 8) keeps its
/// exact colours; others are quantized to 256 (NeuQuant).
pub struct GifWriter {
    // Declared before `file`, so it is dropped (and lets go of the temporary file) first.
    encoder: gif::Encoder<BufWriter<File>>,
    file: AtomicFile,
    width: u32,
    height: u32,
    delay_cs: u16,
    frames: usize,
}

impl GifWriter {
    /// Starts a GIF of `width × height` frames (each 1 to 65535, GIF's limit), shown
    /// `delay_ms` each: rounded to GIF's unit of 10 ms, and at least 20 ms, since browsers show
    /// shorter delays as 100 ms.
    pub fn create(path: &Path, width: u32, height: u32, delay_ms: u32) -> Result<GifWriter> {
        let dims = (u16::try_from(width), u16::try_from(height));
        let (Ok(w), Ok(h)) = dims else {
            return Err(Error::Input(format!(
                "GIF {}: {width}×{height} frames exceed GIF's 65535 × 65535",
                path.display()
            )));
        };
        if w == 0 || h == 0 {
            return Err(Error::Input(format!(
                "GIF {}: {width}×{height} frames are empty",
                path.display()
            )));
        }
        let mut file = AtomicFile::create(path)?;
        let sink = BufWriter::new(file.take_file());
        let mut encoder = gif::Encoder::new(sink, w, h, &[]).map_err(|e| gif_error(&file, e))?;
        encoder
            .set_repeat(gif::Repeat::Infinite)
            .map_err(|e| gif_error(&file, e))?;
        let delay_cs = (delay_ms.saturating_add(5) / 10).clamp(2, u32::from(u16::MAX)) as u16;
        Ok(GifWriter {
            encoder,
            file,
            width,
            height,
            delay_cs,
            frames: 0,
        })
    }

    /// Appends a frame; it must have the size given to [`GifWriter::create`].
    pub fn push(&mut self, frame: &RgbaImage) -> Result<()> {
        if frame.dimensions() != (self.width, self.height) {
            return Err(Error::Input(format!(
                "GIF {}: a {}×{} frame in a {}×{} animation",
                self.file.target().display(),
                frame.width(),
                frame.height(),
                self.width,
                self.height
            )));
        }
        let mut rgba = frame.as_raw().clone();
        // Speed 10 of 1..=30, gif's default: only used past 256 colours.
        let mut f =
            gif::Frame::from_rgba_speed(self.width as u16, self.height as u16, &mut rgba, 10);
        f.delay = self.delay_cs;
        f.dispose = gif::DisposalMethod::Keep;
        self.encoder
            .write_frame(&f)
            .map_err(|e| gif_error(&self.file, e))?;
        self.frames += 1;
        Ok(())
    }

    /// Frames pushed so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Ends the GIF and moves it into place. With no frame pushed, fails and writes nothing.
    pub fn finish(self) -> Result<()> {
        let GifWriter {
            encoder,
            file,
            frames,
            ..
        } = self;
        if frames == 0 {
            return Err(Error::Input(format!(
                "GIF {}: no frame to write",
                file.target().display()
            )));
        }
        let sink = encoder.into_inner().map_err(|e| gif_error(&file, e))?;
        let inner = sink.into_inner().map_err(|e| file.io(e.into_error()))?;
        file.persist(inner)
    }
}

fn gif_error(file: &AtomicFile, e: gif::EncodingError) -> Error {
    match e {
        gif::EncodingError::Io(e) => file.io(e),
        e => Error::Input(format!("GIF {}: {e}", file.target().display())),
    }
}

impl std::fmt::Debug for GifWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GifWriter")
            .field("target", &self.file.target())
            .field("width", &self.width)
            .field("height", &self.height)
            .field("frames", &self.frames)
            .finish()
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_map_runs_black_red_yellow_white() {
        let t = [[0.0f32; 4]; 4];
        let r = [
            [0.0; 4],
            [1.0 / 3.0; 4],
            [2.0 / 3.0; 4],
            [1.0, 1.0, 1.0, 1.0],
        ];
        let m = error_map(&r, &t);
        let close = |a: [f32; 4], b: [f32; 4]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert!(close(m[0], [0.0, 0.0, 0.0, 1.0]));
        assert!(close(m[1], [1.0, 0.0, 0.0, 1.0]));
        assert!(close(m[2], [1.0, 1.0, 0.0, 1.0]));
        assert!(close(m[3], [1.0, 1.0, 1.0, 1.0]));
    }

    use crate::io::test_support::TempDir;

    #[test]
    fn contact_sheet_colours_each_pixel_by_prediction_and_target() {
        // Three 3×2 views in two columns; per view, the four cases at known pixels.
        let (w, h) = (3u32, 2u32);
        #[rustfmt::skip]
        let pred = [
            0.9, 0.6, 0.1, 0.5, 0.0, 1.0, // view 0
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, // view 1
            1.0, 1.0, 1.0, 1.0, 1.0, 1.0, // view 2
        ];
        #[rustfmt::skip]
        let target = [
            1.0, 0.0, 1.0, 0.0, 1.0, 0.0,
            1.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            1.0, 1.0, 1.0, 1.0, 1.0, 0.0,
        ];
        let iou = [0.0, 0.5, 1.5];
        let sheet = contact_sheet(&pred, &target, 3, w, h, 2, Some(&iou));
        let cell_h = h + 1 + IOU_BAR_HEIGHT;
        assert_eq!(sheet.dimensions(), (1 + 2 * (w + 1), 1 + 2 * (cell_h + 1)));

        let px = |x: u32, y: u32| *sheet.get_pixel(x, y);
        // View 0 at (1, 1): both, predicted only, target only; neither (0.5 is not inside),
        // target only, predicted only.
        assert_eq!(
            [px(1, 1), px(2, 1), px(3, 1), px(1, 2), px(2, 2), px(3, 2)],
            [
                BOTH,
                PREDICTED_ONLY,
                TARGET_ONLY,
                NEITHER,
                TARGET_ONLY,
                PREDICTED_ONLY
            ]
        );
        // View 1 at (5, 1), view 2 at (1, 1 + cell_h + 1).
        assert_eq!(
            [px(5, 1), px(6, 1), px(7, 2)],
            [TARGET_ONLY, NEITHER, NEITHER]
        );
        let y2 = 2 + cell_h;
        assert_eq!([px(1, y2), px(3, y2 + 1)], [BOTH, PREDICTED_ONLY]);
        // Gaps: the border, between tiles, between a tile and its bar.
        for (x, y) in [(0, 0), (4, 1), (8, 1), (1, 3), (1, 1 + cell_h), (5, y2)] {
            assert_eq!(px(x, y), GAP, "({x}, {y})");
        }
        // The missing fourth view is all gap.
        assert_eq!(px(6, y2 + 1), GAP);
        // Bars under the tiles: IoU 0 → empty, 0.5 of 3 pixels → 2 (rounded), 1.5 → full.
        let bar = |x0: u32, y: u32| -> Vec<Rgba<u8>> { (x0..x0 + w).map(|x| px(x, y)).collect() };
        for dy in 0..IOU_BAR_HEIGHT {
            assert_eq!(bar(1, 4 + dy), [IOU_EMPTY; 3]);
            assert_eq!(bar(5, 4 + dy), [IOU_FILL, IOU_FILL, IOU_EMPTY]);
            assert_eq!(bar(1, y2 + h + 1 + dy), [IOU_FILL; 3]);
        }
        assert!(sheet.pixels().all(|p| p.0[3] == 255), "opaque");
    }

    #[test]
    fn contact_sheet_without_bars_clamps_columns_and_reads_only_its_views() {
        let pred = vec![1.0f32; 5 * 4];
        let target = vec![0.0f32; 5 * 4];
        // 4 views asked of 5 given, 9 columns clamped to 4, no bars: one row of 2×2 tiles.
        let sheet = contact_sheet(&pred, &target, 4, 2, 2, 9, None);
        assert_eq!(sheet.dimensions(), (1 + 4 * 3, 1 + 3));
        assert_eq!(*sheet.get_pixel(11, 2), PREDICTED_ONLY);
        assert_eq!(*sheet.get_pixel(12, 2), GAP);
        // Degenerate but no panic: zero views, zero columns.
        assert_eq!(
            contact_sheet(&[], &[], 0, 2, 2, 0, None).dimensions(),
            (4, 1)
        );
    }

    #[test]
    #[should_panic(expected = "3 predicted and 8 target values for 2 views of 2×2")]
    fn contact_sheet_panics_on_short_inputs() {
        contact_sheet(&[0.0; 3], &[0.0; 8], 2, 2, 2, 1, None);
    }

    fn line(name: &str, color: [u8; 3], points: &[(f64, f64)]) -> Series {
        Series {
            name: name.into(),
            points: points.to_vec(),
            color,
        }
    }

    const RED: [u8; 3] = [200, 0, 0];
    const BLUE: [u8; 3] = [0, 0, 200];

    /// Pixels of exactly `colour`.
    fn count(img: &RgbImage, colour: [u8; 3]) -> usize {
        img.pixels().filter(|p| p.0 == colour).count()
    }

    /// Pixels of neither the background nor a series' colour: text, grid, frame.
    fn ink(img: &RgbImage) -> usize {
        img.pixels()
            .filter(|p| p.0 != PLOT_BACKGROUND.0 && p.0 != RED && p.0 != BLUE)
            .count()
    }

    #[test]
    fn loss_plot_has_its_size_background_axes_and_each_series_in_its_colour() {
        let series = [
            line("silhouette", RED, &[(0.0, 1.0), (50.0, 0.4), (100.0, 0.2)]),
            line("laplacian", BLUE, &[(0.0, 0.05), (100.0, 0.1)]),
        ];
        let (w, h) = (480, 300);
        for log_y in [false, true] {
            let img = loss_plot(&series, w, h, log_y);
            assert_eq!(img.dimensions(), (w, h));
            assert_eq!(*img.get_pixel(0, 0), PLOT_BACKGROUND);
            assert_eq!(*img.get_pixel(w - 1, h - 1), PLOT_BACKGROUND);
            // Each line spans most of the plot's width (2-pixel strokes, plus its swatch in
            // the legend), and labels, ticks and the frame are drawn.
            for colour in [RED, BLUE] {
                let n = count(&img, colour);
                assert!(n > w as usize / 2, "log {log_y}: {n} pixels of {colour:?}");
            }
            assert!(ink(&img) > 500, "log {log_y}: no axes or labels");
        }
        // The same inputs draw the same pixels.
        assert!(loss_plot(&series, w, h, true) == loss_plot(&series, w, h, true));
    }

    #[test]
    fn log_y_leaves_out_non_positive_values() {
        // Only (2, 0.5) and (3, 0.25) are drawable on a log axis: one short line.
        let s = [line(
            "loss",
            RED,
            &[(0.0, -1.0), (1.0, 0.0), (2.0, 0.5), (3.0, 0.25)],
        )];
        let log = loss_plot(&s, 400, 300, true);
        let linear = loss_plot(&s, 400, 300, false);
        assert!(count(&log, RED) > 0);
        assert!(
            count(&linear, RED) > count(&log, RED),
            "linear draws all four points"
        );
    }

    #[test]
    fn degenerate_plots_do_not_panic() {
        let nan = line(
            "nan",
            RED,
            &[(f64::NAN, 1.0), (1.0, f64::INFINITY), (2.0, 1e308)],
        );
        let single = line("single", BLUE, &[(5.0, 0.3)]);
        let empty = line("empty", RED, &[]);
        for (w, h) in [(1, 1), (40, 20), (120, 80), (800, 500)] {
            for log_y in [false, true] {
                for s in [
                    &[][..],
                    std::slice::from_ref(&nan),
                    std::slice::from_ref(&single),
                    std::slice::from_ref(&empty),
                ] {
                    let img = loss_plot(s, w, h, log_y);
                    assert_eq!(img.dimensions(), (w, h));
                }
            }
        }
        // A single value still shows, as a small square.
        assert!(count(&loss_plot(&[single], 400, 300, false), BLUE) >= 9);
    }

    #[test]
    fn labels_are_drawn_in_the_label_ink_over_their_background() {
        let pixels = vec![[1.0f32, 1.0, 1.0, 1.0]; 32 * 24];
        let frame = side_by_side(&[("target", &pixels), ("result", &pixels)], 32, 24);
        assert_eq!(frame.dimensions(), (2 * 32 + 3, 24 + 14 + 1));
        let label_ink = (0..frame.width())
            .flat_map(|x| (0..14).map(move |y| (x, y)))
            .filter(|&(x, y)| frame.get_pixel(x, y).0[..3] != LABEL_BACKGROUND.0)
            .count();
        assert!(label_ink > 20, "no label text ({label_ink} pixels)");
        // The panels are the images, composited over black.
        assert_eq!(frame.get_pixel(1, 14).0, [255, 255, 255, 255]);
        assert_eq!(frame.get_pixel(1 + 33, 14 + 23).0, [255, 255, 255, 255]);

        let (pred, target) = (vec![1.0f32; 2 * 4 * 4], vec![1.0f32; 2 * 4 * 4]);
        let sheet = labelled_contact_sheet(&pred, &target, &[0.5, 1.0], 2, 4, 4, 2, 3);
        let (cell_w, cell_h) = (12, 12 + 22);
        assert_eq!(sheet.dimensions(), (1 + 2 * (cell_w + 1), 1 + cell_h + 1));
        assert_eq!(*sheet.get_pixel(1, 1), Rgb([BOTH[0], BOTH[1], BOTH[2]]));
        let text = (1..1 + cell_w)
            .flat_map(|x| (1 + 12..1 + cell_h).map(move |y| (x, y)))
            .filter(|&(x, y)| *sheet.get_pixel(x, y) != LABEL_BACKGROUND)
            .count();
        assert!(text > 10, "no IoU label under the first tile");
    }

    fn frames_of(path: &Path) -> Vec<image::Frame> {
        use image::AnimationDecoder;
        let file = std::io::BufReader::new(File::open(path).unwrap());
        image::codecs::gif::GifDecoder::new(file)
            .unwrap()
            .into_frames()
            .collect_frames()
            .unwrap()
    }

    fn sheet(i: usize) -> RgbaImage {
        let pred: Vec<f32> = (0..24)
            .map(|p| if (p + i) % 3 == 0 { 1.0 } else { 0.0 })
            .collect();
        let target: Vec<f32> = (0..24)
            .map(|p| if p % 2 == 0 { 1.0 } else { 0.0 })
            .collect();
        contact_sheet(&pred, &target, 2, 4, 3, 2, Some(&[0.25 * i as f32, 0.5]))
    }

    #[test]
    fn gif_decodes_to_the_pushed_frames_with_their_exact_colours() {
        let dir = TempDir::new("gif");
        let path = dir.path("progress.gif");
        let frames: Vec<RgbaImage> = (0..4).map(sheet).collect();
        let (w, h) = frames[0].dimensions();
        let mut gif = GifWriter::create(&path, w, h, 120).unwrap();
        assert!(!path.exists(), "nothing at the target before finish");
        for f in &frames {
            gif.push(f).unwrap();
        }
        assert_eq!(gif.frames(), 4);
        gif.finish().unwrap();
        assert_eq!(dir.entries(), ["progress.gif"], "no temporary file left");

        let decoded = frames_of(&path);
        assert_eq!(decoded.len(), 4);
        for (d, f) in decoded.iter().zip(&frames) {
            assert_eq!(d.buffer().dimensions(), (w, h));
            assert_eq!(d.buffer(), f, "few colours are kept exactly");
            assert_eq!(d.delay().numer_denom_ms(), (120, 1));
        }
    }

    #[test]
    fn gif_with_many_colours_and_short_delays_still_decodes() {
        let dir = TempDir::new("gif-many");
        let path = dir.path("noise.gif");
        let (w, h) = (40, 30);
        let frame = RgbaImage::from_fn(w, h, |x, y| {
            Rgba([(x * 6) as u8, (y * 8) as u8, (x * y) as u8, 255])
        });
        let mut gif = GifWriter::create(&path, w, h, 1).unwrap();
        gif.push(&frame).unwrap();
        gif.push(&frame).unwrap();
        gif.finish().unwrap();
        let decoded = frames_of(&path);
        assert_eq!(decoded.len(), 2);
        assert_eq!(decoded[0].buffer().dimensions(), (w, h));
        assert_eq!(
            decoded[0].delay().numer_denom_ms(),
            (20, 1),
            "at least 20 ms"
        );
    }

    #[test]
    fn unfinished_or_failed_gifs_leave_nothing_behind() {
        let dir = TempDir::new("gif-fail");
        let path = dir.path("p.gif");
        let (w, h) = sheet(0).dimensions();
        let mut gif = GifWriter::create(&path, w, h, 100).unwrap();
        gif.push(&sheet(0)).unwrap();
        assert_eq!(dir.entries().len(), 1, "only the temporary file");
        drop(gif);
        assert_eq!(dir.entries(), Vec::<String>::new());

        let mut gif = GifWriter::create(&path, 9, 4, 100).unwrap();
        let e = gif.push(&RgbaImage::new(4, 9)).unwrap_err().to_string();
        assert!(
            e.contains("a 4×9 frame in a 9×4 animation") && e.contains("p.gif"),
            "{e}"
        );
        let e = gif.finish().unwrap_err().to_string();
        assert!(e.contains("no frame"), "{e}");
        assert_eq!(dir.entries(), Vec::<String>::new());

        for (w, h) in [(0, 4), (70_000, 4)] {
            assert!(matches!(
                GifWriter::create(&path, w, h, 100),
                Err(Error::Input(_))
            ));
        }
        assert!(matches!(
            GifWriter::create(&dir.path("missing/p.gif"), 9, 4, 100),
            Err(Error::Io { .. })
        ));
        assert_eq!(dir.entries(), Vec::<String>::new());
    }

    #[test]
    fn write_png_round_trips_rgb_and_rgba_atomically() {
        let dir = TempDir::new("png");
        let plot = image::RgbImage::from_fn(120, 80, |x, y| Rgb([x as u8, y as u8, 7]));
        write_png(&dir.path("plot.png"), &plot).unwrap();
        let sheet = sheet(1);
        write_png(&dir.path("sheet.png"), &sheet).unwrap();
        assert_eq!(dir.entries(), ["plot.png", "sheet.png"]);
        assert_eq!(image::open(dir.path("plot.png")).unwrap().to_rgb8(), plot);
        let back = image::open(dir.path("sheet.png")).unwrap();
        assert_eq!(back.color(), image::ColorType::Rgba8);
        assert_eq!(back.to_rgba8(), sheet);
        assert!(matches!(
            write_png(&dir.path("missing/x.png"), &sheet),
            Err(Error::Io { .. })
        ));
        assert_eq!(dir.entries(), ["plot.png", "sheet.png"]);
    }
}
