//! How far the default [`MeshNoise`] (and 3.2x and 0.5x of it) moves the given meshes in the
//! image: the mean and largest projected vertex error at 128 px over the first four
//! benchmark scenes, the calibration `docs/synthetic.md` quotes.
//! `cargo xtask mesh-noise-calibration` runs it.

use bitt_synth::{MeshNoise, SynthConfig, benchmark_seeds, generate_scene};
use burn::tensor::Device;

fn main() {
    let device = Device::flex();
    for scale in [3.2, 1.0, 0.5] {
        let d = MeshNoise::default();
        let noise = MeshNoise {
            pose_std: d.pose_std * scale,
            shape_std: d.shape_std * scale,
            translation_px: d.translation_px * scale,
        };
        let mut means = Vec::new();
        for seed in benchmark_seeds(4) {
            let cfg = SynthConfig {
                size: 128,
                texture_size: 64,
                novel_views: 1,
                novel_poses: 1,
                mesh_noise: Some(noise),
                ..SynthConfig::default()
            };
            let scene = generate_scene(&cfg, seed, &device).unwrap();
            means.push(scene.given_mesh_error_px().unwrap());
        }
        eprintln!("scale {scale}: {noise:?} -> (mean, max) px at 128: {means:?}");
    }
}
