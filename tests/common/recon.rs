//! Training data shared by the reconstruction tests.

use softvk::camera::Camera;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::recon::train::{TrainImages, VIEWS};
use softvk::recon::view_camera;

/// Two classes of one object each, every view rendered by softvk at `size`²: a box and a flat
/// slab, so that the two differ from every side.
pub fn two_objects(ctx: &softvk::gpu::Context, size: u32) -> TrainImages {
    let renderer = Renderer::new(ctx).unwrap();
    let settings = RasterSettings {
        width: size,
        height: size,
        sigma: 1e-5,
        ..RasterSettings::default()
    };
    let cams: Vec<Camera> = (0..VIEWS as usize).map(view_camera).collect();
    let mut images = Vec::new();
    for mesh in [
        Mesh::cuboid([0.3, 0.2, 0.25]),
        Mesh::cuboid([0.4, 0.08, 0.3]),
    ] {
        let frames = renderer
            .render_views(
                ctx,
                &mesh,
                &cams,
                &Lighting::default(),
                &settings,
                Method::default(),
            )
            .unwrap();
        let px = (size * size) as usize;
        for v in 0..VIEWS as usize {
            let img = frames.image(v);
            for c in 0..4 {
                images.extend(
                    img[..px]
                        .iter()
                        .map(|p| (p[c].clamp(0.0, 1.0) * 255.0).round() as u8),
                );
            }
        }
    }
    TrainImages {
        images,
        classes: vec![("box".into(), 0..1), ("slab".into(), 1..2)],
        size,
    }
}
