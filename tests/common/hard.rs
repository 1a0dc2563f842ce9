//! Scenes for the tests of nvdiffrast's primitives (`tests/hard_raster.rs`,
//! `tests/hard_antialias.rs`, `tests/hard_texture.rs`).

use glam::{Mat4, Vec3, Vec4};
use rand::RngExt;
use softvk::mesh::Mesh;

/// FNV-1a over the bytes of `data`: a hash that the tests, not the standard library, define.
pub fn fnv1a(data: &[f32]) -> u64 {
    bytemuck::cast_slice::<f32, u8>(data)
        .iter()
        .fold(0xcbf29ce484222325u64, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x100000001b3)
        })
}

/// f64 copies of f32 values (the twins' inputs).
pub fn wide(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

/// Random triangles in clip space: most in front and in view, some through the near plane,
/// behind the eye, past the far plane or far outside the viewport.
pub fn random_scene(seed: u64, vertices: usize, triangles: usize) -> (Vec<f32>, Vec<[u32; 3]>) {
    let mut rng = super::rng(seed);
    let mut pos = Vec::with_capacity(4 * vertices);
    for i in 0..vertices {
        let w: f32 = if i % 17 == 5 {
            rng.random_range(-0.8..-0.1)
        } else {
            rng.random_range(0.5..2.0)
        };
        let spread = if i % 13 == 7 { 4.0 } else { 1.1 };
        let x = rng.random_range(-spread..spread) * w.abs();
        let y = rng.random_range(-spread..spread) * w.abs();
        let z = rng.random_range(-1.2..1.2) * w.abs();
        pos.extend([x, y, z, w]);
    }
    let tri = (0..triangles)
        .map(|_| {
            let a = rng.random_range(0..vertices as u32);
            let b = rng.random_range(0..vertices as u32);
            let c = rng.random_range(0..vertices as u32);
            [a, b, c]
        })
        .collect();
    (pos, tri)
}

/// Clip-space positions of `mesh` seen from `eye` towards the origin (OpenGL perspective, 40°
/// vertical field of view, near 0.5, far 10), as nvdiffrast's samples build them.
pub fn clip(mesh: &Mesh, eye: Vec3, aspect: f32) -> Vec<f32> {
    let f = (-eye).normalize();
    let up = if f.y.abs() > 0.99 { Vec3::X } else { Vec3::Y };
    let s = f.cross(up).normalize();
    let u = s.cross(f);
    let view = Mat4::from_cols(
        Vec4::new(s.x, u.x, -f.x, 0.0),
        Vec4::new(s.y, u.y, -f.y, 0.0),
        Vec4::new(s.z, u.z, -f.z, 0.0),
        Vec4::new(-s.dot(eye), -u.dot(eye), f.dot(eye), 1.0),
    );
    let (near, far) = (0.5f32, 10.0f32);
    let g = 1.0 / (20f32.to_radians()).tan();
    let proj = Mat4::from_cols(
        Vec4::new(g / aspect, 0.0, 0.0, 0.0),
        Vec4::new(0.0, g, 0.0, 0.0),
        Vec4::new(0.0, 0.0, (far + near) / (near - far), -1.0),
        Vec4::new(0.0, 0.0, 2.0 * far * near / (near - far), 0.0),
    );
    let m = proj * view;
    mesh.positions
        .iter()
        .flat_map(|p| (m * Vec4::new(p[0], p[1], p[2], 1.0)).to_array())
        .collect()
}
