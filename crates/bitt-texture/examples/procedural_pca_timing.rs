//! Times the procedural texture PCA setup of a training preset, stage by stage, through the
//! fit's progress callback (a plain line per stage with its duration, and a redrawn count):
//!
//! `cargo build --release --workspace --examples &&
//!  target/release/examples/procedural_pca_timing paper [--no-eval] [--threads N]`
//!
//! `paper` is the paper preset's model (1024 x 1024 textures, 64 identities, 101
//! components, 2 held-out identities), `quick` the quick preset's (256, 40, 24, 2).

use std::io::Write;
use std::sync::Mutex;
use std::time::Instant;

use bitt_texture::{
    FitStage, ProceduralTextureConfig, procedural_texture_model,
    procedural_texture_pca_with_progress,
};
use burn::tensor::Device;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (resolution, identities, components) = match args.first().map(String::as_str) {
        Some("paper") => (1024, 64, 101),
        Some("quick") => (256, 40, 24),
        _ => {
            eprintln!("usage: procedural_pca_timing paper|quick [--no-eval] [--threads N]");
            std::process::exit(2);
        }
    };
    let no_eval = args.iter().any(|a| a == "--no-eval");
    if let Some(i) = args.iter().position(|a| a == "--threads") {
        let n: usize = args
            .get(i + 1)
            .and_then(|n| n.parse().ok())
            .expect("--threads N");
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .expect("rayon pool");
    }
    let config = ProceduralTextureConfig {
        resolution,
        identities,
        held_out: 2,
        components,
        ..ProceduralTextureConfig::default()
    };
    let start = Instant::now();
    // (stage, its start, the last redraw)
    let state: Mutex<Option<(FitStage, Instant, Instant)>> = Mutex::new(None);
    let progress = |stage: FitStage, done: usize, total: usize| {
        let now = Instant::now();
        let mut s = state.lock().unwrap();
        let mut err = std::io::stderr().lock();
        match *s {
            Some((current, _, _)) if current == stage => {}
            previous => {
                if let Some((p, began, _)) = previous {
                    let _ = writeln!(
                        err,
                        "\r{:<24} {:8.2} s",
                        p.label(),
                        (now - began).as_secs_f64()
                    );
                }
                *s = Some((stage, now, now));
            }
        }
        let (_, began, last) = s.as_mut().unwrap();
        if done == 0 || done == total || (now - *last).as_millis() >= 200 {
            *last = now;
            let _ = write!(
                err,
                "\r{:<24} {done}/{total} ({:.1} s)",
                stage.label(),
                (now - *began).as_secs_f64()
            );
        }
    };
    let device = Device::flex();
    let explained: f32 = if no_eval {
        let (_, report) = procedural_texture_model(&config, &device, &progress).unwrap();
        report.explained_variance_ratio.iter().sum()
    } else {
        let (_, _, eval) =
            procedural_texture_pca_with_progress(&config, &device, &progress).unwrap();
        eval.explained_variance_at_k
    };
    if let Some((p, began, _)) = *state.lock().unwrap() {
        eprintln!(
            "\r{:<24} {:8.2} s",
            p.label(),
            began.elapsed().as_secs_f64()
        );
    }
    println!(
        "{} threads, {}: {:.2} s, explained variance {explained:.4}",
        rayon::current_num_threads(),
        serde_json::to_string(&config).unwrap(),
        start.elapsed().as_secs_f64()
    );
}
