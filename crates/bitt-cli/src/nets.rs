//! `bitt nets` (parameter counts and output shapes of the four networks) and `bitt
//! bench-nets` (forward + backward timings of BTR and the albedo U-Net), both as JSON.

use anyhow::Result;
use bitt_bench::net_shapes::net_shapes;
use bitt_bench::nets_bench::{BenchedNet, bench_net};
use bitt_nets::{BittNetsConfig, ConvImpl, Preset};

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

/// `bitt nets`: prints each network's parameter count, input and output shapes as JSON.
pub fn run(args: &NetsArgs) -> Result<()> {
    let device = args.device.device()?;
    let config = BittNetsConfig::preset(args.preset);
    let mut out = net_shapes(&config, !args.no_run, &device)?;
    out["preset"] = serde_json::json!(args.preset);
    out["device"] = serde_json::json!(args.device);
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// `bitt bench-nets`: times forward + backward of one network ([`bitt_bench::nets_bench`]);
/// prints JSON.
pub fn bench(args: &BenchNetsArgs) -> Result<()> {
    let device = args.device.device()?;
    let mut config = BittNetsConfig::preset(args.preset);
    config.btr.conv = args.conv.into();
    if let Some(t) = args.texels {
        config.num_texels = t;
    }
    let net = match args.net {
        BenchNet::Btr => BenchedNet::Btr,
        BenchNet::Albedo => BenchedNet::Albedo,
        BenchNet::Step => BenchedNet::Step,
    };
    let b = bench_net(net, &config, args.runs, &device)?;
    let out = b.report(
        &config,
        serde_json::json!(args.preset),
        serde_json::json!(args.device),
    );
    println!("{out}");
    Ok(())
}
