//! What the rigged avatar would lose without its pose-corrective morph targets, measured on
//! the demo scene's novel poses (procedural hand): the largest and mean vertex distance
//! between the forward pass and
//! - skinning alone (correctives left out of the file), and
//! - skinning with the input pose's correctives (what an editor shows when the joints are
//!   rotated by hand and the morph weights are not updated).
//!
//! `cargo run --release -p bitt --example avatar_correctives`

use bitt_mesh::glam::DVec3;
use bitt_mesh::model::NUM_POSE_FEATURES;
use bitt_mesh::{HandModel, HandParams, Side, procedural_pair};
use bitt_synth::{SynthConfig, demo_scene_seed, generate_scene};
use burn::tensor::Device;

/// `model` with its correctives frozen at `fixed`'s pose: baked into the template, no pose
/// blend shapes left.
fn frozen_at(model: &HandModel, fixed: &HandParams) -> HandModel {
    let axis = model.pose_axis_angles(&fixed.pose);
    let mut features = vec![0.0; NUM_POSE_FEATURES];
    for j in 0..15 {
        let r =
            bitt_mesh::lbs::rodrigues(DVec3::new(axis[3 * j], axis[3 * j + 1], axis[3 * j + 2]));
        let m = r.transpose().to_cols_array();
        for k in 0..9 {
            features[9 * j + k] = m[k] - if k % 4 == 0 { 1.0 } else { 0.0 };
        }
    }
    let mut out = model.clone();
    for (v, p) in out.v_template.iter_mut().enumerate() {
        for c in 0..3 {
            let row = &model.pose_dirs
                [(v * 3 + c) * NUM_POSE_FEATURES..(v * 3 + c + 1) * NUM_POSE_FEATURES];
            p[c] += row.iter().zip(&features).map(|(a, b)| a * b).sum::<f64>();
        }
    }
    out.pose_dirs.fill(0.0);
    out
}

fn distances(a: &[DVec3], b: &[DVec3]) -> (f64, f64) {
    let d: Vec<f64> = a.iter().zip(b).map(|(p, q)| p.distance(*q)).collect();
    (
        d.iter().copied().fold(0.0, f64::max),
        d.iter().sum::<f64>() / d.len() as f64,
    )
}

fn main() {
    let scene = generate_scene(&SynthConfig::default(), demo_scene_seed(), &Device::flex())
        .expect("the demo scene");
    let pair = procedural_pair();
    println!(
        "pose  hand   without correctives (max / mean mm)   input pose's correctives (max / mean mm)"
    );
    let (mut worst_none, mut worst_stale) = (0.0f64, 0.0f64);
    for (k, view) in scene.novel_poses.iter().enumerate() {
        for side in Side::BOTH {
            let model = pair.get(side);
            let input = scene.given.hand(side).expect("input hand");
            let novel = HandParams {
                betas: input.betas.clone(),
                ..view.hands.hand(side).expect("novel hand").clone()
            };
            let exact = model.forward(&novel).expect("pose").vertices;
            let mut none = model.clone();
            none.pose_dirs.fill(0.0);
            let none = distances(&exact, &none.forward(&novel).expect("pose").vertices);
            let stale = frozen_at(model, input);
            let stale = distances(&exact, &stale.forward(&novel).expect("pose").vertices);
            worst_none = worst_none.max(none.0);
            worst_stale = worst_stale.max(stale.0);
            println!(
                "{k:>4}  {side:<5}  {:>8.3} / {:.3}                        {:>8.3} / {:.3}",
                1e3 * none.0,
                1e3 * none.1,
                1e3 * stale.0,
                1e3 * stale.1
            );
        }
    }
    println!(
        "largest: without correctives {:.3} mm, with the input pose's {:.3} mm",
        1e3 * worst_none,
        1e3 * worst_stale
    );
}
