//! Project automation, run as `cargo xtask <command>` (alias in `.cargo/config.toml`).
//!
//! Heavy work always runs the `bitt` binary in release mode: nobody waits on a debug build
//! of a numeric loop. Commands:
//!
//! - `demo [ARGS]`: the built-in demo scene (`bitt demo`).
//! - `test`: the whole test suite (release build) and then `e2e`.
//! - `e2e`: the same computation on every backend (flex, ndarray, wgpu), compared.
//! - `pose-hands`, `convert-mano`, `texture`, `convert-html`, `render` ARGS: forwarded to
//!   `bitt`.
//! - `synth [ARGS]`: synthetic scenes (default: the 24-scene benchmark), forwarded to `bitt`.
//! - `metrics A.png B.png [--mask M] [--lpips W]`: one pair's image metrics (JSON), and
//!   `convert-lpips --lin vgg.pth [--vgg vgg16-397923af.pth]`: LPIPS weights; forwarded.
//! - `fuzz [TARGET|all] [--seconds N | --runs N]`: the cargo-fuzz targets of `fuzz/` (file
//!   readers: pickles, torch checkpoints, MANO safetensors, annotations, InterHand, keypoints).
//! - `nets [--preset P]`: the networks' parameter counts and output shapes (JSON).
//! - `bench btr|albedo|nets [--preset P]`: burn vs PyTorch timings, side by side.
//! - `slurm-check [--work DIR] [--bitt PATH]`: the sharded evaluation as a Slurm job array on a
//!   one-node cluster started here (installs slurm-wlm and munge; not part of CI), compared
//!   with a single-process run; see `docs/slurm-check.md`.
//! - `check-clients [--run DIR] [--iterations N] [--screenshot PNG] [--chromium PATH]`: a run's
//!   outputs opened headless in the programs people view them with (Chromium: the report's 3D
//!   view); not part of CI; see `docs/clients.md`.

mod bench;
mod bench_render;
mod check_clients;
mod fuzz;
mod nets;
mod slurm;

use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};

use anyhow::{Context, Result, bail};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.current_dir(root());
    c
}

fn check(status: ExitStatus, what: &str) -> Result<()> {
    if !status.success() {
        bail!("{what} failed ({status})");
    }
    Ok(())
}

/// Builds the workspace in release mode and returns the `bitt` binary's path.
///
/// Always the whole workspace with all targets: that is the feature set `cargo test
/// --workspace --release` resolves too, so tests, `e2e` and the CLI share one build of burn
/// (building `-p bitt-cli` alone would unify features differently and rebuild it).
fn build_bitt() -> Result<PathBuf> {
    let status = cargo()
        .args([
            "build",
            "--quiet",
            "--release",
            "--workspace",
            "--all-targets",
        ])
        .status()?;
    check(status, "building bitt")?;
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"));
    let target = if target.is_relative() {
        root().join(target)
    } else {
        target
    };
    Ok(target
        .join("release")
        .join(format!("bitt{}", std::env::consts::EXE_SUFFIX)))
}

/// Runs the release `bitt` with `args`, inheriting stdio.
fn bitt(args: &[String]) -> Result<()> {
    let bin = build_bitt()?;
    let status = Command::new(bin)
        .args(args)
        .status()
        .context("running bitt")?;
    check(status, "bitt")
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-4 + 2e-3 * a.abs().max(b.abs())
}

/// Compares two backend-check outputs; returns the fields that disagree.
fn compare(reference: &serde_json::Value, other: &serde_json::Value) -> Vec<String> {
    let mut bad = Vec::new();
    for field in [
        "loss",
        "output",
        "grad_weight",
        "grad_bias",
        "texture_image_sums",
        "grad_texture_params",
        "hand_vertex_sums",
        "grad_hand_pose",
        "hand_joints",
        "grad_joints_pose",
    ] {
        let flat = |v: &serde_json::Value| -> Vec<f64> {
            match &v[field] {
                serde_json::Value::Array(a) => a.iter().filter_map(|x| x.as_f64()).collect(),
                x => x.as_f64().into_iter().collect(),
            }
        };
        let (a, b) = (flat(reference), flat(other));
        if a.is_empty() || a.len() != b.len() {
            bad.push(format!("{field}: {} vs {} values", a.len(), b.len()));
            continue;
        }
        if let Some((i, (x, y))) = a
            .iter()
            .zip(&b)
            .enumerate()
            .find(|(_, (x, y))| !close(**x, **y))
        {
            bad.push(format!("{field}[{i}]: {x} vs {y}"));
        }
    }
    bad
}

/// Mesa's Vulkan loader wants `XDG_RUNTIME_DIR`; CI shells often lack it.
fn runtime_dir() -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR") {
        Some(d) if Path::new(&d).is_dir() => PathBuf::from(d),
        _ => {
            let d = std::env::temp_dir().join("bitt-xdg-runtime");
            let _ = std::fs::create_dir_all(&d);
            d
        }
    }
}

fn e2e() -> Result<()> {
    let bin = build_bitt()?;
    let mut results = Vec::new();
    for device in ["flex", "ndarray", "wgpu"] {
        // Without XDG_RUNTIME_DIR, as in many CI shells and services: `bitt` must neither
        // need it nor print EGL's complaints about it, and it names the wgpu adapter.
        let out = Command::new(&bin)
            .args(["backend-check", "--device", device])
            .env_remove("XDG_RUNTIME_DIR")
            .output()?;
        let stderr = String::from_utf8_lossy(&out.stderr);
        if stderr.contains("XDG_RUNTIME_DIR") {
            bail!("backend check on {device} printed warnings about XDG_RUNTIME_DIR:\n{stderr}");
        }
        if device == "wgpu" {
            match stderr.lines().find(|l| l.starts_with("wgpu adapter:")) {
                Some(line) => println!("e2e {line}"),
                None => bail!("backend check on wgpu did not name its adapter:\n{stderr}"),
            }
        }
        if !out.status.success() {
            bail!(
                "backend check on {device} failed ({}):\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
                    .lines()
                    .rev()
                    .take(15)
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect::<Vec<_>>()
                    .join("\n")
            );
        }
        let line = String::from_utf8_lossy(&out.stdout);
        let v: serde_json::Value = serde_json::from_str(line.trim())
            .with_context(|| format!("{device} printed {line}"))?;
        println!(
            "e2e {device:8} loss {:.6}  ({:.2} s)",
            v["loss"].as_f64().unwrap_or(f64::NAN),
            v["seconds"].as_f64().unwrap_or(f64::NAN)
        );
        results.push((device, v));
    }
    let (ref_name, reference) = &results[0];
    let mut failed = false;
    for (name, v) in &results[1..] {
        let bad = compare(reference, v);
        if bad.is_empty() {
            println!("e2e {name} matches {ref_name}");
        } else {
            failed = true;
            println!("e2e {name} differs from {ref_name}: {}", bad.join("; "));
        }
    }
    // The demo command end to end, into a scratch folder.
    let scratch = std::env::temp_dir().join(format!("bitt-e2e-demo-{}", std::process::id()));
    let status = Command::new(&bin)
        .args(["demo", "--out"])
        .arg(&scratch)
        .stdout(std::process::Stdio::null())
        .status()?;
    check(status, "bitt demo")?;
    for f in ["hands.obj", "hands.glb", "scene.json"] {
        let len = std::fs::metadata(scratch.join(f))
            .map(|m| m.len())
            .unwrap_or(0);
        if len == 0 {
            bail!("bitt demo did not write {f}");
        }
    }
    println!("e2e demo wrote hands.obj, hands.glb, scene.json");
    // The procedural texture model end to end: fit, save, reload, write a texture.
    let model = scratch.join("skin.safetensors");
    let tex = scratch.join("skin.png");
    let status = Command::new(&bin)
        .args([
            "texture",
            "--procedural",
            "--resolution",
            "128",
            "--random",
            "1",
        ])
        .arg("--save-model")
        .arg(&model)
        .arg("--out")
        .arg(&tex)
        .stdout(std::process::Stdio::null())
        .status()?;
    check(status, "bitt texture --procedural")?;
    let status = Command::new(&bin)
        .args(["texture", "--random", "2", "--model"])
        .arg(&model)
        .arg("--out")
        .arg(&tex)
        .stdout(std::process::Stdio::null())
        .status()?;
    check(status, "bitt texture --model")?;
    println!("e2e texture fitted, saved, reloaded and wrote a 128x128 UV texture");
    // The renderer end to end: the demo scene on flex and on wgpu, images compared.
    let render_diff = render_on_backends(&bin, &scratch)?;
    println!("e2e render --demo: wgpu vs flex mean |difference| {render_diff:.2e}");
    if render_diff >= 1e-3 {
        failed = true;
        println!("e2e render differs between flex and wgpu");
    }
    // The trainer end to end: the tiny preset for a few iterations on every backend.
    let (first_losses, falls) = train_on_backends(&bin, &scratch)?;
    let (f0, rest) = first_losses.split_first().context("no training run")?;
    for (device, loss) in rest {
        let rel = (loss - f0.1).abs() / f0.1.abs().max(1e-12);
        println!(
            "e2e train-scene --preset tiny: first loss {device} {loss:.6} vs {} {:.6} (relative {rel:.1e})",
            f0.0, f0.1
        );
        if rel > TRAIN_LOSS_TOLERANCE {
            failed = true;
            println!(
                "e2e train-scene: {device} disagrees with {} beyond {TRAIN_LOSS_TOLERANCE:e}",
                f0.0
            );
        }
    }
    for (device, first, last) in &falls {
        if last >= first {
            failed = true;
            println!("e2e train-scene: loss did not fall on {device}: {first:.6} -> {last:.6}");
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    if failed {
        bail!("backends disagree");
    }
    println!("e2e: 6 passed, 0 failed");
    Ok(())
}

/// Relative difference allowed between backends' first training losses: the same weights
/// and inputs, different float kernels (summation order, fused multiply-adds).
const TRAIN_LOSS_TOLERANCE: f64 = 1e-3;

/// Trains the tiny preset for 4 iterations on flex, ndarray and wgpu; returns each backend's
/// first loss and (first, last) losses.
#[allow(clippy::type_complexity)]
fn train_on_backends(
    bin: &Path,
    scratch: &Path,
) -> Result<(Vec<(&'static str, f64)>, Vec<(&'static str, f64, f64)>)> {
    let mut first = Vec::new();
    let mut falls = Vec::new();
    for device in ["flex", "ndarray", "wgpu"] {
        let out_dir = scratch.join(format!("train-{device}"));
        let out = Command::new(bin)
            .args([
                "train-scene",
                "--preset",
                "tiny",
                "--iterations",
                "4",
                "--turntable",
                "2",
            ])
            .args(["--device", device])
            .arg("--out")
            .arg(&out_dir)
            .arg("--cache")
            .arg(scratch.join("cache"))
            .env("XDG_RUNTIME_DIR", runtime_dir())
            .output()?;
        if !out.status.success() {
            bail!(
                "bitt train-scene on {device} failed ({}):\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let path = out_dir.join("metrics.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{} missing", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)?;
        let total = |i: usize| v["history"][i]["total"].as_f64();
        let (Some(a), Some(b)) = (total(0), total(3)) else {
            bail!("{}: no loss history", path.display());
        };
        first.push((device, a));
        falls.push((device, a, b));
    }
    Ok((first, falls))
}

/// Renders the demo scene with `bitt render` on flex and on wgpu; returns the mean absolute
/// difference of the two images (values in `[0, 1]`).
fn render_on_backends(bin: &Path, scratch: &Path) -> Result<f64> {
    for device in ["flex", "wgpu"] {
        let out = Command::new(bin)
            .args([
                "render",
                "--procedural",
                "--demo",
                "--uv-size",
                "256",
                "--device",
                device,
            ])
            .arg("--out")
            .arg(scratch.join(format!("render-{device}.png")))
            .env("XDG_RUNTIME_DIR", runtime_dir())
            .output()?;
        if !out.status.success() {
            bail!(
                "bitt render --demo on {device} failed ({}):\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
    let out = Command::new(bin)
        .arg("image-diff")
        .arg(scratch.join("render-flex.png"))
        .arg(scratch.join("render-wgpu.png"))
        .output()?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!(
            "bitt image-diff failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let v: serde_json::Value =
        serde_json::from_str(text.trim()).with_context(|| format!("image-diff printed {text}"))?;
    let mean = v["mean_abs_diff"]
        .as_f64()
        .context("image-diff: no mean_abs_diff")?;
    if v["mean_a"].as_f64().unwrap_or(0.0) < 0.01 {
        bail!("bitt render --demo drew an (almost) black image: {text}");
    }
    Ok(mean)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((cmd, rest)) = args.split_first() else {
        bail!(
            "usage: cargo xtask <demo|test|e2e|train-scene|render-avatar|export|eval|eval-merge|metrics|convert-lpips|pose-hands|convert-mano|texture|convert-html|render|synth|fuzz|bench|check-clients> [ARGS]"
        );
    };
    match cmd.as_str() {
        "demo" => bitt(&[&["demo".to_string()], rest].concat()),
        "pose-hands" | "convert-mano" | "texture" | "convert-html" | "render" | "train-scene"
        | "render-avatar" | "synth" | "eval" | "eval-merge" | "metrics" | "convert-lpips"
        | "refine-hands" | "fit-hands" | "export" => bitt(&args),
        "test" => {
            let status = cargo()
                .args(["test", "--workspace", "--release"])
                .status()?;
            check(status, "cargo test")?;
            let demo = root().join("../shared/data/interhand_demo/01.pkl");
            if !demo.is_file() {
                println!(
                    "note: {} is absent: the InterHand demo-frame tests were SKIPPED",
                    demo.display()
                );
            }
            e2e()
        }
        "e2e" => e2e(),
        "fuzz" => fuzz::fuzz(rest),
        "nets" => nets::nets(rest),
        "bench" => bench::bench(rest),
        "slurm-check" => slurm::slurm_check(rest),
        "check-clients" => check_clients::check_clients(rest),
        other => {
            bail!("unknown command `{other}`; try demo, test, e2e, pose-hands, convert-mano, fuzz")
        }
    }
}
