//! Target silhouettes (`--silhouettes DIR`): one PNG mask per view, loaded in name order and
//! written back as 8-bit alpha.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::{encode_png, unit_to_u8};
use crate::atomic_file::AtomicFile;
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
