//! Tests of the fitting commands' files: silhouettes, cameras and OBJ round trips, each bad
//! input's one error line, and atomic writes.

use super::test_support::TempDir;
use super::*;
use crate::mesh::Mesh;

/// A `w × h` mask with a filled axis-aligned rectangle `[x0, x1) × [y0, y1)`.
fn rect(w: u32, h: u32, x0: u32, x1: u32, y0: u32, y1: u32) -> Vec<f32> {
    (0..h)
        .flat_map(|y| {
            (0..w).map(move |x| {
                if (x0..x1).contains(&x) && (y0..y1).contains(&y) {
                    1.0
                } else {
                    0.0
                }
            })
        })
        .collect()
}

fn save(path: &Path, pixels: &[u8], w: u32, h: u32, color: image::ExtendedColorType) {
    std::fs::write(path, encode_png(pixels, w, h, color, path).unwrap()).unwrap();
}

fn input_error(result: Result<impl std::fmt::Debug>) -> String {
    match result {
        Err(Error::Input(message)) => message,
        other => panic!("expected Error::Input, got {other:?}"),
    }
}

#[test]
fn silhouettes_round_trip_in_name_order_non_square() {
    let dir = TempDir::new("sil-roundtrip");
    let (w, h) = (7, 4);
    let names = silhouette_names(3);
    assert_eq!(names, ["view_000.png", "view_001.png", "view_002.png"]);
    let masks = [
        rect(w, h, 0, 3, 0, 2),
        rect(w, h, 2, 7, 1, 4),
        rect(w, h, 6, 7, 3, 4),
    ]
    .concat();
    write_silhouettes(&dir.0, &names, w, h, &masks).unwrap();
    assert_eq!(dir.entries(), names, "no temporary file is left");
    let back = load_silhouettes(&dir.0).unwrap();
    assert_eq!(
        back,
        Silhouettes {
            width: w,
            height: h,
            names,
            masks: masks.clone()
        }
    );
    assert_eq!(back.views(), 3);
    assert_eq!(back.mask(1), &masks[28..56]);
}

#[test]
fn silhouette_names_sort_in_view_order_past_999() {
    let names = silhouette_names(1001);
    assert_eq!(names[0], "view_0000.png");
    assert_eq!(names[1000], "view_1000.png");
    assert!(names.windows(2).all(|w| w[0] < w[1]));
    assert_eq!(silhouette_names(0), Vec::<String>::new());
}

#[test]
fn silhouettes_use_alpha_when_present_else_luminance_over_half() {
    use image::ExtendedColorType::*;
    let dir = TempDir::new("sil-channels");
    // Alpha decides even where the colour says otherwise.
    save(
        &dir.path("a.png"),
        &[0, 0, 0, 128, 255, 255, 255, 127],
        2,
        1,
        Rgba8,
    );
    // Grey + alpha, upper-case extension: alpha 200 is inside, 100 not.
    save(&dir.path("b.PNG"), &[0, 200, 255, 100], 2, 1, La8);
    // Grey: luminance, threshold between 127 and 128.
    save(&dir.path("c.png"), &[128, 127], 2, 1, L8);
    // RGB: Rec. 709 luminance, pure green is 0.7152 · 255 ≈ 182 > 127.5, pure red 54 not.
    save(&dir.path("d.png"), &[0, 255, 0, 255, 0, 0], 2, 1, Rgb8);
    // 16-bit grey: the threshold is half of 65535 (the encoder takes native-endian samples).
    let l16: Vec<u8> = [32768u16, 32767]
        .iter()
        .flat_map(|v| v.to_ne_bytes())
        .collect();
    save(&dir.path("e.png"), &l16, 2, 1, L16);
    // Not silhouettes: another extension, a hidden file, a folder named like a PNG.
    std::fs::write(dir.path("notes.txt"), b"x").unwrap();
    std::fs::write(dir.path("._a.png"), b"resource fork").unwrap();
    std::fs::create_dir(dir.path("f.png")).unwrap();

    let s = load_silhouettes(&dir.0).unwrap();
    assert_eq!(s.names, ["a.png", "b.PNG", "c.png", "d.png", "e.png"]);
    assert_eq!((s.width, s.height), (2, 1));
    assert_eq!(s.masks, [1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
}

#[test]
fn soft_masks_are_written_as_8_bit_alpha() {
    let dir = TempDir::new("sil-soft");
    write_silhouettes(&dir.0, &["s.png"], 4, 1, &[-1.0, 0.25, 0.5, 2.0]).unwrap();
    let img = image::open(dir.path("s.png")).unwrap().to_rgba8();
    let px: Vec<[u8; 4]> = img.pixels().map(|p| p.0).collect();
    assert_eq!(
        px,
        [
            [255, 255, 255, 0],
            [255, 255, 255, 64],
            [255, 255, 255, 128],
            [255, 255, 255, 255]
        ]
    );
    assert_eq!(
        load_silhouettes(&dir.0).unwrap().masks,
        [0.0, 0.0, 1.0, 1.0]
    );
}

#[test]
fn silhouette_folder_errors_name_the_folder() {
    let dir = TempDir::new("sil-folder");
    let missing = dir.path("missing");
    let e = input_error(load_silhouettes(&missing));
    assert!(e.contains("does not exist") && e.contains("missing"), "{e}");

    std::fs::write(dir.path("file"), b"").unwrap();
    let e = input_error(load_silhouettes(&dir.path("file")));
    assert!(e.contains("is not a folder"), "{e}");

    std::fs::create_dir(dir.path("empty")).unwrap();
    std::fs::write(dir.path("empty/a.jpg"), b"").unwrap();
    let e = input_error(load_silhouettes(&dir.path("empty")));
    assert!(e.contains("no .png file") && e.contains("empty"), "{e}");
}

#[test]
fn corrupt_png_is_named() {
    let dir = TempDir::new("sil-corrupt");
    write_silhouettes(&dir.0, &["a.png"], 2, 2, &rect(2, 2, 0, 1, 0, 1)).unwrap();
    std::fs::write(dir.path("b.png"), b"\x89PNG\r\n\x1a\nnot really").unwrap();
    let e = input_error(load_silhouettes(&dir.0));
    assert!(
        e.contains("b.png") && e.contains("not a readable PNG"),
        "{e}"
    );
}

#[test]
fn differing_sizes_name_both_files() {
    let dir = TempDir::new("sil-sizes");
    write_silhouettes(&dir.0, &["a.png"], 3, 2, &rect(3, 2, 0, 1, 0, 1)).unwrap();
    write_silhouettes(&dir.0, &["b.png"], 2, 3, &rect(2, 3, 0, 1, 0, 1)).unwrap();
    let e = input_error(load_silhouettes(&dir.0));
    assert!(
        e.contains("b.png is 2×3") && e.contains("a.png is 3×2"),
        "{e}"
    );
}

#[test]
fn empty_silhouette_is_named() {
    let dir = TempDir::new("sil-empty");
    write_silhouettes(&dir.0, &["a.png"], 2, 2, &rect(2, 2, 0, 1, 0, 1)).unwrap();
    write_silhouettes(&dir.0, &["b.png"], 2, 2, &[0.5 - 1e-3; 4]).unwrap();
    let e = input_error(load_silhouettes(&dir.0));
    assert!(
        e.contains("b.png has no pixel inside") && e.contains("alpha"),
        "{e}"
    );
    std::fs::remove_file(dir.path("b.png")).unwrap();
    save(
        &dir.path("c.png"),
        &[0, 10, 127, 0],
        2,
        2,
        image::ExtendedColorType::L8,
    );
    let e = input_error(load_silhouettes(&dir.0));
    assert!(
        e.contains("c.png has no pixel inside") && e.contains("luminance"),
        "{e}"
    );
}

#[test]
fn write_silhouettes_checks_names_and_sizes() {
    let dir = TempDir::new("sil-write-bad");
    let one = rect(2, 2, 0, 1, 0, 1);
    for bad in ["a.jpg", "sub/a.png", "../a.png", ".a.png", "a"] {
        let e = input_error(write_silhouettes(&dir.0, &[bad], 2, 2, &one));
        assert!(e.contains(bad), "{e}");
    }
    let e = input_error(write_silhouettes(&dir.0, &["a.png", "b.png"], 2, 2, &one));
    assert!(e.contains("4 mask values for 2 views"), "{e}");
    assert!(input_error(write_silhouettes(&dir.0, &["a.png"], 0, 2, &[])).contains("empty"));
    assert_eq!(dir.entries(), Vec::<String>::new());
}

#[test]
fn cameras_round_trip_exactly() {
    let dir = TempDir::new("cam-roundtrip");
    let path = dir.path("cameras.csv");
    let rows: Vec<CameraRow> = (0..5)
        .map(|i| CameraRow {
            distance: 2.732 + f64::from(i) / 3.0,
            elevation: 30.0 - f64::from(i) * 1e-7,
            azimuth: -f64::from(i) * 72.0 + 1e-300,
        })
        .collect();
    write_cameras(&path, &rows).unwrap();
    assert_eq!(dir.entries(), ["cameras.csv"]);
    assert_eq!(load_cameras(&path).unwrap(), rows);
    let camera = rows[0].camera();
    assert!((camera.eye.length() - 2.732).abs() < 1e-12);
}

#[test]
fn cameras_tolerate_spaces_blank_lines_crlf_and_bom() {
    let dir = TempDir::new("cam-lenient");
    let path = dir.path("c.csv");
    std::fs::write(
        &path,
        "\u{feff}\r\n distance , elevation,azimuth \r\n2.5, 30 ,-45\r\n\r\n  1e1,0,360\r\n",
    )
    .unwrap();
    assert_eq!(
        load_cameras(&path).unwrap(),
        [
            CameraRow {
                distance: 2.5,
                elevation: 30.0,
                azimuth: -45.0
            },
            CameraRow {
                distance: 10.0,
                elevation: 0.0,
                azimuth: 360.0
            }
        ]
    );
}

#[test]
fn each_bad_cameras_file_is_one_clear_error() {
    let dir = TempDir::new("cam-bad");
    let e = input_error(load_cameras(&dir.path("none.csv")));
    assert!(e.contains("none.csv: does not exist"), "{e}");
    let h = CAMERAS_HEADER;
    let cases = [
        ("empty.csv", String::new(), "is empty"),
        (
            "header.csv",
            "distance,azimuth,elevation\n1,2,3\n".into(),
            "header.csv:1: the header is `distance,azimuth,elevation`",
        ),
        (
            "noheader.csv",
            "2.7,0,0\n".into(),
            "noheader.csv:1: the header is `2.7,0,0`",
        ),
        (
            "fields.csv",
            format!("{h}\n1,2,3\n1,2\n"),
            "fields.csv:3: 2 field(s), expected 3",
        ),
        (
            "extra.csv",
            format!("{h}\n1,2,3,4\n"),
            "extra.csv:2: 4 field(s)",
        ),
        (
            "text.csv",
            format!("{h}\n1,up,3\n"),
            "text.csv:2: elevation `up` is not a number",
        ),
        (
            "empty-field.csv",
            format!("{h}\n1,2,\n"),
            "azimuth `` is not a number",
        ),
        (
            "nan.csv",
            format!("{h}\nNaN,2,3\n"),
            "nan.csv:2: distance `NaN` is not a finite",
        ),
        (
            "inf.csv",
            format!("{h}\n1,2,-inf\n"),
            "azimuth `-inf` is not a finite",
        ),
        (
            "zero.csv",
            format!("{h}\n1,2,3\n0,2,3\n"),
            "zero.csv:3: distance 0 must be > 0",
        ),
        (
            "neg.csv",
            format!("{h}\n-2,2,3\n"),
            "distance -2 must be > 0",
        ),
        (
            "norows.csv",
            format!("{h}\n\n"),
            "norows.csv: has a header but no camera row",
        ),
    ];
    for (name, text, expected) in cases {
        let path = dir.path(name);
        std::fs::write(&path, text).unwrap();
        // A fault on a line is `Error::Parse` with that line; a file-wide one `Input`.
        let err = load_cameras(&path).unwrap_err();
        let e = err.to_string();
        let file_wide = ["empty.csv", "norows.csv"].contains(&name);
        match &err {
            Error::Parse { line, path, .. } if !file_wide => {
                assert!(path.ends_with(name), "{name}: {e}");
                assert!(e.contains(&format!("{name}:{line}: ")), "{name}: {e}");
            }
            Error::Input(_) if file_wide => {}
            other => panic!("{name}: the wrong kind of error: {other:?}"),
        }
        assert!(e.contains(expected) && e.contains(name), "{name}: {e}");
    }
}

#[test]
fn counts_must_match() {
    let s = Silhouettes {
        width: 1,
        height: 1,
        names: silhouette_names(6),
        masks: vec![1.0; 6],
    };
    let row = CameraRow {
        distance: 1.0,
        elevation: 0.0,
        azimuth: 0.0,
    };
    let e = input_error(check_counts(&[row; 5], &s));
    assert!(e.starts_with("5 camera rows but 6 silhouettes"), "{e}");
    let one = Silhouettes {
        names: silhouette_names(1),
        masks: vec![1.0],
        ..s.clone()
    };
    assert!(
        input_error(check_counts(&[row; 2], &one)).starts_with("2 camera rows but 1 silhouette:")
    );
    check_counts(&[row; 6], &s).unwrap();
}

#[test]
fn write_cameras_refuses_rows_the_loader_would_refuse() {
    let dir = TempDir::new("cam-write-bad");
    for bad in [
        (0.0, 0.0, 0.0),
        (1.0, f64::NAN, 0.0),
        (1.0, 0.0, f64::INFINITY),
    ] {
        let row = CameraRow {
            distance: bad.0,
            elevation: bad.1,
            azimuth: bad.2,
        };
        let e = input_error(write_cameras(&dir.path("c.csv"), &[row]));
        assert!(e.contains("row 0") && e.contains("c.csv"), "{e}");
    }
    assert_eq!(dir.entries(), Vec::<String>::new());
}

#[test]
fn obj_round_trips_positions_bit_for_bit() {
    let dir = TempDir::new("obj-roundtrip");
    let path = dir.path("fit.obj");
    let mut positions = Mesh::icosphere(2).positions;
    let faces = Mesh::icosphere(2).faces;
    // Awkward floats beside the sphere's irrationals.
    let specials = [
        0.1,
        -0.0,
        1.0 / 3.0,
        f32::MIN_POSITIVE,
        f32::MIN_POSITIVE / 8.0,
        -2.5e-7,
        1.000_000_1,
        f32::MAX,
        -16_777_217.0,
        123_456.79,
    ];
    for (p, s) in positions.iter_mut().zip(specials.chunks(3)) {
        p[..s.len()].copy_from_slice(s);
    }
    write_obj(&path, &positions, &faces).unwrap();
    assert_eq!(dir.entries(), ["fit.obj"]);
    let mesh = Mesh::load_obj(&path, 1).unwrap();
    assert_eq!(mesh.faces, faces);
    let bits = |p: &[[f32; 3]]| -> Vec<u32> { p.iter().flatten().map(|c| c.to_bits()).collect() };
    assert_eq!(bits(&mesh.positions), bits(&positions));
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\nv 0.1 -0 0.33333334\n"), "{text:.200}");
    assert!(text.contains("\nf 1 "), "1-based faces");
}

#[test]
fn write_obj_refuses_non_finite_positions_and_bad_indices() {
    let dir = TempDir::new("obj-bad");
    let path = dir.path("m.obj");
    let p = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let e = input_error(write_obj(
        &path,
        &[p[0], p[1], [0.0, f32::NAN, 0.0]],
        &[[0, 1, 2]],
    ));
    assert!(e.contains("vertex 2") && e.contains("m.obj"), "{e}");
    let e = input_error(write_obj(&path, &p, &[[0, 1, 2], [0, 3, 1]]));
    assert!(
        e.contains("face 1 [0, 3, 1]") && e.contains("3 vertices"),
        "{e}"
    );
    assert_eq!(dir.entries(), Vec::<String>::new());
}

#[test]
fn atomic_writes_replace_whole_files_and_leave_nothing_on_failure() {
    let dir = TempDir::new("atomic");
    let target = dir.path("m.obj");
    std::fs::write(&target, b"old").unwrap();
    let f = AtomicFile::create(&target).unwrap();
    assert_eq!(
        dir.entries().len(),
        2,
        "the temporary file sits beside the target"
    );
    assert_eq!(f.target(), target);
    drop(f);
    assert_eq!(dir.entries(), ["m.obj"]);
    assert_eq!(std::fs::read(&target).unwrap(), b"old");

    write_obj(&target, &[[0.0; 3]; 3], &[[0, 1, 2]]).unwrap();
    assert_eq!(dir.entries(), ["m.obj"]);
    assert!(
        std::fs::read_to_string(&target)
            .unwrap()
            .contains("f 1 2 3")
    );

    // Unwritable destinations fail at once, as Io errors naming the target.
    std::fs::create_dir(dir.path("sub.obj")).unwrap();
    assert!(input_error(write_obj(&dir.path("sub.obj"), &[], &[])).contains("is a folder"));
    match write_cameras(&dir.path("missing/c.csv"), &[]) {
        Err(Error::Io { path, .. }) => assert!(path.ends_with("missing/c.csv")),
        other => panic!("{other:?}"),
    }
    assert_eq!(dir.entries(), ["m.obj", "sub.obj"]);
}
