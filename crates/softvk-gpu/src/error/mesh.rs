//! What can be wrong with a mesh or its files ([`MeshError`]), and where ([`Location`]). The mesh
//! types and loaders live in softvk-raster's `mesh` module, which re-exports these; they are
//! defined here, beside [`Error`](super::Error) that wraps them, so that the one error type of
//! softvk sits below every crate that fails.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::text::one_line;

/// Largest accepted per-face texture resolution. SoftRas stores R² texels per face; beyond 64
/// (4096 texels per face) a mesh of any size would not fit a GPU buffer, so it is a mistake.
pub const MAX_TEXTURE_RES: u32 = 64;

/// Where in an input file a problem was found; empty for meshes built in memory.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Location {
    /// The file, if the mesh came from one.
    pub path: Option<PathBuf>,
    /// 1-based line number in that file, where known.
    pub line: Option<usize>,
}

impl Location {
    /// A whole file.
    pub fn file(path: &Path) -> Location {
        Location {
            path: Some(path.to_path_buf()),
            line: None,
        }
    }

    /// A line of a file.
    pub fn line(path: &Path, line: usize) -> Location {
        Location {
            path: Some(path.to_path_buf()),
            line: Some(line),
        }
    }
}

/// A path as it may appear in a one-line message (see [`one_line`]).
pub fn shown(path: &Path) -> String {
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
    /// Every vertex is at one point: there is no extent to normalize.
    #[error("cannot normalize a mesh whose {vertices} vertices are all at one point")]
    NoExtent {
        /// How many vertices there are.
        vertices: usize,
    },
    /// Subdivision would number vertices past `u32`.
    #[error("subdivision: more than 2^32 vertices")]
    TooManyVertices,
}
