//! The synthetic benchmark's contact sheet `synth_contact.png` (the first 12 of its scenes)
//! written into the folder given as the only argument (default `docs/images`), with each
//! scene's Table-3 statistics and their mean printed. `SYNTH_SCENES=N` takes the first N
//! scenes (default all 24); `SYNTH_DEBUG_DIR=DIR` also writes every scene folder there.
//! `cargo xtask docs-images` runs it.

use std::path::Path;

use bitt_synth::{
    BENCHMARK_SCENES, SynthConfig, SynthScene, TexelStats, benchmark_seeds, contact_sheet,
    generate_scene,
};
use burn::tensor::Device;

fn main() {
    let device = Device::flex();
    let n: usize = std::env::var("SYNTH_SCENES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(BENCHMARK_SCENES);
    let cfg = SynthConfig::default();
    let mut scenes = Vec::new();
    let mut stats = Vec::new();
    for seed in benchmark_seeds(n) {
        let t = std::time::Instant::now();
        let s = generate_scene(&cfg, seed, &device).unwrap();
        let t3 = s.stats.table3;
        println!(
            "{:?} {:.1}s L {:.3} R {:.3} sym {:.3} inv {:.3} gain {:.3}",
            s.train.family,
            t.elapsed().as_secs_f64(),
            t3.left_visible,
            t3.right_visible,
            t3.symmetric_usable,
            t3.invisible,
            s.stats.symmetry_gain
        );
        stats.push(s.stats);
        if let Ok(dir) = std::env::var("SYNTH_DEBUG_DIR") {
            s.write(&Path::new(&dir).join(format!("scene_{:02}", scenes.len())))
                .unwrap();
        }
        scenes.push(s);
    }
    println!("mean {:?}", TexelStats::mean(&stats).unwrap());
    let keep: Vec<SynthScene> = scenes.into_iter().take(12).collect();
    let (img, w, h) = contact_sheet(&keep).unwrap();
    let dir = std::env::args()
        .nth(1)
        .map_or_else(|| Path::new("docs/images").to_path_buf(), Into::into);
    let out = dir.join("synth_contact.png");
    bitt_texture::save_png8(&out, &img, w, h).unwrap();
    println!("wrote {}", out.display());
}
