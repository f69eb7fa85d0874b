//! The rigged avatar: each hand as a skinned glTF mesh over its kinematic tree, standing in
//! its pose through its joints' rotations, with the pose correctives as morph targets and an
//! optional clip of further poses.
//!
//! What a viewer computes from the file is exactly [`HandModel::forward`] (up to `f32` and the
//! 4 largest skinning weights per vertex):
//! - the mesh is the shaped rest mesh (shape blend shapes applied, no pose);
//! - each non-zero pose-corrective feature (an entry of `R_j - I` for a finger joint `j`) is a
//!   morph target, named `{joint}_r{row}{col}`, whose weight is that entry (glTF applies morph
//!   targets before skinning, as the forward pass applies correctives before LBS);
//! - the joint nodes are the kinematic tree: the wrist carries the root rotation and sits at
//!   the rest wrist plus the translation, every other joint at its rest offset from its parent
//!   with its own rotation; inverse bind matrices are `translate(-J_j)` of the rest joints, so a
//!   joint's skinning matrix is the forward pass's `G_j [I | -J_j]`;
//! - 5 fingertip leaf joints (no weights) end the fingers, for retargeting and for tools that
//!   draw bones;
//! - each skeleton hangs from a node of its own (`left_hand_rig`, identity), which importers
//!   such as Blender's make the hand's armature;
//! - above the hands, a node holds the world-to-camera transform of the training camera and
//!   the root node turns OpenCV camera axes into glTF's, so the file shows the hands as the
//!   photo did.
//!
//! Morph weights do not follow joints rotated by hand in an editor: such a pose keeps the
//! correctives of the pose in the file (the clip's keyframes carry their own).

use glam::{DMat3, DQuat, DVec3};
use serde_json::json;

use super::{BinBuilder, Materials, OPENCV_TO_GLTF, PbrMaterial, SplitVertices, assemble_glb};
use crate::OutputError;
use bitt_mesh::lbs::{HandParams, rodrigues};
use bitt_mesh::model::{
    FINGERTIP_NAMES, FINGERTIP_PARENTS, HandModel, JOINT_NAMES, NUM_JOINTS, NUM_POSE_FEATURES,
};

/// One hand of a rigged avatar.
#[derive(Debug, Clone, Copy)]
pub struct RiggedHand<'a> {
    /// Mesh and node name (`"left_hand"`).
    pub name: &'a str,
    /// Prefix of its joints' names (`"left"` gives `left_index1`, ...).
    pub joint_prefix: &'a str,
    /// The hand model (needs a UV layout when `texture` is given).
    pub model: &'a HandModel,
    /// The pose the hand stands in, in the world frame of `RiggedScene::camera_*`.
    pub params: &'a HandParams,
    /// The base-colour texture (sRGB), if any.
    pub texture: Option<&'a image::RgbImage>,
}

/// Everything a rigged avatar file holds.
#[derive(Debug, Clone)]
pub struct RiggedScene<'a> {
    /// The hands.
    pub hands: Vec<RiggedHand<'a>>,
    /// World-to-camera rotation of the camera the hands are shown from (`x_cam = R x + t`).
    pub camera_rotation: DMat3,
    /// World-to-camera translation.
    pub camera_translation: DVec3,
    /// The hands' material.
    pub material: PbrMaterial,
    /// An animation clip: keyframe `k` gives the parameters of every hand (in the order of
    /// `hands`); empty for none. The clip keeps each hand's shape (its rest mesh is fixed):
    /// only the rotations, the translation and the correctives change.
    pub clip: Vec<Vec<HandParams>>,
    /// Seconds between keyframes.
    pub seconds_per_pose: f64,
    /// The clip's name.
    pub clip_name: &'a str,
}

/// The joint rotations `[root, 15 fingers]` of `params`.
fn local_rotations(model: &HandModel, params: &HandParams) -> [DMat3; NUM_JOINTS] {
    let axis_angles = model.pose_axis_angles(&params.pose);
    let mut r = [DMat3::IDENTITY; NUM_JOINTS];
    r[0] = params.root_rotation;
    for (j, rot) in r.iter_mut().enumerate().skip(1) {
        let a = &axis_angles[(j - 1) * 3..j * 3];
        *rot = rodrigues(DVec3::new(a[0], a[1], a[2]));
    }
    r
}

/// The pose-corrective features (`R_j - I`, row-major, joints 1..15) of rotations `r`.
fn pose_features(r: &[DMat3; NUM_JOINTS]) -> [f64; NUM_POSE_FEATURES] {
    let mut f = [0.0; NUM_POSE_FEATURES];
    for j in 1..NUM_JOINTS {
        let m = r[j].transpose().to_cols_array();
        for (k, value) in m.iter().enumerate() {
            f[(j - 1) * 9 + k] = value - if k % 4 == 0 { 1.0 } else { 0.0 };
        }
    }
    f
}

/// A unit quaternion `[x, y, z, w]` of a rotation matrix, on the same side as `previous`
/// (so interpolating keyframes takes the short way).
fn quaternion(m: DMat3, previous: Option<[f32; 4]>) -> Result<[f32; 4], OutputError> {
    let q = DQuat::from_mat3(&m).normalize();
    if !q.is_finite() {
        return Err(OutputError::Invalid(
            "a joint rotation is not a rotation".into(),
        ));
    }
    let mut q = [q.x as f32, q.y as f32, q.z as f32, q.w as f32];
    if let Some(p) = previous
        && p.iter().zip(&q).map(|(a, b)| a * b).sum::<f32>() < 0.0
    {
        q = q.map(|x| -x);
    }
    let n = q.iter().map(|x| x * x).sum::<f32>().sqrt();
    Ok(q.map(|x| x / n))
}

fn vec3(p: DVec3) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

/// The 4 largest skinning weights of each vertex (`[V, J]` row-major), renormalised:
/// joint indices and weights per vertex, zero weights on joint 0. The `f32` weights sum to 1
/// up to rounding (the largest takes the rest).
pub(crate) fn top4_weights(weights: &[f64], num_vertices: usize) -> (Vec<[u8; 4]>, Vec<[f32; 4]>) {
    let mut joints = Vec::with_capacity(num_vertices);
    let mut out = Vec::with_capacity(num_vertices);
    let n = weights.len() / num_vertices.max(1);
    for v in 0..num_vertices {
        let row = &weights[v * n..(v + 1) * n];
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| row[b].total_cmp(&row[a]).then(a.cmp(&b)));
        let top: Vec<(usize, f64)> = order[..4]
            .iter()
            .map(|&j| (j, row[j].max(0.0)))
            .filter(|&(_, w)| w > 0.0)
            .collect();
        let sum: f64 = top.iter().map(|t| t.1).sum();
        let (mut j4, mut w4) = ([0u8; 4], [0f32; 4]);
        for (k, &(j, w)) in top.iter().enumerate() {
            j4[k] = j as u8;
            w4[k] = (w / sum) as f32;
        }
        if !top.is_empty() {
            w4[0] = 1.0 - w4[1..].iter().sum::<f32>();
        }
        joints.push(j4);
        out.push(w4);
    }
    (joints, out)
}

/// The morph targets of `model`: the pose-corrective features with a non-zero column.
fn used_features(model: &HandModel) -> Vec<usize> {
    (0..NUM_POSE_FEATURES)
        .filter(|&k| {
            model
                .pose_dirs
                .iter()
                .skip(k)
                .step_by(NUM_POSE_FEATURES)
                .any(|&x| x != 0.0)
        })
        .collect()
}

/// Adds one morph target's POSITION displacements (`[n, 3]`): sparse when few vertices move.
fn morph_accessor(b: &mut BinBuilder, disp: &[f32]) -> usize {
    let n = disp.len() / 3;
    let moving: Vec<u32> = (0..n as u32)
        .filter(|&i| {
            disp[i as usize * 3..i as usize * 3 + 3]
                .iter()
                .any(|&x| x != 0.0)
        })
        .collect();
    let (mut lo, mut hi) = super::bounds(disp, 3);
    if moving.len() * 4 >= n {
        let view = b.view(&super::f32_bytes(disp), Some(super::ARRAY_BUFFER));
        return b.accessor(json!({"bufferView": view, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi}));
    }
    // Sparse: the unlisted vertices do not move (an accessor without a buffer view is zeros).
    if moving.len() < n {
        for k in 0..3 {
            lo[k] = lo[k].min(0.0);
            hi[k] = hi[k].max(0.0);
        }
    }
    let values: Vec<f32> = moving
        .iter()
        .flat_map(|&i| disp[i as usize * 3..i as usize * 3 + 3].to_vec())
        .collect();
    let mut accessor =
        json!({"componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi});
    if !moving.is_empty() {
        let idx: Vec<u8> = moving.iter().flat_map(|x| x.to_le_bytes()).collect();
        let iv = b.view(&idx, None);
        let vv = b.view(&super::f32_bytes(&values), None);
        accessor["sparse"] = json!({
            "count": moving.len(),
            "indices": {"bufferView": iv, "componentType": 5125},
            "values": {"bufferView": vv},
        });
    }
    b.accessor(accessor)
}

fn check_scene(scene: &RiggedScene) -> Result<(), OutputError> {
    let err = |d: String| Err(OutputError::Invalid(format!("rigged export: {d}")));
    for h in &scene.hands {
        h.model.validate()?;
        h.params
            .validate()
            .map_err(|e| OutputError::Invalid(format!("{}: {e}", h.name)))?;
        if h.texture.is_some() && h.model.uv.is_none() {
            return err(format!("{}: a texture needs a UV layout", h.name));
        }
    }
    if let Some(k) = scene.clip.iter().position(|p| p.len() != scene.hands.len()) {
        return err(format!(
            "clip keyframe {k} has {} hands, the avatar {}",
            scene.clip[k].len(),
            scene.hands.len()
        ));
    }
    for (k, poses) in scene.clip.iter().enumerate() {
        for p in poses {
            p.validate()
                .map_err(|e| OutputError::Invalid(format!("clip keyframe {k}: {e}")))?;
        }
    }
    let r = scene.camera_rotation;
    if !(r.is_finite() && scene.camera_translation.is_finite())
        || (r.determinant() - 1.0).abs() > 1e-3
    {
        return err("the camera's rotation is not a rotation".into());
    }
    if !(scene.seconds_per_pose.is_finite() && scene.seconds_per_pose > 0.0) {
        return err(format!(
            "seconds per pose must be positive (got {})",
            scene.seconds_per_pose
        ));
    }
    Ok(())
}

/// The glTF 2.0 binary of the rigged avatar `scene` (see the module docs).
///
/// # Errors
/// [`OutputError::Invalid`] for a hand that cannot be posed, a texture without a UV
/// layout, a clip keyframe without every hand, or a camera that is not a rotation.
pub fn rigged_glb_bytes(scene: &RiggedScene) -> Result<Vec<u8>, OutputError> {
    check_scene(scene)?;
    let mut b = BinBuilder::new();
    let mut materials = Materials::default();
    let mut doc_nodes = vec![
        json!({"name": "opencv_camera_to_gltf", "rotation": OPENCV_TO_GLTF, "children": [1]}),
        json!({
            "name": "training_camera",
            "rotation": quaternion(scene.camera_rotation, None)?,
            "translation": vec3(scene.camera_translation),
            "children": [],
        }),
    ];
    let (mut meshes, mut skins, mut scene_roots) = (vec![], vec![], vec![0usize]);
    let mut channels = vec![];
    let mut samplers = vec![];
    let times: Vec<f32> = (0..scene.clip.len())
        .map(|k| (k as f64 * scene.seconds_per_pose) as f32)
        .collect();
    let time_accessor =
        (!scene.clip.is_empty()).then(|| b.floats_for(&times, 1, "SCALAR", true, None));

    for (hand_index, h) in scene.hands.iter().enumerate() {
        let model = h.model;
        let rest = model.shaped_vertices(&h.params.betas);
        let rest_joints = model.regress_joints(&rest);
        let rotations = local_rotations(model, h.params);

        // Joint nodes: 16 skeleton joints, then the 5 fingertip leaves.
        // A node of its own above each skeleton (identity), so that importers which make one
        // armature per skeleton parent (Blender) give each hand its own armature.
        let rig = doc_nodes.len();
        doc_nodes[1]["children"]
            .as_array_mut()
            .expect("children")
            .push(json!(rig));
        doc_nodes
            .push(json!({"name": format!("{}_hand_rig", h.joint_prefix), "children": [rig + 1]}));
        let first = doc_nodes.len();
        let mut joint_nodes = Vec::with_capacity(NUM_JOINTS + 5);
        let mut children: Vec<Vec<usize>> = vec![vec![]; NUM_JOINTS + 5];
        for j in 0..NUM_JOINTS {
            if let Some(p) = model.parents[j] {
                children[p].push(first + j);
            }
        }
        for (t, &p) in FINGERTIP_PARENTS.iter().enumerate() {
            children[p].push(first + NUM_JOINTS + t);
        }
        for j in 0..NUM_JOINTS {
            let translation = match model.parents[j] {
                Some(p) => rest_joints[j] - rest_joints[p],
                None => rest_joints[j] + h.params.trans,
            };
            let mut node = json!({
                "name": format!("{}_{}", h.joint_prefix, JOINT_NAMES[j]),
                "rotation": quaternion(rotations[j], None)?,
                "translation": vec3(translation),
            });
            if !children[j].is_empty() {
                node["children"] = json!(children[j]);
            }
            joint_nodes.push(node);
        }
        for (t, &p) in FINGERTIP_PARENTS.iter().enumerate() {
            let tip = rest[model.fingertips[t] as usize];
            joint_nodes.push(json!({
                "name": format!("{}_{}", h.joint_prefix, FINGERTIP_NAMES[t]),
                "translation": vec3(tip - rest_joints[p]),
            }));
        }
        doc_nodes.extend(joint_nodes);

        // Inverse bind matrices: translate(-J) of each rest joint (column-major 4x4).
        let mut ibm = Vec::with_capacity((NUM_JOINTS + 5) * 16);
        let bind_points = rest_joints[..NUM_JOINTS]
            .iter()
            .copied()
            .chain(model.fingertips.iter().map(|&t| rest[t as usize]));
        for p in bind_points {
            let m = glam::DMat4::from_translation(-p).to_cols_array();
            ibm.extend(m.iter().map(|&x| x as f32));
        }
        let ibm_accessor = b.floats_for(&ibm, 16, "MAT4", false, None);
        skins.push(json!({
            "name": format!("{}_skin", h.joint_prefix),
            "inverseBindMatrices": ibm_accessor,
            "joints": (first..first + NUM_JOINTS + 5).collect::<Vec<_>>(),
            "skeleton": first,
        }));

        // The skinned mesh.
        let split = SplitVertices::new(rest.len(), &model.faces, model.uv.as_ref());
        let normals = bitt_mesh::model::vertex_normals(&rest, &model.faces);
        let (joints4, weights4) = top4_weights(&model.skinning_weights, rest.len());
        let joints_bytes: Vec<u8> = split
            .source
            .iter()
            .flat_map(|&v| joints4[v as usize])
            .collect();
        let weights: Vec<f32> = split
            .source
            .iter()
            .flat_map(|&v| weights4[v as usize])
            .collect();
        let jv = b.view(&joints_bytes, Some(super::ARRAY_BUFFER));
        let joints_accessor = b.accessor(json!({"bufferView": jv, "componentType": 5121, "count": split.source.len(), "type": "VEC4"}));
        let mut attributes = json!({
            "POSITION": b.floats(&split.gather(&rest), 3, "VEC3", true),
            "NORMAL": b.floats(&split.gather(&normals), 3, "VEC3", false),
            "JOINTS_0": joints_accessor,
            "WEIGHTS_0": b.floats(&weights, 4, "VEC4", false),
        });
        if let Some(tex) = &split.uvs {
            attributes["TEXCOORD_0"] = json!(b.floats(tex, 2, "VEC2", false));
        }
        let features = used_features(model);
        let mut targets = Vec::with_capacity(features.len());
        for &k in &features {
            let disp: Vec<f32> = split
                .source
                .iter()
                .flat_map(|&v| {
                    let at =
                        |c: usize| model.pose_dirs[(v as usize * 3 + c) * NUM_POSE_FEATURES + k];
                    [at(0) as f32, at(1) as f32, at(2) as f32]
                })
                .collect();
            targets.push(json!({"POSITION": morph_accessor(&mut b, &disp)}));
        }
        let target_names: Vec<String> = features
            .iter()
            .map(|&k| {
                let (j, e) = (k / 9 + 1, k % 9);
                format!("{}_{}_r{}{}", h.joint_prefix, JOINT_NAMES[j], e / 3, e % 3)
            })
            .collect();
        let feature_values = pose_features(&rotations);
        let default_weights: Vec<f32> =
            features.iter().map(|&k| feature_values[k] as f32).collect();
        let material = materials.add(&mut b, h.name, h.texture, &scene.material)?;
        let mut primitive = json!({
            "attributes": attributes,
            "indices": b.indices(&split.indices),
            "mode": 4,
            "material": material,
        });
        let mut mesh = json!({"name": h.name, "primitives": [primitive.take()]});
        if !features.is_empty() {
            mesh["primitives"][0]["targets"] = json!(targets);
            mesh["weights"] = json!(default_weights);
            mesh["extras"] = json!({"targetNames": target_names});
        }
        meshes.push(mesh);
        let mesh_node = doc_nodes.len();
        doc_nodes.push(json!({"name": h.name, "mesh": meshes.len() - 1, "skin": skins.len() - 1}));
        scene_roots.push(mesh_node);

        // The clip: joint rotations, the wrist's translation and the correctives per keyframe.
        if let Some(input) = time_accessor {
            let mut joint_q: Vec<Vec<f32>> = vec![Vec::new(); NUM_JOINTS];
            let mut wrist = Vec::new();
            let mut morph = Vec::new();
            for poses in &scene.clip {
                let p = &poses[hand_index];
                let r = local_rotations(model, p);
                for j in 0..NUM_JOINTS {
                    let prev = joint_q[j].len().checked_sub(4).map(|s| {
                        [
                            joint_q[j][s],
                            joint_q[j][s + 1],
                            joint_q[j][s + 2],
                            joint_q[j][s + 3],
                        ]
                    });
                    joint_q[j].extend(quaternion(r[j], prev)?);
                }
                wrist.extend(vec3(rest_joints[0] + p.trans));
                let f = pose_features(&r);
                morph.extend(features.iter().map(|&k| f[k] as f32));
            }
            let mut add = |node: usize, path: &str, output: usize| {
                samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
                channels.push(
                    json!({"sampler": samplers.len() - 1, "target": {"node": node, "path": path}}),
                );
            };
            for (j, q) in joint_q.iter().enumerate() {
                let out = b.floats_for(q, 4, "VEC4", false, None);
                add(first + j, "rotation", out);
            }
            let out = b.floats_for(&wrist, 3, "VEC3", false, None);
            add(first, "translation", out);
            if !features.is_empty() {
                let out = b.floats_for(&morph, 1, "SCALAR", false, None);
                add(mesh_node, "weights", out);
            }
        }
    }

    if scene.hands.is_empty() {
        return Err(OutputError::Invalid(
            "rigged export: no hands to export".into(),
        ));
    }
    let mut doc = json!({
        "scene": 0,
        "scenes": [{"name": "hands", "nodes": scene_roots}],
        "nodes": doc_nodes,
        "meshes": meshes,
        "skins": skins,
    });
    if !channels.is_empty() {
        doc["animations"] =
            json!([{"name": scene.clip_name, "channels": channels, "samplers": samplers}]);
    }
    materials.finish(&mut doc);
    assemble_glb(doc, b)
}

/// The mesh vertex of `model` each glTF vertex of its exported mesh copies (the exporters
/// split vertices at UV seams), in the file's order.
pub fn gltf_vertex_sources(model: &HandModel) -> Vec<u32> {
    SplitVertices::new(model.num_vertices(), &model.faces, model.uv.as_ref()).source
}

/// What a glTF viewer shows of a skinned file written by [`rigged_glb_bytes`] (or any file
/// whose skinned meshes sit on scene-root nodes): each skinned mesh's name and vertices (in
/// the file's vertex order, glTF axes), evaluated from the file alone with glTF's morph and
/// skinning formulas, in the file's default pose (`keyframe` `None`) or at keyframe `k` of its
/// first animation.
///
/// # Errors
/// [`OutputError::Invalid`] for a file that does not parse or lacks what skinning needs.
pub fn skinned_vertices(
    bytes: &[u8],
    keyframe: Option<usize>,
) -> Result<Vec<(String, Vec<DVec3>)>, OutputError> {
    skinned_vertices_posed(bytes, keyframe, &std::collections::HashMap::new())
}

/// [`skinned_vertices`] with the local transforms of the nodes named in `node_poses` replaced
/// (as a runtime that drives bones by name does, e.g. three.js's `XRHandMeshModel`).
///
/// # Errors
/// As [`skinned_vertices`]; a pose that is not a rotation and translation.
pub fn skinned_vertices_posed(
    bytes: &[u8],
    keyframe: Option<usize>,
    node_poses: &std::collections::HashMap<String, glam::DMat4>,
) -> Result<Vec<(String, Vec<DVec3>)>, OutputError> {
    use glam::{DMat4, Vec4Swizzles};
    use gltf::animation::util::ReadOutputs;
    let bad = |d: &str| OutputError::Invalid(format!("skinned glTF: {d}"));
    let g = gltf::Gltf::from_slice(bytes).map_err(|e| bad(&e.to_string()))?;
    let blob = g.blob.as_deref().ok_or_else(|| bad("no binary chunk"))?;
    let buffers = |_: gltf::Buffer| Some(blob);
    let nodes: Vec<gltf::Node> = g.nodes().collect();
    let mut parent = vec![None; nodes.len()];
    for n in &nodes {
        for c in n.children() {
            parent[c.index()] = Some(n.index());
        }
    }
    // Local transforms, overridden by the clip at the keyframe.
    let mut trs: Vec<(DVec3, DQuat, DVec3)> = nodes
        .iter()
        .map(|n| {
            if let Some(m) = n.name().and_then(|name| node_poses.get(name)) {
                let (s, r, t) = m.to_scale_rotation_translation();
                return (t, r, s);
            }
            let (t, r, s) = n.transform().decomposed();
            (
                DVec3::from(t.map(f64::from)),
                DQuat::from_array(r.map(f64::from)),
                DVec3::from(s.map(f64::from)),
            )
        })
        .collect();
    let mut morph: Vec<Option<Vec<f64>>> = vec![None; nodes.len()];
    if let Some(k) = keyframe {
        let anim = g.animations().next().ok_or_else(|| bad("no animation"))?;
        for ch in anim.channels() {
            let r = ch.reader(buffers);
            let node = ch.target().node().index();
            let keys = r
                .read_inputs()
                .ok_or_else(|| bad("no keyframe times"))?
                .count();
            if k >= keys {
                return Err(bad(&format!("keyframe {k} of {keys}")));
            }
            match r.read_outputs().ok_or_else(|| bad("no channel outputs"))? {
                ReadOutputs::Rotations(q) => {
                    let q = q.into_f32().nth(k).ok_or_else(|| bad("short rotations"))?;
                    trs[node].1 = DQuat::from_array(q.map(f64::from));
                }
                ReadOutputs::Translations(mut t) => {
                    let t = t.nth(k).ok_or_else(|| bad("short translations"))?;
                    trs[node].0 = DVec3::from(t.map(f64::from));
                }
                ReadOutputs::Scales(mut s) => {
                    let s = s.nth(k).ok_or_else(|| bad("short scales"))?;
                    trs[node].2 = DVec3::from(s.map(f64::from));
                }
                ReadOutputs::MorphTargetWeights(w) => {
                    let w: Vec<f32> = w.into_f32().collect();
                    let n = w.len() / keys;
                    morph[node] = Some(
                        w[k * n..(k + 1) * n]
                            .iter()
                            .map(|&x| f64::from(x))
                            .collect(),
                    );
                }
            }
        }
    }
    let global = |mut i: usize| {
        let mut m = DMat4::IDENTITY;
        loop {
            let (t, r, s) = trs[i];
            m = DMat4::from_scale_rotation_translation(s, r, t) * m;
            match parent[i] {
                Some(p) => i = p,
                None => return m,
            }
        }
    };
    let mut out = Vec::new();
    for n in &nodes {
        let (Some(mesh), Some(skin)) = (n.mesh(), n.skin()) else {
            continue;
        };
        if parent[n.index()].is_some() {
            return Err(bad("a skinned mesh node is not a scene root"));
        }
        let ibm: Vec<[[f32; 4]; 4]> = skin
            .reader(buffers)
            .read_inverse_bind_matrices()
            .ok_or_else(|| bad("no inverse bind matrices"))?
            .collect();
        let joint_mats: Vec<DMat4> = skin
            .joints()
            .zip(&ibm)
            .map(|(j, m)| {
                global(j.index()) * DMat4::from_cols_array_2d(&m.map(|c| c.map(f64::from)))
            })
            .collect();
        let prim = mesh
            .primitives()
            .next()
            .ok_or_else(|| bad("no primitive"))?;
        let r = prim.reader(buffers);
        let pos: Vec<[f32; 3]> = r
            .read_positions()
            .ok_or_else(|| bad("no positions"))?
            .collect();
        let joints: Vec<[u16; 4]> = r
            .read_joints(0)
            .ok_or_else(|| bad("no JOINTS_0"))?
            .into_u16()
            .collect();
        let weights: Vec<[f32; 4]> = r
            .read_weights(0)
            .ok_or_else(|| bad("no WEIGHTS_0"))?
            .into_f32()
            .collect();
        let mut targets: Vec<Vec<[f32; 3]>> = Vec::new();
        for (p, _, _) in r.read_morph_targets() {
            targets.push(
                p.ok_or_else(|| bad("a morph target without positions"))?
                    .collect(),
            );
        }
        let mw: Vec<f64> = match &morph[n.index()] {
            Some(w) => w.clone(),
            None => mesh
                .weights()
                .unwrap_or(&[])
                .iter()
                .map(|&x| f64::from(x))
                .collect(),
        };
        if mw.len() != targets.len() || joints.len() != pos.len() || weights.len() != pos.len() {
            return Err(bad("attribute or morph weight counts disagree"));
        }
        let mut verts = Vec::with_capacity(pos.len());
        for v in 0..pos.len() {
            let mut p = DVec3::from(pos[v].map(f64::from));
            for (t, w) in targets.iter().zip(&mw) {
                p += DVec3::from(t[v].map(f64::from)) * *w;
            }
            let mut m = DMat4::ZERO;
            for k in 0..4 {
                let j = joint_mats
                    .get(joints[v][k] as usize)
                    .ok_or_else(|| bad("joint index past the skin"))?;
                m += *j * f64::from(weights[v][k]);
            }
            verts.push((m * p.extend(1.0)).xyz());
        }
        out.push((mesh.name().unwrap_or("").to_string(), verts));
    }
    Ok(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use glam::DVec3;

    use super::*;
    use bitt_mesh::lbs::HandPose;
    use bitt_mesh::model::{NUM_BETAS, NUM_POSE};
    use bitt_mesh::{Side, procedural_pair};

    fn hand_name(side: Side) -> &'static str {
        if side == Side::Left {
            "left_hand"
        } else {
            "right_hand"
        }
    }

    /// A pose, shape and translation of one hand, varied by `seed` (shared with `xr.rs`).
    pub(crate) fn params(seed: f64, side: Side) -> HandParams {
        let s = if side == Side::Left { -1.0 } else { 1.0 };
        HandParams {
            root_rotation: rodrigues(DVec3::new(0.3 * seed, -0.2, 0.5 * s)),
            pose: HandPose::Pca(
                (0..NUM_POSE)
                    .map(|i| 0.4 * ((i as f64 + seed) * 1.3).sin())
                    .collect(),
            ),
            betas: (0..NUM_BETAS)
                .map(|i| 0.5 * ((i as f64) * 0.7 + 1.0).cos())
                .collect(),
            trans: DVec3::new(0.05 * s, -0.02 * seed, 0.6),
        }
    }

    #[test]
    fn skinned_file_poses_like_the_forward_pass() {
        let pair = procedural_pair();
        let cam_r = rodrigues(DVec3::new(0.1, 0.4, -0.2));
        let cam_t = DVec3::new(0.02, -0.05, 0.3);
        let input = [params(1.0, Side::Left), params(1.0, Side::Right)];
        let novel = [params(2.5, Side::Left), params(2.5, Side::Right)];
        let novel = [
            HandParams {
                betas: input[0].betas.clone(),
                ..novel[0].clone()
            },
            HandParams {
                betas: input[1].betas.clone(),
                ..novel[1].clone()
            },
        ];
        let hands: Vec<RiggedHand> = Side::BOTH
            .iter()
            .zip(&input)
            .map(|(&side, p)| RiggedHand {
                name: if side == Side::Left {
                    "left_hand"
                } else {
                    "right_hand"
                },
                joint_prefix: side.as_str(),
                model: pair.get(side),
                params: p,
                texture: None,
            })
            .collect();
        let scene = RiggedScene {
            hands,
            camera_rotation: cam_r,
            camera_translation: cam_t,
            material: PbrMaterial::default(),
            clip: vec![input.to_vec(), novel.to_vec()],
            seconds_per_pose: 1.0,
            clip_name: "novel_poses",
        };
        let bytes = rigged_glb_bytes(&scene).unwrap();
        let flip = DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
        for (key, poses) in [(None, &input), (Some(0), &input), (Some(1), &novel)] {
            let got = skinned_vertices(&bytes, key).unwrap();
            for (h, (&side, p)) in Side::BOTH.iter().zip(poses).enumerate() {
                let model = pair.get(side);
                let want = model.forward(p).unwrap().vertices;
                let source = gltf_vertex_sources(model);
                assert_eq!(got[h].0, hand_name(side));
                let mut worst = 0.0f64;
                for (i, &v) in source.iter().enumerate() {
                    let w = flip * (cam_r * want[v as usize] + cam_t);
                    worst = worst.max((got[h].1[i] - w).length());
                }
                assert!(
                    worst < 1e-4,
                    "{side} hand at keyframe {key:?}: {worst} m off"
                );
            }
        }
    }
}
