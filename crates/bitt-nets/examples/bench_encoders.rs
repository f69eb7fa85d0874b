//! Times forward + backward of the light and HTML networks' encoders on flex with
//! autodiff, batch 1: the encoder as the crate runs it (one custom operation per
//! convolution on flex) and the same layers composed from burn's `Conv2d` and ReLU (the
//! encoder before the custom operation). Prints one JSON line per encoder.
//!
//! `cargo run --release --workspace --example bench_encoders -- [paper|quick|tiny] [RUNS]`

use std::time::Instant;

use bitt_nets::{BittNetsConfig, ConvEncoderConfig, Preset};
use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Distribution, Tensor};

/// The encoder's layers as plain burn `Conv2d`s (the strided ones, then the 1x1 one).
fn burn_layers(c: &ConvEncoderConfig, device: &Device) -> Vec<Conv2d> {
    let widths = c.widths();
    let mut layers = Vec::new();
    let mut c_in = c.channels_in;
    for (i, &c_out) in widths.iter().enumerate() {
        let pad = if i + 1 == widths.len() { 0 } else { 1 };
        layers.push(
            Conv2dConfig::new([c_in, c_out], [4, 4])
                .with_stride([2, 2])
                .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
                .with_bias(false)
                .init(device),
        );
        c_in = c_out;
    }
    layers.push(
        Conv2dConfig::new([c_in, c.channels_out], [1, 1])
            .with_bias(false)
            .init(device),
    );
    layers
}

fn burn_forward(layers: &[Conv2d], image: Tensor<4>) -> Tensor<2> {
    let b = image.dims()[0];
    let (last, strided) = layers.split_last().expect("layers");
    let mut x = image;
    for layer in strided {
        x = relu(layer.forward(x));
    }
    let x = last.forward(x);
    let c = x.dims()[1];
    x.reshape([b, c]).tanh()
}

fn time(runs: usize, mut f: impl FnMut()) -> Vec<f64> {
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .collect()
}

fn main() {
    let mut args = std::env::args().skip(1);
    let preset: Preset = args
        .next()
        .unwrap_or_else(|| "paper".into())
        .parse()
        .expect("preset: paper, quick or tiny");
    let runs: usize = args.next().map_or(5, |r| r.parse().expect("runs"));
    let device = Device::flex().autodiff();
    let config = BittNetsConfig::preset(preset);
    let s = config.image_size;
    let image = Tensor::<4>::random([1, 3, s, s], Distribution::Default, &device);
    for (name, enc) in [
        ("light", config.light.encoder()),
        ("html", config.html.encoder()),
    ] {
        let net = enc.init(&device);
        let layers = burn_layers(&enc, &device);
        let fused = time(runs, || {
            let grads = net.forward(image.clone()).square().mean().backward();
            drop(grads);
        });
        let composed = time(runs, || {
            let grads = burn_forward(&layers, image.clone())
                .square()
                .mean()
                .backward();
            drop(grads);
        });
        println!(
            "{{\"net\":\"{name} encoder\",\"preset\":\"{preset}\",\"params\":{},\"input_shape\":[1,3,{s},{s}],\"seconds_fused\":{fused:?},\"seconds_burn_layers\":{composed:?}}}",
            net.num_params()
        );
    }
}
