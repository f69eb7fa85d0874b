//! The hand model: everything a MANO-style hand needs to be shaped, posed and skinned.
//!
//! One struct serves the licensed MANO files (see [`crate::mano`]) and the project's own
//! procedural hand (see [`crate::procedural`]); the forward pass ([`crate::lbs`]) knows no
//! difference between them.

use glam::{DVec2, DVec3};

use crate::MeshError;

/// Number of skeleton joints (wrist + 5 fingers x 3), as in MANO.
pub const NUM_JOINTS: usize = 16;
/// Number of shape coefficients (betas) used by the forward pass, as in MANO.
pub const NUM_BETAS: usize = 10;
/// Number of finger pose values (15 joints x 3 axis-angle components).
pub const NUM_POSE: usize = 45;
/// Number of pose-corrective features: 15 joints x a 3x3 rotation minus identity.
pub const NUM_POSE_FEATURES: usize = 135;
/// Number of output joints of the forward pass: 16 skeleton joints + 5 fingertips.
pub const NUM_OUTPUT_JOINTS: usize = 21;

/// MANO's kinematic tree: parent of each of the 16 joints (`None` for the wrist).
///
/// Joint order: 0 wrist, 1-3 index, 4-6 middle, 7-9 pinky, 10-12 ring, 13-15 thumb.
pub const MANO_PARENTS: [Option<usize>; NUM_JOINTS] = [
    None,
    Some(0),
    Some(1),
    Some(2),
    Some(0),
    Some(4),
    Some(5),
    Some(0),
    Some(7),
    Some(8),
    Some(0),
    Some(10),
    Some(11),
    Some(0),
    Some(13),
    Some(14),
];

/// Names of the 16 skeleton joints in MANO's order (the rigged avatar's bone names, after
/// the hand: `right_index1`, ...).
pub const JOINT_NAMES: [&str; NUM_JOINTS] = [
    "wrist", "index1", "index2", "index3", "middle1", "middle2", "middle3", "pinky1", "pinky2",
    "pinky3", "ring1", "ring2", "ring3", "thumb1", "thumb2", "thumb3",
];

/// Names of the fingertip leaf joints, in the order of [`HandModel::fingertips`].
pub const FINGERTIP_NAMES: [&str; 5] = [
    "thumb_tip",
    "index_tip",
    "middle_tip",
    "ring_tip",
    "pinky_tip",
];

/// The skeleton joint each fingertip hangs from (the finger's last joint), in the order of
/// [`HandModel::fingertips`].
pub const FINGERTIP_PARENTS: [usize; 5] = [15, 3, 6, 12, 9];

/// Which hand a model describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// The left hand.
    Left,
    /// The right hand.
    Right,
}

impl Side {
    /// Both sides, left first (the order the project writes two-hand outputs in).
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    /// `"left"` or `"right"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }

    /// The other hand.
    pub fn mirrored(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A UV layout: per-UV-vertex coordinates and one UV triangle per mesh face.
///
/// Convention (the HTML / BiTT reference renderer's): `u` grows to the right, `v = 0` is the
/// *bottom* row of the texture image. UV vertices are separate from mesh vertices so that
/// seams can split a mesh vertex into several UV vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct UvLayout {
    /// UV coordinates in `[0, 1]^2`.
    pub uvs: Vec<DVec2>,
    /// For each mesh face, the indices of its three corners in [`UvLayout::uvs`], in the same
    /// corner order as the mesh face.
    pub faces: Vec<[u32; 3]>,
}

/// A MANO-style parametric hand model (all arrays row-major, `f64`).
///
/// `V` is the vertex count (778 for MANO), `F` the face count.
#[derive(Debug, Clone, PartialEq)]
pub struct HandModel {
    /// Which hand this is.
    pub side: Side,
    /// Where the model came from (a file path, or `"procedural"`), for messages.
    pub source: String,
    /// Rest-pose template vertices, `[V]`.
    pub v_template: Vec<DVec3>,
    /// Triangles, `[F]`, counter-clockwise seen from outside the hand.
    pub faces: Vec<[u32; 3]>,
    /// Joint regressor, `[NUM_JOINTS, V]` flattened row-major: joint `j` is
    /// `sum_v joint_regressor[j * V + v] * vertex[v]`.
    pub joint_regressor: Vec<f64>,
    /// Linear-blend-skinning weights, `[V, NUM_JOINTS]` flattened row-major; rows sum to 1.
    pub skinning_weights: Vec<f64>,
    /// Parent of each joint (`None` for the root), `[NUM_JOINTS]`; parents precede children.
    pub parents: Vec<Option<usize>>,
    /// Shape blend shapes, `[V, 3, NUM_BETAS]` flattened row-major.
    pub shape_dirs: Vec<f64>,
    /// Pose-corrective blend shapes, `[V, 3, NUM_POSE_FEATURES]` flattened row-major.
    pub pose_dirs: Vec<f64>,
    /// Pose PCA basis, `[NUM_POSE, NUM_POSE]` row-major: row `i` is component `i`
    /// (MANO's `hands_components`).
    pub pose_pca_components: Vec<f64>,
    /// Pose PCA mean, `[NUM_POSE]` (MANO's `hands_mean`).
    pub pose_pca_mean: Vec<f64>,
    /// Vertex index of each fingertip, in the order thumb, index, middle, ring, pinky.
    pub fingertips: [u32; 5],
    /// The model's own UV layout, if it has one (MANO files carry none; HTML supplies it).
    pub uv: Option<UvLayout>,
}

/// MANO's fingertip vertices (thumb, index, middle, ring, pinky), the common convention.
pub(crate) const MANO_FINGERTIPS: [u32; 5] = [745, 317, 444, 556, 673];

/// Order of the 21 output joints, as indices into `[16 skeleton joints, 5 fingertips]`:
/// wrist, then thumb, index, middle, ring, pinky, each from the knuckle to the tip
/// (the InterHand2.6M / IntagHand convention the reference uses).
pub const OUTPUT_JOINT_ORDER: [usize; NUM_OUTPUT_JOINTS] = [
    0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20,
];

impl HandModel {
    /// Number of vertices `V`.
    pub fn num_vertices(&self) -> usize {
        self.v_template.len()
    }

    /// Checks every array against the vertex count and that all values are finite.
    ///
    /// Loaders call this before handing a model out, so the forward pass can index freely.
    pub fn validate(&self) -> Result<(), MeshError> {
        let v = self.num_vertices();
        let bad = |what: &str, detail: String| {
            Err(MeshError::InvalidModel {
                source_name: self.source.clone(),
                detail: format!("{what}: {detail}"),
            })
        };
        if v == 0 {
            return bad("v_template", "no vertices".into());
        }
        let sizes: [(&str, usize, usize); 6] = [
            (
                "joint_regressor",
                self.joint_regressor.len(),
                NUM_JOINTS * v,
            ),
            (
                "skinning_weights",
                self.skinning_weights.len(),
                v * NUM_JOINTS,
            ),
            ("shape_dirs", self.shape_dirs.len(), v * 3 * NUM_BETAS),
            ("pose_dirs", self.pose_dirs.len(), v * 3 * NUM_POSE_FEATURES),
            (
                "pose_pca_components",
                self.pose_pca_components.len(),
                NUM_POSE * NUM_POSE,
            ),
            ("pose_pca_mean", self.pose_pca_mean.len(), NUM_POSE),
        ];
        for (name, got, want) in sizes {
            if got != want {
                return bad(
                    name,
                    format!("has {got} values, expected {want} for {v} vertices"),
                );
            }
        }
        if self.parents.len() != NUM_JOINTS {
            return bad(
                "parents",
                format!("has {} joints, expected {NUM_JOINTS}", self.parents.len()),
            );
        }
        for (j, p) in self.parents.iter().enumerate() {
            match (j, p) {
                (0, None) => {}
                (0, Some(_)) => return bad("parents", "joint 0 must be the root".into()),
                (_, Some(p)) if *p < j => {}
                _ => {
                    return bad(
                        "parents",
                        format!("joint {j} has parent {p:?}; parents must precede children"),
                    );
                }
            }
        }
        for (i, f) in self.faces.iter().enumerate() {
            if f.iter().any(|&k| k as usize >= v) {
                return bad(
                    "faces",
                    format!("face {i} = {f:?} indexes past {v} vertices"),
                );
            }
        }
        if let Some(&t) = self.fingertips.iter().find(|&&t| t as usize >= v) {
            return bad("fingertips", format!("vertex {t} is past {v} vertices"));
        }
        if let Some(uv) = &self.uv {
            if uv.faces.len() != self.faces.len() {
                return bad(
                    "uv.faces",
                    format!(
                        "{} UV faces for {} mesh faces",
                        uv.faces.len(),
                        self.faces.len()
                    ),
                );
            }
            let n = uv.uvs.len();
            if uv.faces.iter().flatten().any(|&k| k as usize >= n) {
                return bad("uv.faces", format!("indexes past {n} UV vertices"));
            }
            if uv.uvs.iter().any(|p| !p.is_finite()) {
                return bad("uv.uvs", "non-finite coordinate".into());
            }
        }
        let arrays: [(&str, &[f64]); 6] = [
            ("joint_regressor", &self.joint_regressor),
            ("skinning_weights", &self.skinning_weights),
            ("shape_dirs", &self.shape_dirs),
            ("pose_dirs", &self.pose_dirs),
            ("pose_pca_components", &self.pose_pca_components),
            ("pose_pca_mean", &self.pose_pca_mean),
        ];
        for (name, a) in arrays {
            if let Some(i) = a.iter().position(|x| !x.is_finite()) {
                return bad(name, format!("value {i} is not finite"));
            }
        }
        if let Some(i) = self.v_template.iter().position(|p| !p.is_finite()) {
            return bad("v_template", format!("vertex {i} is not finite"));
        }
        Ok(())
    }
}

/// Per-vertex normals: area-weighted face normals, normalized (zero where undefined).
pub fn vertex_normals(vertices: &[DVec3], faces: &[[u32; 3]]) -> Vec<DVec3> {
    let mut n = vec![DVec3::ZERO; vertices.len()];
    for f in faces {
        let [a, b, c] = f.map(|i| vertices[i as usize]);
        let fn_ = (b - a).cross(c - a);
        for &i in f {
            n[i as usize] += fn_;
        }
    }
    n.into_iter().map(|v| v.normalize_or_zero()).collect()
}
