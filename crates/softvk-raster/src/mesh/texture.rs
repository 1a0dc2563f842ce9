//! Texture images as SoftRas uses them: the file a `map_Kd` names, decoded and flipped as SoftRas
//! holds it, and sampled bilinearly into each face's R×R texels at the texel centres.

use std::path::{Path, PathBuf};

use super::{MAX_TEXTURE_PIXELS, MeshError};
use crate::error::one_line;

/// Barycentric coordinates (w0, w1, w2) of the centre of texel `(w_x, w_y)` of an R×R face
/// texture, as SoftRas's `load_textures` kernel places them.
///
/// The R×R grid over (w0, w1) is cut along its anti-diagonals: texel `(w_x, w_y)` with
/// `w_x + w_y < R` is the lower triangle of cell (w_x, w_y), centred at `((w_x + 1/3)/R,
/// (w_y + 1/3)/R)`; the others are the upper triangle of cell `(R-1-w_x, R-1-w_y)`, centred at
/// `((R-1-w_x + 2/3)/R, (R-1-w_y + 2/3)/R)`. This is exactly the inverse of the SPEC §2
/// sampling rule (`reference::surface_texel_index`), which a test checks.
pub fn texel_center_barycentric(res: u32, w_x: u32, w_y: u32) -> [f64; 3] {
    let r = f64::from(res);
    let (w0, w1) = if w_x + w_y < res {
        (
            (f64::from(w_x) + 1.0 / 3.0) / r,
            (f64::from(w_y) + 1.0 / 3.0) / r,
        )
    } else {
        (
            (r - 1.0 - f64::from(w_x) + 2.0 / 3.0) / r,
            (r - 1.0 - f64::from(w_y) + 2.0 / 3.0) / r,
        )
    };
    [w0, w1, 1.0 - w0 - w1]
}

/// A decoded texture as SoftRas holds it: RGB in [0, 1], rows flipped so row 0 is the bottom
/// of the picture (SoftRas does `image[::-1]`), so `v = 0` is the bottom as OBJ intends.
pub(super) struct TextureImage {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

impl TextureImage {
    pub(super) fn load(path: &Path) -> Result<TextureImage, MeshError> {
        let decode_err = |message: String| MeshError::TextureDecode {
            path: path.to_path_buf(),
            message,
        };
        let open = || {
            image::ImageReader::open(path)
                .map_err(|source| MeshError::Read {
                    path: path.to_path_buf(),
                    source,
                })?
                .with_guessed_format()
                .map_err(|e| decode_err(one_line(&e.to_string())))
        };
        // The header first: a small file can claim a picture too large to hold.
        // Only the header is read here, so the decoder's memory limit (which would refuse with
        // a vaguer message) is lifted; it holds for the decoding below.
        let mut header = open()?;
        header.no_limits();
        let (width, height) = header
            .into_dimensions()
            .map_err(|e| decode_err(one_line(&e.to_string())))?;
        if u64::from(width) * u64::from(height) > MAX_TEXTURE_PIXELS {
            return Err(decode_err(format!(
                "the image is {width}×{height}; textures of at most {MAX_TEXTURE_PIXELS} pixels \
                 (8192×8192) are supported"
            )));
        }
        let image = open()?
            .decode()
            .map_err(|e| decode_err(one_line(&e.to_string())))?;
        // Grey is replicated to RGB and alpha dropped, as SoftRas does.
        let rgb = image.to_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        if width == 0 || height == 0 {
            return Err(decode_err("the image is empty".into()));
        }
        let mut flipped = Vec::with_capacity(width * height);
        for row in (0..height).rev() {
            for col in 0..width {
                flipped.push(rgb.get_pixel(col as u32, row as u32).0);
            }
        }
        Ok(TextureImage {
            width,
            height,
            rgb: flipped,
        })
    }

    fn texel(&self, x: usize, y: usize) -> [f64; 3] {
        let p = self.rgb[y.min(self.height - 1) * self.width + x.min(self.width - 1)];
        [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
    }

    /// SoftRas's bilinear lookup at `pos = uv * (size - 1)`, truncating to the lower texel.
    /// SoftRas reads one past the last row/column (with weight 0) at uv = 1; clamping the index
    /// gives the same value without the out-of-bounds read.
    fn bilinear(&self, u: f64, v: f64) -> [f64; 3] {
        let pos_x = u * (self.width - 1) as f64;
        let pos_y = v * (self.height - 1) as f64;
        let (x0, y0) = (pos_x as usize, pos_y as usize);
        let (wx1, wy1) = (pos_x - x0 as f64, pos_y - y0 as f64);
        let (wx0, wy0) = (1.0 - wx1, 1.0 - wy1);
        let c00 = self.texel(x0, y0);
        let c01 = self.texel(x0, y0 + 1);
        let c10 = self.texel(x0 + 1, y0);
        let c11 = self.texel(x0 + 1, y0 + 1);
        std::array::from_fn(|k| {
            c00[k] * wx0 * wy0 + c01[k] * wx0 * wy1 + c10[k] * wx1 * wy0 + c11[k] * wx1 * wy1
        })
    }

    /// Fills one face's R×R texels: each texel centre's barycentrics interpolate the corner
    /// UVs, which are then sampled bilinearly (SoftRas `load_textures`).
    pub(super) fn sample_face(&self, uv: [[f64; 2]; 3], res: u32, texels: &mut [[f32; 3]]) {
        for (i, texel) in texels.iter_mut().enumerate() {
            let (w_x, w_y) = (i as u32 % res, i as u32 / res);
            let w = texel_center_barycentric(res, w_x, w_y);
            let u = w[0] * uv[0][0] + w[1] * uv[1][0] + w[2] * uv[2][0];
            let v = w[0] * uv[0][1] + w[1] * uv[1][1] + w[2] * uv[2][1];
            let c = self.bilinear(u, v);
            *texel = [c[0] as f32, c[1] as f32, c[2] as f32];
        }
    }
}

/// Wraps a texture coordinate into [0, 1]. SoftRas does `uv % 1` for uv > 1 (keeping 1.0);
/// negative uv read out of bounds there, so they repeat here.
pub(super) fn wrap_uv(x: f64) -> f64 {
    if (0.0..=1.0).contains(&x) {
        x
    } else {
        x - x.floor()
    }
}

/// The image file a `map_Kd` value names. Options (`-s 1 1 1 file.png`) come first, the file
/// last; without options the whole value is the name, so names with spaces work.
pub(super) fn texture_file_name(map_kd: &str) -> &str {
    let map_kd = map_kd.trim();
    if map_kd.starts_with('-') {
        map_kd.split_whitespace().last().unwrap_or(map_kd)
    } else {
        map_kd
    }
}

/// Texture paths are relative to the MTL's folder (the usual convention), falling back to the
/// OBJ's folder (SoftRas's choice); they are the same folder in nearly every model. `None` when
/// neither holds the file.
pub(super) fn resolve_texture(mtl_dir: &Path, obj_dir: &Path, map_kd: &str) -> Option<PathBuf> {
    let name = texture_file_name(map_kd);
    [mtl_dir.join(name), obj_dir.join(name)]
        .into_iter()
        .find(|p| p.is_file())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_centres_cover_the_triangle_once_each() {
        for res in 1..=6 {
            let mut sum = [0.0; 3];
            for i in 0..res * res {
                let w = texel_center_barycentric(res, i % res, i / res);
                assert!(w.iter().all(|&x| x > 0.0 && x < 1.0), "{w:?}");
                (0..3).for_each(|k| sum[k] += w[k]);
            }
            // Centres of a uniform subdivision average to the centroid.
            let n = f64::from(res * res);
            assert!(sum.iter().all(|s| (s / n - 1.0 / 3.0).abs() < 1e-12));
        }
    }

    #[test]
    fn map_kd_options_are_skipped() {
        assert_eq!(texture_file_name(" tex.png "), "tex.png");
        assert_eq!(texture_file_name("-s 1 1 1 tex.png"), "tex.png");
        assert_eq!(texture_file_name("my tex.png"), "my tex.png");
        assert_eq!(wrap_uv(1.0), 1.0);
        assert!((wrap_uv(1.25) - 0.25).abs() < 1e-12);
        assert!((wrap_uv(-0.25) - 0.75).abs() < 1e-12);
    }
}
