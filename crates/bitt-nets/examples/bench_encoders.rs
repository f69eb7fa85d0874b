//! Times forward + backward of the light and HTML networks' encoders on flex with
//! autodiff, batch 1: the encoder as the crate runs it (one custom operation per
//! convolution on flex) and the same layers composed from burn's `Conv2d` and ReLU (`ConvEncoder::forward_burn_layers`, the encoder before the custom operation). Prints one JSON line per encoder.
//!
//! `cargo run --release --workspace --example bench_encoders -- [paper|quick|tiny] [RUNS]`

use std::time::Instant;

use bitt_nets::{BittNetsConfig, Preset};
use burn::module::Module;
use burn::tensor::{Device, Distribution, Tensor};

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
        let fused = time(runs, || {
            let grads = net.forward(image.clone()).square().mean().backward();
            drop(grads);
        });
        let composed = time(runs, || {
            let grads = net
                .forward_burn_layers(image.clone())
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
