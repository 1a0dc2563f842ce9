//! Writing rendered images (SPEC §6): RGBA as 8-bit PNG or float32 EXR, chosen by the file
//! extension, and written atomically so that a failed run leaves nothing behind.
//!
//! Values are written as the renderer produced them: colour and alpha straight (not
//! premultiplied; SoftRas's colour already blends the background in, its alpha is coverage), row
//! 0 at the top. OpenEXR tools assume premultiplied colour; softvk's EXR is data, not a plate to
//! composite.

use std::path::{Path, PathBuf};

use softvk::{Error, Result};

/// An output image format, from the extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8-bit RGBA PNG: values clamped to [0, 1] and rounded.
    Png,
    /// OpenEXR, float32 channels R, G, B, A, lossless (ZIP).
    Exr,
}

impl ImageFormat {
    /// `.png` or `.exr` (any case); anything else is an error naming the file.
    pub fn from_path(path: &Path) -> Result<ImageFormat> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(ImageFormat::Png),
            Some("exr") => Ok(ImageFormat::Exr),
            _ => Err(Error::Input(format!(
                "{}: unknown image format (the extension must be .png or .exr)",
                path.display()
            ))),
        }
    }

    /// Encodes `width` × `height` RGBA pixels (row-major, row 0 at the top). The error is the
    /// encoder's message; the caller names the file.
    pub fn encode(
        self,
        pixels: &[[f32; 4]],
        width: u32,
        height: u32,
    ) -> std::result::Result<Vec<u8>, String> {
        assert_eq!(pixels.len(), width as usize * height as usize);
        match self {
            ImageFormat::Png => png_bytes(pixels, width, height),
            ImageFormat::Exr => softvk::exr_io::encode_rgba(pixels, width, height),
        }
    }
}

/// One float to one PNG byte: clamp to [0, 1], scale by 255, round half away from zero.
pub fn to_u8(v: f32) -> u8 {
    // NaN clamps to NaN and `as` maps it to 0; the renderer never produces one.
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The PNG bytes of an 8-bit RGBA picture (a labelled sheet of `report`), the error naming
/// `path`, where they will go.
pub fn encode_sheet_png(sheet: &image::RgbaImage, path: &Path) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            sheet.as_raw(),
            sheet.width(),
            sheet.height(),
            image::ExtendedColorType::Rgba8,
        )
        .map_err(|e| Error::Input(format!("{}: cannot encode PNG: {e}", path.display())))?;
    Ok(out)
}

/// The 8-bit PNG of `pixels` at `size`, the error naming `path`, where it will go.
pub fn encode_png(pixels: &[[f32; 4]], (w, h): (u32, u32), path: &Path) -> Result<Vec<u8>> {
    ImageFormat::Png
        .encode(pixels, w, h)
        .map_err(|e| Error::Input(format!("{}: {e}", path.display())))
}

/// The PNG of labelled `images` at `size` side by side (a fit's target, start and result), the
/// error naming `path`.
pub fn encode_compare(
    images: &[(&str, &Vec<[f32; 4]>)],
    (w, h): (u32, u32),
    path: &Path,
) -> Result<Vec<u8>> {
    let images: Vec<(&str, &[[f32; 4]])> = images.iter().map(|(n, i)| (*n, i.as_slice())).collect();
    encode_sheet_png(&softvk::fit::report::side_by_side(&images, w, h), path)
}

fn png_bytes(pixels: &[[f32; 4]], width: u32, height: u32) -> std::result::Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let bytes: Vec<u8> = pixels.iter().flatten().map(|&v| to_u8(v)).collect();
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&bytes, width, height, image::ExtendedColorType::Rgba8)
        .map_err(|e| format!("cannot encode PNG: {e}"))?;
    Ok(out)
}

pub use softvk::atomic_file::AtomicFile;

/// A fit's target image (`fit-pose`, `fit-articulated`): RGBA floats in [0, 1], row 0 at the
/// top, and its size. It must have an alpha
/// channel: the loss compares coverage too.
pub fn load_target(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    let bytes = std::fs::read(path)
        .map_err(|e| Error::Input(format!("cannot read target {}: {e}", path.display())))?;
    let img =
        image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).map_err(|e| {
            Error::Input(format!(
                "target {}: not a readable PNG: {e}",
                path.display()
            ))
        })?;
    if !img.color().has_alpha() {
        return Err(Error::Input(format!(
            "target {} has no alpha channel; fit-pose compares RGBA (coverage in alpha), as \
             `softvk render` writes it",
            path.display()
        )));
    }
    let rgba = img.to_rgba32f();
    let (w, h) = rgba.dimensions();
    let pixels = rgba.pixels().map(|p| p.0).collect();
    Ok((w, h, pixels))
}

/// A file a command writes beside its main output: `--flag PATH`, or `<out stem><suffix>` beside
/// `--out` when the flag is not given.
pub struct SideFile<'a> {
    /// The flag that names it (for errors).
    pub flag: &'a str,
    /// The path the flag gave.
    pub path: Option<&'a Path>,
    /// What the default's name ends with (`-render.png`); a `.png` one must be a PNG.
    pub suffix: &'a str,
}

/// The side files of `out` (`default_stem` names them when `out` has no stem), in order: each a
/// PNG where its suffix is, and all of them and `out` different files. What `fit-pose` and
/// `fit-articulated` write beside their angles.
pub fn side_files(out: &Path, default_stem: &str, files: &[SideFile<'_>]) -> Result<Vec<PathBuf>> {
    let stem = out
        .file_stem()
        .map_or(default_stem.into(), |s| s.to_string_lossy().into_owned());
    let paths: Vec<PathBuf> = files
        .iter()
        .map(|f| {
            f.path.map_or_else(
                || out.with_file_name(format!("{stem}{}", f.suffix)),
                Path::to_path_buf,
            )
        })
        .collect();
    for (f, p) in files.iter().zip(&paths) {
        if f.suffix.ends_with(".png") && ImageFormat::from_path(p)? != ImageFormat::Png {
            return Err(Error::Input(format!("{}: must be a .png", p.display())));
        }
    }
    let all: Vec<&Path> = std::iter::once(out)
        .chain(paths.iter().map(PathBuf::as_path))
        .collect();
    if (1..all.len()).any(|i| all[..i].contains(&all[i])) {
        let flags: Vec<&str> = files.iter().map(|f| f.flag).collect();
        let (last, rest) = flags.split_last().expect("at least one side file");
        let count = ["two", "three", "four", "five", "six"]
            .get(flags.len() - 1)
            .map_or_else(|| (flags.len() + 1).to_string(), |w| (*w).to_string());
        return Err(Error::Input(format!(
            "--out, {} and {last} must be {count} different files",
            rest.join(", ")
        )));
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;
    use std::path::PathBuf;

    /// A fresh folder under the system's temporary directory, removed when dropped.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> TempDir {
            let dir =
                std::env::temp_dir().join(format!("softvk-output-{tag}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }

        fn entries(&self) -> Vec<String> {
            let mut v: Vec<String> = std::fs::read_dir(&self.0)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// Awkward floats: subnormals, negatives, > 1, values f16 or 8 bits would round.
    fn awkward(width: u32, height: u32) -> Vec<[f32; 4]> {
        let specials = [
            0.0,
            -0.0,
            1.0 / 3.0,
            f32::MIN_POSITIVE / 8.0,
            -2.5e-7,
            1.000_000_1,
            65504.0 * 4.0,
            0.123_456_79,
        ];
        (0..width * height)
            .map(|i| std::array::from_fn(|k| specials[(i as usize * 4 + k) % 8] + i as f32 * 1e-3))
            .collect()
    }

    #[test]
    fn extension_decides_the_format() {
        assert_eq!(
            ImageFormat::from_path(Path::new("a/b.png")).unwrap(),
            ImageFormat::Png
        );
        assert_eq!(
            ImageFormat::from_path(Path::new("B.EXR")).unwrap(),
            ImageFormat::Exr
        );
        for bad in ["a.jpg", "a", "a.png.tmp", ".png", "dir/"] {
            assert!(ImageFormat::from_path(Path::new(bad)).is_err(), "{bad}");
        }
    }

    #[test]
    fn exr_reads_back_the_exact_f32s_as_r_g_b_a() {
        use exr::prelude::*;
        let (w, h) = (7u32, 5u32);
        let pixels = awkward(w, h);
        let bytes = ImageFormat::Exr.encode(&pixels, w, h).unwrap();
        let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(&bytes), false).unwrap();
        let header = &meta.headers[0];
        let mut names: Vec<String> = header
            .channels
            .list
            .iter()
            .map(|c| {
                assert_eq!(c.sample_type, SampleType::F32);
                c.name.to_string()
            })
            .collect();
        names.sort();
        assert_eq!(names, ["A", "B", "G", "R"]);
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |size, _| (size.width(), vec![[0f32; 4]; size.area()]),
                |(width, v), p, (r, g, b, a): (f32, f32, f32, f32)| {
                    v[p.y() * *width + p.x()] = [r, g, b, a];
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(&bytes))
            .unwrap();
        let layer = &image.layer_data;
        assert_eq!((layer.size.width(), layer.size.height()), (7, 5));
        let back = &layer.channel_data.pixels.1;
        for (a, b) in pixels.iter().zip(back) {
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits));
        }
    }

    #[test]
    fn png_is_rgba8_clamped_and_rounded_with_row_0_at_the_top() {
        assert_eq!(
            [-1.0, 0.0, 0.5 / 255.0, 0.499 / 255.0, 0.5, 1.0, 7.0].map(to_u8),
            [0, 0, 1, 0, 128, 255, 255]
        );
        let (w, h) = (3u32, 2u32);
        let mut pixels = vec![[0.0f32; 4]; 6];
        pixels[0] = [1.0, 0.0, 0.0, 1.0]; // top left
        pixels[5] = [0.0, 0.0, 1.0, 0.25]; // bottom right
        let bytes = ImageFormat::Png.encode(&pixels, w, h).unwrap();
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgba8);
        let img = img.to_rgba8();
        assert_eq!(img.dimensions(), (3, 2));
        assert_eq!(img.get_pixel(0, 0).0, [255, 0, 0, 255]);
        assert_eq!(img.get_pixel(2, 1).0, [0, 0, 255, 64]);
        assert_eq!(img.get_pixel(1, 0).0, [0, 0, 0, 0]);
    }

    #[test]
    fn atomic_file_appears_only_on_commit() {
        let dir = TempDir::new("atomic");
        let target = dir.0.join("out.png");
        std::fs::write(&target, b"old").unwrap();

        let f = AtomicFile::create(&target).unwrap();
        assert_eq!(
            dir.entries().len(),
            2,
            "the temporary file exists beside the target"
        );
        drop(f);
        assert_eq!(dir.entries(), ["out.png"]);
        assert_eq!(
            std::fs::read(&target).unwrap(),
            b"old",
            "untouched without a commit"
        );

        AtomicFile::create(&target).unwrap().commit(b"new").unwrap();
        assert_eq!(dir.entries(), ["out.png"]);
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }

    #[test]
    fn unwritable_destinations_fail_at_create() {
        let dir = TempDir::new("unwritable");
        std::fs::write(dir.0.join("file"), b"").unwrap();
        std::fs::create_dir(dir.0.join("sub.png")).unwrap();
        for bad in ["missing/out.png", "file/out.png", "sub.png"] {
            let err = AtomicFile::create(&dir.0.join(bad)).unwrap_err();
            assert!(err.to_string().contains(bad), "{err}");
        }
        assert_eq!(dir.entries(), ["file", "sub.png"]);
    }

    fn side<'a>(flag: &'a str, path: Option<&'a Path>, suffix: &'a str) -> SideFile<'a> {
        SideFile { flag, path, suffix }
    }

    #[test]
    fn side_files_default_beside_the_output_and_must_differ() {
        let out = Path::new("a/b/pose.json");
        let given = Path::new("c/mine.png");
        let files = [
            side("--render", None, "-render.png"),
            side("--compare", Some(given), "-compare.png"),
            side("--mesh-out", None, "-posed.obj"),
        ];
        assert_eq!(
            side_files(out, "pose", &files).unwrap(),
            [
                PathBuf::from("a/b/pose-render.png"),
                PathBuf::from("c/mine.png"),
                PathBuf::from("a/b/pose-posed.obj"),
            ]
        );
        // A PNG side file named otherwise, or two files the same.
        let exr = Path::new("c/mine.exr");
        let err = side_files(out, "pose", &[side("--render", Some(exr), "-render.png")]);
        assert!(err.unwrap_err().to_string().contains("must be a .png"));
        let clash = [
            side("--render", Some(given), "-render.png"),
            side("--compare", Some(given), "-compare.png"),
        ];
        let err = side_files(out, "pose", &clash).unwrap_err().to_string();
        assert!(
            err.contains("--out, --render and --compare must be three different files"),
            "{err}"
        );
    }
}
