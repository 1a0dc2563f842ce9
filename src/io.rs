//! The files of the fitting commands (SPEC §6): the target silhouettes (`--silhouettes DIR`), the
//! views they were taken from (`--cameras C.csv`), and the fitted mesh (`--out M.obj`).
//!
//! Every loader checks its input whole and fails with one [`Error::Input`] line naming the file
//! and what is wrong with it; every writer is atomic (a temporary file beside the target, renamed
//! into place), so a failed run leaves no half-written file and no temporary one.
//!
//! The writers are the loaders' inverses: `write_silhouettes` → `load_silhouettes` and
//! `write_cameras` → `load_cameras` give back what was written, and `write_obj` →
//! [`Mesh::load_obj`](crate::mesh::Mesh::load_obj) the same positions bit for bit.

use std::ffi::OsString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub(crate) use crate::atomic_file::AtomicFile;
use crate::camera::Camera;
use crate::error::{Error, Result, one_line};
use crate::raster::settings::MAX_IMAGE_SIDE;

/// Target silhouettes, one per view, all of one size.
#[derive(Clone, Debug, PartialEq)]
pub struct Silhouettes {
    /// Width of every silhouette, in pixels.
    pub width: u32,
    /// Height of every silhouette, in pixels.
    pub height: u32,
    /// The file names (not paths), in view order: sorted by name.
    pub names: Vec<String>,
    /// `names.len() * height * width` values, view-major then row-major (row 0 at the top), each
    /// 0.0 (outside) or 1.0 (inside): the layout of the silhouette losses' targets.
    pub masks: Vec<f32>,
}

impl Silhouettes {
    /// Number of views.
    pub fn views(&self) -> usize {
        self.names.len()
    }

    /// Pixels in one view.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The mask of `view`, row-major.
    pub fn mask(&self, view: usize) -> &[f32] {
        let n = self.pixels();
        &self.masks[view * n..(view + 1) * n]
    }
}

/// Loads the silhouettes of a fit (SPEC §6): every `*.png` file of `dir` (extension in any
/// case), sorted by file name. A pixel is inside when its alpha, or its luminance when the PNG
/// has no alpha channel, is over half of full scale (> 127 of 255, > 32767 of 65535).
///
/// Hidden files (names starting with `.`, such as the `._name.png` resource forks macOS leaves
/// on other file systems) and folders are skipped; any other PNG must decode. Non-square images
/// are fine. Errors name the folder or file: a missing folder, no PNG in it, a PNG that does not
/// decode, two sizes (naming a file of each), and a silhouette with no pixel inside (a fit to it
/// would shrink the mesh to nothing; it usually means an alpha channel that is not the mask).
pub fn load_silhouettes(dir: &Path) -> Result<Silhouettes> {
    if !dir.is_dir() {
        let what = if dir.exists() {
            "is not a folder"
        } else {
            "does not exist"
        };
        return Err(Error::Input(format!(
            "silhouette folder {}: {what}",
            dir.display()
        )));
    }
    let io = |source| Error::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut files: Vec<(OsString, PathBuf)> = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let entry = entry.map_err(io)?;
        let name = entry.file_name();
        let path = entry.path();
        let is_png = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if is_png && !name.to_string_lossy().starts_with('.') && !path.is_dir() {
            files.push((name, path));
        }
    }
    if files.is_empty() {
        return Err(Error::Input(format!(
            "silhouette folder {}: has no .png file",
            dir.display()
        )));
    }
    files.sort();

    let mut out = Silhouettes {
        width: 0,
        height: 0,
        names: Vec::with_capacity(files.len()),
        masks: Vec::new(),
    };
    let mut first: Option<&Path> = None;
    for (name, path) in &files {
        let (width, height, mask) = load_mask(path)?;
        match first {
            None => {
                first = Some(path);
                out.width = width;
                out.height = height;
                out.masks.reserve(files.len() * mask.len());
            }
            Some(first) if (width, height) != (out.width, out.height) => {
                return Err(Error::Input(format!(
                    "silhouette {} is {width}×{height} but {} is {}×{}; all silhouettes must \
                     have one size",
                    path.display(),
                    first.display(),
                    out.width,
                    out.height
                )));
            }
            Some(_) => {}
        }
        out.names.push(name.to_string_lossy().into_owned());
        out.masks.extend(mask);
    }
    Ok(out)
}

/// One silhouette: width, height and its 0/1 mask.
fn load_mask(path: &Path) -> Result<(u32, u32, Vec<f32>)> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let not_png = |e: image::ImageError| {
        Error::Input(format!(
            "silhouette {}: not a readable PNG: {}",
            path.display(),
            one_line(&e.to_string())
        ))
    };
    let format = image::ImageFormat::Png;
    // The header first: a small file can claim a picture too large to hold.
    // Only the header is read here, so the decoder's memory limit (which would refuse with a
    // vaguer message) is lifted; it holds for the decoding below.
    let mut header = image::ImageReader::with_format(std::io::Cursor::new(&bytes), format);
    header.no_limits();
    let (width, height) = header.into_dimensions().map_err(not_png)?;
    if width.max(height) > MAX_IMAGE_SIDE {
        return Err(Error::Input(format!(
            "silhouette {} is {width}×{height}; sides of at most {MAX_IMAGE_SIDE} are supported",
            path.display()
        )));
    }
    let image = image::load_from_memory_with_format(&bytes, format).map_err(not_png)?;
    let has_alpha = image.color().has_alpha();
    // 16 bits hold 8-bit values exactly (v · 257), so one threshold serves both depths:
    // v8 > 127.5 ⇔ v8 · 257 > 32767.5.
    let la = image.to_luma_alpha16();
    let channel = usize::from(has_alpha);
    let mask: Vec<f32> = la
        .pixels()
        .map(|p| if p.0[channel] > 32767 { 1.0 } else { 0.0 })
        .collect();
    if !mask.contains(&1.0) {
        let what = if has_alpha { "alpha" } else { "luminance" };
        return Err(Error::Input(format!(
            "silhouette {} has no pixel inside (none with {what} over 0.5)",
            path.display()
        )));
    }
    Ok((la.width(), la.height(), mask))
}

/// `count` silhouette file names that sort in view order: `view_000.png`, `view_001.png`, …
/// (at least three digits, more when `count` needs them).
pub fn silhouette_names(count: usize) -> Vec<String> {
    let digits = count.saturating_sub(1).to_string().len().max(3);
    (0..count)
        .map(|i| format!("view_{i:0digits$}.png"))
        .collect()
}

/// Writes silhouettes that [`load_silhouettes`] reads back: for each name, an 8-bit RGBA PNG in
/// `dir` (created if missing), white, with the mask as alpha (clamped to [0, 1] and rounded, so
/// soft masks are kept to 8 bits). `masks` is view-major, row-major, `names.len()` views of
/// `width × height`.
///
/// Views load back in file-name order, so names must sort in view order
/// ([`silhouette_names`] makes such names); each must be a plain file name ending in `.png`.
/// Other PNG files already in `dir` would load with them. Each file is written atomically; a
/// failure part-way leaves the files written before it.
pub fn write_silhouettes(
    dir: &Path,
    names: &[impl AsRef<str>],
    width: u32,
    height: u32,
    masks: &[f32],
) -> Result<()> {
    let pixels = width as usize * height as usize;
    if pixels == 0 {
        return Err(Error::Input(format!(
            "silhouettes for {}: {width}×{height} is empty",
            dir.display()
        )));
    }
    if masks.len() != names.len() * pixels {
        return Err(Error::Input(format!(
            "silhouettes for {}: {} mask values for {} views of {width}×{height} (expected {})",
            dir.display(),
            masks.len(),
            names.len(),
            names.len() * pixels
        )));
    }
    for name in names {
        let name = name.as_ref();
        let plain = Path::new(name).file_name() == Some(name.as_ref()) && !name.starts_with('.');
        let png = Path::new(name)
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if !plain || !png {
            return Err(Error::Input(format!(
                "silhouette name `{name}`: must be a file name ending in .png, without folders"
            )));
        }
    }
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    for (name, mask) in names.iter().zip(masks.chunks_exact(pixels)) {
        let rgba: Vec<u8> = mask
            .iter()
            .flat_map(|&a| [255, 255, 255, unit_to_u8(a)])
            .collect();
        let path = dir.join(name.as_ref());
        let png = encode_png(&rgba, width, height, image::ExtendedColorType::Rgba8, &path)?;
        AtomicFile::create(&path)?.commit(&png)?;
    }
    Ok(())
}

/// One view of a fit: where its camera is, as `render`'s `--distance --elevation --azimuth`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRow {
    /// Distance from the origin, > 0.
    pub distance: f64,
    /// Elevation, degrees.
    pub elevation: f64,
    /// Azimuth, degrees.
    pub azimuth: f64,
}

impl CameraRow {
    /// The look-at camera of this view ([`Camera::from_angles`], perspective).
    pub fn camera(&self) -> Camera {
        Camera::from_angles(self.distance, self.elevation, self.azimuth)
    }
}

/// The header line of a cameras file.
pub const CAMERAS_HEADER: &str = "distance,elevation,azimuth";

/// Loads a cameras file (SPEC §6): the header `distance,elevation,azimuth`, then one row of
/// three numbers per view, angles in degrees, in the order of the silhouettes' file names.
///
/// Spaces around fields, blank lines, CRLF line ends and a UTF-8 byte-order mark are accepted.
/// Errors name the file and line: a missing file, another header, a row without exactly three
/// fields, a field that is not a finite number, a distance that is not > 0, and no rows at all.
pub fn load_cameras(path: &Path) -> Result<Vec<CameraRow>> {
    let text = match std::fs::read(path) {
        Ok(bytes) => String::from_utf8(bytes).map_err(|_| {
            Error::Input(format!("cameras file {}: not UTF-8 text", path.display()))
        })?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(Error::Input(format!(
                "cameras file {}: does not exist",
                path.display()
            )));
        }
        Err(source) => {
            return Err(Error::Io {
                path: path.to_path_buf(),
                source,
            });
        }
    };
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let bad = |line: usize, message: String| Error::Parse {
        what: "cameras file",
        path: path.to_path_buf(),
        line,
        message,
    };

    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((n, header)) = lines.next() else {
        return Err(Error::Input(format!(
            "cameras file {}: is empty; it needs the header `{CAMERAS_HEADER}` and one row per view",
            path.display()
        )));
    };
    let fields: Vec<&str> = header.split(',').map(str::trim).collect();
    if fields != ["distance", "elevation", "azimuth"] {
        return Err(bad(
            n,
            format!(
                "the header is `{}`, not `{CAMERAS_HEADER}`",
                one_line(header.trim())
            ),
        ));
    }

    let mut rows = Vec::new();
    for (n, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 3 {
            return Err(bad(
                n,
                format!("{} field(s), expected 3 ({CAMERAS_HEADER})", fields.len()),
            ));
        }
        let mut values = [0.0f64; 3];
        for ((value, field), name) in
            values
                .iter_mut()
                .zip(&fields)
                .zip(["distance", "elevation", "azimuth"])
        {
            *value = match field.parse::<f64>() {
                Ok(v) if v.is_finite() => v,
                Ok(_) => {
                    return Err(bad(
                        n,
                        format!("{name} `{}` is not a finite number", one_line(field)),
                    ));
                }
                Err(_) => {
                    return Err(bad(
                        n,
                        format!("{name} `{}` is not a number", one_line(field)),
                    ));
                }
            };
        }
        let [distance, elevation, azimuth] = values;
        if distance <= 0.0 {
            return Err(bad(n, format!("distance {distance} must be > 0")));
        }
        rows.push(CameraRow {
            distance,
            elevation,
            azimuth,
        });
    }
    if rows.is_empty() {
        return Err(Error::Input(format!(
            "cameras file {}: has a header but no camera row",
            path.display()
        )));
    }
    Ok(rows)
}

/// Fails with [`Error::Input`] unless there is one camera row per silhouette.
pub fn check_counts(cameras: &[CameraRow], silhouettes: &Silhouettes) -> Result<()> {
    let (c, s) = (cameras.len(), silhouettes.views());
    if c == s {
        return Ok(());
    }
    let plural = |n: usize| if n == 1 { "" } else { "s" };
    Err(Error::Input(format!(
        "{c} camera row{} but {s} silhouette{}: the cameras file needs one row per silhouette, \
         in the order of their file names",
        plural(c),
        plural(s)
    )))
}

/// Writes a cameras file that [`load_cameras`] reads back exactly (shortest round-trip decimals).
/// Every value must be finite and every distance > 0, as the loader requires.
pub fn write_cameras(path: &Path, rows: &[CameraRow]) -> Result<()> {
    let mut text = String::with_capacity(32 * (rows.len() + 1));
    text.push_str(CAMERAS_HEADER);
    text.push('\n');
    for (i, r) in rows.iter().enumerate() {
        let finite = [r.distance, r.elevation, r.azimuth]
            .iter()
            .all(|v| v.is_finite());
        if !finite || r.distance <= 0.0 {
            return Err(Error::Input(format!(
                "cameras for {}: row {i} ({}, {}, {}) needs finite values and a distance > 0",
                path.display(),
                r.distance,
                r.elevation,
                r.azimuth
            )));
        }
        // `{:?}` of an f64 is its shortest round-trip form, and parses back bit for bit.
        let _ = writeln!(text, "{:?},{:?},{:?}", r.distance, r.elevation, r.azimuth);
    }
    AtomicFile::create(path)?.commit(text.as_bytes())
}

/// Writes a triangle mesh as OBJ: `v x y z` lines with the shortest decimals that parse back to
/// the same `f32`s, then `f a b c` lines with 1-based indices. [`Mesh::load_obj`] gives back the
/// same positions, bit for bit, and faces.
///
/// Non-finite positions and face indices out of range are [`Error::Input`].
///
/// [`Mesh::load_obj`]: crate::mesh::Mesh::load_obj
pub fn write_obj(path: &Path, positions: &[[f32; 3]], faces: &[[u32; 3]]) -> Result<()> {
    write_obj_colored(path, positions, None, faces)
}

/// [`write_obj`] with a colour per vertex, as the common `v x y z r g b` extension (read by
/// MeshLab, Blender and tobj); `colors` must hold one per vertex, else [`Error::Input`].
pub fn write_obj_colored(
    path: &Path,
    positions: &[[f32; 3]],
    colors: Option<&[[f32; 3]]>,
    faces: &[[u32; 3]],
) -> Result<()> {
    if let Some(c) = colors
        && c.len() != positions.len()
    {
        return Err(Error::Input(format!(
            "mesh for {}: {} colours for {} vertices",
            path.display(),
            c.len(),
            positions.len()
        )));
    }
    if let Some(v) = positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(Error::Input(format!(
            "mesh for {}: vertex {v} is {:?}, not finite",
            path.display(),
            positions[v]
        )));
    }
    if let Some(f) = faces
        .iter()
        .position(|f| f.iter().any(|&i| i as usize >= positions.len()))
    {
        return Err(Error::Input(format!(
            "mesh for {}: face {f} {:?} indexes past its {} vertices",
            path.display(),
            faces[f],
            positions.len()
        )));
    }
    let mut text = String::with_capacity(40 * positions.len() + 24 * faces.len() + 64);
    let _ = writeln!(
        text,
        "# softvk: {} vertices, {} faces",
        positions.len(),
        faces.len()
    );
    for (i, p) in positions.iter().enumerate() {
        text.push('v');
        for &c in p.iter().chain(colors.map_or(&[][..], |c| &c[i][..])) {
            text.push(' ');
            push_f32(&mut text, c);
        }
        text.push('\n');
    }
    for [a, b, c] in faces {
        let _ = writeln!(text, "f {} {} {}", a + 1, b + 1, c + 1);
    }
    AtomicFile::create(path)?.commit(text.as_bytes())
}

/// The shortest decimal that parses back to `v` (Rust's float formatting guarantees the round
/// trip), positional for ordinary magnitudes and with an exponent for the rest, which would
/// otherwise print dozens of zeros.
fn push_f32(text: &mut String, v: f32) {
    let a = v.abs();
    let _ = if a == 0.0 || (1e-4..1e7).contains(&a) {
        write!(text, "{v}")
    } else {
        write!(text, "{v:e}")
    };
}

/// One float to one 8-bit channel: clamp to [0, 1], scale by 255, round (NaN gives 0).
pub(crate) fn unit_to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// PNG bytes of `pixels` (8-bit, `color`'s layout); the error names `path`.
pub(crate) fn encode_png(
    pixels: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
    path: &Path,
) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(pixels, width, height, color)
        .map_err(|e| Error::Input(format!("cannot encode PNG {}: {e}", path.display())))?;
    Ok(out)
}

/// Test helpers shared with `report`'s tests.
#[cfg(test)]
pub(crate) mod test_support {
    use std::path::{Path, PathBuf};

    /// A fresh folder under the system's temporary directory, removed when dropped.
    pub struct TempDir(pub PathBuf);

    impl TempDir {
        /// `tag` must be unique among the tests (they run in parallel).
        pub fn new(tag: &str) -> TempDir {
            let dir = std::env::temp_dir().join(format!("softvk-fit-{tag}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }

        /// `name` inside the folder.
        pub fn path(&self, name: &str) -> PathBuf {
            self.0.join(name)
        }

        /// The folder's entries, sorted (hidden temporary files included).
        pub fn entries(&self) -> Vec<String> {
            entries(&self.0)
        }
    }

    /// The entries of `dir`, sorted.
    pub fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

#[cfg(test)]
mod tests {
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
            input_error(check_counts(&[row; 2], &one))
                .starts_with("2 camera rows but 1 silhouette:")
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
        let bits =
            |p: &[[f32; 3]]| -> Vec<u32> { p.iter().flatten().map(|c| c.to_bits()).collect() };
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
}
