//! The forward pass: shape blend shapes, pose blend shapes and linear blend skinning.
//!
//! It follows the MANO layer the BiTT reference uses (IntagHand's `ManoLayer` with
//! `center_idx=None`): the root rotation is a matrix applied about the *rest-pose* wrist joint,
//! the 45 finger values are PCA coefficients (`pose @ components + mean`) or axis-angles, and
//! the translation is added last, with no re-centering.

use glam::{DMat3, DMat4, DVec3};

use crate::MeshError;
use crate::model::{
    HandModel, NUM_BETAS, NUM_JOINTS, NUM_OUTPUT_JOINTS, NUM_POSE, NUM_POSE_FEATURES,
    OUTPUT_JOINT_ORDER,
};

/// The 45 finger pose values of one hand.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", content = "values", rename_all = "snake_case")]
pub enum HandPose {
    /// Full-rank pose-PCA coefficients: axis-angles = `coeffs @ components + mean`
    /// (the InterHand2.6M / BiTT annotation convention).
    Pca(Vec<f64>),
    /// Axis-angles of the 15 finger joints, joint-major (`[j0x, j0y, j0z, j1x, ...]`),
    /// used as they are (no mean added).
    AxisAngle(Vec<f64>),
    /// Axis-angles relative to the model's mean pose: axis-angles = `values + mean`
    /// (smplx's `flat_hand_mean=False`, the InterHand2.6M NeuralAnnot JSON convention).
    MeanRelativeAxisAngle(Vec<f64>),
}

/// Everything that places one hand: root rotation, finger pose, shape and translation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HandParams {
    /// Root (global) rotation, applied about the rest-pose wrist joint.
    pub root_rotation: DMat3,
    /// Finger pose.
    pub pose: HandPose,
    /// Shape coefficients (betas), `NUM_BETAS` of them.
    pub betas: Vec<f64>,
    /// Translation added to every vertex and joint after posing.
    pub trans: DVec3,
}

impl HandParams {
    /// The model's mean pose (zero PCA coefficients), mean shape, no rotation, no translation.
    pub fn mean_pose() -> Self {
        HandParams {
            root_rotation: DMat3::IDENTITY,
            pose: HandPose::Pca(vec![0.0; NUM_POSE]),
            betas: vec![0.0; NUM_BETAS],
            trans: DVec3::ZERO,
        }
    }

    /// The flat hand: all finger axis-angles zero (the template itself, up to shape).
    pub fn flat() -> Self {
        HandParams {
            pose: HandPose::AxisAngle(vec![0.0; NUM_POSE]),
            ..Self::mean_pose()
        }
    }

    /// The same hand after moving everything by `x -> rotation x + translation` (e.g. from a
    /// camera frame into the world frame): the root rotation is turned and the translation
    /// moved so that `model` poses the moved hand exactly. The finger pose and shape are kept.
    pub fn rigidly_moved(&self, model: &HandModel, rotation: DMat3, translation: DVec3) -> Self {
        let wrist = model.regress_joints(&model.shaped_vertices(&self.betas))[0];
        HandParams {
            root_rotation: rotation * self.root_rotation,
            trans: rotation * (wrist + self.trans) + translation - wrist,
            ..self.clone()
        }
    }

    /// Checks lengths and that every value is finite.
    pub fn validate(&self) -> Result<(), MeshError> {
        let pose = match &self.pose {
            HandPose::Pca(p) | HandPose::AxisAngle(p) | HandPose::MeanRelativeAxisAngle(p) => p,
        };
        if pose.len() != NUM_POSE {
            return Err(MeshError::InvalidParams(format!(
                "pose has {} values, expected {NUM_POSE}",
                pose.len()
            )));
        }
        if self.betas.len() != NUM_BETAS {
            return Err(MeshError::InvalidParams(format!(
                "shape has {} betas, expected {NUM_BETAS}",
                self.betas.len()
            )));
        }
        let finite = pose.iter().chain(&self.betas).all(|x| x.is_finite())
            && self.root_rotation.is_finite()
            && self.trans.is_finite();
        if !finite {
            return Err(MeshError::InvalidParams(
                "a pose, shape, rotation or translation value is NaN or infinite".into(),
            ));
        }
        let r = self.root_rotation;
        let orthonormal = (r.transpose() * r - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|x| x.abs() < 1e-3)
            && (r.determinant() - 1.0).abs() < 1e-3;
        if !orthonormal {
            return Err(MeshError::InvalidParams(format!(
                "root rotation is not a rotation matrix (det = {:.4})",
                r.determinant()
            )));
        }
        Ok(())
    }
}

/// A posed hand.
#[derive(Debug, Clone, PartialEq)]
pub struct PosedHand {
    /// Posed vertices, `[V]`.
    pub vertices: Vec<DVec3>,
    /// The 21 output joints in [`OUTPUT_JOINT_ORDER`] (wrist, thumb..pinky knuckle to tip).
    pub joints: Vec<DVec3>,
    /// World transform of each of the 16 skeleton joints (rotation and posed position;
    /// translation included).
    pub joint_transforms: Vec<DMat4>,
}

/// Rotation matrix of an axis-angle vector (Rodrigues' formula), exact at zero.
pub fn rodrigues(axis_angle: DVec3) -> DMat3 {
    let angle = axis_angle.length();
    if angle < 1e-12 {
        // First-order expansion: I + [w]x, exact to machine precision for such angles.
        let w = axis_angle;
        return DMat3::from_cols(
            DVec3::new(1.0, w.z, -w.y),
            DVec3::new(-w.z, 1.0, w.x),
            DVec3::new(w.y, -w.x, 1.0),
        );
    }
    DMat3::from_axis_angle(axis_angle / angle, angle)
}

impl HandModel {
    /// Finger axis-angles (`[45]`) of a pose: PCA coefficients are expanded as
    /// `coeffs @ components + mean`, axis-angles pass through.
    pub fn pose_axis_angles(&self, pose: &HandPose) -> Vec<f64> {
        match pose {
            HandPose::AxisAngle(a) => a.clone(),
            HandPose::MeanRelativeAxisAngle(a) => a
                .iter()
                .zip(&self.pose_pca_mean)
                .map(|(a, m)| a + m)
                .collect(),
            HandPose::Pca(c) => (0..NUM_POSE)
                .map(|k| {
                    self.pose_pca_mean[k]
                        + (0..NUM_POSE)
                            .map(|i| c[i] * self.pose_pca_components[i * NUM_POSE + k])
                            .sum::<f64>()
                })
                .collect(),
        }
    }

    /// Vertices with shape blend shapes applied (`v_template + shapedirs @ betas`).
    pub fn shaped_vertices(&self, betas: &[f64]) -> Vec<DVec3> {
        self.v_template
            .iter()
            .enumerate()
            .map(|(v, t)| {
                let d = |c: usize| {
                    let row =
                        &self.shape_dirs[(v * 3 + c) * NUM_BETAS..(v * 3 + c + 1) * NUM_BETAS];
                    row.iter().zip(betas).map(|(a, b)| a * b).sum::<f64>()
                };
                *t + DVec3::new(d(0), d(1), d(2))
            })
            .collect()
    }

    /// The 16 skeleton joints regressed from `vertices` (`J_regressor @ vertices`).
    pub fn regress_joints(&self, vertices: &[DVec3]) -> Vec<DVec3> {
        let n = vertices.len();
        (0..NUM_JOINTS)
            .map(|j| {
                let row = &self.joint_regressor[j * n..(j + 1) * n];
                row.iter()
                    .zip(vertices)
                    .filter(|(w, _)| **w != 0.0)
                    .map(|(w, p)| *p * *w)
                    .sum()
            })
            .collect()
    }

    /// Poses the hand.
    ///
    /// # Shapes
    /// - output vertices: `[V]`, joints: `[21]`, joint transforms: `[16]`.
    ///
    /// # Errors
    /// [`MeshError::InvalidParams`] when a value is NaN/infinite, a length is wrong, or the
    /// root rotation is not a rotation.
    pub fn forward(&self, params: &HandParams) -> Result<PosedHand, MeshError> {
        params.validate()?;
        let v_shaped = self.shaped_vertices(&params.betas);
        let rest_joints = self.regress_joints(&v_shaped);

        // Local rotations: root, then the 15 finger joints.
        let axis_angles = self.pose_axis_angles(&params.pose);
        let mut rotations = [DMat3::IDENTITY; NUM_JOINTS];
        rotations[0] = params.root_rotation;
        for j in 1..NUM_JOINTS {
            let a = &axis_angles[(j - 1) * 3..j * 3];
            rotations[j] = rodrigues(DVec3::new(a[0], a[1], a[2]));
        }

        // Pose-corrective blend shapes from (R_j - I), j = 1..15, each flattened row-major.
        let mut features = [0.0f64; NUM_POSE_FEATURES];
        for j in 1..NUM_JOINTS {
            let m = rotations[j].transpose().to_cols_array(); // row-major of R_j
            for (k, value) in m.iter().enumerate() {
                let identity = if k.is_multiple_of(4) { 1.0 } else { 0.0 };
                features[(j - 1) * 9 + k] = value - identity;
            }
        }
        let v_posed: Vec<DVec3> = v_shaped
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let d = |c: usize| {
                    let row = &self.pose_dirs
                        [(v * 3 + c) * NUM_POSE_FEATURES..(v * 3 + c + 1) * NUM_POSE_FEATURES];
                    row.iter().zip(&features).map(|(a, b)| a * b).sum::<f64>()
                };
                *p + DVec3::new(d(0), d(1), d(2))
            })
            .collect();

        // Global joint transforms in the rest frame: G_j = G_parent * [R_j | J_j - J_parent].
        let mut global = [DMat4::IDENTITY; NUM_JOINTS];
        for j in 0..NUM_JOINTS {
            let offset = match self.parents[j] {
                Some(p) => rest_joints[j] - rest_joints[p],
                None => rest_joints[j],
            };
            let local = DMat4::from_mat3_translation(rotations[j], offset);
            global[j] = match self.parents[j] {
                Some(p) => global[p] * local,
                None => local,
            };
        }
        // Skinning transforms remove the rest joint: A_j = G_j * [I | -J_j].
        let skinning: Vec<DMat4> = (0..NUM_JOINTS)
            .map(|j| global[j] * DMat4::from_translation(-rest_joints[j]))
            .collect();

        let vertices: Vec<DVec3> = v_posed
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let w = &self.skinning_weights[v * NUM_JOINTS..(v + 1) * NUM_JOINTS];
                let mut blended = DMat4::ZERO;
                for (j, weight) in w.iter().enumerate() {
                    if *weight != 0.0 {
                        blended += skinning[j] * *weight;
                    }
                }
                blended.transform_point3(*p) + params.trans
            })
            .collect();

        let mut all_joints: Vec<DVec3> = global
            .iter()
            .map(|g| g.w_axis.truncate() + params.trans)
            .collect();
        all_joints.extend(self.fingertips.iter().map(|&t| vertices[t as usize]));
        let joints = OUTPUT_JOINT_ORDER
            .iter()
            .map(|&i| all_joints[i])
            .collect::<Vec<_>>();
        debug_assert_eq!(joints.len(), NUM_OUTPUT_JOINTS);
        let joint_transforms = global
            .iter()
            .map(|g| DMat4::from_translation(params.trans) * *g)
            .collect();
        Ok(PosedHand {
            vertices,
            joints,
            joint_transforms,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rodrigues_matches_quarter_turn_and_zero() {
        let r = rodrigues(DVec3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2));
        let x = r * DVec3::X;
        assert!((x - DVec3::Y).length() < 1e-12);
        assert_eq!(rodrigues(DVec3::ZERO), DMat3::IDENTITY);
    }

    #[test]
    fn nan_parameters_are_rejected() {
        let mut p = HandParams::flat();
        p.betas[3] = f64::NAN;
        assert!(matches!(p.validate(), Err(MeshError::InvalidParams(_))));
        let mut p = HandParams::flat();
        p.root_rotation = DMat3::from_diagonal(DVec3::new(2.0, 1.0, 1.0));
        assert!(p.validate().is_err());
        let mut p = HandParams::flat();
        p.pose = HandPose::Pca(vec![0.0; 6]);
        assert!(p.validate().is_err());
    }
}
