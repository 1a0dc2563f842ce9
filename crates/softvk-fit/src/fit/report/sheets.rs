//! Contact sheets of predicted against target silhouettes (with each view's IoU as a bar and
//! a label) and renders side by side, laid out on a grid of 1-pixel gaps.

use image::{DynamicImage, Rgb, RgbImage, Rgba, RgbaImage};

use super::{LABEL_BACKGROUND, draw_labels};

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
