//! `cargo xtask bench render [--runs N]`: the renderer's per-stage timings (the example
//! `crates/bitt/examples/bench_render.rs`) on flex and on wgpu, as a table with wgpu/flex
//! ratios and as JSON.

use std::process::Command;

use anyhow::{Context, Result, bail};

/// Runs the `bench_render` example on flex then wgpu and prints the table and the JSON.
pub fn run(args: &[String]) -> Result<()> {
    let runs = match args {
        [] => "5".to_string(),
        [flag, n] if flag == "--runs" => {
            n.parse::<usize>().context("--runs takes a number")?;
            n.clone()
        }
        _ => bail!("usage: cargo xtask bench render [--runs N]"),
    };
    let bin = crate::build_example("bench_render")?;
    let runtime_dir = crate::runtime_dir();
    let mut results = Vec::new();
    for device in ["flex", "wgpu"] {
        eprintln!("bench render: timing on {device} ...");
        let out = Command::new(&bin)
            .args(["--device", device, "--runs", &runs])
            .env("XDG_RUNTIME_DIR", &runtime_dir)
            .output()
            .context("running the bench_render example")?;
        if !out.status.success() {
            bail!(
                "bench_render --device {device} failed ({}):\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let text = String::from_utf8_lossy(&out.stdout);
        let v: serde_json::Value = serde_json::from_str(text.trim())
            .with_context(|| format!("bench_render --device {device} printed {text}"))?;
        results.push((device, v));
    }
    let (flex, wgpu) = (&results[0].1, &results[1].1);
    println!(
        "render stages: {}x{} image, {}x{} texture, {} faces, {} covered pixels; median of {runs} runs (ms)",
        flex["image"][1],
        flex["image"][0],
        flex["texture"][1],
        flex["texture"][0],
        flex["faces"],
        flex["covered_pixels"],
    );
    println!(
        "{:<12} {:>10} {:>10} {:>7}   {:>10} {:>10} {:>7}",
        "stage", "flex fwd", "wgpu fwd", "ratio", "flex bwd", "wgpu bwd", "ratio"
    );
    let ms = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN) * 1e3;
    let empty = Vec::new();
    let stages = flex["stages"].as_array().unwrap_or(&empty);
    for (i, stage) in stages.iter().enumerate() {
        let other = &wgpu["stages"][i];
        let (ff, wf) = (ms(&stage["forward"]), ms(&other["forward"]));
        let (fb, wb) = (ms(&stage["backward"]), ms(&other["backward"]));
        println!(
            "{:<12} {ff:>10.2} {wf:>10.2} {:>7.2}   {fb:>10.2} {wb:>10.2} {:>7.2}",
            stage["name"].as_str().unwrap_or("?"),
            wf / ff,
            wb / fb,
        );
    }
    for (device, v) in &results {
        let t = &v["rasterize_transfer"];
        println!(
            "rasterize on {device:4}: {:.2} ms = host core {:.2} ms + {:.2} ms transfers and \
             tensor set-up (clip read-back alone {:.2} ms)",
            ms(&t["rasterize"]),
            ms(&t["cpu_core"]),
            ms(&t["overhead"]),
            ms(&t["clip_readback"]),
        );
    }
    for (device, v) in &results {
        let (r, d) = (&v["host_readbacks"], &v["rasterize_dense"]);
        println!(
            "host readbacks per rasterization on {device:4}: `rasterize` {} (before), \
             `rasterize_dense` {} (after; {} kernel, {:.2} ms, {} face ids differ from the CPU \
             core)",
            r["rasterize"],
            r["rasterize_dense"],
            d["kernel"].as_str().unwrap_or("?"),
            ms(&d["forward"]),
            d["face_ids_differing_from_cpu_core"],
        );
        println!(
            "host readbacks of a fixed-view training render on {device:4}: `SceneGeometry::new` \
             {} (once per view), `shade` {} (every step)",
            r["scene_geometry_new"], r["shade_step"],
        );
    }
    let json = serde_json::json!({ "flex": flex, "wgpu": wgpu });
    println!("{json}");
    Ok(())
}
