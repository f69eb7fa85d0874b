//! Priors on posed hands shared by the mesh refinement ([`crate::refine`]) and the keypoint
//! fit ([`crate::fit`]): joint-angle limits about each finger joint's flexion axis, and the
//! two hands' joint spheres kept apart.
//!
//! A joint's flexion axis is the axis of the model's mean pose at that joint (the relaxed,
//! slightly curled hand of MANO's `hands_mean` and of the procedural hand), so the limits
//! hold for MANO and the procedural hand alike without a per-model table.

use bitt_mesh::glam::DVec3;
use bitt_mesh::model::NUM_POSE;
use bitt_mesh::{HandPair, Side};
use burn::tensor::{Device, Int, Tensor, TensorData};

/// Flexion about each joint's flexion axis is kept between these (radians): a little
/// hyperextension, at most a full curl.
pub const FLEXION_RANGE: (f64, f64) = (-0.4, 2.0);

/// Rotation about other axes than the flexion axis (abduction, twist) is kept below this
/// (radians).
pub(crate) const OFF_AXIS_LIMIT: f64 = 0.8;

/// The 20 bones of the 21 output joints (child, parent): each finger's chain from the wrist.
pub fn bones() -> Vec<(usize, usize)> {
    let mut b = Vec::new();
    for f in 0..5 {
        for k in 0..4 {
            let child = 1 + 4 * f + k;
            let parent = if k == 0 { 0 } else { child - 1 };
            b.push((child, parent));
        }
    }
    b
}

/// Unit flexion axis of each finger joint of both hands (left, right), from the model's mean
/// pose (zero where the mean pose does not bend the joint), `[2 * 45]`.
pub fn flexion_axes(models: &HandPair) -> Vec<f64> {
    let mut axes = Vec::with_capacity(2 * NUM_POSE);
    for side in Side::BOTH {
        let mean = &models.get(side).pose_pca_mean;
        for j in 0..15 {
            let a = DVec3::new(mean[3 * j], mean[3 * j + 1], mean[3 * j + 2]);
            let u = if a.length() > 1e-3 {
                a.normalize()
            } else {
                DVec3::ZERO
            };
            axes.extend([u.x, u.y, u.z]);
        }
    }
    axes
}

/// Flexion (radians, positive curls towards the palm) of each of the 15 finger joints of a
/// hand's axis-angle pose `[45]`, given that hand's 45 axis values of [`flexion_axes`]; `None`
/// for a joint the mean pose does not bend.
pub fn flexion_angles(pose: &[f64], axes: &[f64]) -> Vec<Option<f64>> {
    (0..15)
        .map(|j| {
            let a = DVec3::from_slice(&axes[3 * j..3 * j + 3]);
            (a.length() > 0.5).then(|| DVec3::from_slice(&pose[3 * j..3 * j + 3]).dot(a))
        })
        .collect()
}

/// The priors' constants on a device.
#[derive(Debug, Clone)]
pub(crate) struct HandPriors {
    /// `[2, 15, 3]`
    axes: Tensor<3>,
    /// Bone children and parents, `[20]` each.
    child: Tensor<1, Int>,
    parent: Tensor<1, Int>,
}

impl HandPriors {
    /// The constants of `models` on `device`.
    pub fn new(models: &HandPair, device: &Device) -> Self {
        let axes: Vec<f32> = flexion_axes(models).iter().map(|&x| x as f32).collect();
        let b = bones();
        let ints = |v: Vec<i64>| Tensor::<1, Int>::from_data(TensorData::new(v, [20]), device);
        HandPriors {
            axes: Tensor::from_data(TensorData::new(axes, [2, 15, 3]), device),
            child: ints(b.iter().map(|x| x.0 as i64).collect()),
            parent: ints(b.iter().map(|x| x.1 as i64).collect()),
        }
    }

    /// Squared violations (radians^2) of [`FLEXION_RANGE`] and [`OFF_AXIS_LIMIT`] per hand.
    ///
    /// # Shapes
    /// `finger_pose [2, 45]` (axis-angles) -> `[2]`
    pub(crate) fn limits(&self, finger_pose: Tensor<2>) -> Tensor<1> {
        self.limits_within(finger_pose, FLEXION_RANGE)
    }

    /// [`HandPriors::limits`] with flexion kept within `range` (radians) instead.
    ///
    /// # Shapes
    /// `finger_pose [2, 45]` (axis-angles) -> `[2]`
    pub(crate) fn limits_within(&self, finger_pose: Tensor<2>, range: (f64, f64)) -> Tensor<1> {
        let aa = finger_pose.reshape([2, 15, 3]);
        let along = (aa.clone() * self.axes.clone()).sum_dim(2); // [2, 15, 1]
        let off = aa - self.axes.clone() * along.clone();
        let off_len = (off.square().sum_dim(2) + 1e-12).sqrt();
        ((along.clone().neg() + range.0).clamp_min(0.0).square()
            + (along - range.1).clamp_min(0.0).square()
            + (off_len - OFF_AXIS_LIMIT).clamp_min(0.0).square())
        .sum_dim(1)
        .reshape([2])
    }

    /// Squared rotation about other axes than each joint's flexion axis (abduction and
    /// twist, radians^2), summed per hand: 2D keypoints hardly see a finger's twist, so the
    /// fit keeps it small.
    ///
    /// # Shapes
    /// `finger_pose [2, 45]` (axis-angles) -> `[2]`
    pub(crate) fn off_axis(&self, finger_pose: Tensor<2>) -> Tensor<1> {
        let aa = finger_pose.reshape([2, 15, 3]);
        let along = (aa.clone() * self.axes.clone()).sum_dim(2);
        let off = aa - self.axes.clone() * along;
        off.square().sum_dim(2).sum_dim(1).reshape([2])
    }

    /// Overlap of the two hands' joint spheres (the 21 joints and the 20 bone midpoints, of
    /// radius `radius` metres), squared in sphere radii and summed.
    ///
    /// # Shapes
    /// `joints [2, 21, 3]` -> `[1]`
    pub(crate) fn penetration(&self, joints: Tensor<3>, radius: f64) -> Tensor<1> {
        let points = |hand: usize| {
            let jh = joints.clone().narrow(0, hand, 1).reshape([21, 3]);
            let mid = (jh.clone().select(0, self.child.clone())
                + jh.clone().select(0, self.parent.clone()))
                * 0.5;
            Tensor::cat(vec![jh, mid], 0) // [41, 3]
        };
        let (a, b) = (points(0), points(1));
        let d2 = a.clone().square().sum_dim(1) + b.clone().square().sum_dim(1).transpose()
            - a.matmul(b.transpose()) * 2.0;
        let d = (d2.clamp_min(0.0) + 1e-12).sqrt();
        ((d.neg() + 2.0 * radius).clamp_min(0.0) / radius)
            .square()
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flexion_of_the_mean_pose_is_its_angle_and_within_limits() {
        let models = bitt_mesh::procedural_pair();
        let axes = flexion_axes(&models);
        for (h, side) in Side::BOTH.into_iter().enumerate() {
            let mean = &models.get(side).pose_pca_mean;
            let angles = flexion_angles(mean, &axes[45 * h..45 * h + 45]);
            for (j, a) in angles.iter().enumerate() {
                let len = DVec3::from_slice(&mean[3 * j..3 * j + 3]).length();
                match a {
                    Some(a) => {
                        assert!((a - len).abs() < 1e-9, "{side} joint {j}: {a} vs {len}");
                        assert!((FLEXION_RANGE.0..=FLEXION_RANGE.1).contains(a));
                    }
                    None => assert!(len <= 1e-3),
                }
            }
        }
    }

    #[test]
    fn limits_are_zero_inside_and_grow_outside() {
        let device = Device::flex();
        let models = bitt_mesh::procedural_pair();
        let priors = HandPriors::new(&models, &device);
        let mean: Vec<f32> = Side::BOTH
            .iter()
            .flat_map(|&s| models.get(s).pose_pca_mean.clone())
            .map(|x| x as f32)
            .collect();
        let t = |v: Vec<f32>| Tensor::<2>::from_data(TensorData::new(v, [2, 45]), &device);
        let inside: Vec<f32> = priors
            .limits(t(mean.clone()))
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap();
        assert!(inside.iter().all(|&x| x.abs() < 1e-9), "{inside:?}");
        // Bend the left index base joint backwards by 1 rad beyond its flexion axis.
        let axes = flexion_axes(&models);
        let mut back = mean;
        let j = 0;
        for k in 0..3 {
            back[3 * j + k] = -(axes[3 * j + k] as f32) * 1.0;
        }
        let out: Vec<f32> = priors
            .limits(t(back))
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap();
        let want = (1.0 + FLEXION_RANGE.0) * (1.0 + FLEXION_RANGE.0);
        assert!(((out[0] as f64) - want).abs() < 1e-4, "{out:?} vs {want}");
        assert!(out[1].abs() < 1e-9);
    }
}
