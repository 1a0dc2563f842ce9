//! The visual hull's boundary (CPU, once per fit), around which the sampler draws most anchors.
//!
//! The lattice is the V³ cell centres of the cube, `lo + (i + ½) · 2h / V` per axis. A lattice
//! point is inside the visual hull when, in every view, it lies in front of the camera and the
//! pixel nearest its projection is inside the silhouette (a pixel outside the image counts as
//! outside). The boundary points are the lattice points whose six neighbours do not all agree
//! with them (a neighbour beyond the lattice counts as outside): both sides of the hull's
//! surface, about one voxel thick.

use glam::DVec3;

use super::ProbeSettings;
use super::targets::Targets;

/// Inside-the-visual-hull flags of the V³ lattice of `settings`' cube, index `(z V + y) V + x`.
pub fn inside_lattice(targets: &Targets, settings: &ProbeSettings) -> Vec<bool> {
    let v = settings.hull_resolution as usize;
    let lo = settings.cube_min();
    let step = 2.0 * settings.cube_half / v as f64;
    let mut inside = vec![true; v * v * v];
    for (k, view) in targets.views.iter().enumerate() {
        for z in 0..v {
            for y in 0..v {
                for x in 0..v {
                    let i = (z * v + y) * v + x;
                    if !inside[i] {
                        continue;
                    }
                    let p = DVec3::new(
                        lo[0] + (x as f64 + 0.5) * step,
                        lo[1] + (y as f64 + 0.5) * step,
                        lo[2] + (z as f64 + 0.5) * step,
                    );
                    let [sx, sy, depth] = view.project(p);
                    let (col, row) = targets.screen_to_pixel(sx, sy);
                    inside[i] =
                        depth > 0.0 && view.denominator(p) > 0.0 && targets.inside(k, col, row);
                }
            }
        }
    }
    inside
}

/// The boundary lattice points of the visual hull, as `(x, y, z, 1)`, in lattice order. Empty
/// when the hull is empty or fills the whole lattice (the sampler then draws every anchor
/// uniformly).
pub fn boundary_points(targets: &Targets, settings: &ProbeSettings) -> Vec<[f32; 4]> {
    let v = settings.hull_resolution as usize;
    let inside = inside_lattice(targets, settings);
    let lo = settings.cube_min();
    let step = 2.0 * settings.cube_half / v as f64;
    let at = |x: isize, y: isize, z: isize| {
        let r = 0..v as isize;
        r.contains(&x)
            && r.contains(&y)
            && r.contains(&z)
            && inside[((z as usize) * v + y as usize) * v + x as usize]
    };
    let mut points = Vec::new();
    for z in 0..v as isize {
        for y in 0..v as isize {
            for x in 0..v as isize {
                let me = at(x, y, z);
                let neighbours = [
                    (x - 1, y, z),
                    (x + 1, y, z),
                    (x, y - 1, z),
                    (x, y + 1, z),
                    (x, y, z - 1),
                    (x, y, z + 1),
                ];
                if neighbours.iter().any(|&(a, b, c)| at(a, b, c) != me) {
                    points.push([
                        (lo[0] + (x as f64 + 0.5) * step) as f32,
                        (lo[1] + (y as f64 + 0.5) * step) as f32,
                        (lo[2] + (z as f64 + 0.5) * step) as f32,
                        1.0,
                    ]);
                }
            }
        }
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::probe::targets::sphere_silhouettes;

    #[test]
    fn the_boundary_of_a_sphere_s_hull_hugs_the_sphere() {
        let cameras = [
            Camera::from_angles(2.732, 0.0, 0.0),
            Camera::from_angles(2.732, 0.0, 90.0),
            Camera::from_angles(2.732, 60.0, 45.0),
        ];
        let radius = 0.5;
        let (w, h) = (64, 48);
        let targets = sphere_silhouettes(&cameras, w, h, radius).unwrap();
        let settings = ProbeSettings {
            hull_resolution: 32,
            ..ProbeSettings::default()
        };
        let points = boundary_points(&targets, &settings);
        assert!(points.len() > 500, "{}", points.len());
        let voxel = 2.0 / 32.0;
        let mut far = 0;
        for p in &points {
            let r = DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])).length();
            // Three views carve a hull a little larger than the sphere, never smaller.
            assert!(r > radius - 1.5 * voxel, "{p:?} at {r}");
            if r > radius + 0.25 {
                far += 1;
            }
        }
        assert!(far * 10 < points.len(), "{far} of {}", points.len());
        // Nothing inside an empty silhouette.
        let empty = Targets::new(&cameras, w, h, vec![0.0; 3 * (w * h) as usize]).unwrap();
        assert!(boundary_points(&empty, &settings).is_empty());
    }
}
