//! The hand model as a differentiable burn function: both hands of a [`HandPair`] in one
//! batch, from continuous parameters to vertices and the 21 joints.
//!
//! It computes exactly what `bitt-mesh`'s f64 forward pass ([`bitt_mesh::HandModel::forward`])
//! computes (root rotation about the rest-pose wrist, shape blend shapes, pose correctives from
//! `R_j - I`, linear blend skinning, translation last), for any `HandModel`, MANO or
//! procedural alike: the layer reads only the model's arrays. `bitt-mesh` stays free of burn;
//! this module is where its geometry becomes tensors, next to the renderer that consumes it.
//!
//! Parameters ([`HandLayerParams`], batch index 0 = left, 1 = right):
//! - the root rotation as the 6-D continuous representation (Zhou et al. 2019: the first two
//!   columns of the matrix, Gram-Schmidt on the way back; [`rotation_to_6d`] /
//!   [`rotation_from_6d`]);
//! - the 15 finger rotations as axis-angles (`[2, 45]`, joint-major), or PCA coefficients
//!   through [`HandLayer::pca_to_axis_angles`] when the model's pose basis is the
//!   annotation's ([`has_learned_pose_pca`]);
//! - 10 betas and the translation.

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::model::{
    NUM_BETAS, NUM_JOINTS, NUM_OUTPUT_JOINTS, NUM_POSE, NUM_POSE_FEATURES, OUTPUT_JOINT_ORDER,
};
use bitt_mesh::{HandModel, HandPair, HandParams, HandPose, Side};
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::FitError;

/// Both hand models' arrays on a device, batch index 0 = left, 1 = right.
#[derive(Debug, Clone)]
pub struct HandLayer {
    num_vertices: usize,
    /// `[2, V, 3]`
    v_template: Tensor<3>,
    /// `[2, 3V, 10]`
    shape_dirs: Tensor<3>,
    /// `[2, 3V, 135]`
    pose_dirs: Tensor<3>,
    /// `[2, 16, V]`
    regressor: Tensor<3>,
    /// `[2, V, 16]`
    weights: Tensor<3>,
    /// `[2, 45, 45]`
    pca_components: Tensor<3>,
    /// `[2, 45]`
    pca_mean: Tensor<2>,
    parents: Vec<Option<usize>>,
    /// Rows of the flattened `[2V + 2*16, 3]` table (vertices then skeleton joints) that make
    /// the 21 output joints of each hand, `[2 * 21]`.
    output_rows: Tensor<1, Int>,
    /// The fingertip vertices alone, for [`HandLayer::joints`].
    tips: PointSet,
    /// Rest skeleton joints of the mean shape `[2, 16, 3]` (the regressor on the template).
    joint_template: Tensor<3>,
    /// The regressor on the shape directions `[2, 48, 10]`.
    joint_shape_dirs: Tensor<3>,
    /// Rows of the flattened `[2*5 + 2*16, 3]` table (fingertips then skeleton joints) that
    /// make the 21 output joints of each hand, `[2 * 21]`.
    tip_rows: Tensor<1, Int>,
}

/// Points skinned by the layer: template, blend shapes and skinning weights of `P` vertices.
#[derive(Debug, Clone)]
struct PointSet {
    /// `[2, P, 3]`
    template: Tensor<3>,
    /// `[2, 3P, 10]`
    shape_dirs: Tensor<3>,
    /// `[2, 3P, 135]`
    pose_dirs: Tensor<3>,
    /// `[2, P, 16]`
    weights: Tensor<3>,
}

/// The parameters of both hands, batch index 0 = left, 1 = right.
#[derive(Debug, Clone)]
pub struct HandLayerParams {
    /// Root rotation, 6-D representation `[2, 6]` (first column, then second column).
    pub root_6d: Tensor<2>,
    /// Finger axis-angles `[2, 45]`, joint-major, used as they are.
    pub finger_pose: Tensor<2>,
    /// Shape coefficients `[2, 10]`.
    pub betas: Tensor<2>,
    /// Translation `[2, 3]`.
    pub trans: Tensor<2>,
}

/// The output of [`HandLayer::forward`].
#[derive(Debug, Clone)]
pub struct HandLayerOutput {
    /// Posed vertices `[2, V, 3]` (the parameters' frame: world, for annotations).
    pub vertices: Tensor<3>,
    /// The 21 output joints `[2, 21, 3]` in `bitt_mesh::OUTPUT_JOINT_ORDER`.
    pub joints: Tensor<3>,
}

/// Whether `model`'s pose PCA is a learned basis (MANO's `hands_components`), so that an
/// annotation's PCA coefficients mean something for it. A model whose components are the
/// identity (the procedural hand) has no such basis: MANO PCA coefficients given to it are
/// meaningless numbers.
pub fn has_learned_pose_pca(model: &HandModel) -> bool {
    (0..NUM_POSE).any(|i| {
        (0..NUM_POSE).any(|k| {
            let want = if i == k { 1.0 } else { 0.0 };
            (model.pose_pca_components[i * NUM_POSE + k] - want).abs() > 1e-9
        })
    })
}

fn f32s(values: impl IntoIterator<Item = f64>) -> Vec<f32> {
    values.into_iter().map(|x| x as f32).collect()
}

fn tensor<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

impl HandLayer {
    /// Uploads both models of `models` (they must have the same vertex count).
    ///
    /// # Errors
    /// Models with different vertex counts or different kinematic trees.
    pub fn new(models: &HandPair, device: &Device) -> Result<Self, FitError> {
        let [l, r] = [&models.left, &models.right];
        let v = l.num_vertices();
        if r.num_vertices() != v || l.parents != r.parents {
            return Err(FitError::Invalid(format!(
                "the hand layer batches both hands: the left model has {} vertices, the right {}, \
                 and their kinematic trees must match",
                v,
                r.num_vertices()
            )));
        }
        let both =
            |f: &dyn Fn(&HandModel) -> Vec<f64>| -> Vec<f32> { f32s(f(l).into_iter().chain(f(r))) };
        let v_template = both(&|m| m.v_template.iter().flat_map(|p| [p.x, p.y, p.z]).collect());
        let shape_dirs = both(&|m| m.shape_dirs.clone());
        let pose_dirs = both(&|m| m.pose_dirs.clone());
        let regressor = both(&|m| m.joint_regressor.clone());
        let weights = both(&|m| m.skinning_weights.clone());
        let comps = both(&|m| m.pose_pca_components.clone());
        let mean = both(&|m| m.pose_pca_mean.clone());
        // Output joints: skeleton joint j of hand h is row 2V + 16h + j, fingertip t of hand
        // h is vertex row hV + t.
        let mut rows = Vec::with_capacity(2 * NUM_OUTPUT_JOINTS);
        let mut tip_rows = Vec::with_capacity(2 * NUM_OUTPUT_JOINTS);
        for (h, m) in [l, r].iter().enumerate() {
            for &i in &OUTPUT_JOINT_ORDER {
                let (row, tip_row) = if i < NUM_JOINTS {
                    (2 * v + h * NUM_JOINTS + i, 2 * 5 + h * NUM_JOINTS + i)
                } else {
                    let t = i - NUM_JOINTS;
                    (h * v + m.fingertips[t] as usize, h * 5 + t)
                };
                rows.push(row as i64);
                tip_rows.push(tip_row as i64);
            }
        }
        // The fingertip rows of every per-vertex array.
        let per_tip = |f: &dyn Fn(&HandModel) -> Vec<f64>, width: usize| -> Vec<f32> {
            let mut out = Vec::with_capacity(2 * 5 * width);
            for m in [l, r] {
                let all = f(m);
                for &t in &m.fingertips {
                    let t = t as usize;
                    out.extend(all[t * width..(t + 1) * width].iter().map(|&x| x as f32));
                }
            }
            out
        };
        let tips = PointSet {
            template: tensor(
                per_tip(
                    &|m| m.v_template.iter().flat_map(|p| [p.x, p.y, p.z]).collect(),
                    3,
                ),
                [2, 5, 3],
                device,
            ),
            shape_dirs: tensor(
                per_tip(&|m| m.shape_dirs.clone(), 3 * NUM_BETAS),
                [2, 15, NUM_BETAS],
                device,
            ),
            pose_dirs: tensor(
                per_tip(&|m| m.pose_dirs.clone(), 3 * NUM_POSE_FEATURES),
                [2, 15, NUM_POSE_FEATURES],
                device,
            ),
            weights: tensor(
                per_tip(&|m| m.skinning_weights.clone(), NUM_JOINTS),
                [2, 5, NUM_JOINTS],
                device,
            ),
        };
        // The regressor applied to the template and to each shape direction (rows 3v + c of
        // `shape_dirs` are vertex v, coordinate c).
        let mut joint_template = Vec::with_capacity(2 * NUM_JOINTS * 3);
        let mut joint_shape_dirs = Vec::with_capacity(2 * NUM_JOINTS * 3 * NUM_BETAS);
        for m in [l, r] {
            for j in 0..NUM_JOINTS {
                let w = &m.joint_regressor[j * v..(j + 1) * v];
                for c in 0..3 {
                    let t: f64 = (0..v).map(|k| w[k] * m.v_template[k][c]).sum();
                    joint_template.push(t as f32);
                }
                for c in 0..3 {
                    for b in 0..NUM_BETAS {
                        let d: f64 = (0..v)
                            .map(|k| w[k] * m.shape_dirs[(3 * k + c) * NUM_BETAS + b])
                            .sum();
                        joint_shape_dirs.push(d as f32);
                    }
                }
            }
        }
        Ok(HandLayer {
            num_vertices: v,
            v_template: tensor(v_template, [2, v, 3], device),
            shape_dirs: tensor(shape_dirs, [2, 3 * v, NUM_BETAS], device),
            pose_dirs: tensor(pose_dirs, [2, 3 * v, NUM_POSE_FEATURES], device),
            regressor: tensor(regressor, [2, NUM_JOINTS, v], device),
            weights: tensor(weights, [2, v, NUM_JOINTS], device),
            pca_components: tensor(comps, [2, NUM_POSE, NUM_POSE], device),
            pca_mean: tensor(mean, [2, NUM_POSE], device),
            parents: l.parents.clone(),
            output_rows: Tensor::from_data(TensorData::new(rows, [2 * NUM_OUTPUT_JOINTS]), device),
            tips,
            joint_template: tensor(joint_template, [2, NUM_JOINTS, 3], device),
            joint_shape_dirs: tensor(joint_shape_dirs, [2, 3 * NUM_JOINTS, NUM_BETAS], device),
            tip_rows: Tensor::from_data(TensorData::new(tip_rows, [2 * NUM_OUTPUT_JOINTS]), device),
        })
    }

    /// Vertices per hand `V`.
    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }

    /// PCA coefficients to axis-angles (`coeffs @ components + mean`), differentiable.
    ///
    /// # Shapes
    /// `[2, 45]` -> `[2, 45]`
    pub fn pca_to_axis_angles(&self, coefficients: Tensor<2>) -> Tensor<2> {
        coefficients
            .unsqueeze_dim::<3>(1)
            .matmul(self.pca_components.clone())
            .reshape([2, NUM_POSE])
            + self.pca_mean.clone()
    }

    /// Poses both hands.
    ///
    /// # Shapes
    /// - `root_6d [2, 6]`, `finger_pose [2, 45]`, `betas [2, 10]`, `trans [2, 3]`
    /// - output: vertices `[2, V, 3]`, joints `[2, 21, 3]`
    pub fn forward(&self, p: &HandLayerParams) -> HandLayerOutput {
        let v = self.num_vertices;
        let j = NUM_JOINTS;
        // Shape blend shapes and the rest joints.
        let offsets = self
            .shape_dirs
            .clone()
            .matmul(p.betas.clone().reshape([2, NUM_BETAS, 1]))
            .reshape([2, v, 3]);
        let v_shaped = self.v_template.clone() + offsets;
        let rest = self.regressor.clone().matmul(v_shaped.clone()); // [2, 16, 3]
        let all = PointSet {
            template: v_shaped,
            shape_dirs: self.shape_dirs.clone(),
            pose_dirs: self.pose_dirs.clone(),
            weights: self.weights.clone(),
        };
        let (vertices, joints_all) = self.pose_points(p, rest, &all);
        let table = Tensor::cat(
            vec![
                vertices.clone().reshape([2 * v, 3]),
                joints_all.reshape([2 * j, 3]),
            ],
            0,
        );
        let joints = table
            .select(0, self.output_rows.clone())
            .reshape([2, NUM_OUTPUT_JOINTS, 3]);
        HandLayerOutput { vertices, joints }
    }

    /// The 21 output joints alone, equal to [`HandLayer::forward`]'s `joints` but skinning
    /// only the five fingertip vertices (the keypoint fit's forward pass).
    ///
    /// # Shapes
    /// - `root_6d [2, 6]`, `finger_pose [2, 45]`, `betas [2, 10]`, `trans [2, 3]`
    /// - output: `[2, 21, 3]`
    pub fn joints(&self, p: &HandLayerParams) -> Tensor<3> {
        let j = NUM_JOINTS;
        let beta = p.betas.clone().reshape([2, NUM_BETAS, 1]);
        let rest = self.joint_template.clone()
            + self
                .joint_shape_dirs
                .clone()
                .matmul(beta.clone())
                .reshape([2, j, 3]);
        let shaped = self.tips.template.clone()
            + self.tips.shape_dirs.clone().matmul(beta).reshape([2, 5, 3]);
        let tips = PointSet {
            template: shaped,
            ..self.tips.clone()
        };
        let (tip_points, joints_all) = self.pose_points(p, rest, &tips);
        Tensor::cat(
            vec![
                tip_points.reshape([2 * 5, 3]),
                joints_all.reshape([2 * j, 3]),
            ],
            0,
        )
        .select(0, self.tip_rows.clone())
        .reshape([2, NUM_OUTPUT_JOINTS, 3])
    }

    /// Poses `points` (their `template` already shaped) with the kinematic chain of the rest
    /// joints `rest [2, 16, 3]`: returns the posed points `[2, P, 3]` and the posed skeleton
    /// joints `[2, 16, 3]`, both translated.
    fn pose_points(
        &self,
        p: &HandLayerParams,
        rest: Tensor<3>,
        points: &PointSet,
    ) -> (Tensor<3>, Tensor<3>) {
        let j = NUM_JOINTS;
        let n = points.template.dims()[1];
        // Local rotations: root from 6-D, fingers from axis-angles.
        let root = rotation_from_6d(p.root_6d.clone()); // [2, 3, 3]
        let fingers =
            rodrigues(p.finger_pose.clone().reshape([2 * (j - 1), 3])).reshape([2, j - 1, 3, 3]);

        // Pose correctives from R_j - I (row-major), j = 1..15.
        let eye = Tensor::<2>::eye(3, &p.betas.device()).reshape([1, 1, 3, 3]);
        let features = (fingers.clone() - eye).reshape([2, NUM_POSE_FEATURES, 1]);
        let posed_rest =
            points.template.clone() + points.pose_dirs.clone().matmul(features).reshape([2, n, 3]);

        // Kinematic chain: G_j = G_parent [R_j | J_j - J_parent], kept as (rotation, origin).
        let mut rot: Vec<Tensor<3>> = Vec::with_capacity(j);
        let mut origin: Vec<Tensor<3>> = Vec::with_capacity(j); // [2, 3, 1]
        let joint = |k: usize| rest.clone().narrow(1, k, 1).reshape([2, 3, 1]);
        for k in 0..j {
            let local = if k == 0 {
                root.clone()
            } else {
                fingers.clone().narrow(1, k - 1, 1).reshape([2, 3, 3])
            };
            match self.parents[k] {
                None => {
                    rot.push(local);
                    origin.push(joint(k));
                }
                Some(parent) => {
                    let offset = joint(k) - joint(parent);
                    let o = rot[parent].clone().matmul(offset) + origin[parent].clone();
                    let r = rot[parent].clone().matmul(local);
                    rot.push(r);
                    origin.push(o);
                }
            }
        }
        // Skinning transforms A_j = G_j [I | -J_j]: rotation R_j, translation o_j - R_j J_j.
        let skin_t: Vec<Tensor<3>> = (0..j)
            .map(|k| origin[k].clone() - rot[k].clone().matmul(joint(k)))
            .collect();
        let rot_all = Tensor::stack::<4>(rot, 1).reshape([2, j, 9]);
        let t_all = Tensor::cat(skin_t, 1).reshape([2, j, 3]);
        let blended = points
            .weights
            .clone()
            .matmul(Tensor::cat(vec![rot_all, t_all], 2)); // [2, P, 12]
        let r = blended.clone().narrow(2, 0, 9).reshape([2, n, 3, 3]);
        let t = blended.narrow(2, 9, 3);
        let trans = p.trans.clone().reshape([2, 1, 3]);
        let posed = (r * posed_rest.unsqueeze_dim::<4>(2))
            .sum_dim(3)
            .reshape([2, n, 3])
            + t
            + trans.clone();
        let joints_all = Tensor::cat(origin, 1).reshape([2, j, 3]) + trans; // [2, 16, 3]
        (posed, joints_all)
    }
}

/// Rotation matrices of axis-angle vectors (Rodrigues), smooth through zero:
/// `R = I + sin(t)/t [w]x + (1 - cos t)/t^2 [w]x^2` with `(1 - cos t) = 2 sin^2(t/2)`.
///
/// # Shapes
/// `[N, 3]` -> `[N, 3, 3]`
pub fn rodrigues(w: Tensor<2>) -> Tensor<3> {
    let n = w.dims()[0];
    let device = w.device();
    let theta = (w.clone().square().sum_dim(1) + 1e-16).sqrt(); // [N, 1]
    let a = theta.clone().sin() / theta.clone();
    let half = (theta.clone() * 0.5).sin();
    let b = half.clone() * half * 2.0 / theta.square();
    let c = |i: usize| w.clone().narrow(1, i, 1);
    let zero = Tensor::<2>::zeros([n, 1], &device);
    let k = Tensor::cat(
        vec![
            zero.clone(),
            c(2).neg(),
            c(1),
            c(2),
            zero.clone(),
            c(0).neg(),
            c(1).neg(),
            c(0),
            zero,
        ],
        1,
    )
    .reshape([n, 3, 3]);
    let k2 = k.clone().matmul(k.clone());
    let eye = Tensor::<2>::eye(3, &device).reshape([1, 3, 3]);
    eye + k * a.reshape([n, 1, 1]) + k2 * b.reshape([n, 1, 1])
}

/// Rotation matrices from the 6-D representation (the first two columns, orthonormalised by
/// Gram-Schmidt; the third is their cross product).
///
/// # Shapes
/// `[N, 6]` -> `[N, 3, 3]`
pub(crate) fn rotation_from_6d(x: Tensor<2>) -> Tensor<3> {
    let n = x.dims()[0];
    let normalize = |t: Tensor<2>| {
        let len = (t.clone().square().sum_dim(1) + 1e-20).sqrt();
        t / len
    };
    let b1 = normalize(x.clone().narrow(1, 0, 3));
    let a2 = x.narrow(1, 3, 3);
    let dot = (b1.clone() * a2.clone()).sum_dim(1);
    let b2 = normalize(a2 - b1.clone() * dot);
    let b3 = b1.clone().cross(b2.clone(), 1);
    // Columns b1, b2, b3: R[r][c] = b_c[r].
    Tensor::stack::<3>(vec![b1, b2, b3], 2).reshape([n, 3, 3])
}

/// The 6-D representation of a rotation matrix (its first two columns).
pub(crate) fn rotation_to_6d(r: DMat3) -> [f64; 6] {
    [
        r.x_axis.x, r.x_axis.y, r.x_axis.z, r.y_axis.x, r.y_axis.y, r.y_axis.z,
    ]
}

/// A rotation matrix from host 6-D values (as [`rotation_from_6d`], in f64).
pub(crate) fn rotation_from_6d_host(x: &[f64]) -> DMat3 {
    let a1 = DVec3::new(x[0], x[1], x[2]);
    let a2 = DVec3::new(x[3], x[4], x[5]);
    let b1 = a1.normalize();
    let b2 = (a2 - b1 * b1.dot(a2)).normalize();
    DMat3::from_cols(b1, b2, b1.cross(b2))
}

/// Host parameters of both hands in the layer's form: `(root_6d, finger axis-angles, betas,
/// trans)`, each flattened left then right. PCA and mean-relative poses are expanded to
/// axis-angles with each hand's own model.
pub(crate) fn host_params(
    models: &HandPair,
    hands: [&HandParams; 2],
) -> ([f64; 12], [f64; 90], [f64; 20], [f64; 6]) {
    let mut root = [0.0; 12];
    let mut pose = [0.0; 90];
    let mut betas = [0.0; 20];
    let mut trans = [0.0; 6];
    for (h, (side, p)) in Side::BOTH.iter().zip(hands).enumerate() {
        root[6 * h..6 * h + 6].copy_from_slice(&rotation_to_6d(p.root_rotation));
        let a = models.get(*side).pose_axis_angles(&p.pose);
        pose[45 * h..45 * h + 45].copy_from_slice(&a);
        betas[10 * h..10 * h + 10].copy_from_slice(&p.betas);
        trans[3 * h..3 * h + 3].copy_from_slice(&p.trans.to_array());
    }
    (root, pose, betas, trans)
}

impl HandLayerParams {
    /// The parameters of two host hands (left, right) on `device`.
    pub fn from_host(models: &HandPair, hands: [&HandParams; 2], device: &Device) -> Self {
        let (root, pose, betas, trans) = host_params(models, hands);
        HandLayerParams {
            root_6d: tensor(f32s(root), [2, 6], device),
            finger_pose: tensor(f32s(pose), [2, NUM_POSE], device),
            betas: tensor(f32s(betas), [2, NUM_BETAS], device),
            trans: tensor(f32s(trans), [2, 3], device),
        }
    }

    /// Back to host hands (left, right): the rotation orthonormalised, the pose as
    /// axis-angles.
    ///
    /// # Errors
    /// Non-finite values.
    pub fn to_host(&self) -> Result<[HandParams; 2], FitError> {
        let read = |t: &Tensor<2>| -> Result<Vec<f64>, FitError> {
            let v = bitt_stdx::to_host(t.clone())?;
            if v.iter().any(|x| !x.is_finite()) {
                return Err(FitError::NonFinite("hand parameters".into()));
            }
            Ok(v.into_iter().map(f64::from).collect())
        };
        let (root, pose, betas, trans) = (
            read(&self.root_6d)?,
            read(&self.finger_pose)?,
            read(&self.betas)?,
            read(&self.trans)?,
        );
        let hand = |h: usize| HandParams {
            root_rotation: rotation_from_6d_host(&root[6 * h..6 * h + 6]),
            pose: HandPose::AxisAngle(pose[45 * h..45 * h + 45].to_vec()),
            betas: betas[10 * h..10 * h + 10].to_vec(),
            trans: DVec3::from_slice(&trans[3 * h..3 * h + 3]),
        };
        Ok([hand(0), hand(1)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::procedural_pair;
    use bitt_testkit::{devices, to_vec};

    /// A deterministic, clearly non-trivial pose of both hands.
    pub(crate) fn test_hands(seed: u64) -> [HandParams; 2] {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        std::array::from_fn(|h| HandParams {
            root_rotation: bitt_mesh::lbs::rodrigues(DVec3::new(rnd(), rnd(), rnd()) * 1.5),
            pose: HandPose::AxisAngle((0..NUM_POSE).map(|_| 0.6 * rnd()).collect()),
            betas: (0..NUM_BETAS).map(|_| 1.5 * rnd()).collect(),
            trans: DVec3::new(
                0.1 * rnd() + 0.05 * h as f64,
                0.1 * rnd(),
                0.5 + 0.1 * rnd(),
            ),
        })
    }

    /// Largest difference between the layer and the f64 forward pass (vertices, joints, and
    /// the joints of [`HandLayer::joints`]).
    pub(crate) fn layer_error(models: &HandPair, hands: &[HandParams; 2], device: &Device) -> f64 {
        let layer = HandLayer::new(models, device).unwrap();
        let params = HandLayerParams::from_host(models, [&hands[0], &hands[1]], device);
        let out = layer.forward(&params);
        let joints_only = to_vec(layer.joints(&params));
        let (verts, joints) = (to_vec(out.vertices), to_vec(out.joints));
        let v = layer.num_vertices();
        let mut worst = 0.0f64;
        for (h, side) in Side::BOTH.iter().enumerate() {
            let want = models.get(*side).forward(&hands[h]).unwrap();
            for (i, p) in want.vertices.iter().enumerate() {
                for c in 0..3 {
                    let got = f64::from(verts[(h * v + i) * 3 + c]);
                    worst = worst.max((got - p[c]).abs());
                }
            }
            for (i, p) in want.joints.iter().enumerate() {
                for c in 0..3 {
                    let k = (h * NUM_OUTPUT_JOINTS + i) * 3 + c;
                    worst = worst.max((f64::from(joints[k]) - p[c]).abs());
                    worst = worst.max((f64::from(joints_only[k]) - p[c]).abs());
                }
            }
        }
        worst
    }

    #[test]
    fn procedural_hands_match_the_f64_forward_pass() {
        let models = procedural_pair();
        for (name, device) in devices() {
            for seed in [1, 2] {
                let err = layer_error(&models, &test_hands(seed), &device);
                assert!(
                    err < 1e-5,
                    "{name} seed {seed}: largest difference {err:e} m"
                );
            }
        }
    }

    #[test]
    fn pca_coefficients_expand_as_the_model_does() {
        let models = procedural_pair();
        let device = Device::flex();
        let layer = HandLayer::new(&models, &device).unwrap();
        let coeffs: Vec<f32> = (0..90)
            .map(|i| ((i * 7) % 11) as f32 * 0.05 - 0.25)
            .collect();
        let got = to_vec(layer.pca_to_axis_angles(tensor(coeffs.clone(), [2, 45], &device)));
        for (h, side) in Side::BOTH.iter().enumerate() {
            let c: Vec<f64> = coeffs[45 * h..45 * h + 45]
                .iter()
                .map(|&x| x.into())
                .collect();
            let want = models.get(*side).pose_axis_angles(&HandPose::Pca(c));
            for k in 0..45 {
                assert!((f64::from(got[45 * h + k]) - want[k]).abs() < 1e-6);
            }
        }
        assert!(!has_learned_pose_pca(&models.left));
    }

    #[test]
    fn six_d_round_trips_and_rodrigues_is_smooth_at_zero() {
        let device = Device::flex();
        let r = bitt_mesh::lbs::rodrigues(DVec3::new(0.3, -1.2, 0.7));
        let six = rotation_to_6d(r);
        let back = rotation_from_6d_host(&six);
        assert!((back - r).to_cols_array().iter().all(|x| x.abs() < 1e-12));
        let t = rotation_from_6d(tensor(f32s(six), [1, 6], &device));
        let got = to_vec(t);
        for row in 0..3 {
            for col in 0..3 {
                assert!((f64::from(got[row * 3 + col]) - r.col(col)[row]).abs() < 1e-6);
            }
        }
        let w = tensor(vec![0.0, 0.0, 0.0, 1e-4, -2e-4, 3e-4], [2, 3], &device);
        let got = to_vec(rodrigues(w));
        let want = bitt_mesh::lbs::rodrigues(DVec3::new(1e-4, -2e-4, 3e-4));
        assert_eq!(&got[..9], &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        for row in 0..3 {
            for col in 0..3 {
                assert!((f64::from(got[9 + row * 3 + col]) - want.col(col)[row]).abs() < 1e-7);
            }
        }
    }

    /// Gradients of a random linear functional of the vertices and joints against central
    /// finite differences of the f64 forward pass, for every parameter group. flex and
    /// ndarray only: the backward pass adds 14 s on lavapipe's wgpu (the forward pass is
    /// checked on wgpu above).
    #[test]
    fn gradients_match_finite_differences() {
        let models = procedural_pair();
        let hands = test_hands(5);
        let (root, pose, betas, trans) = host_params(&models, [&hands[0], &hands[1]]);
        for (name, device) in bitt_testkit::cpu_devices() {
            let device = device.autodiff();
            let layer = HandLayer::new(&models, &device).unwrap();
            let v = layer.num_vertices();
            let weights_v: Vec<f32> = (0..2 * v * 3)
                .map(|i| (((i * 2654435761) % 1000) as f32 / 1000.0) - 0.5)
                .collect();
            let weights_j: Vec<f32> = (0..2 * 21 * 3)
                .map(|i| (((i * 40503) % 1000) as f32 / 1000.0) - 0.5)
                .collect();
            let functional = |verts: &[DVec3], joints: &[DVec3], h: usize| -> f64 {
                let a: f64 = verts
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        (0..3)
                            .map(|c| f64::from(weights_v[(h * v + i) * 3 + c]) * p[c])
                            .sum::<f64>()
                    })
                    .sum();
                let b: f64 = joints
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        (0..3)
                            .map(|c| f64::from(weights_j[(h * 21 + i) * 3 + c]) * p[c])
                            .sum::<f64>()
                    })
                    .sum();
                a + b
            };
            let p = HandLayerParams {
                root_6d: tensor(f32s(root), [2, 6], &device).require_grad(),
                finger_pose: tensor(f32s(pose), [2, 45], &device).require_grad(),
                betas: tensor(f32s(betas), [2, 10], &device).require_grad(),
                trans: tensor(f32s(trans), [2, 3], &device).require_grad(),
            };
            let out = layer.forward(&p);
            let loss = (out.vertices.reshape([2 * v * 3])
                * tensor(weights_v.clone(), [2 * v * 3], &device))
            .sum()
                + (out.joints.reshape([2 * 21 * 3])
                    * tensor(weights_j.clone(), [2 * 21 * 3], &device))
                .sum();
            let grads = loss.backward();
            // f64 finite differences: perturb one host value, re-run the f64 forward pass.
            let eval = |group: usize, k: usize, delta: f64| -> f64 {
                let (mut r, mut q, mut b, mut t) = (root, pose, betas, trans);
                match group {
                    0 => r[k] += delta,
                    1 => q[k] += delta,
                    2 => b[k] += delta,
                    _ => t[k] += delta,
                }
                (0..2)
                    .map(|h| {
                        let params = HandParams {
                            root_rotation: rotation_from_6d_host(&r[6 * h..6 * h + 6]),
                            pose: HandPose::AxisAngle(q[45 * h..45 * h + 45].to_vec()),
                            betas: b[10 * h..10 * h + 10].to_vec(),
                            trans: DVec3::from_slice(&t[3 * h..3 * h + 3]),
                        };
                        let posed = models.get(Side::BOTH[h]).forward(&params).unwrap();
                        functional(&posed.vertices, &posed.joints, h)
                    })
                    .sum()
            };
            let groups: [(&Tensor<2>, usize, &[usize]); 4] = [
                (&p.root_6d, 0, &[0, 4, 7, 11]),
                (&p.finger_pose, 1, &[0, 5, 13, 44, 50, 89]),
                (&p.betas, 2, &[0, 3, 9, 14]),
                (&p.trans, 3, &[0, 2, 4]),
            ];
            for (t, group, ks) in groups {
                let g = to_vec(t.grad(&grads).expect("gradient"));
                for &k in ks {
                    let h = 1e-5;
                    let fd = (eval(group, k, h) - eval(group, k, -h)) / (2.0 * h);
                    let an = f64::from(g[k]);
                    assert!(
                        (an - fd).abs() <= 2e-3 * fd.abs().max(1.0),
                        "{name} group {group} value {k}: analytic {an} vs fd {fd}"
                    );
                }
            }
        }
    }
}
