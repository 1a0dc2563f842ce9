//! Triangle meshes as the soft rasterizer consumes them: positions, triangles and SoftRas-style
//! per-face R×R textures (or per-vertex colours), loaded from OBJ/MTL or generated for tests.
//!
//! The OBJ loader follows SoftRas's `load_obj.py` / `load_textures_cuda_kernel.cu` so that a
//! SoftRas user gets the same mesh and the same texels:
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
use std::fmt;
use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::error::one_line;

/// Largest accepted per-face texture resolution. SoftRas stores R² texels per face; beyond 64
/// (4096 texels per face) a mesh of any size would not fit a GPU buffer, so it is a mistake.
pub const MAX_TEXTURE_RES: u32 = 64;

/// Largest accepted `map_Kd` image, in pixels (8192²): a texture is decoded whole, at 12 bytes
/// a pixel, before it is sampled into per-face texels.
pub const MAX_TEXTURE_PIXELS: u64 = 1 << 26;

/// Largest icosphere subdivision level ([`Mesh::icosphere`] clamps to it): 7 gives 327 680 faces.
pub const MAX_ICOSPHERE_SUBDIVISIONS: u32 = 7;

/// A triangle mesh with SoftRas per-face textures.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// World-space vertex positions, in file order.
    pub positions: Vec<[f32; 3]>,
    /// Triangles as indices into `positions`. Winding: the SPEC §1 normal
    /// `normalize(cross(v2 - v1, v0 - v1))` points to the side the face is seen from.
    pub faces: Vec<[u32; 3]>,
    /// Texture resolution R: each face has R×R texels (R = 1 is a flat colour per face).
    pub texture_res: u32,
    /// `faces.len() * R * R` texels, face-major. Within a face, texel `i = w_y * R + w_x` in
    /// SoftRas order: texels with `w_x + w_y < R` are the lower triangles of the R×R grid over
    /// barycentric (w0, w1), the others the upper triangles (see [`texel_center_barycentric`]).
    pub textures: Vec<[f32; 3]>,
    /// Per-vertex colours for vertex colour mode; `None` means white.
    pub vertex_colors: Option<Vec<[f32; 3]>>,
}

/// Where in an input file a problem was found; empty for meshes built in memory.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Location {
    /// The file, if the mesh came from one.
    pub path: Option<PathBuf>,
    /// 1-based line number in that file, where known.
    pub line: Option<usize>,
}

impl Location {
    fn file(path: &Path) -> Location {
        Location {
            path: Some(path.to_path_buf()),
            line: None,
        }
    }

    fn line(path: &Path, line: usize) -> Location {
        Location {
            path: Some(path.to_path_buf()),
            line: Some(line),
        }
    }
}

/// A path as it may appear in a one-line message (see [`one_line`]).
fn shown(path: &Path) -> String {
    one_line(&path.display().to_string())
}

impl fmt::Display for Location {
    /// Renders as ` (path:line)`, ` (path)` or nothing, to be appended to a message.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.path, self.line) {
            (Some(p), Some(l)) => write!(f, " ({}:{l})", shown(p)),
            (Some(p), None) => write!(f, " ({})", shown(p)),
            (None, Some(l)) => write!(f, " (line {l})"),
            (None, None) => Ok(()),
        }
    }
}

/// Everything that can be wrong with a mesh or its files. One clear message per case.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The OBJ file is missing or unreadable.
    #[error("cannot read mesh file {}: {source}", shown(path))]
    Read {
        /// The file that was asked for.
        path: PathBuf,
        /// What the OS said.
        #[source]
        source: std::io::Error,
    },
    /// The OBJ text is malformed.
    #[error("cannot parse OBJ file {}: {message}", shown(path))]
    ObjParse {
        /// The OBJ file.
        path: PathBuf,
        /// tobj's message, with the offending line where it could be found.
        message: String,
    },
    /// An MTL file exists but is malformed.
    #[error("cannot parse MTL file {}: {message}", shown(path))]
    MtlParse {
        /// The MTL file.
        path: PathBuf,
        /// tobj's message.
        message: String,
    },
    /// A texture image exists but cannot be decoded (only PNG is supported).
    #[error("cannot decode texture {}: {message}", shown(path))]
    TextureDecode {
        /// The image file.
        path: PathBuf,
        /// The decoder's message.
        message: String,
    },
    /// A vertex has a NaN or infinite coordinate.
    #[error("vertex {vertex}{at} has a NaN or infinite coordinate")]
    NonFiniteVertex {
        /// 0-based vertex index (the OBJ index is one more).
        vertex: usize,
        /// Where it was defined.
        at: Location,
    },
    /// The mesh has no triangles.
    #[error("mesh{at} has no faces")]
    NoFaces {
        /// The file, if any.
        at: Location,
    },
    /// A face refers to a vertex that does not exist.
    #[error(
        "face {face}{at} refers to vertex index {index}, but the mesh has {vertex_count} vertices"
    )]
    FaceIndexOutOfRange {
        /// 0-based triangle index (after triangulation).
        face: usize,
        /// The index as written (OBJ: 1-based or negative; in memory: 0-based).
        index: i64,
        /// How many vertices there are.
        vertex_count: usize,
        /// Where the face was defined.
        at: Location,
    },
    /// The per-face texture resolution is 0 or absurdly large.
    #[error("texture resolution {0} is out of range: it must be 1..={MAX_TEXTURE_RES}")]
    TextureRes(u32),
    /// The texel array does not match faces × R².
    #[error(
        "mesh has {actual} texels, but {faces} faces at texture resolution {res} need {expected}"
    )]
    TextureCount {
        /// Texels present.
        actual: usize,
        /// Texels needed.
        expected: usize,
        /// Face count.
        faces: usize,
        /// Texture resolution.
        res: u32,
    },
    /// The vertex colour array does not match the vertex count.
    #[error("mesh has {actual} vertex colours for {expected} vertices")]
    VertexColorCount {
        /// Colours present.
        actual: usize,
        /// Vertices.
        expected: usize,
    },
}

impl Mesh {
    /// A mesh with flat white textures at resolution `texture_res`, validated.
    pub fn new(
        positions: Vec<[f32; 3]>,
        faces: Vec<[u32; 3]>,
        texture_res: u32,
    ) -> Result<Mesh, MeshError> {
        check_texture_res(texture_res)?;
        let texels = faces.len() * (texture_res * texture_res) as usize;
        let mesh = Mesh {
            positions,
            faces,
            texture_res,
            textures: vec![[1.0; 3]; texels],
            vertex_colors: None,
        };
        mesh.validate()?;
        Ok(mesh)
    }

    /// SoftRas's `load_obj(normalization=True)`: moves the bounding box's lower corner to the
    /// origin, divides by the largest coordinate then (so the longest side spans [0, 1]),
    /// doubles, and centres each axis: the longest side spans [-1, 1], the others are centred
    /// in it. Computed in f64. An error, with the mesh unchanged, when every vertex is at one
    /// point (nothing to scale) or a coordinate is not finite.
    pub fn normalize(&mut self) -> crate::Result<()> {
        check_finite(&self.positions, |_| Location::default())?;
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in &self.positions {
            let p = DVec3::from(p.map(f64::from));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let extent = (hi - lo).max_element();
        if extent.is_nan() || extent <= 0.0 {
            return Err(crate::Error::Input(format!(
                "cannot normalize a mesh whose {} vertices are all at one point",
                self.positions.len()
            )));
        }
        let scale = 2.0 / extent;
        let centre = (hi - lo) * scale / 2.0;
        for p in &mut self.positions {
            let q = (DVec3::from(p.map(f64::from)) - lo) * scale - centre;
            *p = q.to_array().map(|c| c as f32);
        }
        Ok(())
    }

    /// Number of triangles.
    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Checks every invariant the renderers rely on, so that bad input is an error and never a
    /// panic or a NaN image.
    pub fn validate(&self) -> Result<(), MeshError> {
        check_texture_res(self.texture_res)?;
        check_finite(&self.positions, |_| Location::default())?;
        if self.faces.is_empty() {
            return Err(MeshError::NoFaces {
                at: Location::default(),
            });
        }
        let n = self.positions.len();
        for (face, f) in self.faces.iter().enumerate() {
            if let Some(&bad) = f.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::FaceIndexOutOfRange {
                    face,
                    index: i64::from(bad),
                    vertex_count: n,
                    at: Location::default(),
                });
            }
        }
        let r2 = (self.texture_res * self.texture_res) as usize;
        if self.textures.len() != self.faces.len() * r2 {
            return Err(MeshError::TextureCount {
                actual: self.textures.len(),
                expected: self.faces.len() * r2,
                faces: self.faces.len(),
                res: self.texture_res,
            });
        }
        if let Some(colors) = &self.vertex_colors
            && colors.len() != n
        {
            return Err(MeshError::VertexColorCount {
                actual: colors.len(),
                expected: n,
            });
        }
        Ok(())
    }

    /// Loads an OBJ (and its MTL and `map_Kd` texture) as SoftRas's `load_obj(load_texture=True)`
    /// does, sampling textures into `texture_res`² texels per face.
    ///
    /// A missing MTL file is not an error (SoftRas only reads it when asked for textures, and
    /// OBJ exporters often name one that was never shipped): its faces are white. A missing
    /// texture image is not an error either: its material's faces take the material's `Kd`, or
    /// white. Each missing file is said once, as one line `softvk: warning: ...` on stderr.
    /// An MTL or texture that exists but does not parse or decode is an error. `v x y z r g b`
    /// lines give [`Mesh::vertex_colors`] when every `v` line has a colour.
    pub fn load_obj(path: &Path, texture_res: u32) -> Result<Mesh, MeshError> {
        load_obj_warning(path, texture_res, &mut |warning| {
            eprintln!("softvk: warning: {warning}");
        })
    }

    /// Unit-radius icosphere: the icosahedron subdivided `subdivisions` times (clamped to
    /// [`MAX_ICOSPHERE_SUBDIVISIONS`]), every face wound so its SPEC normal points outward.
    /// Flat white texture, R = 1. `20·4^s` faces, `10·4^s + 2` vertices.
    pub fn icosphere(subdivisions: u32) -> Mesh {
        let t = (1.0 + 5.0f64.sqrt()) / 2.0;
        let mut positions: Vec<DVec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .iter()
        .map(|&p| DVec3::from(p).normalize())
        .collect();
        let mut faces: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions.min(MAX_ICOSPHERE_SUBDIVISIONS) {
            // In f64, each midpoint pushed back onto the unit sphere.
            faces = subdivide_faces(&faces, |a, b| {
                positions.push((positions[a as usize] + positions[b as usize]).normalize());
                Ok::<u32, std::convert::Infallible>((positions.len() - 1) as u32)
            })
            .unwrap_or_else(|never| match never {});
        }
        white_mesh(positions, faces)
    }

    /// Midpoint subdivision: every triangle `(a, b, c)` becomes `(a, ab, ca)`, `(b, bc, ab)`,
    /// `(c, ca, bc)`, `(ab, bc, ca)`, each wound as its parent and lying in its plane
    /// ([`subdivide_faces`], which the icosphere uses too).
    ///
    /// Faces that share an edge share its midpoint (one new vertex per undirected edge,
    /// appended in order of first use), so a watertight mesh stays watertight. Midpoints are
    /// correctly rounded; per-vertex colours are averaged at them. Children copy their parent's
    /// texels (exact for R = 1; for R > 1 each child shows the whole parent texture).
    pub fn subdivided(&self) -> crate::Result<Mesh> {
        self.validate()?;
        let mut positions = self.positions.clone();
        let mut colors = self.vertex_colors.clone();
        let faces = subdivide_faces(&self.faces, |a, b| {
            let m = u32::try_from(positions.len())
                .map_err(|_| crate::Error::Limit("subdivision: more than 2^32 vertices".into()))?;
            let mid = |p: &[[f32; 3]]| {
                let (p, q) = (p[a as usize], p[b as usize]);
                // f32 + f32 is exact in f64, so this is the correctly rounded midpoint.
                [0, 1, 2].map(|k| ((f64::from(p[k]) + f64::from(q[k])) / 2.0) as f32)
            };
            positions.push(mid(&positions));
            if let Some(c) = colors.as_mut() {
                c.push(mid(c));
            }
            Ok::<u32, crate::Error>(m)
        })?;
        let r2 = (self.texture_res * self.texture_res) as usize;
        let textures = self
            .textures
            .chunks_exact(r2)
            .flat_map(|parent| std::iter::repeat_n(parent, 4).flatten().copied())
            .collect();
        let out = Mesh {
            positions,
            faces,
            texture_res: self.texture_res,
            textures,
            vertex_colors: colors,
        };
        out.validate()?;
        Ok(out)
    }

    /// Axis-aligned box centred at the origin with the given half extents: 8 vertices,
    /// 12 faces wound outward. Flat white texture, R = 1.
    pub fn cuboid(half_extents: [f32; 3]) -> Mesh {
        let h = DVec3::new(
            f64::from(half_extents[0]),
            f64::from(half_extents[1]),
            f64::from(half_extents[2]),
        );
        // Vertex i has coordinate sign bits (x, y, z) = (i & 1, i & 2, i & 4).
        let positions: Vec<DVec3> = (0..8)
            .map(|i| {
                let s = |bit: u32| if i & bit != 0 { 1.0 } else { -1.0 };
                DVec3::new(s(1) * h.x, s(2) * h.y, s(4) * h.z)
            })
            .collect();
        // Quads listed counter-clockwise as seen from outside; fanned into two triangles.
        let quads = [
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
        ];
        let faces = quads
            .iter()
            .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
            .collect();
        white_mesh(positions, faces)
    }
}

/// [`Mesh::load_obj`], with each warning (a missing MTL or texture file) given to `warn` as one
/// line instead of printed.
fn load_obj_warning(
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

/// The topology of one midpoint subdivision: each face `(a, b, c)` becomes `(a, ab, ca)`,
/// `(b, bc, ab)`, `(c, ca, bc)`, `(ab, bc, ca)`, and `new_vertex(a, b)` makes the midpoint of
/// each undirected edge once, on its first use (faces in order, edges ab, bc, ca), returning its
/// index. The one subdivision of the crate: [`Mesh::subdivided`] and [`Mesh::icosphere`] differ
/// only in how they place a midpoint.
pub fn subdivide_faces<E>(
    faces: &[[u32; 3]],
    mut new_vertex: impl FnMut(u32, u32) -> std::result::Result<u32, E>,
) -> std::result::Result<Vec<[u32; 3]>, E> {
    let mut midpoints: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 3 / 2);
    let mut midpoint = |a: u32, b: u32| -> std::result::Result<u32, E> {
        let key = (a.min(b), a.max(b));
        if let Some(&m) = midpoints.get(&key) {
            return Ok(m);
        }
        let m = new_vertex(a, b)?;
        midpoints.insert(key, m);
        Ok(m)
    };
    let mut next = Vec::with_capacity(faces.len() * 4);
    for &[a, b, c] in faces {
        let ab = midpoint(a, b)?;
        let bc = midpoint(b, c)?;
        let ca = midpoint(c, a)?;
        // Same winding as the parent in each child keeps the normals outward.
        next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
    }
    Ok(next)
}

fn white_mesh(positions: Vec<DVec3>, faces: Vec<[u32; 3]>) -> Mesh {
    let textures = vec![[1.0; 3]; faces.len()];
    Mesh {
        positions: positions
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect(),
        faces,
        texture_res: 1,
        textures,
        vertex_colors: None,
    }
}

pub(crate) fn check_texture_res(res: u32) -> Result<(), MeshError> {
    if res == 0 || res > MAX_TEXTURE_RES {
        return Err(MeshError::TextureRes(res));
    }
    Ok(())
}

fn check_finite(positions: &[[f32; 3]], at: impl Fn(usize) -> Location) -> Result<(), MeshError> {
    match positions
        .iter()
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        Some(vertex) => Err(MeshError::NonFiniteVertex {
            vertex,
            at: at(vertex),
        }),
        None => Ok(()),
    }
}

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
struct TextureImage {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

impl TextureImage {
    fn load(path: &Path) -> Result<TextureImage, MeshError> {
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
    fn sample_face(&self, uv: [[f64; 2]; 3], res: u32, texels: &mut [[f32; 3]]) {
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
fn wrap_uv(x: f64) -> f64 {
    if (0.0..=1.0).contains(&x) {
        x
    } else {
        x - x.floor()
    }
}

/// The image file a `map_Kd` value names. Options (`-s 1 1 1 file.png`) come first, the file
/// last; without options the whole value is the name, so names with spaces work.
fn texture_file_name(map_kd: &str) -> &str {
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
fn resolve_texture(mtl_dir: &Path, obj_dir: &Path, map_kd: &str) -> Option<PathBuf> {
    let name = texture_file_name(map_kd);
    [mtl_dir.join(name), obj_dir.join(name)]
        .into_iter()
        .find(|p| p.is_file())
}

/// What the MTL loader saw, kept beside tobj (which merges materials and drops their origin).
#[derive(Default)]
struct MtlLog {
    /// The MTL file that defined each material, to resolve its texture path and name it.
    files: HashMap<String, PathBuf>,
    /// The first MTL that exists but failed to parse.
    error: Option<MeshError>,
    /// The MTL files that could not be opened, each once, in file order.
    missing: Vec<PathBuf>,
}

impl MtlLog {
    /// Reads one MTL file for tobj, noting what happened.
    fn load(&mut self, path: &Path) -> tobj::MTLLoadResult {
        let bytes = match std::fs::read(path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                if !self.missing.iter().any(|m| m == path) {
                    self.missing.push(path.to_path_buf());
                }
                return Err(tobj::LoadError::OpenFileFailed);
            }
            Err(e) => {
                self.fail(path, e.to_string());
                return Err(tobj::LoadError::ReadError);
            }
        };
        if let Err(message) = check_mtl(&bytes) {
            self.fail(path, message);
            return Err(tobj::LoadError::MaterialParseError);
        }
        let result = tobj::load_mtl_buf(&mut bytes.as_slice());
        match &result {
            Ok((materials, _)) => {
                for m in materials {
                    self.files.insert(m.name.clone(), path.to_path_buf());
                }
            }
            Err(e) => self.fail(path, e.to_string()),
        }
        result
    }

    fn fail(&mut self, path: &Path, message: String) {
        self.error.get_or_insert(MeshError::MtlParse {
            path: path.to_path_buf(),
            message,
        });
    }
}

/// What tobj 4 does not check before it panics: a colour (`Ka`, `Kd`, `Ks`, `Ke`) with fewer
/// than three values. The message names the line.
fn check_mtl(bytes: &[u8]) -> Result<(), String> {
    for (i, line) in String::from_utf8_lossy(bytes).lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next()
            && words.count() < 3
        {
            return Err(format!(
                "`{key}` needs three numbers at line {}: `{}`",
                i + 1,
                one_line(line.trim())
            ));
        }
    }
    Ok(())
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
pub(crate) mod tests {
    use super::*;
    use std::collections::HashSet;

    /// SoftRas's normalization: the longest side spans [-1, 1], every axis is centred, the
    /// proportions stay; a mesh at one point is an error that leaves it unchanged.
    #[test]
    fn normalize_centres_and_scales_the_longest_side_to_two() {
        let mut mesh = Mesh::cuboid([0.125, 0.0625, 0.03125]);
        for p in &mut mesh.positions {
            *p = [p[0] + 3.0, p[1] - 1.0, p[2] + 0.5];
        }
        mesh.normalize().unwrap();
        let axis = |k: usize| {
            let c = mesh.positions.iter().map(|p| p[k]);
            (
                c.clone().fold(f32::INFINITY, f32::min),
                c.fold(f32::NEG_INFINITY, f32::max),
            )
        };
        assert_eq!(axis(0), (-1.0, 1.0));
        assert_eq!(axis(1), (-0.5, 0.5));
        assert_eq!(axis(2), (-0.25, 0.25));

        let mut point = Mesh::cuboid([0.0, 0.0, 0.0]);
        let before = point.positions.clone();
        let err = point.normalize().unwrap_err();
        assert!(err.to_string().contains("one point"), "{err}");
        assert_eq!(point.positions, before);
    }

    fn pos(m: &Mesh, i: u32) -> DVec3 {
        DVec3::from(m.positions[i as usize].map(f64::from))
    }
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn spot() -> std::path::PathBuf {
        crate::assets::dir().join("spot_triangulated.obj")
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

    fn face_normal(m: &Mesh, f: usize) -> DVec3 {
        let p = |i: u32| DVec3::from(m.positions[i as usize].map(f64::from));
        let [a, b, c] = m.faces[f];
        (p(c) - p(b)).cross(p(a) - p(b))
    }

    fn centroid(m: &Mesh, f: usize) -> DVec3 {
        let p = |i: u32| DVec3::from(m.positions[i as usize].map(f64::from));
        let [a, b, c] = m.faces[f];
        (p(a) + p(b) + p(c)) / 3.0
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
            let path = crate::assets::dir().join(name);
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

    #[test]
    fn generators_are_closed_and_wound_outward() {
        for (mesh, v, f) in [
            (Mesh::icosphere(0), 12, 20),
            (Mesh::icosphere(2), 162, 320),
            (Mesh::cuboid([0.5, 1.0, 2.0]), 8, 12),
        ] {
            mesh.validate().unwrap();
            assert_eq!((mesh.vertex_count(), mesh.face_count()), (v, f));
            for face in 0..mesh.face_count() {
                let n = face_normal(&mesh, face);
                assert!(n.length() > 1e-6);
                assert!(
                    n.dot(centroid(&mesh, face)) > 0.0,
                    "face {face} of {v} points inward"
                );
            }
            // Closed: every edge is used once in each direction.
            let mut edges = HashMap::new();
            for &[a, b, c] in &mesh.faces {
                for e in [(a, b), (b, c), (c, a)] {
                    *edges.entry(e).or_insert(0) += 1;
                }
            }
            assert!(
                edges
                    .iter()
                    .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
            );
        }
        let sphere = Mesh::icosphere(3);
        for p in &sphere.positions {
            let r = p.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
            assert!((r - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn validate_catches_bad_texel_and_colour_counts() {
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.textures.pop();
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::TextureCount { expected: 12, .. })
        ));
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.vertex_colors = Some(vec![[1.0; 3]; 7]);
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::VertexColorCount { expected: 8, .. })
        ));
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.positions[5][1] = f32::INFINITY;
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::NonFiniteVertex { vertex: 5, .. })
        ));
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

    // Subdivision (`Mesh::subdivided`, and the icosphere through `subdivide_faces`).

    /// Twice the signed area vector of face `f`, along the SPEC normal.
    fn area_vector(m: &Mesh, f: [u32; 3]) -> DVec3 {
        let [a, b, c] = f.map(|i| pos(m, i));
        (c - b).cross(a - b)
    }

    /// Every directed edge of a closed, consistently wound mesh appears once, and so does its
    /// reverse.
    pub(crate) fn is_closed_and_consistent(m: &Mesh) -> bool {
        let mut directed = HashSet::new();
        for &[a, b, c] in &m.faces {
            for e in [(a, b), (b, c), (c, a)] {
                if !directed.insert(e) {
                    return false;
                }
            }
        }
        directed.iter().all(|&(a, b)| directed.contains(&(b, a)))
    }

    fn edge_count(m: &Mesh) -> usize {
        let mut edges = HashSet::new();
        for &[a, b, c] in &m.faces {
            for (p, q) in [(a, b), (b, c), (c, a)] {
                edges.insert((p.min(q), p.max(q)));
            }
        }
        edges.len()
    }

    #[test]
    fn subdivision_makes_four_faces_each_and_one_vertex_per_edge() {
        for mesh in [Mesh::cuboid([1.0, 2.0, 0.5]), Mesh::icosphere(1)] {
            let once = mesh.subdivided().unwrap();
            assert_eq!(once.face_count(), 4 * mesh.face_count());
            assert_eq!(once.vertex_count(), mesh.vertex_count() + edge_count(&mesh));
            assert_eq!(once.positions[..mesh.vertex_count()], mesh.positions[..]);
            let twice = once.subdivided().unwrap();
            assert_eq!(twice.face_count(), 16 * mesh.face_count());
        }
    }

    #[test]
    fn subdivision_keeps_a_closed_mesh_closed_and_consistently_wound() {
        let mut mesh = Mesh::icosphere(0);
        assert!(is_closed_and_consistent(&mesh));
        for _ in 0..3 {
            mesh = mesh.subdivided().unwrap();
            assert!(is_closed_and_consistent(&mesh));
            // Euler characteristic of a sphere: shared edges really share their midpoint.
            let chi =
                mesh.vertex_count() as i64 - edge_count(&mesh) as i64 + mesh.face_count() as i64;
            assert_eq!(chi, 2);
        }
    }

    #[test]
    fn subdivided_children_tile_their_parent_with_its_normal() {
        let mesh = Mesh::cuboid([1.0, 0.25, 3.0]);
        let sub = mesh.subdivided().unwrap();
        for (f, &parent) in mesh.faces.iter().enumerate() {
            let whole = area_vector(&mesh, parent);
            let children = &sub.faces[4 * f..4 * f + 4];
            let sum: DVec3 = children.iter().map(|&c| area_vector(&sub, c)).sum();
            assert!((sum - whole).length() <= 1e-6 * whole.length(), "face {f}");
            for &c in children {
                let child = area_vector(&sub, c);
                // Same plane, same side: a quarter of the parent's area vector.
                assert!((4.0 * child - whole).length() <= 1e-6 * whole.length());
            }
        }
    }

    #[test]
    fn subdivided_icosahedron_is_the_icosphere_before_projection() {
        // Mesh::icosphere makes the same midpoints in the same order, then puts them on the
        // unit sphere: same faces, and directions within f32 rounding.
        let sub = Mesh::icosphere(0).subdivided().unwrap();
        let ico = Mesh::icosphere(1);
        assert_eq!(sub.faces, ico.faces);
        for (p, q) in sub.positions.iter().zip(&ico.positions) {
            let p = DVec3::from(p.map(f64::from)).normalize();
            let q = DVec3::from(q.map(f64::from));
            assert!((p - q).length() < 1e-6);
        }
    }

    #[test]
    fn subdivision_copies_texels_and_averages_vertex_colors() {
        let mut mesh = Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [1, 3, 2]],
            2,
        )
        .unwrap();
        for (i, t) in mesh.textures.iter_mut().enumerate() {
            *t = [i as f32, 0.5, 1.0];
        }
        mesh.vertex_colors = Some(vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]);
        let sub = mesh.subdivided().unwrap();
        assert_eq!(sub.texture_res, 2);
        for (f, child) in sub.textures.chunks_exact(4).enumerate() {
            assert_eq!(child, &mesh.textures[4 * (f / 4)..4 * (f / 4) + 4]);
        }
        let colors = sub.vertex_colors.as_ref().unwrap();
        assert_eq!(colors.len(), sub.vertex_count());
        // Face 0's middle child is (ab, bc, ca); its bc is the midpoint of the shared edge
        // (1, 2), which face 1's children use too, and holds the average of its ends.
        let bc = sub.faces[3][1] as usize;
        assert_eq!(sub.positions[bc], [0.5, 0.5, 0.0]);
        assert_eq!(colors[bc], [0.5, 0.5, 0.0]);
        assert!(sub.faces[4..].iter().flatten().any(|&i| i as usize == bc));
        assert_eq!(sub.vertex_count(), 4 + 5);
    }

    #[test]
    fn subdivision_rejects_an_invalid_mesh() {
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.faces[0][1] = 99;
        assert!(mesh.subdivided().is_err());
    }
}
