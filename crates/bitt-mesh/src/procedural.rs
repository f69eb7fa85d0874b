//! The project's own license-free hand model, generated procedurally.
//!
//! [`procedural_hand`] builds a [`HandModel`] that the forward pass uses exactly like MANO: same
//! 16-joint kinematic tree and joint order, same array layouts, same frame and scale (metres;
//! for the right hand `-x` runs from the wrist to the fingertips, `+y` out of the back of the
//! hand, `+z` towards the thumb, the wrist joint sits near MANO's at about `(0.096, 0.006,
//! 0.006)`). It is not a copy of MANO: everything is derived from a handful of anatomical
//! measurements in [`ProceduralHandConfig`].
//!
//! # Surface
//!
//! One closed, consistently oriented 2-manifold (genus 0), triangles counter-clockwise seen from
//! outside, built from generalized cylinders (rings of vertices lofted along a path):
//!
//! - the **palm** is lofted from a domed cap closing the wrist to the finger webs, through rings
//!   made of four side-by-side *lobes* (rounded boxes, one per finger) with knuckle bumps; at the
//!   webs each lobe has become its finger's round cross-section, and the lobes share the vertices
//!   where they touch, so the last palm ring is the four finger rings fused together;
//! - each **finger** continues from its part of that ring (a *crotch* vertex in each web closes
//!   the gap between two fingers) with rings along its three phalanges, dorsal knuckle bumps and
//!   palmar pads, a flattened, slightly raised nail plate on the distal phalanx, and a rounded
//!   cap whose pole is the fingertip vertex;
//! - the **thumb** is lofted out of a rectangular opening in the palm's radial-palmar corner:
//!   the loft leaves the palm tangentially and swells into the thumb's round cross-section near
//!   its MCP (the thenar eminence and the first web space), then the thumb continues like a
//!   finger, turned so that its nail faces sideways and its pad faces the fingers.
//!
//! With the default configuration the mesh has 4,181 vertices and 8,358 triangles (4,560 UV
//! vertices).
//!
//! # UV layout
//!
//! Every tube (palm, four fingers, thumb) is cut along two seams (its sides) into a palm-side
//! and a back-side half, and each half is unrolled into its own chart (`u`: arc length around
//! the ring, `v`: distance along the tube). All palm-side charts sit in the left half of the
//! texture and all back-side charts in the right half, each laid out like a hand print seen
//! from that side with the fingers up (`v = 0` is the bottom of the image): the thumb at the
//! bottom, the palm above it, the fingers on top. Charts never overlap, UV triangles keep the
//! mesh's counter-clockwise orientation (for the right hand), and one scale is shared by all
//! charts.
//!
//! # Rig
//!
//! - **Skinning weights:** a vertex on a phalanx moves with the joint at the phalanx's proximal
//!   end (MANO's convention), the palm with the wrist; across each joint the weight ramps
//!   linearly over a band about 1-1.5 times the digit's radius on either side, which keeps the
//!   inside of even a right-angle bend from folding over. Near a web, a finger's weights blend
//!   half-way into its neighbour's; the palm around the thumb opening follows the thumb's CMC
//!   partly, and the thumb's loft blends from there to the thumb. No triangle turns inside out
//!   in a tight fist, with or without shape coefficients of +-2.
//! - **Joint regressor:** each joint is a convex combination of the vertices of the three rings
//!   around it, solved so that it reproduces the designed joint exactly on the template.
//! - **Shape blend shapes** (one unit is a few per cent): 0 overall scale about the wrist,
//!   1 finger length, 2 palm width, 3 finger and thumb thickness, 4 palm thickness, 5 thumb
//!   length, 6 finger taper, 7 palm length, 8 finger and thumb splay, 9 radial-versus-ulnar
//!   finger length (longer index, shorter pinky).
//! - **Pose blend shapes:** the back of each knuckle bulges out by up to about 2 mm (MCP) as the
//!   joint bends, proportional to `1 - cos(angle)`, which the pose features express exactly
//!   through the diagonal of `R - I`. All other features have zero blend shapes.
//! - **Pose PCA:** identity components and a relaxed mean pose (every finger joint slightly
//!   flexed about its own flexion axis, the pinky most), so that zero PCA coefficients give a
//!   relaxed hand as with MANO's `hands_mean`.
//!
//! # Left hand
//!
//! The left hand is the exact mirror image of the right, as MANO's are: `x` negated, every
//! triangle's last two corners swapped (in the mesh and the UV layout alike, so normals still
//! point out), the very same UV coordinates (texel `i` is the same spot on both hands), the same
//! regressor and skinning weights, mirrored shape and pose blend shapes, and a mirrored mean
//! pose (axis-angle `(x, y, z)` becomes `(x, -y, -z)`).

mod rig;
mod section;
mod skeleton;
mod surface;
mod tube;
mod uv;

#[cfg(test)]
mod tests;

use glam::DVec3;

use crate::model::{
    HandModel, MANO_PARENTS, NUM_BETAS, NUM_POSE, NUM_POSE_FEATURES, Side, UvLayout,
};
use skeleton::Skeleton;
use surface::Surface;

/// Knobs of the procedural hand. All lengths are in metres, like MANO; the defaults describe an
/// average adult hand about 0.19 m long from the wrist joint to the middle fingertip.
///
/// [`procedural_hand`] clamps out-of-range values to something buildable rather than failing.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ProceduralHandConfig {
    /// Where the wrist joint goes (the right hand's; the left hand mirrors it).
    pub wrist_position: DVec3,
    /// From the wrist joint to the middle finger's knuckle (MCP joint).
    pub palm_length: f64,
    /// Breadth of the palm across the knuckles.
    pub palm_width: f64,
    /// Thickness of the palm at the knuckles.
    pub palm_thickness: f64,
    /// Breadth of the wrist.
    pub wrist_width: f64,
    /// Thickness of the wrist.
    pub wrist_thickness: f64,
    /// How far the dome that closes the wrist end reaches out, as a fraction of the wrist's
    /// thickness (0.5: a half-round profile across the wrist; the former 0.22 read as a flat
    /// stump in renders, issue 34).
    pub wrist_cap_depth: f64,
    /// Phalanx lengths of the index, middle, ring and pinky fingers: MCP to PIP, PIP to DIP,
    /// DIP to the fingertip.
    pub finger_lengths: [[f64; 3]; 4],
    /// Radius of the index, middle, ring and pinky fingers at their proximal phalanx.
    pub finger_radii: [f64; 4],
    /// Angle between neighbouring fingers in the rest pose (radians).
    pub finger_spread: f64,
    /// Thumb lengths: CMC to MCP, MCP to IP, IP to the tip.
    pub thumb_lengths: [f64; 3],
    /// Radius of the thumb at its proximal phalanx.
    pub thumb_radius: f64,
    /// Angle between the thumb's metacarpal and the fingers, in the palm plane (radians).
    pub thumb_abduction: f64,
    /// Vertices around each finger ring (rounded to a multiple of 4, at least 12).
    pub radial_segments: usize,
    /// Target distance between successive rings along the hand.
    pub ring_spacing: f64,
}

impl Default for ProceduralHandConfig {
    fn default() -> Self {
        ProceduralHandConfig {
            wrist_position: DVec3::new(0.096, 0.006, 0.006),
            palm_length: 0.090,
            palm_width: 0.082,
            palm_thickness: 0.026,
            wrist_width: 0.058,
            wrist_thickness: 0.038,
            wrist_cap_depth: 0.5,
            finger_lengths: [
                [0.041, 0.025, 0.023],
                [0.045, 0.028, 0.024],
                [0.042, 0.027, 0.024],
                [0.033, 0.020, 0.021],
            ],
            finger_radii: [0.0093, 0.0095, 0.0089, 0.0079],
            finger_spread: 0.07,
            thumb_lengths: [0.042, 0.031, 0.027],
            thumb_radius: 0.0105,
            thumb_abduction: 0.75,
            radial_segments: 20,
            ring_spacing: 0.005,
        }
    }
}

impl ProceduralHandConfig {
    /// A copy with every value clamped into the range the builder supports.
    fn sanitized(&self) -> Self {
        let d = ProceduralHandConfig::default();
        let clamp = |x: f64, default: f64, lo: f64, hi: f64| {
            if x.is_finite() {
                x.clamp(lo * default, hi * default)
            } else {
                default
            }
        };
        let mut c = self.clone();
        if !c.wrist_position.is_finite() {
            c.wrist_position = d.wrist_position;
        }
        c.palm_length = clamp(c.palm_length, d.palm_length, 0.5, 2.0);
        c.palm_width = clamp(c.palm_width, d.palm_width, 0.6, 1.6);
        c.palm_thickness = clamp(c.palm_thickness, d.palm_thickness, 0.6, 1.6);
        c.wrist_width = clamp(c.wrist_width, d.wrist_width, 0.6, 1.6);
        c.wrist_thickness = clamp(c.wrist_thickness, d.wrist_thickness, 0.6, 1.6);
        c.wrist_cap_depth = clamp(c.wrist_cap_depth, d.wrist_cap_depth, 0.2, 2.0);
        for (lengths, defaults) in c.finger_lengths.iter_mut().zip(d.finger_lengths) {
            for (l, dl) in lengths.iter_mut().zip(defaults) {
                *l = clamp(*l, dl, 0.5, 2.0);
            }
        }
        for (r, dr) in c.finger_radii.iter_mut().zip(d.finger_radii) {
            *r = clamp(*r, dr, 0.6, 1.5);
        }
        c.finger_spread = clamp(c.finger_spread, d.finger_spread, 0.0, 2.5);
        for (l, dl) in c.thumb_lengths.iter_mut().zip(d.thumb_lengths) {
            *l = clamp(*l, dl, 0.5, 2.0);
        }
        c.thumb_radius = clamp(c.thumb_radius, d.thumb_radius, 0.6, 1.5);
        c.thumb_abduction = clamp(c.thumb_abduction, d.thumb_abduction, 0.6, 1.4);
        c.radial_segments = c.radial_segments.clamp(12, 64).div_ceil(4) * 4;
        c.ring_spacing = clamp(c.ring_spacing, d.ring_spacing, 0.4, 3.0);
        c
    }
}

/// Builds the procedural hand model for one side. The result passes [`HandModel::validate`].
///
/// Deterministic: the same configuration always gives the same model.
pub fn procedural_hand(side: Side, config: &ProceduralHandConfig) -> HandModel {
    let right = right_hand(&config.sanitized());
    match side {
        Side::Right => right,
        Side::Left => mirror(&right),
    }
}

/// Shorthand for `procedural_hand(side, &ProceduralHandConfig::default())`.
pub fn default_hand(side: Side) -> HandModel {
    procedural_hand(side, &ProceduralHandConfig::default())
}

/// The right hand.
fn right_hand(cfg: &ProceduralHandConfig) -> HandModel {
    let skel = Skeleton::new(cfg);
    let surface = Surface::build(&skel, cfg);
    let unwrapped = uv::unwrap(&surface.tubes);
    let skinning_weights = rig::skinning_weights(&skel, &surface);
    let mut pose_pca_components = vec![0.0; NUM_POSE * NUM_POSE];
    for i in 0..NUM_POSE {
        pose_pca_components[i * NUM_POSE + i] = 1.0;
    }
    HandModel {
        side: Side::Right,
        source: "procedural".to_owned(),
        v_template: surface
            .positions
            .iter()
            .map(|p| *p + cfg.wrist_position)
            .collect(),
        faces: unwrapped.faces,
        joint_regressor: rig::joint_regressor(&skel, &surface),
        shape_dirs: rig::shape_dirs(&skel, &surface),
        skinning_weights,
        parents: MANO_PARENTS.to_vec(),
        pose_dirs: rig::pose_dirs(&skel, &surface),
        pose_pca_components,
        pose_pca_mean: rig::pose_mean(&skel),
        fingertips: surface.fingertips,
        uv: Some(unwrapped.uv),
    }
}

/// Sign flip of each axis under the mirror `x -> -x`.
const MIRROR: [f64; 3] = [-1.0, 1.0, 1.0];

/// The mirror image of a hand across the `x = 0` plane (see the module docs).
fn mirror(right: &HandModel) -> HandModel {
    let flip_face = |f: &[u32; 3]| [f[0], f[2], f[1]];
    let mut shape_dirs = right.shape_dirs.clone();
    for (i, x) in shape_dirs.iter_mut().enumerate() {
        *x *= MIRROR[(i / NUM_BETAS) % 3];
    }
    let mut pose_dirs = right.pose_dirs.clone();
    for (i, x) in pose_dirs.iter_mut().enumerate() {
        let (coord, feature) = ((i / NUM_POSE_FEATURES) % 3, i % NUM_POSE_FEATURES);
        let (row, col) = ((feature % 9) / 3, feature % 3);
        *x *= MIRROR[coord] * MIRROR[row] * MIRROR[col];
    }
    let pose_pca_mean = right
        .pose_pca_mean
        .iter()
        .enumerate()
        .map(|(i, x)| -x * MIRROR[i % 3])
        .collect();
    HandModel {
        side: Side::Left,
        source: right.source.clone(),
        v_template: right
            .v_template
            .iter()
            .map(|p| DVec3::new(-p.x, p.y, p.z))
            .collect(),
        faces: right.faces.iter().map(flip_face).collect(),
        joint_regressor: right.joint_regressor.clone(),
        skinning_weights: right.skinning_weights.clone(),
        parents: right.parents.clone(),
        shape_dirs,
        pose_dirs,
        pose_pca_components: right.pose_pca_components.clone(),
        pose_pca_mean,
        fingertips: right.fingertips,
        uv: right.uv.as_ref().map(|uv| UvLayout {
            uvs: uv.uvs.clone(),
            faces: uv.faces.iter().map(flip_face).collect(),
        }),
    }
}
