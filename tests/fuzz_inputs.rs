//! Fuzzed inputs: every parser a user feeds (OBJ, MTL, texture images, silhouette PNGs, camera
//! CSVs) over a fixed, bounded corpus of mutated valid files. A parser may accept or refuse an
//! input, but it never panics, what it accepts holds no NaN and breaks no invariant, and every
//! refusal is an `Err` whose message is one line (no line break, no carriage return).
//!
//! The corpus is fixed: proptest runs from a fixed seed (`RngAlgorithm::ChaCha` with a constant
//! seed), a fixed number of cases per parser, and no failure persistence, so every run (and CI)
//! sees the same inputs. A failure prints the shrunk input; add it to the unit tests of the parser
//! when fixing it.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use proptest::prelude::*;
use proptest::sample::select;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

use softvk::io::{load_cameras, load_silhouettes};
use softvk::mesh::Mesh;

/// Cases per parser: the whole file runs in a few seconds in release mode.
const CASES: u32 = 384;

/// A runner with the fixed corpus: fixed seed, `CASES` cases, no regression file.
fn runner(seed: u8) -> TestRunner {
    let config = Config {
        cases: CASES,
        failure_persistence: None,
        ..Config::default()
    };
    TestRunner::new_with_rng(
        config,
        TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32]),
    )
}

/// Runs `test` over `strategy` with the fixed corpus, failing with the shrunk input.
fn fuzz<S: Strategy>(seed: u8, strategy: S, test: impl Fn(S::Value) -> Result<(), TestCaseError>) {
    if let Err(e) = runner(seed).run(&strategy, test) {
        panic!("{e}");
    }
}

/// A fresh folder for one case, removed when dropped.
struct CaseDir(PathBuf);

impl CaseDir {
    fn new(tag: &str) -> CaseDir {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let dir =
            std::env::temp_dir().join(format!("softvk-fuzz-{tag}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        CaseDir(dir)
    }

    fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }
}

impl Drop for CaseDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The refusal is one line.
fn one_line(what: &str, message: &str) -> Result<(), TestCaseError> {
    prop_assert!(!message.is_empty(), "{what}: empty error message");
    prop_assert!(
        !message.contains('\n') && !message.contains('\r'),
        "{what}: the error is not one line: {message:?}"
    );
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Mutations shared by the text formats.

/// One edit of a text file, line-wise. Indices are taken modulo the line count.
#[derive(Clone, Debug)]
enum LineEdit {
    Delete(usize),
    Duplicate(usize),
    Swap(usize, usize),
    Insert(usize, String),
    /// Replace the `k`th whitespace- or comma-separated token of a line.
    Token(usize, usize, String),
}

/// One edit of the file's bytes, after the line edits.
#[derive(Clone, Debug)]
enum ByteEdit {
    Truncate(usize),
    Set(usize, u8),
    Insert(usize, Vec<u8>),
}

fn apply_lines(base: &[&str], edits: &[LineEdit], separator: char) -> String {
    let mut lines: Vec<String> = base.iter().map(|s| s.to_string()).collect();
    for edit in edits {
        let n = lines.len();
        match edit {
            LineEdit::Delete(i) if n > 0 => {
                lines.remove(i % n);
            }
            LineEdit::Duplicate(i) if n > 0 => {
                let l = lines[i % n].clone();
                lines.insert(i % n, l);
            }
            LineEdit::Swap(i, j) if n > 0 => lines.swap(i % n, j % n),
            LineEdit::Insert(i, line) => lines.insert(i % (n + 1), line.clone()),
            LineEdit::Token(i, k, token) if n > 0 => {
                let line = &lines[i % n];
                let mut tokens: Vec<String> = line.split(separator).map(str::to_string).collect();
                let k = k % tokens.len();
                tokens[k] = token.clone();
                lines[i % n] = tokens.join(&separator.to_string());
            }
            _ => {}
        }
    }
    let mut text = lines.join("\n");
    text.push('\n');
    text
}

fn apply_bytes(mut bytes: Vec<u8>, edits: &[ByteEdit]) -> Vec<u8> {
    for edit in edits {
        let n = bytes.len();
        match edit {
            ByteEdit::Truncate(k) => bytes.truncate(k % (n + 1)),
            ByteEdit::Set(k, b) if n > 0 => bytes[k % n] = *b,
            ByteEdit::Insert(k, more) => {
                let at = k % (n + 1);
                bytes.splice(at..at, more.iter().copied());
            }
            _ => {}
        }
    }
    bytes
}

fn line_edits(
    lines: impl Strategy<Value = String> + Clone,
    tokens: impl Strategy<Value = String> + Clone,
    max: usize,
) -> impl Strategy<Value = Vec<LineEdit>> {
    let edit = prop_oneof![
        1 => (0..64usize).prop_map(LineEdit::Delete),
        1 => (0..64usize).prop_map(LineEdit::Duplicate),
        1 => (0..64usize, 0..64usize).prop_map(|(i, j)| LineEdit::Swap(i, j)),
        3 => (0..64usize, lines).prop_map(|(i, l)| LineEdit::Insert(i, l)),
        3 => (0..64usize, 0..8usize, tokens).prop_map(|(i, k, t)| LineEdit::Token(i, k, t)),
    ];
    prop::collection::vec(edit, 0..max)
}

/// Byte edits: mostly none, otherwise truncations, single bytes and short random runs.
fn byte_edits() -> impl Strategy<Value = Vec<ByteEdit>> {
    let edit = prop_oneof![
        (0..100_000usize).prop_map(ByteEdit::Truncate),
        (0..100_000usize, any::<u8>()).prop_map(|(k, b)| ByteEdit::Set(k, b)),
        (0..100_000usize, prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(k, v)| ByteEdit::Insert(k, v)),
    ];
    prop_oneof![
        3 => Just(Vec::new()),
        1 => prop::collection::vec(edit, 1..4),
    ]
}

/// Numbers and words that break parsers.
const NASTY_TOKENS: &[&str] = &[
    "",
    " ",
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "infinity",
    "1e39",
    "-1e39",
    "1e309",
    "1e-320",
    "0",
    "-0",
    "1",
    "-1",
    "2",
    "3",
    "4",
    "0.5",
    "+1",
    "0x10",
    "1,5",
    "1.2.3",
    "abc",
    "é",
    "\t",
    "\r",
    "\u{0}",
    "\u{feff}",
    "/",
    "//",
    "1/1",
    "1//1",
    "1/1/1",
    "1/1/1/1",
    "/1",
    "1/",
    "-1/-1",
    "0/0",
    "99/99",
    "4294967295",
    "4294967296",
    "4294967297",
    "-4294967296",
    "9223372036854775807",
    "-9223372036854775808",
    "9223372036854775808",
    "18446744073709551616",
    "99999999999999999999999",
    "-99999999999999999999999",
];

fn nasty_token() -> impl Strategy<Value = String> + Clone {
    select(NASTY_TOKENS).prop_map(str::to_string)
}

/// A line of `keyword` followed by up to 7 nasty tokens.
fn grammar_line(keywords: &'static [&'static str]) -> impl Strategy<Value = String> + Clone {
    (
        select(keywords),
        prop::collection::vec(nasty_token(), 0..8),
        select(&[" ", "\t", "  "][..]),
    )
        .prop_map(|(k, tokens, sep)| {
            std::iter::once(k.to_string())
                .chain(tokens)
                .collect::<Vec<_>>()
                .join(sep)
        })
}

// ---------------------------------------------------------------------------------------------
// Images.

/// A small image in one of the PNG colour types the loaders see.
#[derive(Clone, Debug)]
struct PngSpec {
    width: u32,
    height: u32,
    color: u8,
    /// Pixel bytes are drawn from this seed (mask patterns, colours).
    seed: u64,
    /// 0: nothing inside, 1: everything inside, else a pattern.
    fill: u8,
}

fn png_spec() -> impl Strategy<Value = PngSpec> {
    (
        select(&[1u32, 2, 3, 8, 13][..]),
        select(&[1u32, 2, 5, 8][..]),
        0u8..6,
        any::<u64>(),
        0u8..4,
    )
        .prop_map(|(width, height, color, seed, fill)| PngSpec {
            width,
            height,
            color,
            seed,
            fill,
        })
}

fn encode_png(spec: &PngSpec) -> Vec<u8> {
    use image::DynamicImage as D;
    let (w, h) = (spec.width, spec.height);
    let mut state = spec.seed | 1;
    let mut value = |i: u32| -> u8 {
        match spec.fill {
            0 => 0,
            1 => 255,
            _ => {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                if i % 3 == 0 { 255 } else { (state >> 56) as u8 }
            }
        }
    };
    let grey = image::GrayImage::from_fn(w, h, |x, y| image::Luma([value(x + y * w)]));
    let image = match spec.color {
        0 => D::ImageLuma8(grey),
        1 => D::ImageLumaA8(image::GrayAlphaImage::from_fn(w, h, |x, y| {
            image::LumaA([9, grey.get_pixel(x, y).0[0]])
        })),
        2 => D::ImageRgb8(image::RgbImage::from_fn(w, h, |x, y| {
            let v = grey.get_pixel(x, y).0[0];
            image::Rgb([v, 255 - v, v / 2])
        })),
        3 => D::ImageRgba8(image::RgbaImage::from_fn(w, h, |x, y| {
            image::Rgba([1, 2, 3, grey.get_pixel(x, y).0[0]])
        })),
        4 => D::ImageLuma16(image::ImageBuffer::from_fn(w, h, |x, y| {
            image::Luma([u16::from(grey.get_pixel(x, y).0[0]) * 257])
        })),
        _ => D::ImageRgba16(image::ImageBuffer::from_fn(w, h, |x, y| {
            let v = u16::from(grey.get_pixel(x, y).0[0]) * 257;
            image::Rgba([v, v, 0, v])
        })),
    };
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .unwrap();
    bytes
}

/// CRC-32 (ISO-HDLC) as PNG chunks use it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// What a PNG file of the corpus holds.
#[derive(Clone, Debug)]
enum ImageCase {
    Valid(PngSpec),
    /// A valid PNG with byte edits.
    Mutated(PngSpec, Vec<ByteEdit>),
    /// A valid PNG whose header claims another size (or depth and colour type), CRC fixed so the
    /// decoder believes it.
    Header {
        spec: PngSpec,
        width: u32,
        height: u32,
        depth_color: Option<(u8, u8)>,
    },
    /// Random bytes, optionally behind a PNG or GIF signature.
    Random(u8, Vec<u8>),
}

fn image_case() -> impl Strategy<Value = ImageCase> {
    let sides = select(
        &[
            0u32,
            1,
            7,
            4096,
            65_535,
            65_536,
            100_000,
            1 << 30,
            (1 << 31) - 1,
            1 << 31,
            u32::MAX,
        ][..],
    );
    prop_oneof![
        2 => png_spec().prop_map(ImageCase::Valid),
        3 => (png_spec(), byte_edits()).prop_map(|(s, e)| ImageCase::Mutated(s, e)),
        3 => (
            png_spec(),
            sides.clone(),
            sides,
            prop::option::of((any::<u8>(), any::<u8>()))
        )
            .prop_map(|(spec, width, height, depth_color)| ImageCase::Header {
                spec,
                width,
                height,
                depth_color
            }),
        1 => (0u8..3, prop::collection::vec(any::<u8>(), 0..64))
            .prop_map(|(kind, bytes)| ImageCase::Random(kind, bytes)),
    ]
}

fn image_bytes(case: &ImageCase) -> Vec<u8> {
    match case {
        ImageCase::Valid(spec) => encode_png(spec),
        ImageCase::Mutated(spec, edits) => apply_bytes(encode_png(spec), edits),
        ImageCase::Header {
            spec,
            width,
            height,
            depth_color,
        } => {
            let mut bytes = encode_png(spec);
            // Signature (8), IHDR length (4) and type (4), then width, height, depth, colour.
            bytes[16..20].copy_from_slice(&width.to_be_bytes());
            bytes[20..24].copy_from_slice(&height.to_be_bytes());
            if let Some((depth, color)) = depth_color {
                bytes[24] = *depth;
                bytes[25] = *color;
            }
            let crc = crc32(&bytes[12..29]);
            bytes[29..33].copy_from_slice(&crc.to_be_bytes());
            bytes
        }
        ImageCase::Random(kind, random) => {
            let signature: &[u8] = match kind {
                0 => b"",
                1 => b"\x89PNG\r\n\x1a\n",
                _ => b"GIF89a",
            };
            [signature, random].concat()
        }
    }
}

// ---------------------------------------------------------------------------------------------
// OBJ and MTL (and the texture they name).

const OBJ: &[&str] = &[
    "# a textured quad and a plain triangle",
    "mtllib m.mtl",
    "o quad",
    "v 0 0 0",
    "v 1 0 0",
    "v 1 1 0",
    "v 0 1 0.5",
    "vt 0 0",
    "vt 1 0",
    "vt 1 1",
    "vt 0 1",
    "vn 0 0 1",
    "usemtl skin",
    "f 1/1/1 2/2/1 3/3/1 4/4/1",
    "g other",
    "usemtl plain",
    "v 0.5 0.5 -1",
    "f -1 1 2",
    "s off",
    "l 1 2",
];

const OBJ_LINES: &[&str] = &[
    "",
    "   ",
    "\t",
    "#",
    "\r",
    "f 1 2 3\r",
    "v 0 0",
    "v 1 2 3 0",
    "v 1 2 3 1e-45",
    "v 1 2 3 4 5",
    "v 1 1 1 0.5 nan 0.5",
    "v 1 1 1 0.5 0.5 0.5",
    "vt nan nan",
    "vt inf 0",
    "vt 1e300 -1e300",
    "vt",
    "f 1 2",
    "f 0 1 2",
    "f 1 1 1",
    "f 1/9 2/1 3/1",
    "f 1/-9 2 3",
    "f 1/0 2/1 3/1",
    "f 1 2 3 4 5 6 7 8 9",
    "f -1 -1 -1",
    "mtllib",
    "mtllib missing.mtl",
    "mtllib m.mtl",
    "mtllib ../../../../../../../../etc/passwd",
    "mtllib /",
    "mtllib .",
    "mtllib m.mtl missing.mtl",
    "usemtl",
    "usemtl nope",
    "usemtl skin",
    "usemtl plain",
    "o",
    "g",
    "p 1",
    "l 1 2 3",
];

const OBJ_KEYWORDS: &[&str] = &["v", "vt", "vn", "f", "l", "p", "mtllib", "usemtl", "o", "g"];

const MTL: &[&str] = &[
    "newmtl skin",
    "Ka 0 0 0",
    "Kd 0.8 0.5 0.2",
    "map_Kd tex.png",
    "newmtl plain",
    "Kd 0.1 0.2 0.3",
    "Ns 10",
    "d 1",
];

const MTL_LINES: &[&str] = &[
    "",
    "newmtl",
    "newmtl skin",
    "newmtl plain",
    "Kd",
    "Kd 1",
    "Kd nan nan nan",
    "Kd inf 0 0",
    "Kd -1 2 1e39",
    "map_Kd",
    "map_Kd missing.png",
    "map_Kd -s 1 1 1",
    "map_Kd -s 1 1 1 tex.png",
    "map_Kd /",
    "map_Kd .",
    "map_Kd ..",
    "map_Kd tex.png",
    "map_Kd m.mtl",
    "Ns abc",
    "illum x",
    "d",
    "\r",
];

const MTL_KEYWORDS: &[&str] = &["newmtl", "Kd", "Ka", "Ks", "Ns", "d", "map_Kd", "illum"];

#[derive(Clone, Debug)]
struct ObjCase {
    obj: Vec<LineEdit>,
    obj_bytes: Vec<ByteEdit>,
    /// `None`: no MTL file.
    mtl: Option<(Vec<LineEdit>, Vec<ByteEdit>)>,
    /// `None`: no texture file.
    texture: Option<ImageCase>,
    texture_res: u32,
}

fn obj_case() -> impl Strategy<Value = ObjCase> {
    let obj_lines = prop_oneof![
        select(OBJ_LINES).prop_map(str::to_string),
        grammar_line(OBJ_KEYWORDS),
    ];
    let mtl_lines = prop_oneof![
        select(MTL_LINES).prop_map(str::to_string),
        grammar_line(MTL_KEYWORDS),
    ];
    (
        line_edits(obj_lines, nasty_token(), 6),
        byte_edits(),
        prop::option::weighted(0.8, (line_edits(mtl_lines, nasty_token(), 4), byte_edits())),
        prop::option::weighted(0.8, image_case()),
        1u32..4,
    )
        .prop_map(|(obj, obj_bytes, mtl, texture, texture_res)| ObjCase {
            obj,
            obj_bytes,
            mtl,
            texture,
            texture_res,
        })
}

fn check_obj(case: ObjCase) -> Result<(), TestCaseError> {
    let dir = CaseDir::new("obj");
    let obj = apply_bytes(
        apply_lines(OBJ, &case.obj, ' ').into_bytes(),
        &case.obj_bytes,
    );
    let path = dir.write("mesh.obj", &obj);
    if let Some((lines, bytes)) = &case.mtl {
        dir.write(
            "m.mtl",
            &apply_bytes(apply_lines(MTL, lines, ' ').into_bytes(), bytes),
        );
    }
    if let Some(texture) = &case.texture {
        dir.write("tex.png", &image_bytes(texture));
    }
    match Mesh::load_obj(&path, case.texture_res) {
        Ok(mesh) => {
            prop_assert!(mesh.validate().is_ok(), "{:?}", mesh.validate());
            prop_assert_eq!(mesh.texture_res, case.texture_res);
            let finite = |v: &[[f32; 3]]| v.iter().flatten().all(|c| c.is_finite());
            prop_assert!(finite(&mesh.positions), "non-finite position");
            prop_assert!(finite(&mesh.textures), "non-finite texel");
            if let Some(colors) = &mesh.vertex_colors {
                prop_assert!(finite(colors), "non-finite vertex colour");
            }
        }
        Err(e) => one_line("OBJ", &e.to_string())?,
    }
    Ok(())
}

#[test]
fn obj_mtl_and_textures_never_panic_and_refuse_in_one_line() {
    fuzz(1, obj_case(), check_obj);
}

#[test]
fn random_bytes_as_obj_never_panic() {
    let bytes = prop_oneof![
        prop::collection::vec(any::<u8>(), 0..256),
        // Printable ASCII with line breaks: more of it gets past UTF-8 to the parser.
        prop::collection::vec(
            prop_oneof![8 => 0x20u8..0x7f, 1 => Just(b'\n'), 1 => Just(b'/')],
            0..256
        ),
    ];
    fuzz(2, bytes, |bytes| {
        let dir = CaseDir::new("objbytes");
        let path = dir.write("mesh.obj", &bytes);
        if let Err(e) = Mesh::load_obj(&path, 1) {
            one_line("OBJ", &e.to_string())?;
        }
        Ok(())
    });
}

/// The texture alone, straight behind a valid OBJ and MTL, so every image case reaches the
/// decoder.
#[test]
fn texture_images_never_panic_and_refuse_in_one_line() {
    fuzz(3, image_case(), |image| {
        check_obj(ObjCase {
            obj: Vec::new(),
            obj_bytes: Vec::new(),
            mtl: Some((Vec::new(), Vec::new())),
            texture: Some(image),
            texture_res: 2,
        })
    });
}

// ---------------------------------------------------------------------------------------------
// Silhouettes.

#[derive(Clone, Debug)]
enum SilhouetteFile {
    Image(ImageCase),
    Empty,
    Folder,
}

fn silhouette_files() -> impl Strategy<Value = Vec<(&'static str, SilhouetteFile)>> {
    let name = prop_oneof![
        4 => select(&["view_000.png", "view_001.png", "view_002.PNG"][..]),
        1 => select(&[".hidden.png", "notes.txt", "view_003.png"][..]),
    ];
    let file = prop_oneof![
        8 => image_case().prop_map(SilhouetteFile::Image),
        1 => Just(SilhouetteFile::Empty),
        1 => Just(SilhouetteFile::Folder),
    ];
    prop::collection::vec((name, file), 0..5)
}

#[test]
fn silhouette_pngs_never_panic_and_refuse_in_one_line() {
    fuzz(4, silhouette_files(), |files| {
        let dir = CaseDir::new("sil");
        for (name, file) in &files {
            let path = dir.0.join(name);
            let _ = std::fs::remove_dir_all(&path);
            match file {
                SilhouetteFile::Image(image) => {
                    dir.write(name, &image_bytes(image));
                }
                SilhouetteFile::Empty => {
                    dir.write(name, b"");
                }
                SilhouetteFile::Folder => {
                    let _ = std::fs::remove_file(&path);
                    std::fs::create_dir_all(&path).unwrap();
                }
            }
        }
        match load_silhouettes(&dir.0) {
            Ok(s) => {
                prop_assert!(s.views() > 0);
                prop_assert_eq!(s.names.len(), s.views());
                prop_assert_eq!(s.masks.len(), s.views() * s.pixels());
                prop_assert!(s.pixels() > 0);
                prop_assert!(s.masks.iter().all(|&m| m == 0.0 || m == 1.0));
            }
            Err(e) => one_line("silhouettes", &e.to_string())?,
        }
        Ok(())
    });
}

// ---------------------------------------------------------------------------------------------
// Camera CSVs.

const CAMERAS: &[&str] = &["distance,elevation,azimuth", "2.732,30,0", "2.5, -10 ,90"];

const CAMERA_LINES: &[&str] = &[
    "",
    "  ",
    "\r",
    "\u{feff}distance,elevation,azimuth",
    "distance,elevation,azimuth",
    "distance;elevation;azimuth",
    "1,2",
    "1,2,3,4",
    "nan,0,0",
    "inf,0,0",
    "0,0,0",
    "-1,0,0",
    "1e309,0,0",
    "1e-320,0,0",
    "1,nan,0",
    "1,,0",
    ",,",
    "1;2;3",
    "1,2,3\r",
    "1,2\r,3",
    "+1,0,0",
];

fn check_cameras(bytes: Vec<u8>) -> Result<(), TestCaseError> {
    let dir = CaseDir::new("cam");
    let path = dir.write("cameras.csv", &bytes);
    match load_cameras(&path) {
        Ok(rows) => {
            prop_assert!(!rows.is_empty());
            for r in &rows {
                prop_assert!(r.distance.is_finite() && r.distance > 0.0, "{r:?}");
                prop_assert!(r.elevation.is_finite() && r.azimuth.is_finite(), "{r:?}");
            }
        }
        Err(e) => one_line("cameras", &e.to_string())?,
    }
    Ok(())
}

#[test]
fn camera_csvs_never_panic_and_refuse_in_one_line() {
    let lines = prop_oneof![
        select(CAMERA_LINES).prop_map(str::to_string),
        prop::collection::vec(nasty_token(), 0..5).prop_map(|t| t.join(",")),
    ];
    let case = (line_edits(lines, nasty_token(), 6), byte_edits());
    fuzz(5, case, |(lines, bytes)| {
        check_cameras(apply_bytes(
            apply_lines(CAMERAS, &lines, ',').into_bytes(),
            &bytes,
        ))
    });
    fuzz(6, prop::collection::vec(any::<u8>(), 0..128), check_cameras);
}

/// The corpus is what it claims: the unmutated files load, so the mutations start from valid
/// inputs (and a parser that refused everything would fail here, not pass the fuzzing).
#[test]
fn the_corpus_starts_from_valid_files() {
    let dir = CaseDir::new("valid");
    let path = dir.write("mesh.obj", apply_lines(OBJ, &[], ' ').as_bytes());
    dir.write("m.mtl", apply_lines(MTL, &[], ' ').as_bytes());
    let spec = PngSpec {
        width: 3,
        height: 2,
        color: 2,
        seed: 7,
        fill: 2,
    };
    dir.write("tex.png", &encode_png(&spec));
    let mesh = Mesh::load_obj(&path, 2).unwrap();
    assert_eq!((mesh.vertex_count(), mesh.face_count()), (5, 3));
    assert_eq!(mesh.textures[8], [0.1, 0.2, 0.3]);

    for color in 0..6 {
        let sil = CaseDir::new("valid-sil");
        let spec = PngSpec {
            width: 8,
            height: 5,
            color,
            seed: 1,
            fill: 2,
        };
        sil.write("view_000.png", &encode_png(&spec));
        let s = load_silhouettes(&sil.0).unwrap();
        assert_eq!((s.width, s.height, s.views()), (8, 5, 1));
    }

    let cameras = dir.write("cameras.csv", apply_lines(CAMERAS, &[], ',').as_bytes());
    assert_eq!(load_cameras(&cameras).unwrap().len(), 2);
}

/// What the fuzzing found, kept as plain cases: each was a panic, a NaN in an accepted mesh, or
/// a multi-line error before its fix.
#[test]
fn found_by_fuzzing() {
    let dir = CaseDir::new("found");
    let obj = |name: &str, body: &str| dir.write(name, format!("mtllib m.mtl\n{body}").as_bytes());
    let triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n";
    let refused = |path: &Path, needles: &[&str]| {
        let message = match Mesh::load_obj(path, 1) {
            Ok(_) => panic!("{}: accepted", path.display()),
            Err(e) => e.to_string(),
        };
        assert!(
            !message.contains('\n') && !message.contains('\r'),
            "{message:?}"
        );
        for needle in needles {
            assert!(
                message.contains(needle),
                "`{needle}` missing from: {message}"
            );
        }
    };

    // tobj 4 panicked (`try_into().unwrap()`) on a colour with fewer than three numbers.
    for kd in ["Kd", "Kd 1", "Ka 1 2", "Ks", "Ke 0 0"] {
        dir.write("m.mtl", format!("newmtl a\n{kd}\n").as_bytes());
        let path = obj("short.obj", &format!("{triangle}usemtl a\nf 1 2 3\n"));
        refused(&path, &["m.mtl", "needs three numbers", "line 2"]);
    }
    // A NaN colour, texture coordinate or vertex colour gave NaN texels or colours.
    dir.write("m.mtl", b"newmtl a\nKd nan 0 inf\n");
    refused(
        &obj("kd.obj", &format!("{triangle}usemtl a\nf 1 2 3\n")),
        &["m.mtl", "'a'", "Kd"],
    );
    dir.write("m.mtl", b"newmtl a\nmap_Kd tex.png\n");
    let spec = PngSpec {
        width: 2,
        height: 2,
        color: 2,
        seed: 3,
        fill: 2,
    };
    dir.write("tex.png", &encode_png(&spec));
    refused(
        &obj(
            "vt.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt nan 0\nusemtl a\nf 1/1 2/1 3/1\n",
        ),
        &[
            "vt.obj",
            "texture coordinate is not a finite number",
            "line 5",
        ],
    );
    refused(
        &obj(
            "colour.obj",
            "v 0 0 0 1 0 0\nv 1 0 0 0 inf 0\nv 0 1 0 0 0 1\nf 1 2 3\n",
        ),
        &[
            "colour.obj",
            "vertex colour is not a finite number",
            "line 3",
        ],
    );
    // Carriage returns inside a line went into messages verbatim.
    refused(
        &obj("cr.obj", "v 0 0 0\nv 1 0 0\nv 0 1\rz\nf 1 2 3\n"),
        &["cr.obj", "line 4", "\\r"],
    );
    let cameras = dir.write("cameras.csv", b"distance,elevation\razimuth\n1,2,3\n");
    let message = load_cameras(&cameras).unwrap_err().to_string();
    assert!(
        !message.contains('\r') && message.contains("\\r"),
        "{message:?}"
    );
    let cameras = dir.write("cameras.csv", b"distance,elevation,azimuth\n1,2,x\ry\n");
    let message = load_cameras(&cameras).unwrap_err().to_string();
    assert!(
        !message.contains('\r') && message.contains("x\\ry"),
        "{message:?}"
    );
}

/// A small file can claim a huge picture in its header: textures and silhouettes are refused
/// by their size before anything is decoded (no allocation of gigabytes).
#[test]
fn absurd_image_headers_are_refused_before_decoding() {
    let spec = PngSpec {
        width: 3,
        height: 2,
        color: 3,
        seed: 5,
        fill: 1,
    };
    let claim = |width: u32, height: u32| {
        image_bytes(&ImageCase::Header {
            spec: spec.clone(),
            width,
            height,
            depth_color: None,
        })
    };
    let dir = CaseDir::new("header");
    dir.write("m.mtl", b"newmtl a\nmap_Kd tex.png\n");
    let path = dir.write(
        "mesh.obj",
        b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\n",
    );
    // 10 000² RGBA8 is 400 MB: under the image crate's own limit, over softvk's.
    for (w, h) in [(10_000, 10_000), (70_000, 1_000), (1 << 30, 1 << 30)] {
        dir.write("tex.png", &claim(w, h));
        let message = Mesh::load_obj(&path, 1).unwrap_err().to_string();
        assert!(
            message.contains("tex.png") && message.contains(&format!("{w}×{h}")),
            "{message}"
        );
        assert!(message.contains("at most 67108864 pixels"), "{message}");
    }
    let sil = CaseDir::new("header-sil");
    for (w, h) in [(20_000, 1), (1, 100_000)] {
        sil.write("view_000.png", &claim(w, h));
        let message = load_silhouettes(&sil.0).unwrap_err().to_string();
        assert!(
            message.contains("view_000.png") && message.contains(&format!("{w}×{h}")),
            "{message}"
        );
        assert!(message.contains("sides of at most 16384"), "{message}");
    }
}

// ---------------------------------------------------------------------------------------------
// Checkpoints.

/// A valid checkpoint file of each kind of fit, with a reader that reads its log and state as
/// a resume does (without a device: the state's checks are the host's): mesh (an icosphere(1)
/// template), field (the default options' field) and pose.
type CheckpointReader = Box<dyn Fn(&Path) -> Result<(), softvk::Error>>;

fn checkpoint_cases() -> Vec<(&'static str, Vec<u8>, CheckpointReader)> {
    use softvk::fit::checkpoint::{
        Checkpoint, FitKind, Reader, Writer, read_adam, read_f64_state, write_f64_state,
    };
    use softvk::fit::field_fit::{FieldFitLog, FieldFitOptions};
    use softvk::fit::log::write_log;
    use softvk::fit::mesh_fit::FitLog;
    use softvk::fit::pose::{Pose, PoseLog};
    use softvk::fit::session::{LogRow, Resume};
    const FINGERPRINT: u64 = 0x5eed;
    let ramp = |n: usize, scale: f32| -> Vec<f32> { (0..n).map(|i| scale * i as f32).collect() };
    let dir = CaseDir::new("checkpoint-seed");
    let checkpoint = |kind, iteration, log: &dyn Fn(&mut Writer), state: &dyn Fn(&mut Writer)| {
        let mut w = Writer::default();
        log(&mut w);
        w.u32(0); // no validations
        state(&mut w);
        let path = dir.0.join("seed.ckpt");
        Checkpoint {
            kind,
            fingerprint: FINGERPRINT,
            iteration,
            seconds: 0.3,
            payload: w.0,
        }
        .write(&path)
        .unwrap();
        std::fs::read(&path).unwrap()
    };
    // What a resume reads: the log, then the state, all of it.
    fn read<R: LogRow>(
        p: &Path,
        kind: FitKind,
        state: impl Fn(&mut Reader<'_>) -> Result<(), softvk::Error>,
    ) -> Result<(), softvk::Error> {
        let resume = Resume::<R>::read(p, kind, FINGERPRINT)?;
        let mut r = Reader::new(&resume.state);
        state(&mut r)?;
        if !r.done() {
            return Err(softvk::Error::Input("bytes after the state".into()));
        }
        Ok(())
    }

    let n_mesh = 3 * Mesh::icosphere(1).vertex_count() + 3;
    let mesh_row = |i: u32| FitLog {
        iteration: i,
        silhouette: 0.5 / i as f32,
        laplacian: 0.1,
        flatten: 0.2,
        total: 0.8,
        entries: 1000 + u64::from(i),
        seconds: 0.1 * f64::from(i),
    };
    let mesh = checkpoint(
        FitKind::Mesh,
        3,
        &|w| write_log(w, &[mesh_row(1), mesh_row(2), mesh_row(3)]),
        &|w| {
            w.f32s(&ramp(n_mesh, 0.01));
            w.f32s(&ramp(n_mesh, -0.001));
            w.f32s(&ramp(n_mesh, 1e-6));
        },
    );
    let n_field = FieldFitOptions::default().field.param_count();
    let field_row = |i: u32| FieldFitLog {
        iteration: i,
        silhouette: 0.3,
        geo: 0.01,
        total: 0.31,
        seconds: 0.5,
    };
    let field = checkpoint(
        FitKind::Field,
        2,
        &|w| write_log(w, &[field_row(1), field_row(2)]),
        &|w| {
            w.f32s(&ramp(n_field, 1e-3));
            w.f32s(&ramp(n_field, 1e-4));
            w.f32s(&ramp(n_field, 1e-8));
        },
    );
    let pose_row = PoseLog {
        iteration: 1,
        loss: 0.2,
        sigma: 1e-4,
        gamma: 1e-4,
        pose: Pose::from_array([0.1, -0.2, 0.3, 0.0, 0.05, 2.0]),
        seconds: 0.2,
    };
    let pose = checkpoint(FitKind::Pose, 1, &|w| write_log(w, &[pose_row]), &|w| {
        write_f64_state(w, &[[0.1, -0.2, 0.3, 0.0, 0.05, 2.0], [0.01; 6], [1e-4; 6]])
    });
    vec![
        (
            "mesh",
            mesh,
            Box::new(move |p: &Path| {
                read::<FitLog>(p, FitKind::Mesh, |r| {
                    read_adam(r, n_mesh, "the template").map(drop)
                })
            }),
        ),
        (
            "field",
            field,
            Box::new(move |p: &Path| {
                read::<FieldFitLog>(p, FitKind::Field, |r| {
                    read_adam(r, n_field, "the field").map(drop)
                })
            }),
        ),
        (
            "pose",
            pose,
            Box::new(|p: &Path| {
                read::<PoseLog>(p, FitKind::Pose, |r| read_f64_state::<6>(r).map(drop))
            }),
        ),
    ]
}

/// Checkpoints of every kind, mutated (truncated, bytes set, runs inserted): never a panic, a
/// damaged file is always refused in one line (the checksum sees every edit that changes a
/// byte), and an unchanged one is read back.
#[test]
fn checkpoints_never_panic_and_refuse_damage_in_one_line() {
    for (seed, (kind, valid, read)) in checkpoint_cases().into_iter().enumerate() {
        let dir = CaseDir::new("checkpoint");
        read(&dir.write("valid.ckpt", &valid)).unwrap_or_else(|e| panic!("{kind}: {e}"));
        fuzz(40 + seed as u8, byte_edits(), |edits| {
            let bytes = apply_bytes(valid.clone(), &edits);
            let path = dir.write("case.ckpt", &bytes);
            match read(&path) {
                Ok(()) => prop_assert!(bytes == valid, "{kind}: a damaged checkpoint was read"),
                Err(e) => {
                    prop_assert!(bytes != valid, "{kind}: the valid file was refused: {e}");
                    one_line(kind, &e.to_string())?;
                }
            }
            Ok(())
        });
    }
}

/// A well-formed checkpoint (checksum right) whose state holds a NaN, an infinity or a negative
/// second moment is refused: a resumed fit would otherwise run on garbage.
#[test]
fn checkpoints_with_non_finite_states_are_refused() {
    use softvk::fit::checkpoint::{Reader, Writer, read_adam, read_f64_state, write_f64_state};
    let n = 3 * Mesh::icosphere(0).vertex_count() + 3;
    for (what, at, value) in [
        ("NaN parameter", 0, f32::NAN),
        ("infinite first moment", n + 1, f32::INFINITY),
        ("negative second moment", 2 * n + 2, -1.0),
    ] {
        let mut flat = vec![0.5f32; 3 * n];
        flat[at] = value;
        let mut w = Writer::default();
        for k in 0..3 {
            w.f32s(&flat[k * n..(k + 1) * n]);
        }
        let err = read_adam(&mut Reader::new(&w.0), n, "the template").unwrap_err();
        assert!(err.to_string().contains("non-finite"), "{what}: {err}");
        // The pose fit's f64 state, likewise.
        let mut state = [[0.5f64; 6]; 3];
        state[at / n][at % 6] = f64::from(value);
        let mut w = Writer::default();
        write_f64_state(&mut w, &state);
        let err = read_f64_state::<6>(&mut Reader::new(&w.0)).unwrap_err();
        assert!(
            err.to_string().contains("non-finite"),
            "{what} (f64): {err}"
        );
    }
}
