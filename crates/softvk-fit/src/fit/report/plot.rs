//! The loss plot: [`Series`] of `(iteration, value)` drawn by plotters on linear or
//! logarithmic axes, with a grid and a legend.

use image::{Rgb, RgbImage};

use super::typeface;

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
