//! `cargo xtask bench <what> [ARGS]`: timings measured side by side with a baseline in the
//! same run, printed with their ratio.
//!
//! - `bench btr [--preset P] [--runs N] [--conv fused|shifted-sum|im2col|burn]`: one forward +
//!   backward of BTR for both hands at the preset's texel count (206,330 for `paper`) on
//!   flex, against the PyTorch module of `xtask/bench/nets_torch.py` on the CPU.
//! - `bench albedo [--preset P] [--runs N]`: the same for the albedo U-Net at the preset's
//!   image size (256 x 256 for `paper`).
//! - `bench step [--preset P] [--runs N]`: a training step of the four networks as the
//!   trainer runs them (light and HTML encoders on one image, the albedo U-Net on a batch of
//!   4, BTR on both hands): forward, backward and the Adam update, against the same step of
//!   the PyTorch modules with `torch.optim.Adam`. Rendering, unwrapping and the losses are
//!   not in it (the reference renders with PyTorch3D).
//! - `bench nets`: BTR and the albedo U-Net.
//!
//! The burn side runs in the release `bitt bench-nets`; the PyTorch side with `python3`
//! (override with `BITT_PYTHON`). When torch is not importable the burn timings are still
//! printed, with a clear note. Each side reports the best of its runs.
//!
//! - `bench render [--runs N]`: the renderer's stages forward and backward on flex and on
//!   wgpu (the `bench_render` example of `bitt`), wgpu against flex; see `bench_render.rs`.
//!
//! - `bench detect [--runs N] [PHOTO...]`: the two-hand search against one pass of
//!   MediaPipe's own pipeline with the same networks (the `bench_detect` example of
//!   `bitt-detect`), on each photo (default: the demo frames, when `../shared` is present) and
//!   on a 1920 x 1080 canvas holding it enlarged.
//!
//! New benchmarks are another arm in [`bench`].

use std::path::PathBuf;
use std::process::Command;

use anyhow::{Context, Result, bail};

/// Dispatches `cargo xtask bench <what>`.
pub fn bench(args: &[String]) -> Result<()> {
    let Some((what, rest)) = args.split_first() else {
        bail!(
            "usage: cargo xtask bench <btr|albedo|step|nets> [--preset P] [--runs N] [--conv C] \
             | cargo xtask bench render [--runs N] | cargo xtask bench detect [--runs N] [PHOTO...]"
        );
    };
    match what.as_str() {
        "btr" => net_vs_torch("btr", rest),
        "albedo" => net_vs_torch("albedo", rest),
        "step" => net_vs_torch("step", rest),
        "nets" => {
            net_vs_torch("btr", rest)?;
            net_vs_torch("albedo", rest)
        }
        "render" => crate::bench_render::run(rest),
        "detect" => {
            let bin = crate::build_example("bench_detect")?;
            let status = Command::new(&bin)
                .args(rest)
                .status()
                .context("running the bench_detect example")?;
            if !status.success() {
                bail!("bench_detect failed ({status})");
            }
            Ok(())
        }
        other => bail!("unknown benchmark `{other}`; try btr, albedo, step, nets, render, detect"),
    }
}

/// Options shared by the network benchmarks.
struct NetOptions {
    preset: String,
    runs: usize,
    conv: Option<String>,
}

fn parse(args: &[String]) -> Result<NetOptions> {
    let mut o = NetOptions {
        preset: "paper".into(),
        runs: 2,
        conv: None,
    };
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let value = it.next().with_context(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--preset" => o.preset = value.clone(),
            "--runs" => o.runs = value.parse().context("--runs takes a number")?,
            "--conv" => o.conv = Some(value.clone()),
            other => bail!("unknown option {other}; expected --preset, --runs, --conv"),
        }
    }
    Ok(o)
}

fn best(v: &serde_json::Value) -> Option<f64> {
    v["seconds"]
        .as_array()?
        .iter()
        .filter_map(|s| s.as_f64())
        .reduce(f64::min)
}

fn python() -> String {
    std::env::var("BITT_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Runs one command that prints one JSON value; returns it parsed.
fn json_of(mut cmd: Command, what: &str) -> Result<serde_json::Value> {
    let out = cmd.output().with_context(|| format!("running {what}"))?;
    if !out.status.success() {
        bail!(
            "{what} failed ({}):\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim()).with_context(|| format!("{what} printed {text}"))
}

fn net_vs_torch(net: &str, args: &[String]) -> Result<()> {
    let o = parse(args)?;
    let bin = crate::build_bitt()?;
    // The sizes come from the preset, as `bitt nets --no-run` reports them.
    let mut info = Command::new(&bin);
    info.args(["nets", "--no-run", "--preset", &o.preset]);
    let info = json_of(info, "bitt nets")?;
    let texels = info["num_texels"].as_u64().context("num_texels")?;
    let image = info["image_size"].as_u64().context("image_size")?;
    let config = &info["config"];

    println!(
        "bench {net} --preset {} ({} runs each, best shown)",
        o.preset, o.runs
    );
    let mut cmd = Command::new(&bin);
    cmd.args(["bench-nets", net, "--preset", &o.preset, "--runs"])
        .arg(o.runs.to_string());
    if let Some(conv) = &o.conv {
        cmd.args(["--conv", conv]);
    }
    let burn = json_of(cmd, "bitt bench-nets")?;
    let burn_s = best(&burn).context("no burn timings")?;
    println!(
        "  burn  (flex, {} params, conv {}): {:.2} s  {}",
        burn["params"],
        burn["conv"].as_str().unwrap_or("-"),
        burn_s,
        burn["seconds"]
    );

    let have_torch = Command::new(python())
        .args(["-c", "import torch"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !have_torch {
        println!(
            "  torch: NOT AVAILABLE: `{} -c 'import torch'` failed, so there is no baseline \
             and no ratio (install: pip install torch --index-url \
             https://download.pytorch.org/whl/cpu, or where that index is unreachable the \
             PyPI wheel, pip install torch; then BITT_PYTHON names its python if it is not \
             python3)",
            python()
        );
        return Ok(());
    }
    let script: PathBuf = crate::root().join("xtask/bench/nets_torch.py");
    let mut cmd = Command::new(python());
    cmd.arg(&script)
        .arg(net)
        .arg("--runs")
        .arg(o.runs.to_string());
    let channels = config["btr"]["channels"]
        .as_array()
        .context("btr channels")?
        .iter()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(",");
    if net != "albedo" {
        cmd.arg("--texels")
            .arg(texels.to_string())
            .arg("--channels")
            .arg(&channels);
    }
    if net != "btr" {
        cmd.arg("--image")
            .arg(image.to_string())
            .arg("--ngf")
            .arg(config["albedo"]["base_channels"].to_string())
            .arg("--num-downs")
            .arg(config["albedo"]["num_downs"].to_string());
    }
    if net == "step" {
        cmd.arg("--light-base")
            .arg(config["light"]["base_channels"].to_string())
            .arg("--html-base")
            .arg(config["html"]["base_channels"].to_string())
            .arg("--coefficients")
            .arg(config["html"]["coefficients_per_hand"].to_string());
    }
    let torch = json_of(cmd, "nets_torch.py")?;
    let torch_s = best(&torch).context("no torch timings")?;
    println!(
        "  torch ({} {} threads, {} params): {:.2} s  {}",
        torch["torch"].as_str().unwrap_or("?"),
        torch["threads"],
        torch["params"],
        torch_s,
        torch["seconds"]
    );
    if torch["params"] != burn["params"] {
        println!("  WARNING: parameter counts differ: the two modules are not the same network");
    }
    println!(
        "  ratio burn / torch = {:.2} ({})",
        burn_s / torch_s,
        if burn_s <= torch_s {
            "burn is as fast or faster"
        } else {
            "burn is slower"
        }
    );
    Ok(())
}
