//! A small, fixed, real computation run on one backend: a padded conv2d with bias, `tanh`,
//! a matmul and a mean-square loss, then the gradients of the conv weight and bias; and a
//! texture PCA turned into a UV image by the layout's gather, with the gradient of a loss on
//! the image with respect to the PCA parameters; and the differentiable hand layer posing
//! both procedural hands, with the gradient with respect to the finger pose. The
//! numbers are printed as JSON so `cargo xtask e2e` can compare backends.

use std::time::Instant;

use anyhow::{Context, Result};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};

use bitt_texture::{TextureLayout, TexturePca};

use crate::device::DeviceName;

/// Deterministic inputs: smooth, non-symmetric patterns (no RNG, so every backend sees the
/// same bits).
fn pattern(n: usize, scale: f32, freq: f32, phase: f32) -> Vec<f32> {
    (0..n)
        .map(|i| scale * ((i as f32) * freq + phase).sin())
        .collect()
}

/// The numbers the check computes.
#[derive(Debug, serde::Serialize)]
struct Numbers {
    loss: f32,
    output: Vec<f32>,
    grad_weight: Vec<f32>,
    grad_bias: Vec<f32>,
    /// A texture PCA's UV image (sum per channel) and the gradient of a loss on that image
    /// with respect to the PCA parameters: the compact -> image gather path.
    texture_image_sums: Vec<f32>,
    grad_texture_params: Vec<f32>,
    /// The differentiable hand layer on the procedural hands: per hand, the sums of the
    /// posed vertices' x, y, z, and the gradient of a weighted sum of the vertices with
    /// respect to both hands' finger axis-angles.
    hand_vertex_sums: Vec<f32>,
    grad_hand_pose: Vec<f32>,
    /// The joints-only pass of the keypoint fit (`HandLayer::joints`): both hands' 21 joints
    /// flattened, and the gradient of a weighted sum of them with respect to the finger pose.
    hand_joints: Vec<f32>,
    grad_joints_pose: Vec<f32>,
}

/// The outputs of [`hand_layer_check`].
type HandLayerOutputs = [Vec<f32>; 4];

/// The hand layer (`bitt::hand_layer`) posing both procedural hands, with a gradient; then
/// its joints-only pass, with a gradient.
fn hand_layer_check(device: &Device) -> Result<HandLayerOutputs> {
    use bitt::hand_layer::{HandLayer, HandLayerParams};
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
        .context("no gradient for the finger pose")?;
    let read = |t: Tensor<1>| {
        t.into_data()
            .try_to_vec::<f32>()
            .map_err(|e| anyhow::anyhow!("{e:?}"))
    };
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
        .context("no gradient of the joints for the finger pose")?;
    Ok([
        read(sums)?,
        read(grad.reshape([90]))?,
        read(joints.without_autodiff().reshape([2 * 21 * 3]))?,
        read(grad_j.reshape([90]))?,
    ])
}

/// A small texture PCA on a 9x7 layout (every other texel used), deterministic.
fn texture_check(device: &Device) -> Result<(Vec<f32>, Vec<f32>)> {
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
        .context("no gradient for the texture parameters")?;
    let read = |t: Tensor<1>| {
        t.into_data()
            .try_to_vec::<f32>()
            .map_err(|e| anyhow::anyhow!("{e:?}"))
    };
    Ok((read(sums)?, read(grad)?))
}

/// Result of the check, printed as one JSON line.
#[derive(Debug, serde::Serialize)]
struct CheckOutput {
    device: DeviceName,
    #[serde(flatten)]
    numbers: Numbers,
    seconds: f64,
}

fn compute(device: &Device) -> Result<Numbers> {
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

    let vec = |t: Tensor<1>| -> Result<Vec<f32>> {
        t.into_data()
            .try_to_vec::<f32>()
            .map_err(|e| anyhow::anyhow!("reading back a tensor: {e:?}"))
    };
    let loss_v = vec(loss.clone().without_autodiff())?[0];
    let gw = w.grad(&grads).context("no gradient for the conv weight")?;
    let gb = b.grad(&grads).context("no gradient for the conv bias")?;
    let (texture_image_sums, grad_texture_params) = texture_check(device)?;
    let [
        hand_vertex_sums,
        grad_hand_pose,
        hand_joints,
        grad_joints_pose,
    ] = hand_layer_check(device)?;
    Ok(Numbers {
        hand_vertex_sums,
        grad_hand_pose,
        hand_joints,
        grad_joints_pose,
        texture_image_sums,
        grad_texture_params,
        loss: loss_v,
        output: vec(z.without_autodiff().reshape([10]))?,
        grad_weight: vec(gw.reshape([108]))?,
        grad_bias: vec(gb)?,
    })
}

/// Runs the check on `name` and prints one JSON line.
pub fn run(name: DeviceName) -> Result<()> {
    let device = name.device()?;
    let start = Instant::now();
    let numbers = compute(&device)?;
    let out = CheckOutput {
        device: name,
        numbers,
        seconds: start.elapsed().as_secs_f64(),
    };
    println!("{}", serde_json::to_string(&out)?);
    Ok(())
}
