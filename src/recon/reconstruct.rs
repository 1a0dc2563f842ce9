//! Reconstruction with a trained model of either kind (the mesh decoder's or a conditioned
//! field's), and what training, evaluation and `softvk recon` share around it: the validation
//! score, the views an evaluation spreads over, and how reconstructions are shown.

use super::dataset::{self, ClassData, Dataset};
use super::eval;
use super::field::FieldReconstructor;
use super::model::{ReconModel, Reconstruction, Reconstructor};
use crate::error::Result;
use crate::gpu::Context;
use crate::mesh::Mesh;
use crate::raster::settings::{ColorMode, RasterSettings};

/// `n` views spread evenly over the 24.
pub fn spread_views(n: u32) -> Vec<usize> {
    let n = n.min(dataset::VIEWS as u32) as usize;
    (0..n).map(|i| i * dataset::VIEWS / n).collect()
}

/// A trained model of either kind, ready to reconstruct.
pub enum AnyReconstructor {
    /// The mesh decoder's.
    Mesh(Box<Reconstructor>),
    /// A conditioned field's.
    Field(Box<FieldReconstructor>),
}

impl AnyReconstructor {
    /// `model`'s reconstructor, for batches of up to `capacity` images.
    pub fn new(ctx: &Context, model: &ReconModel, capacity: u32) -> Result<Self> {
        Ok(match model.field {
            Some(_) => Self::Field(Box::new(FieldReconstructor::new(ctx, model, capacity)?)),
            None => Self::Mesh(Box::new(Reconstructor::new(ctx, model, capacity)?)),
        })
    }

    /// The 3D IoU of the reconstruction from each `(object, view)` input of `class`.
    pub fn ious(
        &self,
        ctx: &Context,
        class: &ClassData,
        inputs: &[(usize, usize)],
        voxelizer: eval::Voxelizer,
    ) -> Result<Vec<f64>> {
        match self {
            Self::Mesh(r) => {
                Ok(eval::reconstruction_ious(ctx, r, class, inputs, &[voxelizer])?.remove(0))
            }
            Self::Field(r) => eval::field_reconstruction_ious(ctx, r, class, inputs),
        }
    }

    /// The mesh of one image (`4 × H × W` bytes): the deformed template with its colours, or
    /// the field's marching-cubes mesh in grey (`None` when φ never crosses 0.5).
    pub fn mesh(&self, ctx: &Context, image: &[u8]) -> Result<Option<Mesh>> {
        match self {
            Self::Mesh(r) => Ok(Some(colored_mesh(r.reconstruct(ctx, image)?.remove(0)))),
            Self::Field(r) => {
                let iso = r.isosurface(ctx, image, FIELD_MESH_RES)?;
                if iso.is_empty() {
                    return Ok(None);
                }
                let mut mesh = iso.to_mesh()?;
                mesh.vertex_colors = Some(vec![[0.7; 3]; mesh.positions.len()]);
                Ok(Some(mesh))
            }
        }
    }

    /// The IoU columns of this model over `inputs` of `class` (`[column][input]`): a mesh
    /// model's once per voxelizer of `mesh_voxelizers`, a field's once.
    pub fn columns(
        &self,
        ctx: &Context,
        class: &ClassData,
        inputs: &[(usize, usize)],
        mesh_voxelizers: &[eval::Voxelizer],
    ) -> Result<Vec<Vec<f64>>> {
        match self {
            Self::Mesh(r) => eval::reconstruction_ious(ctx, r, class, inputs, mesh_voxelizers),
            Self::Field(r) => Ok(vec![eval::field_reconstruction_ious(
                ctx, r, class, inputs,
            )?]),
        }
    }

    /// `mesh` or `field`.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Mesh(_) => "mesh",
            Self::Field(_) => "field",
        }
    }
}

/// Lattice of the marching cubes that mesh a conditioned field.
pub const FIELD_MESH_RES: u32 = 64;

/// The mean validation IoU of `model` over `views` of every val object.
pub fn validation_iou(
    ctx: &Context,
    model: &ReconModel,
    val: &Dataset,
    views: &[usize],
) -> Result<f64> {
    let recon = AnyReconstructor::new(ctx, model, 32)?;
    let mut all = Vec::new();
    for c in &val.classes {
        let inputs: Vec<(usize, usize)> = (0..c.count)
            .flat_map(|n| views.iter().map(move |&v| (n, v)))
            .collect();
        all.extend(recon.ious(ctx, c, &inputs, eval::Voxelizer::default())?);
    }
    Ok(all.iter().sum::<f64>() / all.len().max(1) as f64)
}

/// The template with a reconstruction's positions and vertex colours.
pub fn colored_mesh(r: Reconstruction) -> Mesh {
    let mut mesh = super::train::template();
    mesh.positions = r.positions;
    mesh.vertex_colors = Some(r.colors);
    mesh
}

/// Renders of reconstructions: their vertex colours under the default light (the colour
/// generator samples the input's shaded colours; the light shows the shape even where it did
/// not), crisp.
pub fn view_settings(size: u32) -> RasterSettings {
    RasterSettings {
        width: size,
        height: size,
        sigma: 1e-5,
        gamma: 1e-4,
        color_mode: ColorMode::Vertex,
        ..RasterSettings::default()
    }
}

/// NMR-layout RGBA planes (`size²` each) as `big × big` pixels (nearest), values in [0, 1].
pub fn upscale(planes: &[u8], size: u32, big: u32) -> Vec<[f32; 4]> {
    let px = (size * size) as usize;
    (0..big * big)
        .map(|i| {
            let (x, y) = ((i % big) * size / big, (i / big) * size / big);
            let j = (y * size + x) as usize;
            [0, 1, 2, 3].map(|c| f32::from(planes[c * px + j]) / 255.0)
        })
        .collect()
}
