//! Skinned articulated meshes (non-rigid pose): hinge joints in a tree, forward
//! kinematics to one rigid transform per bone, and linear blend skinning (LBS), in f64 on the
//! host. These are the twins of the GPU kernels `kernels/fit/skin/*.comp` that
//! [`articulated`](super::articulated) fits with.
//!
//! # The model
//!
//! A [`Rig`] is a rest mesh, a list of hinge [`Joint`]s (each with a parent that comes before it,
//! or the unmoved root), and per vertex up to four [`SkinWeights`]. Joint `j` turns by its angle
//! θ_j about its axis a_j through its pivot o_j, both given in the rest pose and carried along by
//! the joint's parent. Bone 0 is the root (the identity); bone `j + 1` is moved by joint `j`:
//!
//! ```text
//! G_{j+1}(x) = G_parent(R(a_j, θ_j) (x − o_j) + o_j),     R(a, θ) = I + sin θ [a]× + (1 − cos θ) [a]×²
//! p'_v = Σ_i w_vi G_{k_vi}(p_v)                                            (linear blend skinning)
//! ```
//!
//! A joint with more than one degree of freedom (a shoulder) is two or three hinges at one
//! pivot, each the parent of the next.
//!
//! # The gradient
//!
//! Turning joint `j` by dθ moves a point x of every bone below it (its own included) by
//! ω_j × (x − c_j) dθ, where ω_j = M_parent a_j and c_j = G_parent(o_j) are the joint's posed
//! axis and pivot. With g_v = dL/dp'_v:
//!
//! ```text
//! dL/dθ_j = ω_j · Σ_v ( Σ_i [k_vi below j] w_vi (G_{k_vi}(p_v) − c_j) ) × g_v
//! ```
//!
//! [`Rig::angle_gradient`] is that sum in f64; tests check it against central differences of
//! [`Rig::skin`].

use glam::{DMat3, DVec3};

use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// The most joints a rig may have (the GPU gradient marks a bone's joints in 64 bits).
pub const MAX_JOINTS: usize = 64;

/// The joint index of [`SkinWeights`] that means "the unmoved root".
pub const ROOT: u32 = u32::MAX;

/// A hinge joint (see the [module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// A name for reports (`"l_elbow"`).
    pub name: String,
    /// The joint that carries this one (an index below this joint's), or `None` for the root.
    pub parent: Option<usize>,
    /// The point it turns about, in the rest pose.
    pub pivot: DVec3,
    /// The axis it turns about, in the rest pose (normalized when used; not zero).
    pub axis: DVec3,
}

/// Up to four joints that move a vertex, and their weights (≥ 0, summing to 1). An unused slot
/// has weight 0 (and still a valid joint, usually [`ROOT`]); [`ROOT`] names the unmoved root.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkinWeights {
    /// Joint indices, or [`ROOT`].
    pub joints: [u32; 4],
    /// Their weights.
    pub weights: [f32; 4],
}

impl SkinWeights {
    /// A vertex moved by one joint (or [`ROOT`]) alone.
    pub fn rigid(joint: u32) -> Self {
        Self {
            joints: [joint, ROOT, ROOT, ROOT],
            weights: [1.0, 0.0, 0.0, 0.0],
        }
    }

    /// The bone of slot `i` (0: the root, `j + 1`: joint `j`).
    pub fn bone(&self, i: usize) -> u32 {
        bone_of(self.joints[i])
    }
}

/// The bone a joint moves (0 for [`ROOT`]).
pub fn bone_of(joint: u32) -> u32 {
    if joint == ROOT { 0 } else { joint + 1 }
}

/// A rest mesh with hinge joints and skinning weights (see the [module docs](self)).
#[derive(Clone, Debug)]
pub struct Rig {
    /// The mesh in its rest pose (all angles 0), with its colours.
    pub mesh: Mesh,
    /// The joints, each after its parent.
    pub joints: Vec<Joint>,
    /// One per vertex of `mesh`.
    pub skin: Vec<SkinWeights>,
}

/// Every bone's transform `x ↦ linear x + offset` (bone 0 the root), and each joint's posed
/// axis and pivot, at some angles.
#[derive(Clone, Debug, PartialEq)]
pub struct Kinematics {
    /// Per bone.
    pub linear: Vec<DMat3>,
    /// Per bone.
    pub offset: Vec<DVec3>,
    /// Per joint: ω_j, the axis as the parent carries it.
    pub axis: Vec<DVec3>,
    /// Per joint: c_j, the pivot as the parent carries it.
    pub pivot: Vec<DVec3>,
}

impl Kinematics {
    /// Bone `k`'s transform of `x`.
    pub fn apply(&self, k: usize, x: DVec3) -> DVec3 {
        self.linear[k] * x + self.offset[k]
    }
}

/// R(a, θ) for a unit axis a (Rodrigues).
pub fn axis_rotation(axis: DVec3, theta: f64) -> DMat3 {
    let k = DMat3::from_cols(
        DVec3::new(0.0, axis.z, -axis.y),
        DVec3::new(-axis.z, 0.0, axis.x),
        DVec3::new(axis.y, -axis.x, 0.0),
    );
    DMat3::IDENTITY + k * theta.sin() + (k * k) * (1.0 - theta.cos())
}

impl Rig {
    /// Joints.
    pub fn joint_count(&self) -> usize {
        self.joints.len()
    }

    /// [`Error::Input`] for a rig that cannot be posed: no joints or more than [`MAX_JOINTS`], a
    /// parent not before its child, a non-finite pivot or a zero or non-finite axis, skinning
    /// weights that are not one per vertex, negative, not summing to 1 (within 1e-4) or naming a
    /// joint that does not exist; and the mesh's own checks.
    pub fn validate(&self) -> Result<()> {
        self.mesh.validate()?;
        let n = self.joints.len();
        if n == 0 || n > MAX_JOINTS {
            return Err(Error::Input(format!(
                "a rig needs 1 to {MAX_JOINTS} joints; this one has {n}"
            )));
        }
        for (j, joint) in self.joints.iter().enumerate() {
            if joint.parent.is_some_and(|p| p >= j) {
                return Err(Error::Input(format!(
                    "joint {j} ({}): its parent {:?} must come before it",
                    joint.name, joint.parent
                )));
            }
            let len = joint.axis.length();
            if !joint.pivot.is_finite() || !len.is_finite() || len < 1e-9 {
                return Err(Error::Input(format!(
                    "joint {j} ({}): pivot {} and axis {} must be finite, the axis not zero",
                    joint.name, joint.pivot, joint.axis
                )));
            }
        }
        if self.skin.len() != self.mesh.vertex_count() {
            return Err(Error::Input(format!(
                "a rig needs skinning weights for each of its {} vertices; it has {}",
                self.mesh.vertex_count(),
                self.skin.len()
            )));
        }
        for (v, s) in self.skin.iter().enumerate() {
            let sum: f32 = s.weights.iter().sum();
            let bad_weight = s.weights.iter().any(|w| !w.is_finite() || *w < 0.0);
            // Unused slots too: the GPU reads every slot's bone (times its weight).
            let bad_joint = s.joints.iter().any(|&j| j != ROOT && j as usize >= n);
            if bad_weight || bad_joint || (sum - 1.0).abs() > 1e-4 {
                return Err(Error::Input(format!(
                    "vertex {v}: skinning weights {:?} of joints {:?} must be ≥ 0, sum to 1 and \
                     name joints below {n} (or the root)",
                    s.weights, s.joints
                )));
            }
        }
        Ok(())
    }

    /// [`Error::Input`] unless `angles` holds one finite angle per joint.
    pub fn check_angles(&self, angles: &[f64]) -> Result<()> {
        if angles.len() != self.joints.len() || !angles.iter().all(|a| a.is_finite()) {
            return Err(Error::Input(format!(
                "the rig has {} joints; got {} angles {angles:?} (all must be finite)",
                self.joints.len(),
                angles.len()
            )));
        }
        Ok(())
    }

    /// Forward kinematics at `angles` (radians, one per joint).
    pub fn kinematics(&self, angles: &[f64]) -> Kinematics {
        let n = self.joints.len();
        let mut k = Kinematics {
            linear: Vec::with_capacity(n + 1),
            offset: Vec::with_capacity(n + 1),
            axis: Vec::with_capacity(n),
            pivot: Vec::with_capacity(n),
        };
        k.linear.push(DMat3::IDENTITY);
        k.offset.push(DVec3::ZERO);
        for (joint, &theta) in self.joints.iter().zip(angles) {
            let p = joint.parent.map_or(0, |p| p + 1);
            let (mp, bp) = (k.linear[p], k.offset[p]);
            let a = joint.axis.normalize();
            let r = axis_rotation(a, theta);
            k.linear.push(mp * r);
            k.offset.push(mp * (joint.pivot - r * joint.pivot) + bp);
            k.axis.push(mp * a);
            k.pivot.push(mp * joint.pivot + bp);
        }
        k
    }

    /// The rest positions in f64.
    pub fn rest(&self) -> Vec<DVec3> {
        self.mesh
            .positions
            .iter()
            .map(|p| DVec3::from(p.map(f64::from)))
            .collect()
    }

    /// The skinned positions at `angles` (linear blend skinning of [`Rig::kinematics`]).
    pub fn skin(&self, angles: &[f64]) -> Vec<DVec3> {
        let k = self.kinematics(angles);
        self.rest()
            .iter()
            .zip(&self.skin)
            .map(|(&p, s)| {
                (0..4)
                    .map(|i| f64::from(s.weights[i]) * k.apply(s.bone(i) as usize, p))
                    .sum()
            })
            .collect()
    }

    /// The mesh posed at `angles` (f32 positions; colours as at rest).
    pub fn posed_mesh(&self, angles: &[f64]) -> Mesh {
        Mesh {
            positions: self
                .skin(angles)
                .iter()
                .map(|p| p.as_vec3().to_array())
                .collect(),
            ..self.mesh.clone()
        }
    }

    /// Per bone, the bits of the joints that move it (itself and its ancestors): joint `j` is
    /// bit `j % 32` of word `j / 32`.
    pub fn below_masks(&self) -> Vec<[u32; 2]> {
        let mut masks = vec![[0u32; 2]; self.joints.len() + 1];
        for (j, joint) in self.joints.iter().enumerate() {
            let mut m = joint.parent.map_or([0; 2], |p| masks[p + 1]);
            m[j / 32] |= 1 << (j % 32);
            masks[j + 1] = m;
        }
        masks
    }

    /// dL/dθ from dL/dp' per vertex (see the [module docs](self)).
    pub fn angle_gradient(&self, angles: &[f64], d_posed: &[[f64; 3]]) -> Vec<f64> {
        let k = self.kinematics(angles);
        let masks = self.below_masks();
        let rest = self.rest();
        (0..self.joints.len())
            .map(|j| {
                let c = k.pivot[j];
                let torque: DVec3 = rest
                    .iter()
                    .zip(&self.skin)
                    .zip(d_posed)
                    .map(|((&p, s), g)| {
                        let moved: DVec3 = (0..4)
                            .filter(|&i| masks[s.bone(i) as usize][j / 32] & (1 << (j % 32)) != 0)
                            .map(|i| f64::from(s.weights[i]) * (k.apply(s.bone(i) as usize, p) - c))
                            .sum();
                        moved.cross(DVec3::from(*g))
                    })
                    .sum();
                k.axis[j].dot(torque)
            })
            .collect()
    }

    /// The built-in figure: a torso with a head, two arms and two legs of two segments each,
    /// in the plane z = 0 facing −z (SoftRas's default camera), arms out and legs spread 20° from
    /// the vertical at rest.
    /// Nine hinges, each about z (in the image plane of a camera on the z axis, where a
    /// silhouette pins its angle down): neck, shoulders, elbows, hips, knees. Each limb is an
    /// octagonal tube of 8 rings, skinned across its joints over a blend zone a little wider
    /// than the limb; each body part has its own colour.
    pub fn figure() -> Rig {
        figure::build()
    }
}

/// The procedural figure of [`Rig::figure`].
mod figure {
    use glam::DVec3;

    use super::{Joint, ROOT, Rig, SkinWeights};
    use crate::mesh::Mesh;

    /// Sides of a limb's cross-section, and rings along it.
    const SIDES: usize = 8;
    const RINGS: usize = 8;

    /// Where a limb meets its neighbour: the pivot, the joint on the far side (towards the
    /// limb's end) and the near side, and the half-width of the blend.
    struct Blend {
        pivot: DVec3,
        along: DVec3,
        near: u32,
        far: u32,
        half: f64,
    }

    impl Blend {
        /// The far joint's weight at `x`: 0 → 1 across [−half, half] along the limb.
        fn far_weight(&self, x: DVec3) -> f64 {
            (0.5 + (x - self.pivot).dot(self.along) / (2.0 * self.half)).clamp(0.0, 1.0)
        }
    }

    #[derive(Default)]
    struct Builder {
        positions: Vec<[f32; 3]>,
        faces: Vec<[u32; 3]>,
        face_colors: Vec<[f32; 3]>,
        vertex_colors: Vec<[f32; 3]>,
        skin: Vec<SkinWeights>,
    }

    impl Builder {
        /// A closed tube from `a` to `b` (in the plane z = 0), half-width `w` in the plane and
        /// half-depth `h` along z, extended by `extend` past both ends (to close the gaps at
        /// joints), owned by `joint` and blended across `blends`.
        #[allow(clippy::too_many_arguments)]
        fn limb(
            &mut self,
            a: DVec3,
            b: DVec3,
            w: f64,
            h: f64,
            extend: f64,
            joint: u32,
            blends: &[Blend],
            color: [f32; 3],
        ) {
            let along = (b - a).normalize();
            let side = DVec3::new(-along.y, along.x, 0.0);
            let (start, end) = (a - along * extend, b + along * extend);
            let base = self.positions.len() as u32;
            let add = |this: &mut Self, x: DVec3| {
                this.positions.push(x.as_vec3().to_array());
                this.vertex_colors.push(color);
                this.skin.push(weights(x, joint, blends));
            };
            for r in 0..RINGS {
                let c = start.lerp(end, r as f64 / (RINGS - 1) as f64);
                for s in 0..SIDES {
                    let phi = std::f64::consts::TAU * (s as f64 + 0.5) / SIDES as f64;
                    add(
                        self,
                        c + side * (w * phi.cos()) + DVec3::Z * (h * phi.sin()),
                    );
                }
            }
            let (cap0, cap1) = (
                base + (RINGS * SIDES) as u32,
                base + (RINGS * SIDES) as u32 + 1,
            );
            add(self, start);
            add(self, end);
            let at = |r: usize, s: usize| base + (r * SIDES + s % SIDES) as u32;
            let mut tris = Vec::new();
            for r in 0..RINGS - 1 {
                for s in 0..SIDES {
                    tris.push([at(r, s), at(r + 1, s), at(r + 1, s + 1)]);
                    tris.push([at(r, s), at(r + 1, s + 1), at(r, s + 1)]);
                }
            }
            for s in 0..SIDES {
                tris.push([cap0, at(0, s + 1), at(0, s)]);
                tris.push([cap1, at(RINGS - 1, s), at(RINGS - 1, s + 1)]);
            }
            // Outward: SPEC §1's normal cross(v2 − v1, v0 − v1) points away from the axis.
            for mut t in tris {
                let p = t.map(|i| DVec3::from(self.positions[i as usize].map(f64::from)));
                let n = (p[2] - p[1]).cross(p[0] - p[1]);
                let centre = (p[0] + p[1] + p[2]) / 3.0;
                let s = (centre - start)
                    .dot(along)
                    .clamp(0.0, (end - start).length());
                if n.dot(centre - (start + along * s)) < 0.0 {
                    t.swap(0, 2);
                }
                self.faces.push(t);
                self.face_colors.push(color);
            }
        }

        fn finish(self, joints: Vec<Joint>) -> Rig {
            Rig {
                mesh: Mesh {
                    positions: self.positions,
                    faces: self.faces,
                    texture_res: 1,
                    textures: self.face_colors,
                    vertex_colors: Some(self.vertex_colors),
                },
                joints,
                skin: self.skin,
            }
        }
    }

    /// A vertex of `joint`'s limb at `x`: its joint's, blended with a neighbour's near a pivot.
    fn weights(x: DVec3, joint: u32, blends: &[Blend]) -> SkinWeights {
        for b in blends {
            let t = b.far_weight(x);
            if t > 0.0 && t < 1.0 {
                return SkinWeights {
                    joints: [b.far, b.near, ROOT, ROOT],
                    weights: [t as f32, 1.0 - t as f32, 0.0, 0.0],
                };
            }
            let owner = if t >= 1.0 { b.far } else { b.near };
            if owner != joint {
                return SkinWeights::rigid(owner);
            }
        }
        SkinWeights::rigid(joint)
    }

    pub(super) fn build() -> Rig {
        let v = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        let mut joints = Vec::new();
        let mut joint = |name: &str, parent: Option<usize>, pivot: DVec3| {
            joints.push(Joint {
                name: name.into(),
                parent,
                pivot,
                axis: DVec3::Z,
            });
            joints.len() - 1
        };
        let neck = joint("neck", None, v(0.0, 0.50));
        let mut limbs = Vec::new(); // (joint, from, to, half-width, colour, parent joint)
        let l_shoulder = joint("l_shoulder", None, v(0.24, 0.40));
        let l_elbow = joint("l_elbow", Some(l_shoulder), v(0.62, 0.40));
        let r_shoulder = joint("r_shoulder", None, v(-0.24, 0.40));
        let r_elbow = joint("r_elbow", Some(r_shoulder), v(-0.62, 0.40));
        // Legs spread 20° from the vertical, so that turns of ±20° at the hips never cross them.
        let (sin, cos) = 20f64.to_radians().sin_cos();
        let (hip, thigh, shin) = (v(0.14, -0.42), 0.42, 0.40);
        let leg_at = |side: f64, length: f64| v(side * sin * length, -cos * length);
        let l_knee_at = hip + leg_at(1.0, thigh);
        let r_hip_at = v(-hip.x, hip.y);
        let r_knee_at = r_hip_at + leg_at(-1.0, thigh);
        let l_hip = joint("l_hip", None, hip);
        let l_knee = joint("l_knee", Some(l_hip), l_knee_at);
        let r_hip = joint("r_hip", None, r_hip_at);
        let r_knee = joint("r_knee", Some(r_hip), r_knee_at);
        let arm = 0.085;
        let leg = 0.1;
        limbs.push((
            l_shoulder,
            v(0.24, 0.40),
            v(0.62, 0.40),
            arm,
            [0.85, 0.25, 0.2],
        ));
        limbs.push((
            l_elbow,
            v(0.62, 0.40),
            v(0.98, 0.40),
            0.8 * arm,
            [0.95, 0.55, 0.3],
        ));
        limbs.push((
            r_shoulder,
            v(-0.24, 0.40),
            v(-0.62, 0.40),
            arm,
            [0.2, 0.6, 0.3],
        ));
        limbs.push((
            r_elbow,
            v(-0.62, 0.40),
            v(-0.98, 0.40),
            0.8 * arm,
            [0.45, 0.85, 0.4],
        ));
        limbs.push((l_hip, hip, l_knee_at, leg, [0.2, 0.3, 0.85]));
        let l_foot = l_knee_at + leg_at(1.0, shin);
        limbs.push((l_knee, l_knee_at, l_foot, 0.8 * leg, [0.4, 0.6, 0.95]));
        limbs.push((r_hip, r_hip_at, r_knee_at, leg, [0.85, 0.75, 0.2]));
        let r_foot = r_knee_at + leg_at(-1.0, shin);
        limbs.push((r_knee, r_knee_at, r_foot, 0.8 * leg, [0.95, 0.9, 0.5]));
        let mut b = Builder::default();
        // The torso (unmoved) and the head on its neck.
        b.limb(
            v(0.0, -0.48),
            v(0.0, 0.50),
            0.2,
            0.11,
            0.0,
            ROOT,
            &[],
            [0.55, 0.55, 0.7],
        );
        let blend = |pivot: DVec3, along: DVec3, near: u32, far: u32, half: f64| Blend {
            pivot,
            along: along.normalize(),
            near,
            far,
            half,
        };
        let neck_blend = blend(v(0.0, 0.50), DVec3::Y, ROOT, neck as u32, 0.05);
        b.limb(
            v(0.0, 0.50),
            v(0.0, 0.80),
            0.12,
            0.11,
            0.04,
            neck as u32,
            &[neck_blend],
            [0.95, 0.8, 0.65],
        );
        for &(j, from, to, w, color) in &limbs {
            let parent = joints[j].parent.map_or(ROOT, |p| p as u32);
            let child = limbs
                .iter()
                .find(|l| joints[l.0].parent == Some(j))
                .map(|l| l.0 as u32);
            let along = to - from;
            let mut blends = vec![blend(from, along, parent, j as u32, 1.2 * w)];
            if let Some(c) = child {
                blends.push(blend(to, along, j as u32, c, w));
            }
            // A limb that hangs off the torso starts inside it.
            let extend = if parent == ROOT { 0.06 } else { 0.5 * w };
            b.limb(from, to, w, 0.8 * w, extend, j as u32, &blends, color);
        }
        b.finish(joints)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::{Lcg, assert_grad_matches_fd};

    fn random_angles(rng: &mut Lcg, n: usize, scale: f64) -> Vec<f64> {
        (0..n).map(|_| rng.range(-scale, scale)).collect()
    }

    /// Three joints in a chain with tilted axes and two on the root, over a jittered blob whose
    /// vertices blend up to four joints.
    fn tangled_rig() -> Rig {
        let mut rng = Lcg(17);
        let mut mesh = Mesh::icosphere(1);
        for p in &mut mesh.positions {
            *p = p.map(|c| c * 0.8 + rng.range(-0.05, 0.05) as f32);
        }
        let j = |name: &str, parent, pivot: [f64; 3], axis: [f64; 3]| Joint {
            name: name.into(),
            parent,
            pivot: DVec3::from(pivot),
            axis: DVec3::from(axis),
        };
        let joints = vec![
            j("a", None, [0.1, 0.2, 0.0], [0.0, 0.0, 1.0]),
            j("b", Some(0), [0.4, -0.1, 0.2], [1.0, 0.5, 0.0]),
            j("c", Some(1), [-0.3, 0.3, 0.1], [0.2, 1.0, -0.3]),
            j("d", None, [0.0, -0.4, -0.2], [0.0, 1.0, 1.0]),
        ];
        let skin = (0..mesh.vertex_count())
            .map(|_| {
                let w: [f64; 4] = std::array::from_fn(|_| rng.range(0.0, 1.0));
                let sum: f64 = w.iter().sum();
                let mut joints = [0, 1, 2, 3];
                if rng.unit() < 0.3 {
                    joints[3] = ROOT;
                }
                SkinWeights {
                    joints,
                    weights: w.map(|x| (x / sum) as f32),
                }
            })
            .map(|mut s| {
                // Exactly 1 in f32.
                s.weights[3] = 1.0 - s.weights[0] - s.weights[1] - s.weights[2];
                s
            })
            .collect();
        Rig { mesh, joints, skin }
    }

    #[test]
    fn zero_angles_leave_the_rest_pose() {
        for rig in [tangled_rig(), Rig::figure()] {
            rig.validate().unwrap();
            let rest = rig.rest();
            let posed = rig.skin(&vec![0.0; rig.joint_count()]);
            for (a, b) in rest.iter().zip(&posed) {
                assert!(a.abs_diff_eq(*b, 1e-6), "{a} vs {b}");
            }
        }
    }

    #[test]
    fn a_joint_turns_its_bones_rigidly_about_its_pivot() {
        // The figure's left elbow alone: the forearm's rigid vertices turn about the elbow, the
        // upper arm's stay, and a child follows its parent.
        let rig = Rig::figure();
        let elbow = rig.joints.iter().position(|j| j.name == "l_elbow").unwrap();
        let shoulder = rig.joints[elbow].parent.unwrap();
        let mut angles = vec![0.0; rig.joint_count()];
        angles[elbow] = 0.7;
        let posed = rig.skin(&angles);
        let rest = rig.rest();
        let r = axis_rotation(DVec3::Z, 0.7);
        let o = rig.joints[elbow].pivot;
        let (mut moved, mut still) = (0, 0);
        for ((p, q), s) in rest.iter().zip(&posed).zip(&rig.skin) {
            if *s == SkinWeights::rigid(elbow as u32) {
                assert!(q.abs_diff_eq(r * (*p - o) + o, 1e-12));
                moved += 1;
            } else if *s == SkinWeights::rigid(shoulder as u32) {
                assert!(q.abs_diff_eq(*p, 1e-12));
                still += 1;
            }
        }
        assert!(moved > 20 && still > 10, "{moved} {still}");
        // Shoulder and elbow together: the forearm turns by the sum about the carried pivot.
        angles[shoulder] = -0.3;
        let k = rig.kinematics(&angles);
        let c = axis_rotation(DVec3::Z, -0.3) * (o - rig.joints[shoulder].pivot)
            + rig.joints[shoulder].pivot;
        assert!(k.pivot[elbow].abs_diff_eq(c, 1e-12));
        assert!(k.linear[elbow + 1].abs_diff_eq(axis_rotation(DVec3::Z, 0.4), 1e-12));
    }

    #[test]
    fn angle_gradient_is_the_gradient_of_a_linear_function_of_the_skinned_points() {
        let rig = tangled_rig();
        let mut rng = Lcg(23);
        let a: Vec<[f64; 3]> = (0..rig.mesh.vertex_count())
            .map(|_| std::array::from_fn(|_| rng.range(-1.0, 1.0)))
            .collect();
        for scale in [1e-6, 0.8, 2.5] {
            let angles = random_angles(&mut rng, rig.joint_count(), scale);
            let analytic = rig.angle_gradient(&angles, &a);
            assert_grad_matches_fd(&angles, &analytic, 1e-8, |x| {
                rig.skin(x)
                    .iter()
                    .zip(&a)
                    .map(|(p, g)| p.dot(DVec3::from(*g)))
                    .sum()
            });
        }
    }

    #[test]
    fn the_figure_is_closed_outward_and_skinned_at_its_joints() {
        let rig = Rig::figure();
        assert_eq!(rig.joint_count(), 9);
        // Every face's normal points away from the centre line of its limb: the signed volume
        // of each closed tube is positive, so the whole mesh's is the sum of eleven.
        let p = rig.rest();
        let volume: f64 = rig
            .mesh
            .faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| p[i as usize]);
                // SPEC §1's normal cross(c − b, a − b) is cross(b − a, c − a): outward faces
                // give a positive a · (b × c) / 6 summed over a closed surface.
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        assert!(volume > 0.1, "{volume}");
        let blended = rig.skin.iter().filter(|s| s.weights[1] > 0.0).count();
        assert!(blended > 50, "{blended}");
        // The figure fits SoftRas's default view (|x|, |y| < 1.5 at z = 0).
        assert!(p.iter().all(|q| q.x.abs() < 1.2 && q.y.abs() < 1.4));
    }

    #[test]
    fn bad_rigs_are_refused() {
        let good = Rig::figure();
        let mut r = good.clone();
        r.joints[2].parent = Some(5);
        assert!(r.validate().is_err());
        let mut r = good.clone();
        r.joints[0].axis = DVec3::ZERO;
        assert!(r.validate().is_err());
        let mut r = good.clone();
        r.skin[3].weights = [0.7, 0.0, 0.0, 0.0];
        assert!(r.validate().is_err());
        let mut r = good.clone();
        r.skin[3].joints[0] = 9;
        assert!(r.validate().is_err());
        let mut r = good.clone();
        r.skin[3].joints[3] = 9; // an unused slot (weight 0) must name a joint too
        assert!(r.validate().is_err());
        let mut r = good.clone();
        r.skin.pop();
        assert!(r.validate().is_err());
        let mut r = good.clone();
        r.joints.clear();
        assert!(r.validate().is_err());
        assert!(good.check_angles(&[0.0; 8]).is_err());
        assert!(good.check_angles(&[f64::NAN; 9]).is_err());
        good.check_angles(&[0.1; 9]).unwrap();
    }
}
