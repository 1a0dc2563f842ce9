//! Tests of the antialias twin: the shared scene builders (a brute-force rasterizer, octahedra,
//! a ranged two-layer scene) here; the forward's and the backward's tests in the two children.
use super::*;

/// splitmix64: a seeded, dependency-free source of test data.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    fn values(&mut self, n: usize, lo: f64, hi: f64) -> Vec<f64> {
        (0..n).map(|_| lo + (hi - lo) * self.uniform()).collect()
    }
}

/// A brute-force f64 rasterizer of one image, computing coverage and `(u, v, z/w)` as
/// nvdiffrast's pixel shader does: homogeneous 2D edge functions at the pixel centre,
/// inside when all three have the sign of their sum, nearest `z/w` in [−1, 1] wins. `pos`
/// holds the image's vertices; ids written are `t + 1` for the global index `t`.
fn rasterize_image(
    pos: &[f64],
    tri: &[[u32; 3]],
    triangles: std::ops::Range<usize>,
    width: usize,
    height: usize,
) -> Vec<f64> {
    let mut rast = vec![0.0; width * height * 4];
    for y in 0..height {
        for x in 0..width {
            let fx = (2 * x + 1) as f64 / width as f64 - 1.0;
            let fy = (2 * y + 1) as f64 / height as f64 - 1.0;
            let mut best: Option<(f64, [f64; 4])> = None;
            for t in triangles.clone() {
                let v = tri[t].map(|i| {
                    let i = 4 * i as usize;
                    [pos[i], pos[i + 1], pos[i + 2], pos[i + 3]]
                });
                let p = v.map(|c| [c[0] - fx * c[3], c[1] - fy * c[3]]);
                let a = [
                    p[1][0] * p[2][1] - p[1][1] * p[2][0],
                    p[2][0] * p[0][1] - p[2][1] * p[0][0],
                    p[0][0] * p[1][1] - p[0][1] * p[1][0],
                ];
                let sum = a[0] + a[1] + a[2];
                if sum == 0.0 || a.iter().any(|&ak| ak * sum < 0.0) {
                    continue;
                }
                let zw = (0..3).map(|k| v[k][2] * a[k]).sum::<f64>()
                    / (0..3).map(|k| v[k][3] * a[k]).sum::<f64>();
                if !(-1.0..=1.0).contains(&zw) {
                    continue;
                }
                if best.is_none_or(|(z, _)| zw < z) {
                    best = Some((zw, [a[0] / sum, a[1] / sum, zw, (t + 1) as f64]));
                }
            }
            if let Some((_, r)) = best {
                rast[4 * (y * width + x)..4 * (y * width + x) + 4].copy_from_slice(&r);
            }
        }
    }
    rast
}

/// Everything one antialias call reads, owned.
struct Scene {
    pos: Vec<f64>,
    layout: PosLayout,
    tri: Vec<[u32; 3]>,
    rast: Vec<f64>,
    color: Vec<f64>,
    shape: ImageShape,
}

impl Scene {
    fn input(&self) -> AntialiasInput<'_> {
        self.input_with(&self.pos)
    }

    fn input_with<'a>(&'a self, pos: &'a [f64]) -> AntialiasInput<'a> {
        AntialiasInput {
            color: &self.color,
            rast: &self.rast,
            pos,
            pos_layout: self.layout,
            tri: &self.tri,
            shape: self.shape,
        }
    }
}

/// One image over `clip` (flattened `[V, 4]`), rasterized by [`rasterize_image`].
fn single_image(
    clip: Vec<f64>,
    tri: Vec<[u32; 3]>,
    width: usize,
    height: usize,
    channels: usize,
) -> Scene {
    let rast = rasterize_image(&clip, &tri, 0..tri.len(), width, height);
    let shape = ImageShape {
        batch: 1,
        height,
        width,
        channels,
    };
    Scene {
        layout: PosLayout::Range {
            vertices: clip.len() / 4,
        },
        pos: clip,
        tri,
        rast,
        color: vec![0.0; shape.pixel_count() * channels],
        shape,
    }
}

/// A regular octahedron of radius 1: vertices ±x, ±y, ±z, eight faces.
fn octahedron() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let v = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let t = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    (v, t)
}

/// Rotates `p` by `yaw` about y then `pitch` about x, puts it `dist` in front of a camera
/// at the origin looking down −z, and projects with focal length 2.2 (OpenGL depth for
/// near 1, far 10).
fn project(p: [f64; 3], yaw: f64, pitch: f64, dist: f64) -> [f64; 4] {
    let (sy, cy) = yaw.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let x1 = cy * p[0] + sy * p[2];
    let z1 = -sy * p[0] + cy * p[2];
    let y2 = cp * p[1] - sp * z1;
    let z2 = sp * p[1] + cp * z1 - dist;
    let (near, far, focal) = (1.0, 10.0, 2.2);
    [
        focal * x1,
        focal * y2,
        (far + near) / (near - far) * z2 + 2.0 * far * near / (near - far),
        -z2,
    ]
}

/// Flattened clip positions of `verts` in one pose.
fn posed(verts: &[[f64; 3]], yaw: f64, pitch: f64) -> Vec<f64> {
    verts
        .iter()
        .flat_map(|&p| project(p, yaw, pitch, 3.5))
        .collect()
}

/// The octahedron in one pose per minibatch item (instanced), random colours.
fn instanced_octahedra(poses: &[(f64, f64)], size: usize, channels: usize, rng: &mut Rng) -> Scene {
    let (verts, tri) = octahedron();
    let mut pos = Vec::new();
    let mut rast = Vec::new();
    for &(yaw, pitch) in poses {
        let clip = posed(&verts, yaw, pitch);
        rast.extend(rasterize_image(&clip, &tri, 0..tri.len(), size, size));
        pos.extend(clip);
    }
    let shape = ImageShape {
        batch: poses.len(),
        height: size,
        width: size,
        channels,
    };
    Scene {
        pos,
        layout: PosLayout::Instanced {
            vertices: verts.len(),
        },
        tri,
        rast,
        color: rng.values(shape.pixel_count() * channels, 0.0, 1.0),
        shape,
    }
}

/// Range mode, two images over one `pos`: image 0 draws the octahedron (triangles 0..8),
/// image 1 a small triangle in front of a big one (8..10), with varied w (perspective).
fn ranged_scene(size: usize, channels: usize, rng: &mut Rng) -> Scene {
    let (verts, mut tri) = octahedron();
    let mut pos = posed(&verts, 0.45, -0.3);
    // (NDC x, NDC y, z/w, w): back triangle at z/w 0.5, front one at −0.2.
    let layers = [
        [-0.9, -0.8, 0.5, 1.0],
        [0.85, -0.7, 0.5, 1.3],
        [0.1, 0.9, 0.5, 1.6],
        [-0.5, -0.3, -0.2, 1.2],
        [0.6, -0.1, -0.2, 0.9],
        [-0.1, 0.6, -0.2, 1.5],
    ];
    for [x, y, z, w] in layers {
        pos.extend([x * w, y * w, z * w, w]);
    }
    tri.push([6, 7, 8]);
    tri.push([9, 10, 11]);
    let mut rast = rasterize_image(&pos, &tri, 0..8, size, size);
    rast.extend(rasterize_image(&pos, &tri, 8..10, size, size));
    let shape = ImageShape {
        batch: 2,
        height: size,
        width: size,
        channels,
    };
    Scene {
        layout: PosLayout::Range {
            vertices: pos.len() / 4,
        },
        pos,
        tri,
        rast,
        color: rng.values(shape.pixel_count() * channels, 0.0, 1.0),
        shape,
    }
}

/// `Σ dy · antialias(input)`.
fn loss(input: &AntialiasInput, dy: &[f64]) -> f64 {
    let out = antialias(input, None).unwrap();
    out.iter().zip(dy).map(|(o, d)| o * d).sum()
}

/// The forward's discrete decisions, with α reduced to what changes the blend's formula:
/// its sign, whether it saturates, whether it is the +0 no-op.
fn decisions(input: &AntialiasInput) -> Vec<EdgePair> {
    find_edge_pairs(input, None)
        .unwrap()
        .into_iter()
        .map(|p| {
            let class = if p.alpha.to_bits() == 0 {
                0.0
            } else if p.alpha.abs() >= 0.5 {
                2.0
            } else {
                1.0
            };
            EdgePair {
                alpha: class * p.alpha.signum(),
                ..p
            }
        })
        .collect()
}

fn id(scene: &Scene, pixel: usize) -> f64 {
    scene.rast[4 * pixel + 3]
}

mod backward;
mod forward;
