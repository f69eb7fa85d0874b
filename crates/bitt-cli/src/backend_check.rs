//! A small, fixed, real computation run on one backend: a padded conv2d with bias, `tanh`,
//! a matmul and a mean-square loss, then the gradients of the conv weight and bias. The
//! numbers are printed as JSON so `cargo xtask e2e` can compare backends.

use std::time::Instant;

use anyhow::{Context, Result};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};

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
    Ok(Numbers {
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
