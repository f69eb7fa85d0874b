//! `bitt nets` (parameter counts and output shapes of the four networks) and `bitt
//! bench-nets` (forward + backward timings of BTR and the albedo U-Net), both as JSON.

use std::time::Instant;

use anyhow::{Context, Result};
use burn::module::Module;
use burn::tensor::{Device, Distribution, Tensor};

use bitt_nets::{BittNetsConfig, ConvImpl, LightParams, Preset};

use crate::device::DeviceName;

/// Which network `bench-nets` times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchNet {
    /// BTR, both hands, at the preset's texel count.
    Btr,
    /// The albedo U-Net at the preset's image size.
    Albedo,
    /// A training step of all four networks as the trainer runs them: light and HTML
    /// encoders on one image, the albedo U-Net on a batch of 4 (the hand image and the three
    /// consistency renders), BTR on both hands; forward, backward and the Adam update.
    Step,
}

/// The 1-D convolution of BTR (`--conv`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ConvChoice {
    /// One matmul over stacked shifted views.
    Im2col,
    /// One matmul per kernel tap, summed, from burn tensor operations.
    ShiftedSum,
    /// burn's conv1d.
    Burn,
    /// Conv + group norm + SiLU as one custom operation on flex (the default).
    Fused,
}

impl From<ConvChoice> for ConvImpl {
    fn from(c: ConvChoice) -> Self {
        match c {
            ConvChoice::Im2col => ConvImpl::Im2col,
            ConvChoice::ShiftedSum => ConvImpl::ShiftedSum,
            ConvChoice::Burn => ConvImpl::Burn,
            ConvChoice::Fused => ConvImpl::Fused,
        }
    }
}

/// Arguments of `bitt nets`.
#[derive(Debug, clap::Args)]
pub struct NetsArgs {
    /// paper, quick or tiny.
    #[arg(long, default_value = "paper")]
    preset: Preset,
    /// flex, ndarray, wgpu or cuda.
    #[arg(long, default_value = "flex")]
    device: DeviceName,
    /// Only count parameters; do not run the networks for their output shapes.
    #[arg(long)]
    no_run: bool,
}

/// Arguments of `bitt bench-nets`.
#[derive(Debug, clap::Args)]
pub struct BenchNetsArgs {
    /// The network to time.
    #[arg(value_enum)]
    net: BenchNet,
    /// paper, quick or tiny.
    #[arg(long, default_value = "paper")]
    preset: Preset,
    /// flex, ndarray, wgpu or cuda.
    #[arg(long, default_value = "flex")]
    device: DeviceName,
    /// Timed forward + backward runs (no warm-up: the first run is included).
    #[arg(long, default_value_t = 2)]
    runs: usize,
    /// BTR texel count (default: the preset's).
    #[arg(long)]
    texels: Option<usize>,
    /// How BTR's 1-D convolutions are evaluated.
    #[arg(long, value_enum, default_value = "fused")]
    conv: ConvChoice,
}

fn dims<const D: usize>(t: &Tensor<D>) -> Vec<usize> {
    t.dims().to_vec()
}

/// `bitt nets`: prints each network's parameter count, input and output shapes as JSON.
pub fn run(args: &NetsArgs) -> Result<()> {
    let device = args.device.device()?;
    let config = BittNetsConfig::preset(args.preset);
    let nets = config.init(&device)?;
    let (s, t) = (config.image_size, config.num_texels);
    let image_shape = vec![1, 3, s, s];
    let texel_shape = vec![1, 3, t];
    let mut out = serde_json::json!({
        "preset": args.preset,
        "device": args.device,
        "image_size": s,
        "num_texels": t,
        "networks": {
            "albedo": { "params": nets.albedo.num_params(), "input": [image_shape] },
            "light": { "params": nets.light.num_params(), "input": [image_shape] },
            "html": { "params": nets.html.num_params(), "input": [image_shape] },
            "btr": {
                "params": nets.btr.num_params(),
                "input": [texel_shape, texel_shape],
                "bidirectional": nets.btr.bidirectional(),
            },
        },
        "config": config,
    });
    if !args.no_run {
        let image = Tensor::<4>::random([1, 3, s, s], Distribution::Default, &device);
        let n = &mut out["networks"];
        n["albedo"]["output"] = serde_json::json!([dims(&nets.albedo.forward(image.clone()))]);
        let raw = nets.light.forward(image.clone());
        n["light"]["output"] = serde_json::json!([dims(&raw)]);
        let light = LightParams::from_raw(raw);
        n["light"]["light_params"] = serde_json::json!({
            "ambient": dims(&light.ambient),
            "diffuse": dims(&light.diffuse),
            "specular": dims(&light.specular),
            "location": dims(&light.location),
        });
        let html = nets.html.predict(image);
        n["html"]["output"] = serde_json::json!([dims(&html.left), dims(&html.right)]);
        let x = Tensor::<3>::random([1, 3, t], Distribution::Default, &device);
        let y = nets.btr.forward(x.clone(), x);
        n["btr"]["output"] = serde_json::json!([dims(&y.left), dims(&y.right)]);
    }
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// One forward + backward; returns the seconds it took.
fn time_once(f: impl FnOnce() -> Result<()>) -> Result<f64> {
    let start = Instant::now();
    f()?;
    Ok(start.elapsed().as_secs_f64())
}

fn mean_square<const D: usize>(t: Tensor<D>) -> Tensor<1> {
    t.square().mean()
}

/// `bitt bench-nets`: times forward + backward of one network; prints JSON.
pub fn bench(args: &BenchNetsArgs) -> Result<()> {
    let device: Device = args.device.device()?.autodiff();
    let mut config = BittNetsConfig::preset(args.preset);
    config.btr.conv = args.conv.into();
    if let Some(t) = args.texels {
        config.num_texels = t;
    }
    config.validate()?;
    let (s, t) = (config.image_size, config.num_texels);
    let mut seconds = Vec::with_capacity(args.runs);
    let (params, input_shape) = match args.net {
        BenchNet::Btr => {
            let net = config.btr.init(&device);
            let left = Tensor::<3>::random([1, 3, t], Distribution::Default, &device);
            let right = Tensor::<3>::random([1, 3, t], Distribution::Default, &device);
            for _ in 0..args.runs {
                seconds.push(time_once(|| {
                    let out = net.forward(left.clone(), right.clone());
                    let grads = (mean_square(out.left) + mean_square(out.right)).backward();
                    check_grads(&net, &grads)
                })?);
            }
            (net.num_params(), vec![1, 3, t])
        }
        BenchNet::Albedo => {
            let net = config.albedo.init(&device);
            let image = Tensor::<4>::random([1, 3, s, s], Distribution::Default, &device);
            for _ in 0..args.runs {
                seconds.push(time_once(|| {
                    let grads = mean_square(net.forward(image.clone())).backward();
                    check_grads(&net, &grads)
                })?);
            }
            (net.num_params(), vec![1, 3, s, s])
        }
        BenchNet::Step => {
            let mut nets = config.init(&device)?;
            let mut adam = bitt::optim::Adam::new(bitt::OptimConfig::default());
            let image = Tensor::<4>::random([1, 3, s, s], Distribution::Default, &device);
            let batch = Tensor::<4>::random([4, 3, s, s], Distribution::Default, &device);
            let left = Tensor::<3>::random([1, 3, t], Distribution::Default, &device);
            let right = Tensor::<3>::random([1, 3, t], Distribution::Default, &device);
            for _ in 0..args.runs {
                seconds.push(time_once(|| {
                    let out = nets.btr.forward(left.clone(), right.clone());
                    let loss = mean_square(nets.light.forward(image.clone()))
                        + mean_square(nets.html.forward(image.clone()))
                        + mean_square(nets.albedo.forward(batch.clone()))
                        + mean_square(out.left)
                        + mean_square(out.right);
                    let grads = loss.backward();
                    check_grads(&nets, &grads)?;
                    nets = adam.step(nets.clone(), &grads, 1e-3);
                    // Read a parameter back, so the timing includes the whole update.
                    check_params(&nets)
                })?);
            }
            (nets.num_params(), vec![1, 3, s, s])
        }
    };
    let out = serde_json::json!({
        "net": match args.net {
            BenchNet::Btr => "btr",
            BenchNet::Albedo => "albedo",
            BenchNet::Step => "step",
        },
        "preset": args.preset,
        "device": args.device,
        "conv": format!("{:?}", config.btr.conv),
        "params": params,
        "input_shape": input_shape,
        "seconds": seconds,
    });
    println!("{out}");
    Ok(())
}

/// Reads the first parameter back (its sum must be finite).
fn check_params<M: Module>(net: &M) -> Result<()> {
    struct First {
        value: Option<f32>,
    }
    impl burn::module::ModuleVisitor for First {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            if self.value.is_none() {
                self.value = Some(param.val().sum().into_scalar::<f32>());
            }
        }
    }
    let mut first = First { value: None };
    net.visit(&mut first);
    match first.value {
        Some(v) if v.is_finite() => Ok(()),
        other => anyhow::bail!("the first parameter's sum is {other:?} after the update"),
    }
}

/// Reads one gradient back, so the timing includes the whole backward pass.
fn check_grads<M: Module>(net: &M, grads: &burn::tensor::Gradients) -> Result<()> {
    struct First<'a> {
        grads: &'a burn::tensor::Gradients,
        value: Option<f32>,
    }
    impl burn::module::ModuleVisitor for First<'_> {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            if self.value.is_none()
                && let Some(g) = param.val().grad(self.grads)
            {
                self.value = Some(g.sum().into_scalar::<f32>());
            }
        }
    }
    let mut first = First { grads, value: None };
    net.visit(&mut first);
    first.value.context("no parameter received a gradient")?;
    Ok(())
}
