//! The OBJ loader behind [`Mesh::load_obj`]. It follows SoftRas's `load_obj.py` /
//! `load_textures_cuda_kernel.cu` so that a SoftRas user gets the same mesh and the same texels:
//! - vertex order is the order of the `v` lines (unreferenced vertices are kept), so per-vertex
//!   outputs (gradients) line up with the file;
//! - polygons are fan-triangulated `(v0, vi, vi+1)`, all objects and groups merged in file order;
//! - an MTL `map_Kd` image is sampled once, at load time, into per-face R×R texels at texel-centre
//!   barycentrics, with SoftRas's bilinear filter and vertical flip; a material without a texture
//!   gives its `Kd`; no material gives white.
//!   A missing MTL or texture file is a warning on stderr, not an error (see [`Mesh::load_obj`]).
//!
//! tobj does the parsing and the MTL reading. tobj re-indexes positions per object in order of
//! first use, which loses the file order that SPEC §6 requires, so a light second pass over the
//! `v`/`vt`/`f` lines recovers the global indices, and every corner is checked to agree with tobj.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::mtl::MtlLog;
use super::texture::{TextureImage, resolve_texture, texture_file_name, wrap_uv};
use super::{Location, Mesh, MeshError, check_finite, check_texture_res, shown};
use crate::error::one_line;

/// [`Mesh::load_obj`], with each warning (a missing MTL or texture file) given to `warn` as one
/// line instead of printed.
pub(super) fn load_obj_warning(
    path: &Path,
    texture_res: u32,
    warn: &mut dyn FnMut(String),
) -> Result<Mesh, MeshError> {
    check_texture_res(texture_res)?;
    let text = std::fs::read_to_string(path).map_err(|source| MeshError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let obj_dir = path.parent().unwrap_or(Path::new("")).to_path_buf();

    let mtl_log = RefCell::new(MtlLog::default());
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        // SoftRas makes no triangle from a point or a line; tobj would make degenerate ones.
        ignore_points: true,
        ignore_lines: true,
    };
    let loaded = tobj::load_obj_buf(&mut text.as_bytes(), &options, |mtl_path| {
        mtl_log.borrow_mut().load(&obj_dir.join(mtl_path))
    });
    let scan = scan_obj(&text);

    let (models, materials) = match loaded {
        Ok(ok) => ok,
        Err(e) => return Err(explain_tobj_error(path, e, scan)),
    };
    let mtl_log = mtl_log.into_inner();
    if let Some(err) = mtl_log.error {
        return Err(err);
    }
    // Materials from the MTL files that did load; a missing one was logged and is skipped.
    let materials = materials.unwrap_or_default();
    let scan = scan.map_err(|e| e.into_mesh_error(path))?;

    check_finite(&scan.positions, |v| {
        Location::line(path, scan.position_lines[v])
    })?;
    if scan.triangles.is_empty() {
        return Err(MeshError::NoFaces {
            at: Location::file(path),
        });
    }
    let vertex_count = scan.positions.len();
    let mut faces = Vec::with_capacity(scan.triangles.len());
    for (face, tri) in scan.triangles.iter().enumerate() {
        let mut f = [0u32; 3];
        for ((slot, &v), &raw) in f.iter_mut().zip(&tri.v).zip(&tri.raw) {
            if v < 0 || v as usize >= vertex_count {
                return Err(MeshError::FaceIndexOutOfRange {
                    face,
                    index: raw,
                    vertex_count,
                    at: Location::line(path, tri.line),
                });
            }
            *slot = v as u32;
        }
        faces.push(f);
    }

    let face_materials = match_tobj_models(path, &models, &scan)?;

    // Said only once the mesh has loaded: a failed load is one error line, nothing more.
    let mut warnings: Vec<String> = mtl_log
        .missing
        .iter()
        .map(|mtl| {
            format!(
                "{}: material file {} not found; its faces are white",
                shown(path),
                shown(mtl)
            )
        })
        .collect();
    let r2 = (texture_res * texture_res) as usize;
    let mut textures = vec![[1.0f32; 3]; faces.len() * r2];
    let mut images: HashMap<PathBuf, TextureImage> = HashMap::new();
    let mut missing_textures: Vec<&str> = Vec::new();
    for (face, material) in face_materials.iter().enumerate() {
        let Some(material) = material.and_then(|id| materials.get(id)) else {
            continue;
        };
        let texels = &mut textures[face * r2..(face + 1) * r2];
        let mtl_file = mtl_log.files.get(&material.name);
        if let Some(kd) = material.diffuse
            && kd.iter().any(|c| !c.is_finite())
        {
            return Err(MeshError::MtlParse {
                path: mtl_file.cloned().unwrap_or_default(),
                message: format!(
                    "material '{}' has a NaN or infinite Kd",
                    one_line(&material.name)
                ),
            });
        }
        let mtl_dir = mtl_file
            .and_then(|f| f.parent())
            .unwrap_or(obj_dir.as_path());
        let image_path = material
            .diffuse_texture
            .as_ref()
            .map(|map| (map, resolve_texture(mtl_dir, &obj_dir, map)));
        if let Some((_, Some(image_path))) = image_path {
            if !images.contains_key(&image_path) {
                let image = TextureImage::load(&image_path)?;
                images.insert(image_path.clone(), image);
            }
            let uv = scan.face_uv(face);
            images[&image_path].sample_face(uv, texture_res, texels);
            continue;
        }
        if let Some((map, None)) = image_path
            && !missing_textures.contains(&material.name.as_str())
        {
            missing_textures.push(&material.name);
            warnings.push(format!(
                "{}: texture {} of material '{}' not found; its faces are {}",
                shown(path),
                shown(&mtl_dir.join(texture_file_name(map))),
                one_line(&material.name),
                if material.diffuse.is_some() {
                    "its Kd colour"
                } else {
                    "white"
                }
            ));
        }
        if let Some(kd) = material.diffuse {
            texels.fill(kd);
        }
    }

    let mesh = Mesh {
        positions: scan.positions,
        faces,
        texture_res,
        textures,
        vertex_colors: scan.colors,
    };
    mesh.validate()?;
    for warning in warnings {
        warn(warning);
    }
    Ok(mesh)
}

/// Result of the light pass over the OBJ text: what tobj does not keep in file order.
#[derive(Debug)]
struct ObjScan {
    positions: Vec<[f32; 3]>,
    /// 1-based line of each `v`.
    position_lines: Vec<usize>,
    /// `Some` when every `v` line has an RGB colour.
    colors: Option<Vec<[f32; 3]>>,
    texcoords: Vec<[f64; 2]>,
    triangles: Vec<ScanTriangle>,
}

#[derive(Debug)]
struct ScanTriangle {
    /// 0-based position indices, not yet range-checked (negative or too large is an error).
    v: [i64; 3],
    /// The indices as written, for error messages.
    raw: [i64; 3],
    /// 0-based texcoord indices, where given.
    vt: [Option<i64>; 3],
    line: usize,
}

impl ObjScan {
    /// Corner UVs of a face, wrapped into [0, 1]. A corner without a `vt` takes the file's last
    /// `vt` (SoftRas turns the missing index 0 into index -1), or (0, 0) when there is none.
    fn face_uv(&self, face: usize) -> [[f64; 2]; 3] {
        let tri = &self.triangles[face];
        std::array::from_fn(|c| {
            let uv = tri.vt[c]
                .and_then(|i| usize::try_from(i).ok())
                .and_then(|i| self.texcoords.get(i))
                .or(self.texcoords.last())
                .copied()
                .unwrap_or([0.0, 0.0]);
            [wrap_uv(uv[0]), wrap_uv(uv[1])]
        })
    }
}

#[derive(Debug)]
struct ScanError {
    line: usize,
    text: String,
    message: String,
}

impl ScanError {
    fn into_mesh_error(self, path: &Path) -> MeshError {
        MeshError::ObjParse {
            path: path.to_path_buf(),
            message: format!("{} at line {}: `{}`", self.message, self.line, self.text),
        }
    }
}

/// Reads `v`, `vt` and `f` lines in file order with the same rules as tobj: `v x y z [w]` is
/// divided by w, `v x y z r g b` carries a colour, negative indices count back from the
/// elements defined so far, faces with fewer than 3 corners are skipped, polygons are fanned.
fn scan_obj(text: &str) -> Result<ObjScan, ScanError> {
    let mut positions = Vec::new();
    let mut position_lines = Vec::new();
    let mut colors = Vec::new();
    let mut texcoords = Vec::new();
    let mut triangles = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let fail = |message: &str| ScanError {
            line: line_no,
            text: one_line(line.trim()),
            message: message.to_owned(),
        };
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let values: Vec<f32> = words
                    .map(str::parse::<f32>)
                    .collect::<Result<_, _>>()
                    .map_err(|_| fail("vertex coordinate is not a number"))?;
                let p = match values.len() {
                    3 | 6 => [values[0], values[1], values[2]],
                    4 if values[3] != 0.0 => [
                        values[0] / values[3],
                        values[1] / values[3],
                        values[2] / values[3],
                    ],
                    _ => return Err(fail("a vertex needs x y z, x y z w or x y z r g b")),
                };
                if values.len() == 6 {
                    if !values[3..].iter().all(|c| c.is_finite()) {
                        return Err(fail("vertex colour is not a finite number"));
                    }
                    colors.push([values[3], values[4], values[5]]);
                }
                positions.push(p);
                position_lines.push(line_no);
            }
            Some("vt") => {
                let uv: Vec<f64> = words
                    .take(2)
                    .map(str::parse::<f64>)
                    .collect::<Result<_, _>>()
                    .map_err(|_| fail("texture coordinate is not a number"))?;
                if uv.len() < 2 {
                    return Err(fail("a texture coordinate needs u and v"));
                }
                if !uv.iter().all(|c| c.is_finite()) {
                    return Err(fail("texture coordinate is not a finite number"));
                }
                texcoords.push([uv[0], uv[1]]);
            }
            Some("f") => {
                let mut corners = Vec::new();
                for word in words {
                    let mut fields = word.split('/');
                    let resolve = |field: &str, count: usize| -> Result<(i64, i64), ScanError> {
                        let raw: i64 = field
                            .parse()
                            .map_err(|_| fail("face index is not an integer"))?;
                        let index = if raw < 0 { count as i64 + raw } else { raw - 1 };
                        Ok((raw, index))
                    };
                    let (raw, v) = resolve(fields.next().unwrap_or(""), positions.len())?;
                    let vt = match fields.next() {
                        Some(f) if !f.is_empty() => Some(resolve(f, texcoords.len())?.1),
                        _ => None,
                    };
                    corners.push((raw, v, vt));
                }
                for k in 1..corners.len().saturating_sub(1) {
                    let c = [corners[0], corners[k], corners[k + 1]];
                    triangles.push(ScanTriangle {
                        v: c.map(|c| c.1),
                        raw: c.map(|c| c.0),
                        vt: c.map(|c| c.2),
                        line: line_no,
                    });
                }
            }
            _ => {}
        }
    }
    for tri in &triangles {
        if tri
            .vt
            .iter()
            .flatten()
            .any(|&t| t < 0 || t as usize >= texcoords.len())
        {
            return Err(ScanError {
                line: tri.line,
                text: one_line(text.lines().nth(tri.line - 1).unwrap_or("").trim()),
                message: "texture coordinate index out of range".into(),
            });
        }
    }
    let colors = (!positions.is_empty() && colors.len() == positions.len()).then_some(colors);
    Ok(ObjScan {
        positions,
        position_lines,
        colors,
        texcoords,
        triangles,
    })
}

/// Turns a tobj error into ours, naming the bad face or line when the scan can find it.
fn explain_tobj_error(
    path: &Path,
    error: tobj::LoadError,
    scan: Result<ObjScan, ScanError>,
) -> MeshError {
    match scan {
        Ok(scan) => {
            let n = scan.positions.len();
            let bad = scan.triangles.iter().enumerate().find_map(|(face, tri)| {
                (0..3)
                    .find(|&c| tri.v[c] < 0 || tri.v[c] as usize >= n)
                    .map(|c| (face, tri.raw[c], tri.line))
            });
            match (error, bad) {
                (tobj::LoadError::FaceVertexOutOfBounds, Some((face, index, line))) => {
                    MeshError::FaceIndexOutOfRange {
                        face,
                        index,
                        vertex_count: n,
                        at: Location::line(path, line),
                    }
                }
                (error, _) => MeshError::ObjParse {
                    path: path.to_path_buf(),
                    message: error.to_string(),
                },
            }
        }
        Err(scan_error) => MeshError::ObjParse {
            path: path.to_path_buf(),
            message: format!("{error} (line {}: `{}`)", scan_error.line, scan_error.text),
        },
    }
}

/// Walks tobj's models (in file order) beside the scanned triangles, checks that every corner
/// has the same position in both, and returns each triangle's material id.
fn match_tobj_models(
    path: &Path,
    models: &[tobj::Model],
    scan: &ObjScan,
) -> Result<Vec<Option<usize>>, MeshError> {
    let disagree = |what: String| MeshError::ObjParse {
        path: path.to_path_buf(),
        message: format!("tobj and the OBJ scan disagree: {what}"),
    };
    let mut materials = Vec::with_capacity(scan.triangles.len());
    for model in models {
        let m = &model.mesh;
        for corners in m.indices.chunks_exact(3) {
            let face = materials.len();
            let tri = scan.triangles.get(face).ok_or_else(|| {
                disagree(format!("tobj has more than {} faces", scan.triangles.len()))
            })?;
            for (&corner, &v) in corners.iter().zip(&tri.v) {
                let local = corner as usize * 3;
                let ours = scan.positions[v as usize];
                let theirs = m.positions.get(local..local + 3);
                if theirs
                    .is_none_or(|t| t.iter().zip(ours).any(|(a, b)| a.to_bits() != b.to_bits()))
                {
                    return Err(disagree(format!("face {face} at line {}", tri.line)));
                }
            }
            materials.push(m.material_id);
        }
    }
    if materials.len() != scan.triangles.len() {
        return Err(disagree(format!(
            "tobj has {} faces, the scan {}",
            materials.len(),
            scan.triangles.len()
        )));
    }
    Ok(materials)
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::super::{MAX_TEXTURE_RES, texel_center_barycentric};
    use super::*;

    fn spot() -> std::path::PathBuf {
        softvk_testing::assets_dir().join("spot_triangulated.obj")
    }

    /// A fresh temporary folder, removed when dropped.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new() -> TempDir {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let dir =
                std::env::temp_dir().join(format!("raster-cpu-mesh-{}-{n}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }

        fn write(&self, name: &str, text: &str) -> PathBuf {
            let p = self.0.join(name);
            std::fs::write(&p, text).unwrap();
            p
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn spot_loads_with_file_counts_and_a_real_texture() {
        let text = std::fs::read_to_string(spot()).unwrap();
        let v_lines = text.lines().filter(|l| l.starts_with("v ")).count();
        let f_lines = text.lines().filter(|l| l.starts_with("f ")).count();
        let mesh = Mesh::load_obj(&spot(), 2).unwrap();
        assert_eq!(mesh.vertex_count(), v_lines);
        assert_eq!(mesh.face_count(), f_lines);
        assert_eq!((mesh.vertex_count(), mesh.face_count()), (2930, 5856));
        assert_eq!(mesh.textures.len(), 5856 * 4);
        let n = mesh.textures.len() as f64;
        let mean: [f64; 3] =
            std::array::from_fn(|k| mesh.textures.iter().map(|t| f64::from(t[k])).sum::<f64>() / n);
        assert!(
            mean.iter().all(|&c| c < 0.9),
            "mean texel {mean:?} looks white"
        );
        assert!(
            mesh.textures
                .iter()
                .flatten()
                .all(|c| (0.0..=1.0).contains(c))
        );
        // The first `v` line is vertex 0.
        let first: Vec<f32> = text
            .lines()
            .find(|l| l.starts_with("v "))
            .unwrap()
            .split_whitespace()
            .skip(1)
            .map(|w| w.parse().unwrap())
            .collect();
        assert_eq!(mesh.positions[0].to_vec(), first);
    }

    #[test]
    fn shared_spheres_load_white_even_with_a_missing_mtl() {
        // sphere_642.obj names sphere_642.mtl, which is not shipped.
        for (name, v, f) in [
            ("sphere_642.obj", 642, 1280),
            ("sphere_1352.obj", 1352, 2700),
        ] {
            let path = softvk_testing::assets_dir().join(name);
            let mesh = Mesh::load_obj(&path, 1).unwrap();
            assert_eq!((mesh.vertex_count(), mesh.face_count()), (v, f), "{name}");
            assert!(mesh.textures.iter().all(|t| *t == [1.0; 3]));
        }
    }

    #[test]
    fn vertex_order_is_file_order_across_objects_quads_and_negative_indices() {
        let dir = TempDir::new();
        let path = dir.write(
            "order.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 9 9 9\n\
             o first\nf 3 4 1\no second\nf -4 -3 -2 -1\n",
        );
        let mesh = Mesh::load_obj(&path, 1).unwrap();
        // The unreferenced vertex 4 is kept, all in `v` order.
        assert_eq!(mesh.vertex_count(), 5);
        assert_eq!(mesh.positions[4], [9.0, 9.0, 9.0]);
        assert_eq!(mesh.positions[2], [1.0, 1.0, 0.0]);
        // The quad is fanned from its first corner; the objects share vertices.
        assert_eq!(mesh.faces, vec![[2, 3, 0], [1, 2, 3], [1, 3, 4]]);
        assert_eq!(mesh.textures, vec![[1.0; 3]; 3]);
        assert!(mesh.vertex_colors.is_none());
    }

    #[test]
    fn vertex_colours_and_kd_are_loaded() {
        let dir = TempDir::new();
        dir.write("m.mtl", "newmtl red\nKd 0.8 0.1 0.2\n");
        let path = dir.write(
            "c.obj",
            "mtllib m.mtl\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\n\
             f 1 2 3\nusemtl red\nf 1 3 2\n",
        );
        let mesh = Mesh::load_obj(&path, 2).unwrap();
        let colors = mesh.vertex_colors.as_ref().unwrap();
        assert_eq!(colors[1], [0.0, 1.0, 0.0]);
        assert_eq!(&mesh.textures[..4], &[[1.0; 3]; 4]);
        assert_eq!(&mesh.textures[4..], &[[0.8, 0.1, 0.2]; 4]);
    }

    /// The mesh and the warnings it gave.
    fn load_warned(path: &Path, res: u32) -> (Result<Mesh, MeshError>, Vec<String>) {
        let mut warnings = Vec::new();
        let mesh = load_obj_warning(path, res, &mut |w| warnings.push(w));
        (mesh, warnings)
    }

    #[test]
    fn missing_mtl_file_gives_white_faces_and_one_warning() {
        let dir = TempDir::new();
        let path = dir.write(
            "nomtl.obj",
            "mtllib absent.mtl\nmtllib absent.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        );
        let (mesh, warnings) = load_warned(&path, 1);
        assert_eq!(mesh.unwrap().textures, vec![[1.0; 3]]);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].contains("nomtl.obj")
                && warnings[0].contains("absent.mtl")
                && warnings[0].contains("not found")
                && !warnings[0].contains('\n'),
            "{warnings:?}"
        );
        // A failed load says only its error.
        let bad = dir.write("bad.obj", "mtllib absent.mtl\nv 0 0 0\n");
        let (mesh, warnings) = load_warned(&bad, 1);
        assert!(mesh.is_err() && warnings.is_empty(), "{warnings:?}");
        // Nothing to say when the MTL is there.
        dir.write("there.mtl", "newmtl x\nKd 1 0 0\n");
        let ok = dir.write(
            "ok.obj",
            "mtllib there.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        );
        let (mesh, warnings) = load_warned(&ok, 1);
        assert_eq!(mesh.unwrap().textures, vec![[1.0, 0.0, 0.0]]);
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    /// A 256×2 image whose red is x/255 and whose green is 1 on the top row of the file and 0 on
    /// the bottom: SoftRas's bilinear lookup (after its vertical flip) then returns (u, v, b).
    fn ramp_texture(dir: &TempDir) {
        let mut img = image::RgbImage::new(256, 2);
        for x in 0..256u32 {
            img.put_pixel(x, 0, image::Rgb([x as u8, 255, 51]));
            img.put_pixel(x, 1, image::Rgb([x as u8, 0, 51]));
        }
        img.save(dir.0.join("ramp.png")).unwrap();
        dir.write("ramp.mtl", "newmtl ramp\nKd 0 0 0\nmap_Kd ramp.png\n");
    }

    #[test]
    fn textures_sample_uv_bilinearly_at_softras_texel_centres() {
        let dir = TempDir::new();
        ramp_texture(&dir);
        let path = dir.write(
            "tex.obj",
            "mtllib ramp.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n\
             vt 0.1 0.2\nvt 0.9 0.3\nvt 1.4 0.95\nusemtl ramp\nf 1/1 2/2 3/3\n",
        );
        let res = 4;
        let mesh = Mesh::load_obj(&path, res).unwrap();
        // uv > 1 wraps (SoftRas: uv % 1).
        let uv = [[0.1, 0.2], [0.9, 0.3], [0.4, 0.95]];
        for (i, texel) in mesh.textures.iter().enumerate() {
            let w = texel_center_barycentric(res, i as u32 % res, i as u32 / res);
            let u = w[0] * uv[0][0] + w[1] * uv[1][0] + w[2] * uv[2][0];
            let v = w[0] * uv[0][1] + w[1] * uv[1][1] + w[2] * uv[2][1];
            let expected = [u, v, 0.2];
            for k in 0..3 {
                assert!(
                    (f64::from(texel[k]) - expected[k]).abs() < 1e-5,
                    "texel {i} channel {k}: {texel:?} vs {expected:?}"
                );
            }
        }
    }

    #[test]
    fn missing_file_is_an_error_naming_the_path() {
        let err = Mesh::load_obj(Path::new("/nonexistent/nothing.obj"), 1).unwrap_err();
        assert!(matches!(err, MeshError::Read { .. }));
        assert!(
            err.to_string().contains("/nonexistent/nothing.obj"),
            "{err}"
        );
    }

    #[test]
    fn malformed_obj_is_a_parse_error_naming_the_line() {
        let dir = TempDir::new();
        let path = dir.write("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1\nf 1 2 3\n");
        let err = Mesh::load_obj(&path, 1).unwrap_err();
        assert!(matches!(err, MeshError::ObjParse { .. }), "{err:?}");
        let msg = err.to_string();
        assert!(
            msg.contains("bad.obj") && msg.contains("position parse error"),
            "{msg}"
        );
        assert!(msg.contains("line 3"), "{msg}");

        let path = dir.write("bad2.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n");
        let msg = Mesh::load_obj(&path, 1).unwrap_err().to_string();
        assert!(
            msg.contains("face parse error") && msg.contains("line 4"),
            "{msg}"
        );
    }

    #[test]
    fn nan_vertex_is_an_error_naming_the_vertex() {
        let dir = TempDir::new();
        let path = dir.write("nan.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
        let err = Mesh::load_obj(&path, 1).unwrap_err();
        assert!(
            matches!(err, MeshError::NonFiniteVertex { vertex: 1, .. }),
            "{err:?}"
        );
        let msg = err.to_string();
        assert!(
            msg.contains("vertex 1") && msg.contains("nan.obj:2"),
            "{msg}"
        );
        assert!(msg.contains("NaN"), "{msg}");

        let path = dir.write("inf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n");
        let err = Mesh::load_obj(&path, 1).unwrap_err();
        assert!(matches!(err, MeshError::NonFiniteVertex { vertex: 2, .. }));
    }

    #[test]
    fn zero_faces_is_an_error() {
        let dir = TempDir::new();
        let path = dir.write("empty.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n");
        let err = Mesh::load_obj(&path, 1).unwrap_err();
        assert!(matches!(err, MeshError::NoFaces { .. }), "{err:?}");
        assert!(err.to_string().contains("has no faces"));
        assert!(matches!(
            Mesh::new(vec![[0.0; 3]; 3], vec![], 1),
            Err(MeshError::NoFaces { .. })
        ));
    }

    #[test]
    fn face_index_out_of_range_names_the_face() {
        let dir = TempDir::new();
        let path = dir.write(
            "range.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 7\n",
        );
        let err = Mesh::load_obj(&path, 1).unwrap_err();
        // Face 2 is the second triangle of the fanned quad on line 5.
        assert!(
            matches!(
                err,
                MeshError::FaceIndexOutOfRange {
                    face: 2,
                    index: 7,
                    vertex_count: 3,
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("face 2 (") && err.to_string().contains(":5)"));

        let err = Mesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 2], [0, 3, 1]], 1).unwrap_err();
        assert!(matches!(
            err,
            MeshError::FaceIndexOutOfRange {
                face: 1,
                index: 3,
                ..
            }
        ));
    }

    #[test]
    fn absurd_texture_res_is_an_error() {
        for res in [0, MAX_TEXTURE_RES + 1] {
            let err = Mesh::load_obj(&spot(), res).unwrap_err();
            assert!(matches!(err, MeshError::TextureRes(r) if r == res));
            assert!(err.to_string().contains("texture resolution"));
        }
    }

    #[test]
    fn missing_texture_image_falls_back_to_kd_with_one_warning() {
        let dir = TempDir::new();
        dir.write(
            "t.mtl",
            "newmtl skin\nKd 0.5 0.25 1\nmap_Kd gone.png\nnewmtl bare\nmap_Kd gone.png\n",
        );
        let path = dir.write(
            "t.obj",
            "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl skin\n\
             f 1/1 2/1 3/1\nf 1/1 3/1 2/1\nusemtl bare\nf 1 2 3\n",
        );
        let (mesh, warnings) = load_warned(&path, 1);
        assert_eq!(
            mesh.unwrap().textures,
            vec![[0.5, 0.25, 1.0], [0.5, 0.25, 1.0], [1.0; 3]]
        );
        assert_eq!(warnings.len(), 2, "one per material: {warnings:?}");
        assert!(
            warnings[0].contains("t.obj")
                && warnings[0].contains("gone.png")
                && warnings[0].contains("'skin'")
                && warnings[0].contains("Kd"),
            "{warnings:?}"
        );
        assert!(
            warnings[1].contains("'bare'") && warnings[1].contains("white"),
            "{warnings:?}"
        );
        // A texture that is there but does not decode is still an error.
        dir.write("gone.png", "not a png");
        let (mesh, warnings) = load_warned(&path, 1);
        assert!(
            matches!(mesh, Err(MeshError::TextureDecode { .. })),
            "{mesh:?}"
        );
        assert!(warnings.is_empty());
    }
}
