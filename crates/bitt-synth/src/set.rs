//! A set of synthetic scenes on disk (`bitt synth`): scene folders, `stats.json`, contact sheet.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::Device;

use crate::{PoseFamily, SynthConfig, SynthError, TexelStats, generate_scene};

/// One scene of a set, just written (for a progress line).
#[derive(Debug, Clone, Copy)]
pub struct WrittenScene {
    /// Position in the set (the folder is `scene_{index:03}`).
    pub index: usize,
    /// The scene's seed.
    pub seed: u64,
    /// Pose family of the training view.
    pub family: PoseFamily,
    /// Table-3 statistics of the training view.
    pub stats: TexelStats,
    /// Seconds spent generating the scene.
    pub generate_s: f64,
    /// Seconds spent writing its folder.
    pub write_s: f64,
}

fn percent(x: f64) -> String {
    format!("{:6.2}%", 100.0 * x)
}

impl WrittenScene {
    /// The scene's progress line: index, seed, pose family, Table-3 fractions, timings.
    pub fn line(&self) -> String {
        let t = self.stats.table3;
        format!(
            "scene {:3} seed {:#018x} {:13} left {} right {} sym {} invisible {}  ({:.1} s + write {:.1} s)",
            self.index,
            self.seed,
            format!("{:?}", self.family),
            percent(t.left_visible),
            percent(t.right_visible),
            percent(t.symmetric_usable),
            percent(t.invisible),
            self.generate_s,
            self.write_s,
        )
    }
}

impl SceneSet {
    /// The set's Table 3 of `scenes` scenes (training views) beside the paper's numbers
    /// (InterHand2.6M), with the symmetry gain and the reachable texels per hand.
    pub fn table3_lines(&self, scenes: usize) -> Vec<String> {
        let (t, mean) = (self.mean.table3, &self.mean);
        vec![
            format!(
                "Table 3 ({scenes} scenes, training views)      this     paper (InterHand2.6M)"
            ),
            format!(
                "left-hand visible texture          {}   35.40%",
                percent(t.left_visible)
            ),
            format!(
                "right-hand visible texture         {}   36.44%",
                percent(t.right_visible)
            ),
            format!(
                "usable symmetric (exactly one)     {}   24.29%",
                percent(t.symmetric_usable)
            ),
            format!(
                "invisible (on neither hand)        {}   19.89%",
                percent(t.invisible)
            ),
            format!(
                "symmetry gain per hand             {}",
                percent(mean.symmetry_gain)
            ),
            format!(
                "reachable per hand (own + other)   {}   ~60%",
                percent(mean.reachable)
            ),
        ]
    }
}

/// What [`write_scene_set`] wrote.
#[derive(Debug, Clone)]
pub struct SceneSet {
    /// Mean statistics over the scenes.
    pub mean: TexelStats,
    /// `<out>/stats.json`.
    pub stats_path: PathBuf,
    /// `<out>/contact.png`.
    pub sheet_path: PathBuf,
    /// The contact sheet, `[3, H, W]` in `[0, 1]`, with its width and height.
    pub sheet: (Vec<f32>, usize, usize),
}

/// Generates the scene of each seed with `config` on `device` and writes it to
/// `<out>/scene_NNN` (N the seed's position), then `<out>/stats.json` (the configuration,
/// mean and per-scene statistics, the paper's InterHand2.6M values, timings) and
/// `<out>/contact.png` of the first `sheet_scenes` scenes. `on_scene` sees each scene once
/// written. `out` must exist.
///
/// # Errors
/// No seeds; a scene that cannot be generated ([`SynthError::Scene`], naming its position
/// and seed); unwritable files.
pub fn write_scene_set(
    config: &SynthConfig,
    seeds: &[u64],
    out: &Path,
    sheet_scenes: usize,
    device: &Device,
    mut on_scene: impl FnMut(&WrittenScene),
) -> Result<SceneSet, SynthError> {
    let mut sheet = Vec::new();
    let mut stats = Vec::new();
    let mut per_scene = Vec::new();
    let started = Instant::now();
    for (index, &seed) in seeds.iter().enumerate() {
        let t0 = Instant::now();
        let scene = generate_scene(config, seed, device).map_err(|e| SynthError::Scene {
            index,
            seed,
            source: Box::new(e),
        })?;
        let generate_s = t0.elapsed().as_secs_f64();
        let dir = out.join(format!("scene_{index:03}"));
        scene.write(&dir)?;
        on_scene(&WrittenScene {
            index,
            seed,
            family: scene.train.family,
            stats: scene.stats,
            generate_s,
            write_s: t0.elapsed().as_secs_f64() - generate_s,
        });
        per_scene.push(serde_json::json!({
            "folder": dir.file_name().map(|n| n.to_string_lossy().into_owned()),
            "seed": seed,
            "family": scene.train.family,
            "stats": scene.stats,
            "seconds": generate_s,
        }));
        stats.push(scene.stats);
        if index < sheet_scenes {
            sheet.push(scene);
        }
    }
    let mean = TexelStats::mean(&stats).ok_or_else(|| SynthError::Generate("no scenes".into()))?;
    let summary = serde_json::json!({
        "config": config,
        "scenes": seeds.len(),
        "mean": mean,
        "paper_interhand": {
            "left_visible": 0.3540, "right_visible": 0.3644,
            "symmetric_usable": 0.2429, "invisible": 0.1989,
        },
        "per_scene": per_scene,
        "seconds": started.elapsed().as_secs_f64(),
    });
    let stats_path = out.join("stats.json");
    let text = serde_json::to_string_pretty(&summary)
        .map_err(|e| SynthError::Generate(format!("cannot encode stats.json: {e}")))?;
    bitt_stdx::write_atomically(&stats_path, text.as_bytes())?;
    let sheet = crate::contact_sheet(&sheet)?;
    let sheet_path = out.join("contact.png");
    bitt_texture::save_png8(&sheet_path, &sheet.0, sheet.1, sheet.2)?;
    Ok(SceneSet {
        mean,
        stats_path,
        sheet_path,
        sheet,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> SynthConfig {
        SynthConfig {
            size: 128,
            texture_size: 64,
            novel_views: 1,
            novel_poses: 1,
            mesh_noise: None,
            degrade: false,
        }
    }

    /// Two scenes: two folders, `stats.json` with both and the paper's values, a contact
    /// sheet of the first only, and one progress call per scene in order.
    #[test]
    fn writes_folders_stats_and_sheet() {
        let out = std::env::temp_dir().join(format!("bitt-synth-set-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        std::fs::create_dir_all(&out).unwrap();
        let device = Device::flex();
        let mut seen = Vec::new();
        let set = write_scene_set(&tiny(), &[3, 4], &out, 1, &device, |w| {
            seen.push((w.index, w.seed))
        })
        .unwrap();
        assert_eq!(seen, vec![(0, 3), (1, 4)]);
        assert!(out.join("scene_000/scene.json").is_file());
        assert!(out.join("scene_001/scene.json").is_file());
        assert!(set.sheet_path.is_file());
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&set.stats_path).unwrap()).unwrap();
        assert_eq!(json["scenes"], 2);
        assert_eq!(json["per_scene"][1]["folder"], "scene_001");
        assert_eq!(json["paper_interhand"]["invisible"], 0.1989);
        assert_eq!(set.sheet.0.len(), 3 * set.sheet.1 * set.sheet.2);
        std::fs::remove_dir_all(&out).unwrap();
    }

    /// An empty seed list is an error, not an empty `stats.json`.
    #[test]
    fn no_seeds_is_an_error() {
        let out = std::env::temp_dir().join(format!("bitt-synth-set0-{}", std::process::id()));
        std::fs::create_dir_all(&out).unwrap();
        let err = write_scene_set(&tiny(), &[], &out, 1, &Device::flex(), |_| {}).unwrap_err();
        assert!(err.to_string().contains("no scenes"), "{err}");
        std::fs::remove_dir_all(&out).unwrap();
    }
}
