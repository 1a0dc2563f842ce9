//! What a fit shows a person: a contact sheet of predicted against target silhouettes
//! ([`contact_sheet`]), a loss plot ([`loss_plot`]), an animated GIF of the progress
//! ([`GifWriter`]), and atomic PNG writing ([`write_png`]). All CPU, all deterministic: the same
//! inputs give the same pixels.
//!
//! The plot's text is a hand-written 5×7 bitmap font (the [`font`] module) rather than
//! `plotters`: plotters draws text only through a font engine, either `ttf` (font-kit, which
//! finds fonts through the system's fontconfig and FreeType, absent on headless machines and
//! CI images) or `ab_glyph` (which needs a TTF file registered at run time, so one would ship
//! in the crate), and brings its own bitmap and GIF stack beside `image`. Axis labels need
//! digits, `.`, `-`, `e` and the series names; a table of ASCII glyphs is smaller than any of
//! that and renders identically everywhere.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use image::{
    DynamicImage, EncodableLayout, ImageBuffer, PixelWithColorType, Rgb, RgbImage, Rgba, RgbaImage,
};

use super::io::AtomicFile;
use crate::error::{Error, Result};

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
/// [`contact_sheet`]'s, with a label under it, `"<v>: IoU <iou>"` (IoU to three decimals), in the
/// plots' 5×7 font (doubled from a scale of 3 up). `columns` as [`contact_sheet`]'s; opaque.
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
    let text_scale: i64 = if scale >= 3 { 2 } else { 1 };
    let label_h = (font::HEIGHT * text_scale) as u32 + 6;
    let (columns, rows, _, _) = sheet_grid(views, width, height, columns, false);
    let (tile_w, tile_h) = (width * scale, height * scale);
    let (cell_w, cell_h) = (tile_w, tile_h + label_h);
    let gap = Rgb([GAP[0], GAP[1], GAP[2]]);
    let mut sheet = RgbImage::from_pixel(1 + columns * (cell_w + 1), 1 + rows * (cell_h + 1), gap);
    let bounds = Rect {
        x0: 0,
        y0: 0,
        x1: i64::from(sheet.width()) - 1,
        y1: i64::from(sheet.height()) - 1,
    };
    for (v, iou) in ious.iter().enumerate().take(views) {
        let (sx, sy) = tile_origin(v, columns, width, height);
        let (x0, y0) = tile_origin(v, columns, cell_w, cell_h);
        for y in 0..tile_h {
            for x in 0..tile_w {
                let p = small.get_pixel(sx + x / scale, sy + y / scale);
                sheet.put_pixel(x0 + x, y0 + y, Rgb([p[0], p[1], p[2]]));
            }
        }
        let label = format!("{v}: IoU {iou:.3}");
        let mut canvas = Canvas {
            img: &mut sheet,
            clip: Rect {
                x0: i64::from(x0),
                y0: i64::from(y0 + tile_h),
                x1: i64::from(x0 + cell_w) - 1,
                y1: i64::from(y0 + cell_h) - 1,
            }
            .within(&bounds),
        };
        canvas.fill(
            i64::from(x0),
            i64::from(y0 + tile_h),
            i64::from(x0 + cell_w) - 1,
            i64::from(y0 + cell_h) - 1,
            Rgb([24, 24, 24]),
        );
        canvas.text(
            i64::from(x0) + 3,
            i64::from(y0 + tile_h) + 3,
            &label,
            text_scale,
            Rgb([235, 235, 235]),
        );
    }
    sheet
}

/// Renders placed side by side, each `width × height` RGBA (row 0 at the top, values in [0, 1],
/// composited over black) with its name above it in the plots' font: one frame of a turntable.
///
/// # Panics
/// When an image holds fewer than `width · height` pixels (a caller's bug).
pub fn side_by_side(images: &[(&str, &[[f32; 4]])], width: u32, height: u32) -> RgbaImage {
    let label_h = font::HEIGHT as u32 + 6;
    let n = images.len().max(1) as u32;
    let mut frame =
        RgbImage::from_pixel(n * width + (n + 1), height + label_h + 1, Rgb([24, 24, 24]));
    let bounds = Rect {
        x0: 0,
        y0: 0,
        x1: i64::from(frame.width()) - 1,
        y1: i64::from(frame.height()) - 1,
    };
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
        let mut canvas = Canvas {
            img: &mut frame,
            clip: bounds,
        };
        canvas.text(i64::from(x0) + 2, 3, name, 1, Rgb([235, 235, 235]));
    }
    DynamicImage::ImageRgb8(frame).to_rgba8()
}

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
    /// Shown in the legend beside a swatch of `color`. Characters outside printable ASCII
    /// (and `×`, `λ`) are drawn as a box.
    pub name: String,
    /// `(iteration, value)` pairs, in drawing order. A pair with a non-finite (or beyond
    /// ±1e300) coordinate, or on a log axis a value ≤ 0, is left out and breaks the line there.
    pub points: Vec<(f64, f64)>,
    /// The line's colour.
    pub color: [u8; 3],
}

/// The plot's background.
pub const PLOT_BACKGROUND: Rgb<u8> = Rgb([255, 255, 255]);
/// Axes, ticks and labels.
pub const PLOT_INK: Rgb<u8> = Rgb([0, 0, 0]);
/// Grid lines at the major ticks.
pub const PLOT_GRID: Rgb<u8> = Rgb([228, 228, 228]);

/// A line chart of loss curves: `value` against `iteration` for each series, on a white
/// background with a frame, grid, ticks every 1, 2 or 5 × 10ᵏ (every decade with `log_y`, plus
/// unlabelled ticks at 2…9 × 10ᵏ when there is room), numeric tick labels, the x-axis title
/// `iteration`, and a legend above the plot (a swatch and the name of each series with one).
///
/// With `log_y`, values ≤ 0 cannot be placed: they are left out, breaking the line there, and
/// the axis spans whole decades around the positive values. Non-finite values (and any beyond
/// ±1e300) are left out on either axis. A point with no drawable neighbour is drawn as a small square, so a single
/// value still shows. Series may be empty; with no drawable point at all the axes span [0, 1]
/// (1 to 10 with `log_y`).
///
/// The font is 5×7 pixels, doubled when the image is at least 1000 × 640. Too small an image
/// (under about 120 × 80) gives what fits, never a panic.
pub fn loss_plot(series: &[Series], width: u32, height: u32, log_y: bool) -> RgbImage {
    let mut img = RgbImage::from_pixel(width.max(1), height.max(1), PLOT_BACKGROUND);
    let layout = PlotLayout::new(series, width, height, log_y);
    let s = layout.scale;
    let Rect { x0, y0, x1, y1 } = layout.plot;
    let mut canvas = Canvas {
        img: &mut img,
        clip: Rect {
            x0: 0,
            y0: 0,
            x1: i64::from(width) - 1,
            y1: i64::from(height) - 1,
        },
    };

    // Grid, then the frame over it.
    for t in &layout.x_ticks {
        let px = layout.x_pixel(t.value).round() as i64;
        canvas.vline(px, y0, y1, PLOT_GRID);
    }
    for t in layout.y_ticks.iter().filter(|t| t.label.is_some()) {
        let py = layout.y_pixel(t.value).round() as i64;
        canvas.hline(x0, x1, py, PLOT_GRID);
    }
    canvas.hline(x0, x1, y0, PLOT_INK);
    canvas.hline(x0, x1, y1, PLOT_INK);
    canvas.vline(x0, y0, y1, PLOT_INK);
    canvas.vline(x1, y0, y1, PLOT_INK);

    // Ticks and labels.
    let tick = 4 * s;
    for t in &layout.x_ticks {
        let px = layout.x_pixel(t.value).round() as i64;
        canvas.vline(px, y1, y1 + tick, PLOT_INK);
        if let Some(label) = &t.label {
            let w = font::text_width(label, s);
            canvas.text(px - w / 2, y1 + tick + 3 * s, label, s, PLOT_INK);
        }
    }
    for t in &layout.y_ticks {
        let py = layout.y_pixel(t.value).round() as i64;
        let len = if t.label.is_some() { tick } else { tick / 2 };
        canvas.hline(x0 - len, x0, py, PLOT_INK);
        if let Some(label) = &t.label {
            let w = font::text_width(label, s);
            canvas.text(
                x0 - tick - 3 * s - w,
                py - font::HEIGHT * s / 2,
                label,
                s,
                PLOT_INK,
            );
        }
    }
    let title = "iteration";
    canvas.text(
        (x0 + x1) / 2 - font::text_width(title, s) / 2,
        y1 + tick + 3 * s + font::LINE * s,
        title,
        s,
        PLOT_INK,
    );

    // The data, clipped to the inside of the frame.
    canvas.clip = Rect {
        x0: x0 + 1,
        y0: y0 + 1,
        x1: x1 - 1,
        y1: y1 - 1,
    };
    for series in series {
        let colour = Rgb(series.color);
        // Points land in the frame, except where a range overflows f64 (data near ±1e308):
        // those are left out, as a line walked to them would never end.
        let pts: Vec<Option<(f64, f64)>> = series
            .points
            .iter()
            .map(|&p| {
                layout
                    .pixel(p)
                    .filter(|p| p.0.abs() < 1e6 && p.1.abs() < 1e6)
            })
            .collect();
        for (i, p) in pts.iter().enumerate() {
            let Some(p) = *p else { continue };
            let next = pts.get(i + 1).copied().flatten();
            let prev = i.checked_sub(1).and_then(|j| pts[j]);
            if let Some(q) = next {
                canvas.line(p, q, s, colour);
            } else if prev.is_none() {
                let (cx, cy) = (p.0.round() as i64, p.1.round() as i64);
                canvas.fill(cx - s, cy - s, cx + s, cy + s, colour);
            }
        }
    }

    // Legend, in the top margin.
    canvas.clip = Rect {
        x0: 0,
        y0: 0,
        x1: i64::from(width) - 1,
        y1: i64::from(height) - 1,
    };
    for entry in &layout.legend {
        let colour = Rgb(series[entry.series].color);
        let mid = entry.y + font::HEIGHT * s / 2;
        canvas.fill(
            entry.x,
            mid - s,
            entry.x + LEGEND_SWATCH * s - 1,
            mid + s - 1 + i64::from(s == 1),
            colour,
        );
        canvas.text(
            entry.x + (LEGEND_SWATCH + 4) * s,
            entry.y,
            &series[entry.series].name,
            s,
            PLOT_INK,
        );
    }
    img
}

/// Width of a legend swatch, in font pixels.
const LEGEND_SWATCH: i64 = 14;

/// An inclusive pixel rectangle.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rect {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
}

impl Rect {
    /// The part of `self` inside `outer`.
    fn within(&self, outer: &Rect) -> Rect {
        Rect {
            x0: self.x0.max(outer.x0),
            y0: self.y0.max(outer.y0),
            x1: self.x1.min(outer.x1),
            y1: self.y1.min(outer.y1),
        }
    }
}

/// A tick: its value on the axis (log10 of the data on a log axis) and label (none: minor).
#[derive(Clone, Debug, PartialEq)]
struct Tick {
    value: f64,
    label: Option<String>,
}

/// Where a legend entry goes: series index, top-left of its swatch row.
#[derive(Clone, Debug, PartialEq)]
struct LegendEntry {
    series: usize,
    x: i64,
    y: i64,
}

/// Everything about a plot but its pixels: scale, frame, axis ranges, ticks, legend.
#[derive(Clone, Debug)]
struct PlotLayout {
    scale: i64,
    log_y: bool,
    /// The frame; data go strictly inside it.
    plot: Rect,
    x_range: (f64, f64),
    /// In log10 units with `log_y`.
    y_range: (f64, f64),
    x_ticks: Vec<Tick>,
    y_ticks: Vec<Tick>,
    legend: Vec<LegendEntry>,
}

impl PlotLayout {
    fn new(series: &[Series], width: u32, height: u32, log_y: bool) -> PlotLayout {
        let (w, h) = (i64::from(width), i64::from(height));
        let s: i64 = if width >= 1000 && height >= 640 { 2 } else { 1 };
        let line = font::LINE * s;
        let pad = 6 * s;
        let tick = 4 * s;

        // Legend rows, wrapped to the width.
        let mut legend = Vec::new();
        let (mut lx, mut ly) = (pad, pad);
        for (i, series) in series.iter().enumerate() {
            if series.name.is_empty() {
                continue;
            }
            let entry_w = (LEGEND_SWATCH + 4) * s + font::text_width(&series.name, s);
            if lx > pad && lx + entry_w > w - pad {
                lx = pad;
                ly += line + 3 * s;
            }
            legend.push(LegendEntry {
                series: i,
                x: lx,
                y: ly,
            });
            lx += entry_w + 12 * s;
        }
        let top = if legend.is_empty() {
            pad + font::HEIGHT * s / 2
        } else {
            ly + line + 3 * s
        };
        let bottom = tick + 3 * s + 2 * line + pad;

        // Data ranges.
        let mut x_lo = f64::INFINITY;
        let mut x_hi = f64::NEG_INFINITY;
        let mut y_lo = f64::INFINITY;
        let mut y_hi = f64::NEG_INFINITY;
        for &(x, y) in series.iter().flat_map(|s| &s.points) {
            if let Some(y) = axis_value(x, y, log_y) {
                x_lo = x_lo.min(x);
                x_hi = x_hi.max(x);
                y_lo = y_lo.min(y);
                y_hi = y_hi.max(y);
            }
        }
        if x_lo > x_hi {
            (x_lo, x_hi, y_lo, y_hi) = (0.0, 1.0, 0.0, 1.0);
        }
        (x_lo, x_hi) = widen(x_lo, x_hi);

        // y ticks first: their labels' width sets the left margin.
        let plot_h = (h - top - bottom).max(1);
        let (y_range, y_ticks) = if log_y {
            let mut lo = y_lo.floor();
            let mut hi = y_hi.ceil();
            if lo == hi {
                lo -= 1.0;
                hi += 1.0;
            }
            log_ticks(lo, hi, plot_h, line)
        } else {
            (y_lo, y_hi) = widen(y_lo, y_hi);
            let max = (plot_h / (3 * line)).max(2);
            linear_ticks(y_lo, y_hi, max)
        };
        let label_w = y_ticks
            .iter()
            .filter_map(|t| t.label.as_deref())
            .map(|l| font::text_width(l, s))
            .max()
            .unwrap_or(0);
        let left = pad + label_w + 3 * s + tick;

        // x ticks: as many as fit with a gap of two characters between labels.
        let mut right = pad + 3 * font::ADVANCE * s;
        let mut plot_w = (w - left - right).max(1);
        let mut max = (plot_w / (8 * font::ADVANCE * s)).max(2);
        let (x_range, x_ticks) = loop {
            let (range, ticks) = linear_ticks(x_lo, x_hi, max);
            let widest = ticks
                .iter()
                .filter_map(|t| t.label.as_deref())
                .map(|l| font::text_width(l, s))
                .max()
                .unwrap_or(0);
            let spacing = plot_w as f64 / (ticks.len().max(2) - 1) as f64;
            if max <= 2 || spacing >= (widest + 2 * font::ADVANCE * s) as f64 {
                // The last label is centred on the frame's right edge: leave it room.
                right = right.max(pad + widest / 2);
                plot_w = (w - left - right).max(1);
                break (range, ticks);
            }
            max -= 1;
        };

        PlotLayout {
            scale: s,
            log_y,
            plot: Rect {
                x0: left,
                y0: top,
                x1: left + plot_w,
                y1: top + plot_h,
            },
            x_range,
            y_range,
            x_ticks,
            y_ticks,
            legend,
        }
    }

    fn x_pixel(&self, x: f64) -> f64 {
        let (lo, hi) = self.x_range;
        self.plot.x0 as f64 + (x - lo) / (hi - lo) * (self.plot.x1 - self.plot.x0) as f64
    }

    /// `y` in axis units (log10 of the value with `log_y`).
    fn y_pixel(&self, y: f64) -> f64 {
        let (lo, hi) = self.y_range;
        self.plot.y1 as f64 - (y - lo) / (hi - lo) * (self.plot.y1 - self.plot.y0) as f64
    }

    /// Where a data point lands, or `None` when it cannot be drawn.
    fn pixel(&self, (x, y): (f64, f64)) -> Option<(f64, f64)> {
        axis_value(x, y, self.log_y).map(|y| (self.x_pixel(x), self.y_pixel(y)))
    }
}

/// Largest magnitude plotted: beyond it, ranges and their widening could overflow f64.
const MAX_PLOTTED: f64 = 1e300;

/// A point's y in axis units, or `None` when it is not drawable.
fn axis_value(x: f64, y: f64, log_y: bool) -> Option<f64> {
    let inside = |v: f64| v.abs() <= MAX_PLOTTED; // false for NaN and infinities
    if !inside(x) || !inside(y) || (log_y && y <= 0.0) {
        return None;
    }
    Some(if log_y { y.log10() } else { y })
}

/// `[lo, hi]`, or a range around its middle when it is too narrow to tick (one value, or
/// values equal to 9 digits, whose differences a plot could not show anyway).
fn widen(lo: f64, hi: f64) -> (f64, f64) {
    let mag = lo.abs().max(hi.abs());
    if hi - lo > 1e-9 * mag && hi - lo > 1e-290 {
        return (lo, hi);
    }
    let v = lo / 2.0 + hi / 2.0;
    let d = (v.abs() * 0.5).max(if v == 0.0 { 1.0 } else { 1e-290 });
    (v - d, v + d)
}

/// Ticks every 1, 2 or 5 × 10ᵏ over `[lo, hi]` (lo < hi), at most about `max` of them; the
/// range is widened to whole steps.
fn linear_ticks(lo: f64, hi: f64, max: i64) -> ((f64, f64), Vec<Tick>) {
    let raw = (hi - lo) / (max.max(2) - 1) as f64;
    let k = raw.log10().floor();
    let mut step = 10f64.powf(k);
    for m in [1.0, 2.0, 5.0, 10.0] {
        step = m * 10f64.powf(k);
        if step >= raw * (1.0 - 1e-9) {
            break;
        }
    }
    let first = (lo / step).floor();
    let last = (hi / step).ceil();
    let n = (last - first) as i64;
    let ticks = (0..=n)
        .map(|i| {
            let v = (first + i as f64) * step;
            Tick {
                value: v,
                label: Some(format_tick(v, step)),
            }
        })
        .collect();
    ((first * step, last * step), ticks)
}

/// Ticks for a log axis over whole decades `[lo, hi]` (log10 units): every decade labelled
/// (every few when they would crowd), and unlabelled ticks at 2…9 × 10ᵏ when decades are
/// tall enough to hold them.
fn log_ticks(lo: f64, hi: f64, plot_h: i64, line: i64) -> ((f64, f64), Vec<Tick>) {
    let decades = (hi - lo) as i64;
    let per_decade = plot_h as f64 / decades as f64;
    let every = ((2 * line) as f64 / per_decade).ceil().max(1.0) as i64;
    let mut ticks = Vec::new();
    for d in 0..=decades {
        let k = lo + d as f64;
        if d % every == 0 {
            ticks.push(Tick {
                value: k,
                label: Some(decade_label(k as i64)),
            });
        }
        if every == 1 && per_decade >= 40.0 && d < decades {
            ticks.extend((2..10).map(|m| Tick {
                value: k + f64::from(m).log10(),
                label: None,
            }));
        }
    }
    ((lo, hi), ticks)
}

/// `10^k` as a label: plain for 0.001 to 10000, else `1e{k}`.
fn decade_label(k: i64) -> String {
    match k {
        -3..=-1 => format!("{:.*}", (-k) as usize, 10f64.powi(k as i32)),
        0..=4 => format!("{}", 10i64.pow(k as u32)),
        _ => format!("1e{k}"),
    }
}

/// A tick value with as many digits as its step needs: `0.25`, `1500`, `2.5e-4`, `1e6`; zero
/// as `0`, or `0.0` to `0.000` beside labels with that many decimals.
fn format_tick(v: f64, step: f64) -> String {
    // Steps are m·10^k with m in {1, 2, 5}; k is the last digit that varies.
    let k = (step.log10() + 1e-9).floor() as i64;
    let a = v.abs();
    if a < step * 1e-6 {
        // As many decimals as its neighbours when they have few ("0.0" beside "0.5").
        let digits = if (-3..=0).contains(&k) {
            (-k) as usize
        } else {
            0
        };
        return format!("{:.digits$}", 0.0);
    }
    if !(1e-3..1e5).contains(&a) {
        let e = (a.log10() + 1e-9).floor() as i64;
        let digits = e.saturating_sub(k).clamp(0, 15) as usize;
        format!("{v:.digits$e}")
    } else {
        let digits = k.saturating_neg().clamp(0, 15) as usize;
        format!("{v:.digits$}")
    }
}

/// Pixel drawing on an image, clipped to a rectangle.
struct Canvas<'a> {
    img: &'a mut RgbImage,
    clip: Rect,
}

impl Canvas<'_> {
    /// Fills the inclusive rectangle.
    fn fill(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb<u8>) {
        let r = self.clip;
        for y in y0.max(r.y0)..=y1.min(r.y1) {
            for x in x0.max(r.x0)..=x1.min(r.x1) {
                self.img.put_pixel(x as u32, y as u32, c);
            }
        }
    }

    fn hline(&mut self, x0: i64, x1: i64, y: i64, c: Rgb<u8>) {
        self.fill(x0, y, x1, y, c);
    }

    fn vline(&mut self, x: i64, y0: i64, y1: i64, c: Rgb<u8>) {
        self.fill(x, y0, x, y1, c);
    }

    /// A Bresenham line between pixel positions, `thickness` pixels wide (a square pen).
    fn line(&mut self, a: (f64, f64), b: (f64, f64), thickness: i64, c: Rgb<u8>) {
        let (mut x, mut y) = (a.0.round() as i64, a.1.round() as i64);
        let (x1, y1) = (b.0.round() as i64, b.1.round() as i64);
        let (dx, dy) = ((x1 - x).abs(), -(y1 - y).abs());
        let (sx, sy) = (if x < x1 { 1 } else { -1 }, if y < y1 { 1 } else { -1 });
        let mut err = dx + dy;
        let lo = -(thickness - 1) / 2;
        let hi = lo + thickness - 1;
        loop {
            self.fill(x + lo, y + lo, x + hi, y + hi, c);
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// `text` with its top-left at `(x, y)`, each font pixel `scale` pixels wide.
    fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, c: Rgb<u8>) {
        for (i, ch) in text.chars().enumerate() {
            let gx = x + i as i64 * font::ADVANCE * scale;
            for (row, bits) in font::glyph(ch).iter().enumerate() {
                for col in 0..font::WIDTH {
                    if bits & (1 << (font::WIDTH - 1 - col)) != 0 {
                        let px = gx + col * scale;
                        let py = y + row as i64 * scale;
                        self.fill(px, py, px + scale - 1, py + scale - 1, c);
                    }
                }
            }
        }
    }
}

/// A 5×7 bitmap font: printable ASCII, `×` and `λ`; anything else draws as a box.
pub mod font {
    /// Glyph width in pixels.
    pub const WIDTH: i64 = 5;
    /// Glyph height in pixels.
    pub const HEIGHT: i64 = 7;
    /// Horizontal advance: a glyph and a column of space.
    pub const ADVANCE: i64 = 6;
    /// Line height: a glyph and two rows of space.
    pub const LINE: i64 = 9;

    /// Width in pixels of `text` drawn at `scale` (no trailing space).
    pub fn text_width(text: &str, scale: i64) -> i64 {
        let n = text.chars().count() as i64;
        (n * ADVANCE - 1).max(0) * scale
    }

    /// The rows of `c`, top first, bit 4 the leftmost pixel.
    pub fn glyph(c: char) -> [u8; 7] {
        let art = GLYPHS
            .iter()
            .find(|(g, _)| *g == c)
            .map_or(&MISSING, |(_, rows)| rows);
        art.map(|row| {
            row.bytes()
                .fold(0u8, |bits, b| (bits << 1) | u8::from(b == b'#'))
        })
    }

    /// Drawn for characters the font lacks.
    const MISSING: [&str; 7] = [
        "#####", "#...#", "#...#", "#...#", "#...#", "#...#", "#####",
    ];

    /// Hand-drawn glyphs, `#` for ink.
    pub(super) const GLYPHS: &[(char, [&str; 7])] = &[
        (
            ' ',
            [
                ".....", ".....", ".....", ".....", ".....", ".....", ".....",
            ],
        ),
        (
            '!',
            [
                "..#..", "..#..", "..#..", "..#..", "..#..", ".....", "..#..",
            ],
        ),
        (
            '"',
            [
                ".#.#.", ".#.#.", ".....", ".....", ".....", ".....", ".....",
            ],
        ),
        (
            '#',
            [
                ".#.#.", ".#.#.", "#####", ".#.#.", "#####", ".#.#.", ".#.#.",
            ],
        ),
        (
            '$',
            [
                "..#..", ".####", "#.#..", ".###.", "..#.#", "####.", "..#..",
            ],
        ),
        (
            '%',
            [
                "##...", "##..#", "...#.", "..#..", ".#...", "#..##", "...##",
            ],
        ),
        (
            '&',
            [
                ".##..", "#..#.", "#.#..", ".#...", "#.#.#", "#..#.", ".##.#",
            ],
        ),
        (
            '\'',
            [
                "..#..", "..#..", ".#...", ".....", ".....", ".....", ".....",
            ],
        ),
        (
            '(',
            [
                "...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#.",
            ],
        ),
        (
            ')',
            [
                ".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#...",
            ],
        ),
        (
            '*',
            [
                ".....", "..#..", "#.#.#", ".###.", "#.#.#", "..#..", ".....",
            ],
        ),
        (
            '+',
            [
                ".....", "..#..", "..#..", "#####", "..#..", "..#..", ".....",
            ],
        ),
        (
            ',',
            [
                ".....", ".....", ".....", ".....", ".##..", "..#..", ".#...",
            ],
        ),
        (
            '-',
            [
                ".....", ".....", ".....", "#####", ".....", ".....", ".....",
            ],
        ),
        (
            '.',
            [
                ".....", ".....", ".....", ".....", ".....", ".##..", ".##..",
            ],
        ),
        (
            '/',
            [
                ".....", "....#", "...#.", "..#..", ".#...", "#....", ".....",
            ],
        ),
        (
            '0',
            [
                ".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###.",
            ],
        ),
        (
            '1',
            [
                "..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###.",
            ],
        ),
        (
            '2',
            [
                ".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####",
            ],
        ),
        (
            '3',
            [
                "#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###.",
            ],
        ),
        (
            '4',
            [
                "...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#.",
            ],
        ),
        (
            '5',
            [
                "#####", "#....", "####.", "....#", "....#", "#...#", ".###.",
            ],
        ),
        (
            '6',
            [
                "..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###.",
            ],
        ),
        (
            '7',
            [
                "#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#...",
            ],
        ),
        (
            '8',
            [
                ".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###.",
            ],
        ),
        (
            '9',
            [
                ".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##..",
            ],
        ),
        (
            ':',
            [
                ".....", ".##..", ".##..", ".....", ".##..", ".##..", ".....",
            ],
        ),
        (
            ';',
            [
                ".....", ".##..", ".##..", ".....", ".##..", "..#..", ".#...",
            ],
        ),
        (
            '<',
            [
                "...#.", "..#..", ".#...", "#....", ".#...", "..#..", "...#.",
            ],
        ),
        (
            '=',
            [
                ".....", ".....", "#####", ".....", "#####", ".....", ".....",
            ],
        ),
        (
            '>',
            [
                ".#...", "..#..", "...#.", "....#", "...#.", "..#..", ".#...",
            ],
        ),
        (
            '?',
            [
                ".###.", "#...#", "....#", "...#.", "..#..", ".....", "..#..",
            ],
        ),
        (
            '@',
            [
                ".###.", "#...#", "....#", ".##.#", "#.#.#", "#.#.#", ".###.",
            ],
        ),
        (
            'A',
            [
                ".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#",
            ],
        ),
        (
            'B',
            [
                "####.", "#...#", "#...#", "####.", "#...#", "#...#", "####.",
            ],
        ),
        (
            'C',
            [
                ".###.", "#...#", "#....", "#....", "#....", "#...#", ".###.",
            ],
        ),
        (
            'D',
            [
                "###..", "#..#.", "#...#", "#...#", "#...#", "#..#.", "###..",
            ],
        ),
        (
            'E',
            [
                "#####", "#....", "#....", "####.", "#....", "#....", "#####",
            ],
        ),
        (
            'F',
            [
                "#####", "#....", "#....", "####.", "#....", "#....", "#....",
            ],
        ),
        (
            'G',
            [
                ".###.", "#...#", "#....", "#.###", "#...#", "#...#", ".####",
            ],
        ),
        (
            'H',
            [
                "#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#",
            ],
        ),
        (
            'I',
            [
                ".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###.",
            ],
        ),
        (
            'J',
            [
                "..###", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##..",
            ],
        ),
        (
            'K',
            [
                "#...#", "#..#.", "#.#..", "##...", "#.#..", "#..#.", "#...#",
            ],
        ),
        (
            'L',
            [
                "#....", "#....", "#....", "#....", "#....", "#....", "#####",
            ],
        ),
        (
            'M',
            [
                "#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#",
            ],
        ),
        (
            'N',
            [
                "#...#", "#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#",
            ],
        ),
        (
            'O',
            [
                ".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###.",
            ],
        ),
        (
            'P',
            [
                "####.", "#...#", "#...#", "####.", "#....", "#....", "#....",
            ],
        ),
        (
            'Q',
            [
                ".###.", "#...#", "#...#", "#...#", "#.#.#", "#..#.", ".##.#",
            ],
        ),
        (
            'R',
            [
                "####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#",
            ],
        ),
        (
            'S',
            [
                ".####", "#....", "#....", ".###.", "....#", "....#", "####.",
            ],
        ),
        (
            'T',
            [
                "#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#..",
            ],
        ),
        (
            'U',
            [
                "#...#", "#...#", "#...#", "#...#", "#...#", "#...#", ".###.",
            ],
        ),
        (
            'V',
            [
                "#...#", "#...#", "#...#", "#...#", "#...#", ".#.#.", "..#..",
            ],
        ),
        (
            'W',
            [
                "#...#", "#...#", "#...#", "#.#.#", "#.#.#", "#.#.#", ".#.#.",
            ],
        ),
        (
            'X',
            [
                "#...#", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "#...#",
            ],
        ),
        (
            'Y',
            [
                "#...#", "#...#", ".#.#.", "..#..", "..#..", "..#..", "..#..",
            ],
        ),
        (
            'Z',
            [
                "#####", "....#", "...#.", "..#..", ".#...", "#....", "#####",
            ],
        ),
        (
            '[',
            [
                ".###.", ".#...", ".#...", ".#...", ".#...", ".#...", ".###.",
            ],
        ),
        (
            '\\',
            [
                ".....", "#....", ".#...", "..#..", "...#.", "....#", ".....",
            ],
        ),
        (
            ']',
            [
                ".###.", "...#.", "...#.", "...#.", "...#.", "...#.", ".###.",
            ],
        ),
        (
            '^',
            [
                "..#..", ".#.#.", "#...#", ".....", ".....", ".....", ".....",
            ],
        ),
        (
            '_',
            [
                ".....", ".....", ".....", ".....", ".....", ".....", "#####",
            ],
        ),
        (
            '`',
            [
                ".#...", "..#..", ".....", ".....", ".....", ".....", ".....",
            ],
        ),
        (
            'a',
            [
                ".....", ".....", ".###.", "....#", ".####", "#...#", ".####",
            ],
        ),
        (
            'b',
            [
                "#....", "#....", "#.##.", "##..#", "#...#", "#...#", "####.",
            ],
        ),
        (
            'c',
            [
                ".....", ".....", ".###.", "#....", "#....", "#...#", ".###.",
            ],
        ),
        (
            'd',
            [
                "....#", "....#", ".##.#", "#..##", "#...#", "#...#", ".####",
            ],
        ),
        (
            'e',
            [
                ".....", ".....", ".###.", "#...#", "#####", "#....", ".###.",
            ],
        ),
        (
            'f',
            [
                "..##.", ".#..#", ".#...", "###..", ".#...", ".#...", ".#...",
            ],
        ),
        (
            'g',
            [
                ".....", ".....", ".####", "#...#", ".####", "....#", ".###.",
            ],
        ),
        (
            'h',
            [
                "#....", "#....", "#.##.", "##..#", "#...#", "#...#", "#...#",
            ],
        ),
        (
            'i',
            [
                "..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###.",
            ],
        ),
        (
            'j',
            [
                "...#.", ".....", "..##.", "...#.", "...#.", "#..#.", ".##..",
            ],
        ),
        (
            'k',
            [
                "#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#.",
            ],
        ),
        (
            'l',
            [
                ".##..", "..#..", "..#..", "..#..", "..#..", "..#..", ".###.",
            ],
        ),
        (
            'm',
            [
                ".....", ".....", "##.#.", "#.#.#", "#.#.#", "#...#", "#...#",
            ],
        ),
        (
            'n',
            [
                ".....", ".....", "#.##.", "##..#", "#...#", "#...#", "#...#",
            ],
        ),
        (
            'o',
            [
                ".....", ".....", ".###.", "#...#", "#...#", "#...#", ".###.",
            ],
        ),
        (
            'p',
            [
                ".....", ".....", "####.", "#...#", "####.", "#....", "#....",
            ],
        ),
        (
            'q',
            [
                ".....", ".....", ".####", "#...#", ".####", "....#", "....#",
            ],
        ),
        (
            'r',
            [
                ".....", ".....", "#.##.", "##..#", "#....", "#....", "#....",
            ],
        ),
        (
            's',
            [
                ".....", ".....", ".####", "#....", ".###.", "....#", "####.",
            ],
        ),
        (
            't',
            [
                ".#...", ".#...", "###..", ".#...", ".#...", ".#..#", "..##.",
            ],
        ),
        (
            'u',
            [
                ".....", ".....", "#...#", "#...#", "#...#", "#..##", ".##.#",
            ],
        ),
        (
            'v',
            [
                ".....", ".....", "#...#", "#...#", "#...#", ".#.#.", "..#..",
            ],
        ),
        (
            'w',
            [
                ".....", ".....", "#...#", "#...#", "#.#.#", "#.#.#", ".#.#.",
            ],
        ),
        (
            'x',
            [
                ".....", ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#",
            ],
        ),
        (
            'y',
            [
                ".....", ".....", "#...#", "#...#", ".####", "....#", ".###.",
            ],
        ),
        (
            'z',
            [
                ".....", ".....", "#####", "...#.", "..#..", ".#...", "#####",
            ],
        ),
        (
            '{',
            [
                "...#.", "..#..", "..#..", ".#...", "..#..", "..#..", "...#.",
            ],
        ),
        (
            '|',
            [
                "..#..", "..#..", "..#..", "..#..", "..#..", "..#..", "..#..",
            ],
        ),
        (
            '}',
            [
                ".#...", "..#..", "..#..", "...#.", "..#..", "..#..", ".#...",
            ],
        ),
        (
            '~',
            [
                ".....", ".....", ".#...", "#.#.#", "...#.", ".....", ".....",
            ],
        ),
        (
            '×',
            [
                ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", ".....",
            ],
        ),
        (
            'λ',
            [
                "##...", "..#..", "..#..", ".#.#.", ".#.#.", "#...#", "#...#",
            ],
        ),
    ];
}

/// Writes an 8-bit (or 16-bit) image as PNG, atomically: a failed write leaves no file.
pub fn write_png<P>(path: &Path, image: &ImageBuffer<P, Vec<P::Subpixel>>) -> Result<()>
where
    P: PixelWithColorType,
    [P::Subpixel]: EncodableLayout,
{
    let file = AtomicFile::create(path)?;
    let bytes = super::io::encode_png(
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

#[cfg(test)]
mod tests {
    use super::super::io::test_support::TempDir;
    use super::*;

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

    /// Columns (x) that hold a pixel of `colour` inside the frame.
    fn columns_with(img: &RgbImage, layout: &PlotLayout, colour: [u8; 3]) -> Vec<i64> {
        let r = layout.plot;
        (r.x0 + 1..r.x1)
            .filter(|&x| (r.y0 + 1..r.y1).any(|y| img.get_pixel(x as u32, y as u32).0 == colour))
            .collect()
    }

    #[test]
    fn loss_plot_has_its_size_background_frame_and_each_series_in_its_colour() {
        let series = [
            line("silhouette", RED, &[(0.0, 1.0), (50.0, 0.4), (100.0, 0.2)]),
            line("laplacian", BLUE, &[(0.0, 0.05), (100.0, 0.1)]),
        ];
        let (w, h) = (480, 300);
        let img = loss_plot(&series, w, h, false);
        assert_eq!(img.dimensions(), (w, h));
        assert_eq!(*img.get_pixel(0, h - 1), PLOT_BACKGROUND);
        assert_eq!(*img.get_pixel(w - 1, h - 1), PLOT_BACKGROUND);

        let layout = PlotLayout::new(&series, w, h, false);
        let r = layout.plot;
        assert!(
            r.x1 - r.x0 > w as i64 / 2 && r.y1 - r.y0 > h as i64 / 2,
            "{r:?}"
        );
        assert_eq!(
            *img.get_pixel(r.x0 as u32, (r.y0 + r.y1) as u32 / 2),
            PLOT_INK
        );
        assert_eq!(
            *img.get_pixel((r.x0 + r.x1) as u32 / 2, r.y1 as u32),
            PLOT_INK
        );
        // Both ranges cover the data, with 1-2-5 ticks.
        assert_eq!(layout.x_range, (0.0, 100.0));
        assert!(layout.y_range.0 <= 0.05 && layout.y_range.1 >= 1.0);

        for s in &series {
            // Every vertex lands on a pixel of the series' colour...
            for &p in &s.points {
                let (x, y) = layout.pixel(p).unwrap();
                let x = (x.round() as i64).clamp(r.x0 + 1, r.x1 - 1);
                let y = (y.round() as i64).clamp(r.y0 + 1, r.y1 - 1);
                assert_eq!(
                    img.get_pixel(x as u32, y as u32).0,
                    s.color,
                    "{} at {p:?}",
                    s.name
                );
            }
            // ...and the polyline is unbroken from the first vertex's column to the last's.
            let cols = columns_with(&img, &layout, s.color);
            let first = layout.pixel(s.points[0]).unwrap().0.round() as i64;
            let last = layout.pixel(*s.points.last().unwrap()).unwrap().0.round() as i64;
            assert_eq!(
                cols,
                ((first + 1).max(r.x0 + 1)..=last.min(r.x1 - 1)).collect::<Vec<_>>()
            );
        }
        // The legend swatches, above the frame, in each series' colour.
        assert_eq!(layout.legend.len(), 2);
        for e in &layout.legend {
            assert!(e.y + font::HEIGHT <= r.y0, "legend above the plot");
            let mid = (e.y + font::HEIGHT / 2) as u32;
            assert_eq!(img.get_pixel(e.x as u32 + 2, mid).0, series[e.series].color);
        }
    }

    #[test]
    fn loss_plot_labels_ticks_with_numbers_in_the_bitmap_font() {
        let series = [line("loss", RED, &[(0.0, 0.0), (2000.0, 1.0)])];
        let (w, h) = (640, 400);
        let img = loss_plot(&series, w, h, false);
        let layout = PlotLayout::new(&series, w, h, false);
        let labels = |ticks: &[Tick]| -> Vec<String> {
            ticks.iter().filter_map(|t| t.label.clone()).collect()
        };
        assert_eq!(
            labels(&layout.x_ticks),
            [
                "0", "200", "400", "600", "800", "1000", "1200", "1400", "1600", "1800", "2000"
            ]
        );
        let y = labels(&layout.y_ticks);
        assert_eq!((y[0].as_str(), y[y.len() - 1].as_str()), ("0.0", "1.0"));
        // The bottom y label is drawn where the layout puts it, glyph for glyph.
        let s = layout.scale;
        let label = "0.0";
        let x = layout.plot.x0 - 4 * s - 3 * s - font::text_width(label, s);
        let y = layout.y_pixel(0.0).round() as i64 - font::HEIGHT * s / 2;
        for (i, c) in label.chars().enumerate() {
            let glyph = font::glyph(c);
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..font::WIDTH {
                    let px = (x + (i as i64 * font::ADVANCE + col) * s) as u32;
                    let py = (y + row as i64 * s) as u32;
                    let ink = bits & (1 << (font::WIDTH - 1 - col)) != 0;
                    let expected = if ink { PLOT_INK } else { PLOT_BACKGROUND };
                    assert_eq!(
                        *img.get_pixel(px, py),
                        expected,
                        "'{c}' row {row} col {col}"
                    );
                }
            }
        }
    }

    #[test]
    fn log_y_leaves_out_non_positive_values_and_spans_whole_decades() {
        let points = [
            (0.0, 1.0),
            (1.0, 0.0),
            (2.0, -1.0),
            (3.0, 0.02),
            (4.0, f64::NAN),
            (5.0, 0.1),
            (6.0, 0.5),
        ];
        let series = [line("loss", RED, &points)];
        let (w, h) = (400, 300);
        let img = loss_plot(&series, w, h, true);
        let layout = PlotLayout::new(&series, w, h, true);
        assert_eq!(layout.y_range, (-2.0, 0.0), "0.01 to 1");
        let labels: Vec<_> = layout
            .y_ticks
            .iter()
            .filter_map(|t| t.label.clone())
            .collect();
        assert_eq!(labels, ["0.01", "0.1", "1"]);
        assert!(
            layout.y_ticks.iter().any(|t| t.label.is_none()),
            "minor ticks"
        );
        assert!(layout.pixel((1.0, 0.0)).is_none() && layout.pixel((2.0, -1.0)).is_none());

        let px = |i: usize| layout.pixel(points[i]).unwrap().0.round() as i64;
        let cols = columns_with(&img, &layout, RED);
        // 1.0 at x = 0 and 0.02 at x = 3 have no drawable neighbour: a dot each (±1 pixel),
        // nothing between them; 0.1 → 0.5 is a segment.
        let between: Vec<_> = cols
            .iter()
            .filter(|&&x| x > px(0) + 1 && x < px(3) - 1)
            .collect();
        assert!(between.is_empty(), "{between:?}");
        assert!(cols.contains(&(px(3) - 1)) && cols.contains(&(px(3) + 1)));
        assert!(
            !cols.iter().any(|&x| x > px(3) + 1 && x < px(5)),
            "NaN breaks the line"
        );
        assert!((px(5)..=px(6).min(layout.plot.x1 - 1)).all(|x| cols.contains(&x)));

        // Nothing drawable at all: default decades, no panic.
        let none = [line("zeros", RED, &[(0.0, 0.0), (1.0, -2.0)])];
        let layout = PlotLayout::new(&none, w, h, true);
        assert_eq!((layout.x_range, layout.y_range), ((0.0, 1.0), (0.0, 1.0)));
        let img = loss_plot(&none, w, h, true);
        assert!(columns_with(&img, &layout, RED).is_empty());
    }

    #[test]
    fn degenerate_plots_do_not_panic() {
        let one = [line("one", RED, &[(5.0, 3.0)])];
        for (w, h) in [(1, 1), (0, 0), (12, 9), (60, 40), (130, 90), (2000, 1200)] {
            for log_y in [false, true] {
                let img = loss_plot(&one, w, h, log_y);
                assert_eq!(img.dimensions(), (w.max(1), h.max(1)));
            }
        }
        // A single point is a visible dot.
        let layout = PlotLayout::new(&one, 300, 200, false);
        let img = loss_plot(&one, 300, 200, false);
        assert!(!columns_with(&img, &layout, RED).is_empty());
        // Huge, tiny and constant values, and no series at all.
        let odd = [
            line("big", RED, &[(0.0, 1e300), (1.0, 1e300)]),
            line("tiny", BLUE, &[(0.0, 1e-300), (1e9, 2e-300)]),
        ];
        loss_plot(&odd, 300, 200, false);
        let huge = [
            line("overflow", RED, &[(-1e308, -1e308), (1e308, 1e308)]),
            line("edge", RED, &[(-1e300, -1e300), (1e300, 1e300)]),
            line("subnormal", BLUE, &[(0.0, 5e-324), (5e-324, 0.0)]),
            line("close", BLUE, &[(1.0, 1.0), (1.0 + 1e-15, 1.0 - 1e-15)]),
        ];
        for log_y in [false, true] {
            for s in &huge {
                loss_plot(std::slice::from_ref(s), 300, 200, log_y);
            }
        }
        let layout = PlotLayout::new(&huge[3..], 300, 200, false);
        let (lo, hi) = layout.x_range;
        assert!(
            lo <= 0.5 && hi >= 1.5,
            "equal to 9 digits: widened to ±0.5, {lo}..{hi}"
        );
        loss_plot(&odd, 300, 200, true);
        loss_plot(&[], 300, 200, true);
    }

    #[test]
    fn tick_labels_have_the_digits_their_step_needs() {
        assert_eq!(format_tick(0.25, 0.05), "0.25");
        assert_eq!(format_tick(0.30000000000000004, 0.1), "0.3");
        assert_eq!(format_tick(-1.5, 0.5), "-1.5");
        assert_eq!(format_tick(1500.0, 500.0), "1500");
        assert_eq!(format_tick(1e-17, 0.1), "0.0");
        assert_eq!(format_tick(-1e-19, 2e-3), "0.000");
        assert_eq!(format_tick(0.0, 5e-4), "0");
        assert_eq!(format_tick(0.0, 5e-5), "0");
        assert_eq!(format_tick(0.0, 500.0), "0");
        assert_eq!(format_tick(2.5e-4, 5e-5), "2.5e-4");
        assert_eq!(format_tick(3e-4, 1e-4), "3e-4");
        assert_eq!(format_tick(2e6, 1e6), "2e6");
        assert_eq!(format_tick(1.5e6, 5e5), "1.5e6");
        let labels: Vec<_> = [-5, -3, -1, 0, 2, 4, 5]
            .into_iter()
            .map(decade_label)
            .collect();
        assert_eq!(labels, ["1e-5", "0.001", "0.1", "1", "100", "10000", "1e5"]);
        let ((lo, hi), ticks) = linear_ticks(0.03, 0.97, 6);
        assert_eq!((lo, hi, ticks.len()), (0.0, 1.0, 6));
        let ((lo, hi), _) = linear_ticks(-7.0, 13.0, 3);
        assert_eq!((lo, hi), (-10.0, 20.0));
    }

    #[test]
    fn font_glyphs_are_5_by_7_unique_and_cover_labels_and_names() {
        let mut seen = std::collections::HashSet::new();
        for (c, rows) in font::GLYPHS {
            assert!(seen.insert(*c), "'{c}' twice");
            for row in rows {
                assert!(
                    row.len() == 5 && row.bytes().all(|b| b == b'#' || b == b'.'),
                    "'{c}'"
                );
            }
        }
        for c in (' '..='~').chain(['×', 'λ']) {
            assert!(seen.contains(&c), "'{c}' missing");
        }
        assert_eq!(
            font::glyph('1'),
            [
                0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110
            ]
        );
        assert_eq!(
            font::glyph('é'),
            [
                0b11111, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b11111
            ]
        );
        assert_eq!(font::text_width("1e-3", 2), (4 * 6 - 1) * 2);
        assert_eq!(font::text_width("", 1), 0);
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
        let plot = loss_plot(&[line("a", RED, &[(0.0, 1.0), (1.0, 2.0)])], 120, 80, false);
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
