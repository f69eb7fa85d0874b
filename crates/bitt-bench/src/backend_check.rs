//! The backend check: a small, fixed, real computation to compare backends with.
//!
//! A padded conv2d with bias, `tanh`, a matmul and a mean-square loss, then the gradients of
//! the conv weight and bias; a texture PCA turned into a UV image by the layout's gather,
//! with the gradient of a loss on the image with respect to the PCA parameters; and the
//! differentiable hand layer posing both procedural hands, with the gradient with respect to
//! the finger pose. `bitt backend-check` prints [`BackendNumbers`] as JSON for `cargo xtask
//! e2e`; `bitt gpu-check` compares two devices in one process ([`compare`]).

use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};

use bitt_texture::{TextureLayout, TexturePca};

use bitt::BittError;
use bitt::hand_layer::{HandLayer, HandLayerParams};
use bitt_stdx::to_host;

/// Deterministic inputs: smooth, non-symmetric patterns (no RNG, so every backend sees the
/// same bits).
fn pattern(n: usize, scale: f32, freq: f32, phase: f32) -> Vec<f32> {
    (0..n)
        .map(|i| scale * ((i as f32) * freq + phase).sin())
        .collect()
}

/// The numbers the check computes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BackendNumbers {
    /// The mean-square loss after conv2d, `tanh` and the matmul.
    pub loss: f32,
    /// The matmul's output `[2, 5]`, flattened.
    pub output: Vec<f32>,
    /// Gradient of the loss with respect to the conv weight `[4, 3, 3, 3]`, flattened.
    pub grad_weight: Vec<f32>,
    /// Gradient of the loss with respect to the conv bias `[4]`.
    pub grad_bias: Vec<f32>,
    /// A texture PCA's UV image (sum per channel): the compact -> image gather path.
    pub texture_image_sums: Vec<f32>,
    /// The gradient of a loss on that image with respect to the PCA parameters.
    pub grad_texture_params: Vec<f32>,
    /// The differentiable hand layer on the procedural hands: per hand, the sums of the
    /// posed vertices' x, y, z.
    pub hand_vertex_sums: Vec<f32>,
    /// The gradient of a weighted sum of the vertices with respect to both hands' finger
    /// axis-angles.
    pub grad_hand_pose: Vec<f32>,
    /// The joints-only pass of the keypoint fit (`HandLayer::joints`): both hands' 21 joints
    /// flattened.
    pub hand_joints: Vec<f32>,
    /// The gradient of a weighted sum of the joints with respect to the finger pose.
    pub grad_joints_pose: Vec<f32>,
}

/// Whether two backends' values agree: `1e-4` absolute plus `2e-3` relative (different
/// float kernels: summation order, fused multiply-adds). `cargo xtask e2e` uses the same
/// tolerance on the JSON of separate processes.
pub fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-4 + 2e-3 * a.abs().max(b.abs())
}

impl BackendNumbers {
    /// Every field by name, flattened, in a fixed order.
    pub fn fields(&self) -> [(&'static str, Vec<f32>); 10] {
        [
            ("loss", vec![self.loss]),
            ("output", self.output.clone()),
            ("grad_weight", self.grad_weight.clone()),
            ("grad_bias", self.grad_bias.clone()),
            ("texture_image_sums", self.texture_image_sums.clone()),
            ("grad_texture_params", self.grad_texture_params.clone()),
            ("hand_vertex_sums", self.hand_vertex_sums.clone()),
            ("grad_hand_pose", self.grad_hand_pose.clone()),
            ("hand_joints", self.hand_joints.clone()),
            ("grad_joints_pose", self.grad_joints_pose.clone()),
        ]
    }
}

/// How one backend's numbers compare with a reference's.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BackendComparison {
    /// Values compared, over all fields.
    pub values: usize,
    /// The largest absolute difference over all values.
    pub max_abs_diff: f64,
    /// The fields that disagree beyond [`close`], each with its first differing value
    /// (`"grad_bias[2]: 0.1 vs 0.2"`) or its lengths.
    pub disagreements: Vec<String>,
}

/// Compares `other` with `reference`, field by field.
pub fn compare(reference: &BackendNumbers, other: &BackendNumbers) -> BackendComparison {
    let mut out = BackendComparison {
        values: 0,
        max_abs_diff: 0.0,
        disagreements: Vec::new(),
    };
    for ((field, a), (_, b)) in reference.fields().into_iter().zip(other.fields()) {
        if a.is_empty() || a.len() != b.len() {
            out.disagreements
                .push(format!("{field}: {} vs {} values", a.len(), b.len()));
            continue;
        }
        out.values += a.len();
        let mut first_bad = None;
        for (i, (&x, &y)) in a.iter().zip(&b).enumerate() {
            let (x, y) = (f64::from(x), f64::from(y));
            let d = (x - y).abs();
            // NaN never compares close and always counts as the largest difference.
            out.max_abs_diff = if d.is_nan() {
                f64::NAN
            } else {
                out.max_abs_diff.max(d)
            };
            if first_bad.is_none() && !close(x, y) {
                first_bad = Some(format!("{field}[{i}]: {x} vs {y}"));
            }
        }
        out.disagreements.extend(first_bad);
    }
    out
}

/// The outputs of [`hand_layer_check`].
type HandLayerOutputs = [Vec<f32>; 4];

fn missing_grad(what: &str) -> BittError {
    BittError::Invalid(format!("backend check: no gradient for {what}"))
}

/// The hand layer posing both procedural hands, with a gradient; then its joints-only pass,
/// with a gradient.
fn hand_layer_check(device: &Device) -> Result<HandLayerOutputs, BittError> {
    let models = bitt_mesh::procedural_pair();
    let ad = device.clone().autodiff();
    let layer = HandLayer::new(&models, &ad)?;
    let v = layer.num_vertices();
    let t2 = |values: Vec<f32>, shape: [usize; 2]| {
        Tensor::<2>::from_data(TensorData::new(values, shape), &ad)
    };
    let pose = t2(pattern(90, 0.4, 0.29, 0.3), [2, 45]).require_grad();
    let params = HandLayerParams {
        root_6d: t2(
            vec![1.0, 0.1, 0.0, -0.1, 1.0, 0.2, 0.9, -0.2, 0.1, 0.3, 1.0, 0.0],
            [2, 6],
        ),
        finger_pose: pose.clone(),
        betas: t2(pattern(20, 1.0, 0.41, 0.5), [2, 10]),
        trans: t2(vec![-0.1, 0.0, 0.6, 0.1, 0.02, 0.6], [2, 3]),
    };
    let out = layer.forward(&params);
    let weights = Tensor::<3>::from_data(
        TensorData::new(pattern(2 * v * 3, 1.0, 0.013, 0.2), [2, v, 3]),
        &ad,
    );
    let grads = (out.vertices.clone() * weights).sum().backward();
    let sums = out.vertices.without_autodiff().sum_dim(1).reshape([6]);
    let grad = pose
        .grad(&grads)
        .ok_or_else(|| missing_grad("the finger pose"))?;
    let pose_j = t2(pattern(90, 0.4, 0.29, 0.3), [2, 45]).require_grad();
    let params_j = HandLayerParams {
        finger_pose: pose_j.clone(),
        ..params
    };
    let joints = layer.joints(&params_j);
    let joint_weights = Tensor::<3>::from_data(
        TensorData::new(pattern(2 * 21 * 3, 1.0, 0.17, 0.4), [2, 21, 3]),
        &ad,
    );
    let grads_j = (joints.clone() * joint_weights).sum().backward();
    let grad_j = pose_j
        .grad(&grads_j)
        .ok_or_else(|| missing_grad("the finger pose of the joints"))?;
    Ok([
        to_host(sums)?,
        to_host(grad.reshape([90]))?,
        to_host(joints.without_autodiff().reshape([2 * 21 * 3]))?,
        to_host(grad_j.reshape([90]))?,
    ])
}

/// A small texture PCA on a 9x7 layout (every other texel used), deterministic.
fn texture_check(device: &Device) -> Result<(Vec<f32>, Vec<f32>), BittError> {
    let (w, h) = (9usize, 7usize);
    let texels: Vec<(u32, u32)> = (0..h as u32)
        .flat_map(|r| (0..w as u32).map(move |c| (r, c)))
        .filter(|(r, c)| (r + c) % 2 == 0)
        .collect();
    let layout = TextureLayout::from_texels(w, h, texels, None)?;
    let t = layout.num_texels();
    let k = 4;
    let mean = pattern(3 * t, 0.2, 0.31, 0.2)
        .into_iter()
        .map(|x| x + 0.5)
        .collect();
    let pca = TexturePca::new(layout, mean, pattern(3 * t * k, 0.05, 0.07, 1.1), k, 1.0)?;
    let ad = device.clone().autodiff();
    let tensors = pca.to_device(&ad);
    let params = Tensor::<1>::from_data(TensorData::new(vec![0.3f32, -0.8, 1.2, 0.1], [k]), &ad)
        .require_grad();
    let image = pca
        .layout
        .compact_to_image_tensor(tensors.texture(params.clone()), [0.1, 0.2, 0.3]);
    let weights = Tensor::<3>::from_data(
        TensorData::new(pattern(3 * h * w, 1.0, 0.17, 0.4), [3, h, w]),
        &ad,
    );
    let loss = (image.clone() * weights).sum();
    let grads = loss.backward();
    let sums = image.without_autodiff().sum_dim(2).sum_dim(1).reshape([3]);
    let grad = params
        .grad(&grads)
        .ok_or_else(|| missing_grad("the texture parameters"))?;
    Ok((to_host(sums)?, to_host(grad)?))
}

/// Runs the check on `device` (a plain device; autodiff is added here).
pub fn compute(device: &Device) -> Result<BackendNumbers, BittError> {
    let ad = device.clone().autodiff();
    let x = Tensor::<4>::from_data(
        TensorData::new(pattern(2 * 3 * 12 * 12, 0.5, 0.37, 0.1), [2, 3, 12, 12]),
        &ad,
    );
    let w = Tensor::<4>::from_data(
        TensorData::new(pattern(4 * 3 * 3 * 3, 0.2, 0.11, 0.7), [4, 3, 3, 3]),
        &ad,
    )
    .require_grad();
    let b = Tensor::<1>::from_data(TensorData::new(vec![0.05f32, -0.02, 0.01, 0.0], [4]), &ad)
        .require_grad();
    let m = Tensor::<2>::from_data(
        TensorData::new(pattern(576 * 5, 0.05, 0.013, 0.3), [576, 5]),
        &ad,
    );

    let y = conv2d(
        x,
        w.clone(),
        Some(b.clone()),
        ConvOptions::new([1, 1], [1, 1], [1, 1], 1),
    )
    .tanh();
    let z = y.reshape([2, 4 * 12 * 12]).matmul(m);
    let loss = (z.clone() * z.clone()).mean();
    let grads = loss.backward();

    let loss_v = to_host(loss.without_autodiff())?[0];
    let gw = w
        .grad(&grads)
        .ok_or_else(|| missing_grad("the conv weight"))?;
    let gb = b
        .grad(&grads)
        .ok_or_else(|| missing_grad("the conv bias"))?;
    let (texture_image_sums, grad_texture_params) = texture_check(device)?;
    let [
        hand_vertex_sums,
        grad_hand_pose,
        hand_joints,
        grad_joints_pose,
    ] = hand_layer_check(device)?;
    Ok(BackendNumbers {
        loss: loss_v,
        output: to_host(z.without_autodiff().reshape([10]))?,
        grad_weight: to_host(gw.reshape([108]))?,
        grad_bias: to_host(gb)?,
        texture_image_sums,
        grad_texture_params,
        hand_vertex_sums,
        grad_hand_pose,
        hand_joints,
        grad_joints_pose,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flex_numbers_are_finite_and_compare_equal_to_themselves() {
        let a = compute(&Device::flex()).unwrap();
        assert_eq!(a.output.len(), 10);
        assert_eq!(a.grad_weight.len(), 108);
        assert_eq!(a.hand_joints.len(), 126);
        assert!(a.loss > 0.0 && a.loss.is_finite());
        let same = compare(&a, &a);
        assert_eq!(same.values, 1 + 10 + 108 + 4 + 3 + 4 + 6 + 90 + 126 + 90);
        assert_eq!(same.max_abs_diff, 0.0);
        assert!(same.disagreements.is_empty());
        let mut b = a.clone();
        b.grad_bias[2] += 0.5;
        b.hand_joints.pop();
        let diff = compare(&a, &b);
        assert_eq!(diff.disagreements.len(), 2, "{:?}", diff.disagreements);
        assert!(diff.disagreements[0].starts_with("grad_bias[2]:"));
        assert_eq!(diff.disagreements[1], "hand_joints: 126 vs 125 values");
        assert!((diff.max_abs_diff - 0.5).abs() < 1e-6);
    }
}
