//! Per-hand avatars that hand-tracking runtimes drive: one glTF file per hand whose bones are
//! the joints a runtime reports, named, placed and oriented as its convention says.
//!
//! - **WebXR Hand Input** (W3C, `immersive-web/webxr-hand-input`): 25 joints per hand, `wrist`,
//!   `thumb-metacarpal` ... `pinky-finger-tip`. three.js's `XRHandMeshModel` finds the bones by
//!   these names and copies each tracked joint's pose onto its bone every frame.
//! - **OpenXR `XR_EXT_hand_tracking`**: the same joints plus `PALM` (26, `XrHandJointEXT`
//!   order), named after the enum as its note suggests (`Index_Metacarpal_L`).
//!
//! Both share one joint frame: `-Z` along the joint's bone towards the fingertip (a tip copies
//! its distal joint, the wrist points to the middle finger's metacarpal joint), `+Y` out of the
//! back of the hand (for a thumb joint, out of the nail), `X = Y x Z`, metres.
//!
//! **The skeleton from the hand model.** The wrist, the thumb's three joints and the fingers'
//! knuckle, middle and end joints are the model's own (MANO's `wrist`, `thumb1..3`,
//! `index1..3`, ...), the tips its fingertip vertices. MANO has no metacarpal joints for the
//! four fingers: each is placed on the line from the wrist to the finger's knuckle, at the
//! fraction of that line where the webxr-input-profiles `generic-hand` asset puts it
//! ([`METACARPAL_FRACTIONS`]). OpenXR's palm is the middle of the middle finger's metacarpal
//! bone, with that bone's frame. The back-of-hand direction is the normal of the plane through
//! the wrist and the index and little-finger knuckles; a thumb joint's `+Y` is that direction
//! turned about the thumb bone by [`THUMB_TWIST_DEGREES`] (the generic-hand asset's mean).
//!
//! **Every joint follows one model joint.** A runtime moves the metacarpals with the wrist
//! when the hand does not cup; the model never moves them apart. So the joint pose a tracker
//! reports for a pose of the model is `T_x = W A_m B_x` ([`XrSkeleton::tracked_poses`]):
//! `B_x` the joint's rest frame, `A_m` the skinning transform of the model joint `m` it
//! follows, `W` the tracking space. The file's inverse bind matrices are `B_x^-1`, so a bone
//! driven by `T_x` moves its vertices by `W A_m`, exactly the forward pass's linear blend
//! skinning (without the pose correctives, which no tracker reports).
//!
//! **Skinning weights.** A finger or thumb joint takes its model joint's weight. The wrist's
//! weight is split between the `wrist` bone and the metacarpal bones by one rule
//! ([`XrSkeleton::new`]): the share `s` that goes to the metacarpals grows linearly along the
//! wrist-to-middle-knuckle axis, from 0 at the middle finger's metacarpal joint to 1 at the
//! knuckles; it goes to the two metacarpal bones nearest the vertex, in inverse proportion to
//! the squared distance. A vertex keeps the model's 4 largest weights (as `avatar.glb` does);
//! where the split would give it more than 4 bones, the smallest wrist-group weights join the
//! largest one, which moves the same way under the model's poses. Then an XR-driven hand
//! matches the model's poses exactly, and a tracker that does cup the palm bends it where the
//! metacarpals are.
//!
//! **The file.** One root node, the skinned mesh (identity transform, so glTF's rule that a
//! skinned mesh node's transform is ignored changes nothing), with the bones as its direct
//! children, flat: three.js writes each tracked pose (a pose in the tracking space) straight
//! into the bone's local transform, which is right only for bones whose parent is the
//! identity. The bones stand in the avatar's own rest pose (its shape, no pose), in the
//! model's frame. One primitive, the fine texture as base colour, no morph targets.

use glam::{DMat3, DMat4, DQuat, DVec3};
use serde_json::json;

use super::{BinBuilder, Materials, PbrMaterial, SplitVertices, assemble_glb};
use crate::OutputError;
use bitt_mesh::lbs::HandParams;
use bitt_mesh::model::{HandModel, JOINT_NAMES, NUM_JOINTS, Side};

/// WebXR Hand Input's 25 joints in the specification's order.
pub const WEBXR_JOINTS: [&str; 25] = [
    "wrist",
    "thumb-metacarpal",
    "thumb-phalanx-proximal",
    "thumb-phalanx-distal",
    "thumb-tip",
    "index-finger-metacarpal",
    "index-finger-phalanx-proximal",
    "index-finger-phalanx-intermediate",
    "index-finger-phalanx-distal",
    "index-finger-tip",
    "middle-finger-metacarpal",
    "middle-finger-phalanx-proximal",
    "middle-finger-phalanx-intermediate",
    "middle-finger-phalanx-distal",
    "middle-finger-tip",
    "ring-finger-metacarpal",
    "ring-finger-phalanx-proximal",
    "ring-finger-phalanx-intermediate",
    "ring-finger-phalanx-distal",
    "ring-finger-tip",
    "pinky-finger-metacarpal",
    "pinky-finger-phalanx-proximal",
    "pinky-finger-phalanx-intermediate",
    "pinky-finger-phalanx-distal",
    "pinky-finger-tip",
];

/// OpenXR `XR_EXT_hand_tracking`'s 26 joints in `XrHandJointEXT` order
/// (`XR_HAND_JOINT_{name}_EXT`).
pub const OPENXR_JOINTS: [&str; 26] = [
    "PALM",
    "WRIST",
    "THUMB_METACARPAL",
    "THUMB_PROXIMAL",
    "THUMB_DISTAL",
    "THUMB_TIP",
    "INDEX_METACARPAL",
    "INDEX_PROXIMAL",
    "INDEX_INTERMEDIATE",
    "INDEX_DISTAL",
    "INDEX_TIP",
    "MIDDLE_METACARPAL",
    "MIDDLE_PROXIMAL",
    "MIDDLE_INTERMEDIATE",
    "MIDDLE_DISTAL",
    "MIDDLE_TIP",
    "RING_METACARPAL",
    "RING_PROXIMAL",
    "RING_INTERMEDIATE",
    "RING_DISTAL",
    "RING_TIP",
    "LITTLE_METACARPAL",
    "LITTLE_PROXIMAL",
    "LITTLE_INTERMEDIATE",
    "LITTLE_DISTAL",
    "LITTLE_TIP",
];

/// Where each finger's metacarpal joint lies on the line from the wrist to its knuckle
/// (index, middle, ring, little): the webxr-input-profiles `generic-hand` asset's
/// (`packages/assets/profiles/generic-hand/{left,right}.glb`; index 0.398 left and 0.341
/// right, averaged).
pub const METACARPAL_FRACTIONS: [f64; 4] = [0.37, 0.32, 0.33, 0.50];

/// The angle (degrees) between a thumb joint's `+Y` and the back-of-hand direction, about
/// the joint's `+Z` (negative on the left hand): the `generic-hand` asset's thumb joints turn
/// by 64-77 degrees, 70 on average.
pub const THUMB_TWIST_DEGREES: f64 = 70.0;

/// A hand-tracking joint convention.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum XrConvention {
    /// WebXR Hand Input: 25 joints, bones named as the joints (`index-finger-tip`).
    WebXr,
    /// OpenXR `XR_EXT_hand_tracking`: 26 joints (with the palm), bones named after the enum
    /// and the hand (`Index_Tip_L`).
    OpenXr,
}

impl XrConvention {
    /// Both conventions.
    pub const ALL: [XrConvention; 2] = [XrConvention::WebXr, XrConvention::OpenXr];

    /// `"webxr"` or `"openxr"`.
    pub fn as_str(self) -> &'static str {
        match self {
            XrConvention::WebXr => "webxr",
            XrConvention::OpenXr => "openxr",
        }
    }

    /// The convention named `name` (`webxr`, `openxr`; any case).
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|c| c.as_str().eq_ignore_ascii_case(name))
    }

    /// The joints the runtime reports, in its order: WebXR's names, or OpenXR's
    /// `XR_HAND_JOINT_*_EXT` enumerants.
    pub(crate) fn runtime_names(self) -> Vec<String> {
        match self {
            XrConvention::WebXr => WEBXR_JOINTS.iter().map(|s| s.to_string()).collect(),
            XrConvention::OpenXr => OPENXR_JOINTS
                .iter()
                .map(|s| format!("XR_HAND_JOINT_{s}_EXT"))
                .collect(),
        }
    }

    /// The bones' names in the file, in the runtime's order.
    pub(crate) fn bone_names(self, side: Side) -> Vec<String> {
        match self {
            XrConvention::WebXr => WEBXR_JOINTS.iter().map(|s| s.to_string()).collect(),
            XrConvention::OpenXr => {
                let hand = if side == Side::Left { "L" } else { "R" };
                OPENXR_JOINTS
                    .iter()
                    .map(|s| {
                        let words: Vec<String> = s
                            .split('_')
                            .map(|w| {
                                let lower = w.to_ascii_lowercase();
                                lower[..1].to_ascii_uppercase() + &lower[1..]
                            })
                            .collect();
                        format!("{}_{hand}", words.join("_"))
                    })
                    .collect()
            }
        }
    }
}

/// Where a WebXR joint sits at rest.
#[derive(Debug, Clone, Copy)]
enum Anchor {
    /// A model joint (MANO order).
    Joint(usize),
    /// A fingertip vertex (index into `HandModel::fingertips`: thumb, index, middle, ring,
    /// pinky).
    Tip(usize),
    /// A metacarpal joint: on the line from the wrist to the knuckle (a model joint), at
    /// [`METACARPAL_FRACTIONS`]`[finger]`.
    Metacarpal { knuckle: usize, finger: usize },
}

/// One WebXR joint: its rest position, the model joint it follows, the joint its bone points
/// to (`None`: the previous joint's direction, for tips), and whose skinning weight it takes.
struct JointDef {
    anchor: Anchor,
    follows: usize,
    towards: Option<usize>,
    thumb: bool,
}

/// The 25 WebXR joints (MANO joints: 0 wrist, 1-3 index, 4-6 middle, 7-9 pinky, 10-12 ring,
/// 13-15 thumb).
fn webxr_joint_defs() -> Vec<JointDef> {
    let mut defs = vec![JointDef {
        anchor: Anchor::Joint(0),
        follows: 0,
        towards: Some(10),
        thumb: false,
    }];
    for j in [13, 14, 15] {
        defs.push(JointDef {
            anchor: Anchor::Joint(j),
            follows: j,
            towards: Some(defs.len() + 1),
            thumb: true,
        });
    }
    defs.push(JointDef {
        anchor: Anchor::Tip(0),
        follows: 15,
        towards: None,
        thumb: true,
    });
    // index, middle, ring, pinky: knuckle joints 1, 4, 10, 7; fingertip slots 1..4.
    for (finger, knuckle) in [1usize, 4, 10, 7].into_iter().enumerate() {
        defs.push(JointDef {
            anchor: Anchor::Metacarpal { knuckle, finger },
            follows: 0,
            towards: Some(defs.len() + 1),
            thumb: false,
        });
        for j in knuckle..knuckle + 3 {
            defs.push(JointDef {
                anchor: Anchor::Joint(j),
                follows: j,
                towards: Some(defs.len() + 1),
                thumb: false,
            });
        }
        defs.push(JointDef {
            anchor: Anchor::Tip(finger + 1),
            follows: knuckle + 2,
            towards: None,
            thumb: false,
        });
    }
    defs
}

/// One joint of an [`XrSkeleton`].
#[derive(Debug, Clone, PartialEq)]
pub struct XrJoint {
    /// The bone's name in the file.
    pub bone: String,
    /// The runtime's name of the joint (WebXR name or `XR_HAND_JOINT_*_EXT`).
    pub runtime_name: String,
    /// The model joint (MANO order) whose motion it follows.
    pub follows: usize,
    /// How it was placed: `"model joint wrist"`, `"fingertip vertex 317"`, ...
    pub placed: String,
    /// Its rest frame in the model's rest space (rotation columns `X, Y, Z`; translation the
    /// joint's position), metres.
    pub rest: DMat4,
}

/// A hand's skeleton in a hand-tracking convention, with the skinning weights of its rest mesh.
#[derive(Debug, Clone)]
pub struct XrSkeleton {
    /// The convention.
    pub convention: XrConvention,
    /// The hand.
    pub side: Side,
    /// Joints in the runtime's order.
    pub joints: Vec<XrJoint>,
    /// The rest mesh (the shaped model, no pose), metres.
    pub rest_vertices: Vec<DVec3>,
    /// The model's rest joints (MANO order) for that shape.
    pub rest_model_joints: Vec<DVec3>,
    /// Per vertex, up to 4 (joint index, weight) pairs, weights summing to 1.
    pub weights: Vec<Vec<(usize, f64)>>,
}

/// The joint frame of a bone: `Z = -bone` (so `-Z` points along it), `Y` the part of `up`
/// orthogonal to it, `X = Y x Z`.
fn joint_frame(bone: DVec3, up: DVec3) -> Option<DMat3> {
    let z = -bone.try_normalize()?;
    let y = (up - z * up.dot(z)).try_normalize()?;
    let x = y.cross(z);
    Some(DMat3::from_cols(x, y, z))
}

/// Distance from `p` to the segment `a`-`b`.
fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-18)).clamp(0.0, 1.0);
    (a + ab * t - p).length()
}

impl XrSkeleton {
    /// The skeleton of `model` with shape `betas` in `convention` (see the module docs).
    ///
    /// # Errors
    /// [`OutputError::Invalid`] for an invalid model or betas, or a degenerate skeleton
    /// (joints on one point).
    pub fn new(
        model: &HandModel,
        betas: &[f64],
        convention: XrConvention,
    ) -> Result<Self, OutputError> {
        model.validate()?;
        HandParams {
            betas: betas.to_vec(),
            ..HandParams::flat()
        }
        .validate()?;
        let bad = |d: String| OutputError::Invalid(format!("XR skeleton: {d}"));
        let rest = model.shaped_vertices(betas);
        let j = model.regress_joints(&rest);
        let defs = webxr_joint_defs();
        let position = |a: Anchor| match a {
            Anchor::Joint(m) => j[m],
            Anchor::Tip(t) => rest[model.fingertips[t] as usize],
            Anchor::Metacarpal { knuckle, finger } => {
                j[0] + (j[knuckle] - j[0]) * METACARPAL_FRACTIONS[finger]
            }
        };
        let positions: Vec<DVec3> = defs.iter().map(|d| position(d.anchor)).collect();
        // The back of the hand: the normal of wrist, index and little-finger knuckles.
        let n = (j[1] - j[0])
            .cross(j[7] - j[0])
            .try_normalize()
            .ok_or_else(|| bad("the wrist and knuckles are on one line".into()))?;
        let dorsal = if model.side == Side::Left { n } else { -n };
        let twist =
            THUMB_TWIST_DEGREES.to_radians() * if model.side == Side::Left { -1.0 } else { 1.0 };
        let mut frames: Vec<DMat3> = Vec::with_capacity(defs.len());
        for (k, d) in defs.iter().enumerate() {
            let frame = match d.towards {
                Some(t) => {
                    let bone = positions[t] - positions[k];
                    let mut up = dorsal;
                    if d.thumb {
                        let z = -bone.normalize_or_zero();
                        up = DQuat::from_axis_angle(z, twist) * (dorsal - z * dorsal.dot(z));
                    }
                    joint_frame(bone, up)
                }
                None => frames.last().copied(),
            };
            frames.push(
                frame.ok_or_else(|| bad(format!("joint {} has no direction", WEBXR_JOINTS[k])))?,
            );
        }
        let mut webxr: Vec<(usize, DMat4, String)> = defs
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let placed = match d.anchor {
                    Anchor::Joint(m) => format!("model joint {}", JOINT_NAMES[m]),
                    Anchor::Tip(t) => format!("fingertip vertex {}", model.fingertips[t]),
                    Anchor::Metacarpal { knuckle, finger } => format!(
                        "added: {} of the way from the wrist to {}",
                        METACARPAL_FRACTIONS[finger], JOINT_NAMES[knuckle]
                    ),
                };
                (
                    d.follows,
                    DMat4::from_mat3_translation(frames[k], positions[k]),
                    placed,
                )
            })
            .collect();
        if convention == XrConvention::OpenXr {
            // The palm: the middle of the middle finger's metacarpal bone, with its frame.
            let (meta, knuckle) = (10, 11);
            let centre = (positions[meta] + positions[knuckle]) * 0.5;
            webxr.insert(
                0,
                (
                    0,
                    DMat4::from_mat3_translation(frames[meta], centre),
                    "added: the middle of the middle finger's metacarpal bone".into(),
                ),
            );
        }
        let names = convention.bone_names(model.side);
        let runtime = convention.runtime_names();
        let joints: Vec<XrJoint> = webxr
            .into_iter()
            .enumerate()
            .map(|(k, (follows, rest, placed))| XrJoint {
                bone: names[k].clone(),
                runtime_name: runtime[k].clone(),
                follows,
                placed,
                rest,
            })
            .collect();
        let offset = usize::from(convention == XrConvention::OpenXr);
        let weights = split_weights(model, &rest, &j, &positions, offset);
        Ok(XrSkeleton {
            convention,
            side: model.side,
            joints,
            rest_vertices: rest,
            rest_model_joints: j,
            weights,
        })
    }

    /// The pose of every joint (in [`XrSkeleton::joints`] order) that a tracker reports for the
    /// model posed by `posed_joint_transforms` (the forward pass's world transforms of the 16
    /// model joints, [`crate::PosedHand::joint_transforms`], with this skeleton's shape), in
    /// the tracking space `world` (a rigid map from the forward pass's frame).
    pub(crate) fn tracked_poses(
        &self,
        posed_joint_transforms: &[DMat4],
        world: DMat4,
    ) -> Vec<DMat4> {
        self.joints
            .iter()
            .map(|x| {
                let a = posed_joint_transforms[x.follows]
                    * DMat4::from_translation(-self.rest_model_joints[x.follows]);
                world * a * x.rest
            })
            .collect()
    }

    /// The model's own linear blend skinning without pose correctives (its weights, not the
    /// file's), of this skeleton's rest mesh by the forward pass's `joint_transforms`, in
    /// `world`: what [`XrSkeleton::skin`] is held against.
    pub(crate) fn blend_skinning(
        &self,
        model: &HandModel,
        joint_transforms: &[DMat4],
        world: DMat4,
    ) -> Vec<DVec3> {
        let a: Vec<DMat4> = (0..NUM_JOINTS)
            .map(|m| {
                world * joint_transforms[m] * DMat4::from_translation(-self.rest_model_joints[m])
            })
            .collect();
        self.rest_vertices
            .iter()
            .enumerate()
            .map(|(v, r)| {
                let w = &model.skinning_weights[v * NUM_JOINTS..(v + 1) * NUM_JOINTS];
                let mut m = DMat4::ZERO;
                for (j, &x) in w.iter().enumerate() {
                    if x != 0.0 {
                        m += a[j] * x;
                    }
                }
                m.transform_point3(*r)
            })
            .collect()
    }

    /// The skinned rest mesh driven by `poses` (one per joint), with the file's weights: what
    /// a glTF viewer computes (glTF's linear blend skinning, `sum w T_x B_x^-1 v`).
    pub fn skin(&self, poses: &[DMat4]) -> Vec<DVec3> {
        let skinning: Vec<DMat4> = self
            .joints
            .iter()
            .zip(poses)
            .map(|(x, t)| *t * x.rest.inverse())
            .collect();
        self.rest_vertices
            .iter()
            .zip(&self.weights)
            .map(|(v, w)| {
                let mut m = DMat4::ZERO;
                for &(k, weight) in w {
                    m += skinning[k] * weight;
                }
                m.transform_point3(*v)
            })
            .collect()
    }
}

/// The per-vertex weights over the XR joints (indices into the convention's joint list;
/// `offset` is 1 when the palm comes first): see the module docs.
fn split_weights(
    model: &HandModel,
    rest: &[DVec3],
    j: &[DVec3],
    positions: &[DVec3],
    offset: usize,
) -> Vec<Vec<(usize, f64)>> {
    let defs = webxr_joint_defs();
    // The XR joint that takes model joint m's weight (the root's goes to the wrist group).
    let mut takes = [usize::MAX; NUM_JOINTS];
    for (k, d) in defs.iter().enumerate() {
        if let Anchor::Joint(m) = d.anchor {
            takes[m] = k;
        }
    }
    const WRIST: usize = 0;
    let metacarpals = [5usize, 10, 15, 20];
    let axis = j[4] - j[0];
    let start = METACARPAL_FRACTIONS[1];
    let (top_joints, top_weights) =
        super::skinned::top4_weights(&model.skinning_weights, rest.len());
    rest.iter()
        .enumerate()
        .map(|(v, p)| {
            let mut out: Vec<(usize, f64)> = Vec::with_capacity(6);
            let mut wrist_group: Vec<usize> = Vec::new();
            for (&m, &w) in top_joints[v].iter().zip(&top_weights[v]) {
                let w = f64::from(w);
                if w <= 0.0 {
                    continue;
                }
                if m != 0 {
                    out.push((takes[m as usize], w));
                    continue;
                }
                let t = (*p - j[0]).dot(axis) / axis.length_squared();
                let s = ((t - start) / (1.0 - start)).clamp(0.0, 1.0);
                let mut near: Vec<(usize, f64)> = metacarpals
                    .iter()
                    .map(|&k| (k, segment_distance(*p, positions[k], positions[k + 1])))
                    .collect();
                near.sort_by(|a, b| a.1.total_cmp(&b.1));
                let inv = |d: f64| 1.0 / (d * d).max(1e-12);
                let (a, b) = (inv(near[0].1), inv(near[1].1));
                for (k, share) in [
                    (WRIST, 1.0 - s),
                    (near[0].0, s * a / (a + b)),
                    (near[1].0, s * b / (a + b)),
                ] {
                    if share * w > 0.0 {
                        wrist_group.push(out.len());
                        out.push((k, share * w));
                    }
                }
            }
            // At most 4 bones: the smallest wrist-group weights join the largest one.
            while out.len() > 4 && wrist_group.len() > 1 {
                wrist_group.sort_by(|&a, &b| out[b].1.total_cmp(&out[a].1));
                let smallest = wrist_group.pop().expect("two or more");
                out[wrist_group[0]].1 += out[smallest].1;
                out[smallest].1 = 0.0;
                out.retain(|e| e.1 > 0.0);
                wrist_group = out
                    .iter()
                    .enumerate()
                    .filter(|(_, e)| e.0 == WRIST || metacarpals.contains(&e.0))
                    .map(|(i, _)| i)
                    .collect();
            }
            out.sort_by(|a, b| b.1.total_cmp(&a.1));
            let sum: f64 = out.iter().map(|e| e.1).sum();
            out.iter().map(|&(k, w)| (k + offset, w / sum)).collect()
        })
        .collect()
}

/// One hand's XR avatar file.
#[derive(Debug, Clone, Copy)]
pub struct XrHand<'a> {
    /// The hand model (needs a UV layout when `texture` is given).
    pub model: &'a HandModel,
    /// Its skeleton ([`XrSkeleton::new`] of `model`).
    pub skeleton: &'a XrSkeleton,
    /// The base-colour texture (sRGB), if any.
    pub texture: Option<&'a image::RgbImage>,
    /// The material.
    pub material: PbrMaterial,
}

/// The glTF 2.0 binary of one hand for a hand-tracking runtime (see the module docs).
///
/// # Errors
/// [`OutputError::Invalid`] for a skeleton of another model, or a texture without a UV
/// layout.
pub fn xr_glb_bytes(hand: &XrHand) -> Result<Vec<u8>, OutputError> {
    let (model, sk) = (hand.model, hand.skeleton);
    let bad = |d: String| Err(OutputError::Invalid(format!("XR export: {d}")));
    if sk.rest_vertices.len() != model.num_vertices() || sk.side != model.side {
        return bad("the skeleton is of another hand model".into());
    }
    if hand.texture.is_some() && model.uv.is_none() {
        return bad("a texture needs a UV layout".into());
    }
    let name = format!("{}_hand", model.side.as_str());
    let mut b = BinBuilder::new();
    let mut materials = Materials::default();
    let n = sk.joints.len();
    let mut nodes = vec![json!({
        "name": name,
        "mesh": 0,
        "skin": 0,
        "children": (1..=n).collect::<Vec<_>>(),
    })];
    let mut ibm = Vec::with_capacity(n * 16);
    for x in &sk.joints {
        let (_, r, t) = x.rest.to_scale_rotation_translation();
        let r = r.normalize();
        nodes.push(json!({
            "name": x.bone,
            "rotation": [r.x as f32, r.y as f32, r.z as f32, r.w as f32],
            "translation": [t.x as f32, t.y as f32, t.z as f32],
        }));
        ibm.extend(x.rest.inverse().to_cols_array().iter().map(|&v| v as f32));
    }
    let ibm_accessor = b.floats_for(&ibm, 16, "MAT4", false, None);
    let skin = json!({
        "name": format!("{name}_{}", sk.convention.as_str()),
        "inverseBindMatrices": ibm_accessor,
        "joints": (1..=n).collect::<Vec<_>>(),
    });
    let rest = &sk.rest_vertices;
    let split = SplitVertices::new(rest.len(), &model.faces, model.uv.as_ref());
    let normals = bitt_mesh::model::vertex_normals(rest, &model.faces);
    let mut joints_bytes = Vec::with_capacity(split.source.len() * 4);
    let mut weights = Vec::with_capacity(split.source.len() * 4);
    for &v in &split.source {
        let w = &sk.weights[v as usize];
        let mut j4 = [0u8; 4];
        let mut w4 = [0f32; 4];
        for (k, &(joint, weight)) in w.iter().take(4).enumerate() {
            j4[k] = u8::try_from(joint).unwrap_or(0);
            w4[k] = weight as f32;
        }
        // f32 weights summing to 1 up to rounding: the largest takes the rest.
        w4[0] = 1.0 - w4[1..].iter().sum::<f32>();
        joints_bytes.extend(j4);
        weights.extend(w4);
    }
    let jv = b.view(&joints_bytes, Some(super::ARRAY_BUFFER));
    let joints_accessor = b.accessor(json!({"bufferView": jv, "componentType": 5121, "count": split.source.len(), "type": "VEC4"}));
    let mut attributes = json!({
        "POSITION": b.floats(&split.gather(rest), 3, "VEC3", true),
        "NORMAL": b.floats(&split.gather(&normals), 3, "VEC3", false),
        "JOINTS_0": joints_accessor,
        "WEIGHTS_0": b.floats(&weights, 4, "VEC4", false),
    });
    if let Some(tex) = &split.uvs {
        attributes["TEXCOORD_0"] = json!(b.floats(tex, 2, "VEC2", false));
    }
    let material = materials.add(&mut b, &name, hand.texture, &hand.material)?;
    let primitive = json!({
        "attributes": attributes,
        "indices": b.indices(&split.indices),
        "mode": 4,
        "material": material,
    });
    let mut doc = json!({
        "scene": 0,
        "scenes": [{"name": format!("{name}_{}", sk.convention.as_str()), "nodes": [0]}],
        "nodes": nodes,
        "meshes": [{"name": format!("{name}_mesh"), "primitives": [primitive]}],
        "skins": [skin],
    });
    materials.finish(&mut doc);
    assemble_glb(doc, b)
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use crate::export::skinned::tests::params;
    use crate::export::skinned_vertices_posed;
    use bitt_mesh::model::NUM_BETAS;
    use bitt_mesh::procedural_pair;

    #[test]
    fn conventions_name_their_joints() {
        assert_eq!(XrConvention::WebXr.bone_names(Side::Left).len(), 25);
        let openxr = XrConvention::OpenXr.bone_names(Side::Right);
        assert_eq!(openxr.len(), 26);
        assert_eq!(openxr[0], "Palm_R");
        assert_eq!(openxr[6], "Index_Metacarpal_R");
        assert_eq!(openxr[25], "Little_Tip_R");
        assert_eq!(
            XrConvention::OpenXr.runtime_names()[1],
            "XR_HAND_JOINT_WRIST_EXT"
        );
        assert_eq!(XrConvention::parse("OpenXR"), Some(XrConvention::OpenXr));
        assert_eq!(XrConvention::parse("vr"), None);
        // WebXR's order is OpenXR's without the palm.
        for (w, o) in WEBXR_JOINTS.iter().zip(&OPENXR_JOINTS[1..]) {
            let o = o.to_ascii_lowercase().replace("little", "pinky");
            let last = o.rsplit('_').next().unwrap();
            assert!(w.starts_with(o.split('_').next().unwrap()), "{w} {o}");
            assert!(w.ends_with(last), "{w} {o}");
        }
    }

    /// The frames follow the convention: `-Z` along each bone towards the tip, `+Y` out of
    /// the back of the hand, right-handed; `+X` towards the thumb on the left hand and the
    /// little finger on the right one (as the generic-hand asset's).
    #[test]
    fn rest_frames_follow_the_convention() {
        let pair = procedural_pair();
        for side in Side::BOTH {
            let model = pair.get(side);
            let sk = XrSkeleton::new(model, &[0.0; NUM_BETAS], XrConvention::WebXr).unwrap();
            let frame = |name: &str| {
                let x = sk.joints.iter().find(|x| x.bone == name).unwrap();
                (DMat3::from_mat4(x.rest), x.rest.w_axis.truncate())
            };
            for (k, x) in sk.joints.iter().enumerate() {
                let r = DMat3::from_mat4(x.rest);
                assert!((r.determinant() - 1.0).abs() < 1e-9, "{}", x.bone);
                assert!((r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, 1e-9));
                let next_is_same_finger = k + 1 < 25 && !WEBXR_JOINTS[k].ends_with("tip");
                if next_is_same_finger && k != 0 {
                    let bone = sk.joints[k + 1].rest.w_axis.truncate() - x.rest.w_axis.truncate();
                    assert!((-r.z_axis).dot(bone.normalize()) > 0.999, "{}", x.bone);
                }
            }
            // Back of the hand: most of the hand's flesh lies on the palm side of the
            // knuckles' plane, i.e. against +Y of the wrist.
            let (wrist, p0) = frame("wrist");
            let mean = sk
                .rest_vertices
                .iter()
                .map(|v| (*v - p0).dot(wrist.y_axis))
                .sum::<f64>()
                / sk.rest_vertices.len() as f64;
            assert!(mean < 0.0, "{side}: {mean}");
            // +X: the thumb side on the left hand, the little finger's on the right.
            let (_, thumb) = frame("thumb-phalanx-proximal");
            let (_, pinky) = frame("pinky-finger-phalanx-proximal");
            let towards_thumb = (thumb - pinky).dot(wrist.x_axis);
            assert_eq!(towards_thumb > 0.0, side == Side::Left, "{side}");
        }
    }

    #[test]
    fn weights_split_the_wrist_into_the_metacarpals() {
        let pair = procedural_pair();
        let model = pair.get(Side::Right);
        let sk = XrSkeleton::new(model, &[0.0; NUM_BETAS], XrConvention::WebXr).unwrap();
        let mut metacarpal_weight = 0.0;
        for (v, w) in sk.weights.iter().enumerate() {
            assert!(w.len() <= 4 && !w.is_empty());
            assert!((w.iter().map(|e| e.1).sum::<f64>() - 1.0).abs() < 1e-9);
            // Tips take no weight.
            assert!(w.iter().all(|e| !WEBXR_JOINTS[e.0].ends_with("tip")), "{v}");
            metacarpal_weight += w
                .iter()
                .filter(|e| WEBXR_JOINTS[e.0].ends_with("metacarpal") && e.0 != 1)
                .map(|e| e.1)
                .sum::<f64>();
        }
        assert!(metacarpal_weight > 50.0, "{metacarpal_weight}");
        // A vertex at the wrist end stays with the wrist; one on the index knuckle's back
        // goes mostly to the index metacarpal.
        let j = &sk.rest_model_joints;
        let nearest = |p: DVec3| {
            (0..sk.rest_vertices.len())
                .min_by(|&a, &b| {
                    (sk.rest_vertices[a] - p)
                        .length()
                        .total_cmp(&(sk.rest_vertices[b] - p).length())
                })
                .unwrap()
        };
        let wrist_end = nearest(j[0] - (j[4] - j[0]) * 0.2);
        assert!(
            sk.weights[wrist_end]
                .iter()
                .all(|e| e.0 == 0 || !WEBXR_JOINTS[e.0].ends_with("finger-metacarpal"))
        );
        let knuckle = nearest(j[0] + (j[1] - j[0]) * 0.85);
        let top = sk.weights[knuckle][0];
        assert_eq!(
            WEBXR_JOINTS[top.0], "index-finger-metacarpal",
            "{:?}",
            sk.weights[knuckle]
        );
    }

    /// Driving the written file by the joint poses a tracker would report for a pose gives the
    /// forward pass without its correctives (up to `f32` and the 4-weight cut, which
    /// `avatar.glb` shares).
    #[test]
    fn tracked_poses_drive_the_file_like_the_forward_pass() {
        let pair = procedural_pair();
        for convention in XrConvention::ALL {
            for side in Side::BOTH {
                let model = pair.get(side);
                let p = params(1.7, side);
                let sk = XrSkeleton::new(model, &p.betas, convention).unwrap();
                let glb = xr_glb_bytes(&XrHand {
                    model,
                    skeleton: &sk,
                    texture: None,
                    material: PbrMaterial::default(),
                })
                .unwrap();
                let posed = model.forward(&p).unwrap();
                let world = DMat4::from_rotation_translation(
                    DQuat::from_rotation_x(std::f64::consts::PI),
                    DVec3::new(0.1, 0.0, -0.2),
                );
                let poses = sk.tracked_poses(&posed.joint_transforms, world);
                // The model's blend skinning without correctives.
                let lbs = sk.blend_skinning(model, &posed.joint_transforms, world);
                let by_name: HashMap<String, DMat4> = sk
                    .joints
                    .iter()
                    .zip(&poses)
                    .map(|(x, t)| (x.bone.clone(), *t))
                    .collect();
                let file = skinned_vertices_posed(&glb, None, &by_name).unwrap();
                assert_eq!(file.len(), 1);
                let sources = crate::export::gltf_vertex_sources(model);
                let own = sk.skin(&poses);
                let mut worst: f64 = 0.0;
                for (i, &src) in sources.iter().enumerate() {
                    let e = (file[0].1[i] - own[src as usize]).length();
                    assert!(e < 1e-5, "file vs own skinning {e}");
                    worst = worst.max((own[src as usize] - lbs[src as usize]).length());
                }
                // 5e-10 m measured: the procedural hand has at most 4 weights per vertex.
                assert!(worst < 1e-6, "{convention:?} {side}: {worst} m");
                // At rest, the file's own pose: the rest mesh.
                let rest = skinned_vertices_posed(&glb, None, &HashMap::new()).unwrap();
                for (i, &src) in sources.iter().enumerate() {
                    assert!((rest[0].1[i] - sk.rest_vertices[src as usize]).length() < 1e-5);
                }
            }
        }
    }
}
