//! `act(InstanceNorm(conv2d(x)))` for the image networks: one custom operation on flex
//! (`fused::conv2d`), burn's composition of `Conv2d`, `InstanceNorm` and the activation on
//! every other backend (the same function).

use burn::nn::conv::Conv2d;
use burn::nn::{InstanceNorm, PaddingConfig2d};
use burn::tensor::Tensor;
use burn::tensor::activation::{leaky_relu, relu, sigmoid};
use burn::tensor::ops::ConvOptions;

pub(crate) use crate::fused::conv2d::Activation;
use crate::fused::conv2d::{Conv2dBlock, Norm2d, conv2d_norm_act};

/// `act(norm(conv(x)))`, `norm` optional.
///
/// # Shapes
/// - `x`: `[B, C_in, H, W]`
/// - output: `[B, C_out, OH, OW]` as `conv.forward(x)`
pub(crate) fn conv_norm_act(
    conv: &Conv2d,
    norm: Option<&InstanceNorm>,
    act: Activation,
    x: Tensor<4>,
) -> Tensor<4> {
    if let Some(y) = fused(conv, norm, act, &x) {
        return y;
    }
    compose(conv, norm, act, x)
}

/// The custom operation, when the layers fit it and the tensors live on flex.
fn fused(
    conv: &Conv2d,
    norm: Option<&InstanceNorm>,
    act: Activation,
    x: &Tensor<4>,
) -> Option<Tensor<4>> {
    let padding = match conv.padding {
        PaddingConfig2d::Valid => [0, 0],
        PaddingConfig2d::Explicit(top, left, bottom, right) if top == bottom && left == right => {
            [top, left]
        }
        _ => return None,
    };
    if conv.dilation != [1, 1] || conv.groups != 1 {
        return None;
    }
    let weight = conv.weight.val();
    let bias = conv.bias.as_ref().map(|b| b.val());
    let affine = match norm {
        Some(n) => match (&n.gamma, &n.beta) {
            (Some(g), Some(b)) => Some((g.val(), b.val())),
            (None, None) => None,
            _ => return None,
        },
        None => None,
    };
    let block = Conv2dBlock {
        weight: &weight,
        bias: bias.as_ref(),
        stride: conv.stride,
        padding,
        norm: norm.map(|n| Norm2d {
            epsilon: n.epsilon,
            affine: affine.as_ref().map(|(g, b)| (g, b)),
        }),
        act,
    };
    conv2d_norm_act(x, &block)
}

/// `act(conv2d(x, weight) + bias)`, stride 1, no padding, for a weight that is not a
/// layer's (one custom operation on flex, burn's `conv2d` elsewhere).
///
/// # Shapes
/// - `x`: `[B, C_in, H, W]`; `weight`: `[C_out, C_in, kh, kw]`; `bias`: `[C_out]`
/// - output: `[B, C_out, H - kh + 1, W - kw + 1]`
pub(crate) fn conv_act(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    act: Activation,
) -> Tensor<4> {
    let block = Conv2dBlock {
        weight: &weight,
        bias: bias.as_ref(),
        stride: [1, 1],
        padding: [0, 0],
        norm: None,
        act,
    };
    if let Some(y) = conv2d_norm_act(&x, &block) {
        return y;
    }
    let options = ConvOptions::new([1, 1], [0, 0], [1, 1], 1);
    activate(act, burn::tensor::module::conv2d(x, weight, bias, options))
}

/// burn's composition: `Conv2d::forward`, `InstanceNorm::forward`, the activation.
pub(crate) fn compose(
    conv: &Conv2d,
    norm: Option<&InstanceNorm>,
    act: Activation,
    x: Tensor<4>,
) -> Tensor<4> {
    let y = conv.forward(x);
    let y = match norm {
        Some(n) => n.forward(y),
        None => y,
    };
    activate(act, y)
}

/// The activation as a burn operation.
pub(crate) fn activate<const D: usize>(act: Activation, y: Tensor<D>) -> Tensor<D> {
    match act {
        Activation::Identity => y,
        Activation::Relu => relu(y),
        Activation::LeakyRelu(slope) => leaky_relu(y, slope),
        Activation::Sigmoid => sigmoid(y),
    }
}

#[cfg(test)]
mod tests {
    use burn::module::Param;
    use burn::nn::InstanceNormConfig;
    use burn::nn::conv::Conv2dConfig;
    use burn::tensor::Device;

    use super::*;
    use bitt_testkit::{assert_close, devices, random, to_vec};

    /// One test case: `[batch, c_in, c_out]`, input size, kernel, stride, padding, bias,
    /// norm (`Some(affine)`), activation.
    type Case = (
        [usize; 3],
        [usize; 2],
        usize,
        usize,
        usize,
        bool,
        Option<bool>,
        Activation,
    );

    const LEAKY: Activation = Activation::LeakyRelu(0.2);
    const RELU: Activation = Activation::Relu;
    const ID: Activation = Activation::Identity;

    /// The U-Net's and the encoders' blocks, odd sizes, batches above one.
    const CASES: [Case; 9] = [
        ([2, 3, 5], [9, 7], 4, 2, 1, true, None, LEAKY),
        ([1, 4, 6], [8, 8], 4, 2, 1, false, Some(true), LEAKY),
        ([2, 5, 4], [7, 5], 1, 1, 0, false, Some(false), ID),
        ([3, 4, 3], [6, 6], 1, 1, 0, true, None, Activation::Relu),
        ([2, 6, 3], [7, 9], 3, 1, 0, true, None, Activation::Sigmoid),
        ([2, 4, 5], [8, 8], 4, 2, 0, false, None, Activation::Relu),
        ([1, 3, 4], [4, 4], 4, 2, 0, false, None, Activation::Relu),
        ([2, 3, 4], [9, 11], 3, 1, 1, true, Some(true), RELU),
        ([2, 7, 6], [13, 10], 4, 2, 1, false, Some(false), LEAKY),
    ];

    /// The case's layers on `device`, with random parameters (norm scale and shift too).
    fn layers(case: &Case, device: &Device) -> (Conv2d, Option<InstanceNorm>) {
        let ([_, c_in, c_out], _, k, s, p, bias, norm, _) = *case;
        let mut conv = Conv2dConfig::new([c_in, c_out], [k, k])
            .with_stride([s, s])
            .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
            .with_bias(bias)
            .init(device);
        conv.weight = Param::from_tensor(random([c_out, c_in, k, k], 11, device).mul_scalar(0.5));
        if bias {
            conv.bias = Some(Param::from_tensor(random([c_out], 12, device)));
        }
        let norm = norm.map(|affine| {
            let mut n = InstanceNormConfig::new(c_out)
                .with_affine(affine)
                .init(device);
            if affine {
                n.gamma = Some(Param::from_tensor(
                    random([c_out], 13, device).add_scalar(1.5),
                ));
                n.beta = Some(Param::from_tensor(random([c_out], 14, device)));
            }
            n
        });
        (conv, norm)
    }

    fn input(case: &Case, device: &Device) -> Tensor<4> {
        let ([b, c_in, _], [h, w], ..) = *case;
        random([b, c_in, h, w], 15, device).mul_scalar(2.0)
    }

    /// Values and every gradient (input, weight, bias, norm scale and shift) of the custom
    /// operation against burn's `Conv2d` + `InstanceNorm` + activation on flex.
    #[test]
    fn fused_conv2d_matches_burn_values_and_gradients() {
        let device = Device::flex().autodiff();
        for case in &CASES {
            let (conv, norm) = layers(case, &device);
            let act = case.7;
            let x = input(case, &device).require_grad();
            let fused_y = fused(&conv, norm.as_ref(), act, &x).expect("flex runs the operation");
            let burn_y = compose(&conv, norm.as_ref(), act, x.clone());
            assert_eq!(fused_y.dims(), burn_y.dims(), "{case:?}");
            let what = format!("{case:?}");
            assert_close(
                &to_vec(fused_y.clone()),
                &to_vec(burn_y.clone()),
                1e-4,
                &format!("values {what}"),
            );
            let g = random(fused_y.dims(), 16, &device);
            let grads_fused = (fused_y * g.clone()).sum().backward();
            let grads_burn = (burn_y * g).sum().backward();
            let grad = |t: &Tensor<4>, grads| to_vec(t.grad(grads).expect("gradient"));
            assert_close(
                &grad(&x, &grads_fused),
                &grad(&x, &grads_burn),
                1e-4,
                &format!("dx {what}"),
            );
            let w = conv.weight.val();
            assert_close(
                &grad(&w, &grads_fused),
                &grad(&w, &grads_burn),
                1e-4,
                &format!("dW {what}"),
            );
            let mut params: Vec<(&str, Tensor<1>)> = Vec::new();
            if let Some(b) = &conv.bias {
                params.push(("bias", b.val()));
            }
            if let Some(n) = &norm
                && let (Some(gm), Some(bt)) = (&n.gamma, &n.beta)
            {
                params.push(("gamma", gm.val()));
                params.push(("beta", bt.val()));
            }
            for (name, p) in params {
                let get = |grads| to_vec(p.grad(grads).expect("gradient"));
                assert_close(
                    &get(&grads_fused),
                    &get(&grads_burn),
                    1e-4,
                    &format!("d{name} {what}"),
                );
            }
        }
    }

    /// Without autodiff the operation runs too (inference), with the same values.
    #[test]
    fn fused_conv2d_runs_without_autodiff() {
        let device = Device::flex();
        for case in &CASES[..3] {
            let (conv, norm) = layers(case, &device);
            let x = input(case, &device);
            let y = fused(&conv, norm.as_ref(), case.7, &x).expect("flex");
            let r = compose(&conv, norm.as_ref(), case.7, x);
            assert_close(&to_vec(y), &to_vec(r), 1e-4, "inference");
        }
    }

    /// On another backend (ndarray, wgpu) the operation declines and the block is burn's
    /// composition; the same parameters give the same values as flex's operation.
    #[test]
    fn fused_conv2d_declines_off_flex() {
        for (name, plain) in devices().into_iter().filter(|(n, _)| *n != "flex") {
            for device in [plain.clone(), plain.autodiff()] {
                for case in &CASES {
                    let (conv, norm) = layers(case, &device);
                    let x = input(case, &device);
                    assert!(fused(&conv, norm.as_ref(), case.7, &x).is_none(), "{name}");
                    let y = conv_norm_act(&conv, norm.as_ref(), case.7, x.clone());
                    let flex = Device::flex();
                    let (conv_f, norm_f) = layers(case, &flex);
                    let yf = conv_norm_act(&conv_f, norm_f.as_ref(), case.7, input(case, &flex));
                    assert_close(&to_vec(y), &to_vec(yf), 1e-4, &format!("{name} {case:?}"));
                }
            }
        }
    }
}
