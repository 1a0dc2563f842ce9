//! Tests of the pictures: the error map, contact sheets, loss plots, labels, GIFs and PNGs.

use std::fs::File;

use image::{Rgba, RgbaImage};

use super::*;
use crate::error::Error;

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
