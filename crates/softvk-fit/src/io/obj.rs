//! The fitted mesh (`--out M.obj`): OBJ with the shortest decimals that parse back to the
//! same `f32`s, optionally with per-vertex colours.

use std::fmt::Write as _;
use std::path::Path;

use crate::atomic_file::AtomicFile;
use crate::error::{Error, Result};

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
