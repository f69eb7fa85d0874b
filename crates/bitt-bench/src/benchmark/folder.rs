//! The evaluation folder: one result file per scene and mesh setting, shards, resume, merged tables.

use bitt_stdx::FileErrorExt;
use std::path::{Path, PathBuf};

use bitt_stdx::write_atomically;

use super::photos::photo_consistency;
use super::{
    ContactSheets, MeshSetting, Method, SCENE_RESULT_FORMAT, SceneResult, models_text,
    photos_markdown, results_markdown, summarize,
};
use bitt::BittError;
use bitt::baselines::BaselineConfig;
use bitt::config::TrainConfig;
use bitt::outputs::{contact_sheet, write_json, write_png};

/// Parses `--scenes`: a positive number (the first N scenes), or `all` (the synthetic
/// benchmark's [`bitt_synth::BENCHMARK_SCENES`]).
pub fn parse_scenes(s: &str) -> Result<usize, BittError> {
    match s {
        "all" => Ok(bitt_synth::BENCHMARK_SCENES),
        n => n.parse::<usize>().ok().filter(|&n| n >= 1).ok_or_else(|| {
            BittError::Invalid(format!("--scenes {n}: expected a positive number or `all`"))
        }),
    }
}

/// Parses a shard `i/N` (0-based): scene `k` belongs to shard `k % N`.
pub fn parse_shard(s: &str) -> Result<(usize, usize), BittError> {
    let invalid = |why: String| BittError::Invalid(format!("--shard {s}: {why}"));
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| invalid("expected i/N".into()))?;
    let number = |x: &str| {
        x.trim()
            .parse::<usize>()
            .map_err(|e| invalid(e.to_string()))
    };
    let (i, n) = (number(i)?, number(n)?);
    if n == 0 || i >= n {
        return Err(invalid("need 0 <= i < N".into()));
    }
    Ok((i, n))
}

/// `scenes/{setting}-{seed:016x}.json`: the result file of one scene and mesh setting.
pub fn result_path(out: &Path, setting: MeshSetting, seed: u64) -> PathBuf {
    out.join("scenes")
        .join(format!("{}-{seed:016x}.json", setting.key()))
}

/// The seeds of the first `scenes` benchmark scenes that belong to shard `(i, N)`.
pub fn shard_seeds(scenes: usize, (shard, shards): (usize, usize)) -> Vec<u64> {
    bitt_synth::benchmark_seeds(scenes)
        .into_iter()
        .enumerate()
        .filter(|(k, _)| k % shards == shard)
        .map(|(_, seed)| seed)
        .collect()
}

/// The scene/setting pairs without a result file in `out` yet (finished ones are skipped).
pub fn pending(out: &Path, seeds: &[u64], settings: &[MeshSetting]) -> Vec<(u64, MeshSetting)> {
    seeds
        .iter()
        .flat_map(|&seed| settings.iter().map(move |&s| (seed, s)))
        .filter(|&(seed, s)| !result_path(out, s, seed).is_file())
        .collect()
}

/// BiTT trainings per scene (the HTML baseline trains one when no BiTT variant does): the
/// unit of an evaluation's progress, with the iterations of each.
pub fn trainings_per_scene(methods: &[Method], config: &TrainConfig) -> usize {
    methods
        .iter()
        .filter(|m| m.bitt_config(config).is_some())
        .count()
        .max(usize::from(methods.contains(&Method::Html)))
}

/// A stable id of an InterHand2.6M scene (FNV-1a of split, capture, frame and camera): the
/// name of its result file.
pub fn interhand_scene_id(split: &str, capture: i64, frame: i64, camera: &str) -> u64 {
    format!("interhand/{split}/{capture}/{frame}/{camera}")
        .bytes()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        })
}

/// A stable id of the photo scene that trains on `image` (`--photos`; FNV-1a of its path as
/// given): the name of its result file.
pub fn photo_scene_id(image: &Path) -> u64 {
    interhand_scene_id("photos", 0, 0, &image.display().to_string())
}

/// What an evaluation runs: written to `config.json` of its folder.
#[derive(Debug, Clone, Copy)]
pub struct EvalPlan<'a> {
    /// Every BiTT training.
    pub train: &'a TrainConfig,
    /// The HARP-like and S2Hand-like baselines.
    pub baseline: &'a BaselineConfig,
    /// The methods compared.
    pub methods: &'a [Method],
    /// The mesh settings.
    pub settings: &'a [MeshSetting],
    /// How many scenes.
    pub scenes: usize,
    /// Where the scenes come from (`synthetic`, `interhand SPLIT ROOT`).
    pub dataset: &'a str,
    /// The hand models and texture prior of real scenes, when they are the user's MANO and
    /// HTML folders (`None`: the procedural hands and texture PCA, whose folders' plans have
    /// no such key).
    pub models: Option<&'a serde_json::Value>,
}

/// The keys of an evaluation folder's `config.json`.
const PLAN_KEYS: [&str; 6] = [
    "train", "baseline", "methods", "settings", "scenes", "dataset",
];

/// The keys a plan has only when they apply: `models` (the user's MANO and HTML folders).
/// A folder evaluated with the procedural models, before the key existed or since, has none.
const OPTIONAL_PLAN_KEYS: [&str; 1] = ["models"];

/// Creates `out/scenes/` and writes the plan to `out/config.json`. An existing folder must be
/// an evaluation of the same plan (a rerun resumes it, skipping finished scenes): a folder
/// that is not an evaluation is refused untouched, and so is one whose `config.json` holds
/// other settings, whose results would otherwise be kept as if they were this plan's.
///
/// # Errors
/// A folder of the user's, an evaluation of another plan (naming what differs), or a write
/// failure.
pub fn prepare_folder(out: &Path, plan: &EvalPlan<'_>) -> Result<(), BittError> {
    let mut config = serde_json::json!({
        "train": plan.train,
        "baseline": plan.baseline,
        "methods": plan.methods.iter().map(|m| m.key()).collect::<Vec<_>>(),
        "settings": plan.settings.iter().map(|s| s.key()).collect::<Vec<_>>(),
        "scenes": plan.scenes,
        "dataset": plan.dataset,
    });
    if let Some(models) = plan.models {
        config["models"] = models.clone();
    }
    check_eval_folder(out, &config)?;
    // config.json first: shards starting together into one folder see it missing (with at
    // most another shard's temporary of it) or whole, never a folder without it.
    write_json(&out.join("config.json"), &config)?;
    let scenes = out.join("scenes");
    std::fs::create_dir_all(&scenes).map_err(|e| BittError::io(&scenes, e))
}

/// Refuses `out` unless it is missing, empty, or an evaluation whose `config.json` is
/// `config` (see [`prepare_folder`]).
fn check_eval_folder(out: &Path, config: &serde_json::Value) -> Result<(), BittError> {
    if out.exists() && !out.is_dir() {
        return Err(BittError::Invalid(format!(
            "{}: exists and is not a folder",
            out.display()
        )));
    }
    // Empty, or holding only another shard's config.json on its way in.
    let empty = !out.exists()
        || std::fs::read_dir(out)
            .map_err(|e| BittError::io(out, e))?
            .flatten()
            .all(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(".config.json.tmp")
            });
    if empty {
        return Ok(());
    }
    let Some(existing) = existing_plan(out) else {
        return Err(BittError::Invalid(format!(
            "{}: the folder is not an evaluation (no config.json of one); nothing was written: \
             choose another --out",
            out.display()
        )));
    };
    let differ = plan_differences(&existing, config);
    if !differ.is_empty() {
        return Err(BittError::Invalid(format!(
            "{}: holds an evaluation with other settings ({} differ from this run's); its \
             finished scenes would be kept as this run's. Rerun with its settings to resume it, \
             or choose another --out",
            out.display(),
            differ.join(", ")
        )));
    }
    Ok(())
}

/// Writes one evaluated scene: its contact sheet ([`write_sheet`]), then its result file
/// ([`result_path`]), which marks it finished.
pub fn write_scene(
    out: &Path,
    result: &SceneResult,
    input: &[f32],
    sheets: &ContactSheets,
    size: usize,
) -> Result<(), BittError> {
    let name = format!("{}-{:016x}", result.setting.key(), result.seed);
    write_sheet(out, &name, input, sheets, size)?;
    Ok(write_json(
        &result_path(out, result.setting, result.seed),
        result,
    )?)
}

/// `sheets/{name}.png`: the input, the ground truth and each method at the first novel view
/// (top row; photo scenes: the input view) and the first novel pose (bottom row), either row
/// left out when the scene has no such view; `sheets/columns.txt` names the columns.
pub fn write_sheet(
    out: &Path,
    name: &str,
    input: &[f32],
    sheets: &ContactSheets,
    size: usize,
) -> Result<(), BittError> {
    let rows: Vec<(&Vec<f32>, usize)> = [(&sheets.view, 0), (&sheets.pose, 1)]
        .into_iter()
        .filter_map(|(truth, k)| truth.as_ref().map(|t| (t, k)))
        .collect();
    if rows.is_empty() {
        return Ok(());
    }
    let mut panels = Vec::new();
    for (truth, k) in rows {
        panels.push(input.to_vec());
        panels.push(truth.clone());
        panels.extend(
            sheets
                .methods
                .iter()
                .map(|(_, s)| if k == 0 { s.0.clone() } else { s.1.clone() }),
        );
    }
    let (img, h, w) = contact_sheet(&panels, size, size, 2 + sheets.methods.len());
    let dir = out.join("sheets");
    std::fs::create_dir_all(&dir).map_err(|e| BittError::io(&dir, e))?;
    write_png(&dir.join(format!("{name}.png")), &img, h, w)?;
    let legend: Vec<&str> = ["input", "ground truth"]
        .into_iter()
        .chain(sheets.methods.iter().map(|(m, _)| m.key()))
        .collect();
    write_atomically(
        &dir.join("columns.txt"),
        format!("{}\n", legend.join(" | ")).as_bytes(),
    )?;
    Ok(())
}

/// Reads every scene result under `dirs[k]/scenes/` and writes `results.json` and
/// `results.md` into `dirs[0]`; returns `results.md`. The folders must be evaluations of one
/// plan (their `config.json` equal: shards of one evaluation), and a scene and setting found
/// in two folders must have the same scores there (timings aside), else nothing is written.
///
/// # Errors
/// A folder that is not an evaluation, folders of different plans (naming what differs), two
/// results of one scene that disagree (naming both files), a result file that is not one, or
/// no result at all.
pub fn merge(dirs: &[PathBuf]) -> Result<String, BittError> {
    let mut plan: Option<(&PathBuf, serde_json::Value)> = None;
    for dir in dirs {
        let this = read_plan(dir)?;
        match &plan {
            None => plan = Some((dir, this)),
            Some((first, p)) => {
                let differ = plan_differences(p, &this);
                if !differ.is_empty() {
                    return Err(BittError::Invalid(format!(
                        "{} and {} are evaluations of other settings ({} differ in their \
                         config.json): their results cannot share one table; nothing was written",
                        first.display(),
                        dir.display(),
                        differ.join(", ")
                    )));
                }
            }
        }
    }
    let mut results: Vec<(PathBuf, SceneResult)> = Vec::new();
    for dir in dirs {
        for (path, r) in read_results(&dir.join("scenes"))? {
            match results
                .iter()
                .find(|(_, x)| x.seed == r.seed && x.setting == r.setting)
            {
                None => results.push((path, r)),
                Some((_, x)) if same_scores(x, &r)? => {}
                Some((kept, _)) => {
                    return Err(BittError::Invalid(format!(
                        "{} and {} are results of the same scene ({}, {}) that disagree: one \
                         of them was made with other settings or changed; remove the wrong one \
                         and merge again (nothing was written)",
                        kept.display(),
                        path.display(),
                        r.seed,
                        r.setting.key()
                    )));
                }
            }
        }
    }
    let results: Vec<SceneResult> = results.into_iter().map(|(_, r)| r).collect();
    let Some(out) = dirs.first().filter(|_| !results.is_empty()) else {
        return Err(BittError::Invalid(format!(
            "no scene results under {}",
            dirs.first()
                .map_or(PathBuf::new(), |d| d.join("scenes"))
                .display()
        )));
    };
    let summary = summarize(&results);
    let consistency = photo_consistency(out, &results)?;
    write_json(
        &out.join("results.json"),
        &serde_json::json!({
            "summary": summary,
            "scenes": results,
            "photo_consistency": consistency,
        }),
    )?;
    let has_lpips = summary
        .settings
        .values()
        .flat_map(|per| per.values())
        .any(|m| {
            [m.input_view, m.novel_views, m.novel_poses]
                .iter()
                .any(|x| x.is_some_and(|x| x.lpips.is_some()))
        });
    let note = if has_lpips {
        "LPIPS-VGG from the user's weights (`bitt convert-lpips`), on images mapped to [-1, 1]"
    } else {
        "unavailable (no LPIPS weights; never estimated)"
    };
    let plan = existing_plan(out);
    let alb = plan
        .as_ref()
        .and_then(|p| p["train"]["loss"]["alb"].as_f64());
    let models = models_text(plan.as_ref().and_then(|p| p.get("models")));
    let mut md = results_markdown(&summary, note, alb, &models);
    if let Some(photos) = photos_markdown(&results, &consistency) {
        md.push('\n');
        md.push_str(&photos);
    }
    write_atomically(&out.join("results.md"), md.as_bytes())?;
    Ok(md)
}

/// The plan (`config.json`, with every [`PLAN_KEYS`] entry) of evaluation folder `dir`, if it
/// has one.
fn existing_plan(dir: &Path) -> Option<serde_json::Value> {
    std::fs::read_to_string(dir.join("config.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .filter(|v| {
            v.as_object()
                .is_some_and(|o| PLAN_KEYS.iter().all(|k| o.contains_key(*k)))
        })
}

/// The plan keys on which two plans differ.
fn plan_differences(a: &serde_json::Value, b: &serde_json::Value) -> Vec<&'static str> {
    PLAN_KEYS
        .iter()
        .chain(&OPTIONAL_PLAN_KEYS)
        .copied()
        .filter(|k| a[*k] != b[*k])
        .collect()
}

/// The plan of evaluation folder `dir` ([`existing_plan`]).
///
/// # Errors
/// A folder without the `config.json` of an evaluation.
fn read_plan(dir: &Path) -> Result<serde_json::Value, BittError> {
    existing_plan(dir).ok_or_else(|| {
        BittError::Invalid(format!(
            "{}: not an evaluation folder (no config.json of one), so its results' settings \
             are unknown; nothing was written",
            dir.display()
        ))
    })
}

/// Whether two results of one scene agree on everything but their timings (`seconds`).
fn same_scores(a: &SceneResult, b: &SceneResult) -> Result<bool, BittError> {
    fn without_timings(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(o) => {
                o.remove("seconds");
                o.values_mut().for_each(without_timings);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(without_timings),
            _ => {}
        }
    }
    let value = |r: &SceneResult| -> Result<serde_json::Value, BittError> {
        let mut v = serde_json::to_value(r)
            .map_err(|e| BittError::Invalid(format!("cannot encode a scene result: {e}")))?;
        without_timings(&mut v);
        Ok(v)
    };
    Ok(value(a)? == value(b)?)
}

/// The scene results in one `scenes/` folder with their files, in file-name order.
fn read_results(scenes: &Path) -> Result<Vec<(PathBuf, SceneResult)>, BittError> {
    let entries = std::fs::read_dir(scenes).map_err(|e| BittError::io(scenes, e))?;
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    paths
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p).map_err(|e| BittError::io(p, e))?;
            let r: SceneResult = serde_json::from_str(&text)
                .map_err(|e| BittError::format(p, format!("not a scene result: {e}")))?;
            if r.format != SCENE_RESULT_FORMAT {
                return Err(BittError::format(
                    p,
                    format!("format {} (expected {SCENE_RESULT_FORMAT})", r.format),
                ));
            }
            Ok((p.clone(), r))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 38, classes 7 and 8: an evaluation folder is resumed only with its own plan; a
    /// user's folder and an evaluation of other settings are refused untouched.
    #[test]
    fn eval_folders_resume_only_their_own_plan() {
        let dir = std::env::temp_dir().join(format!("bitt-eval-plan-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let plan = |iterations: u64| {
            serde_json::json!({
                "train": {"iterations": iterations}, "baseline": {}, "methods": ["bitt"],
                "settings": ["true"], "scenes": 2, "dataset": "synthetic",
            })
        };
        // Missing, empty, or another shard's config.json on its way in: fine.
        check_eval_folder(&dir.join("new"), &plan(10)).unwrap();
        std::fs::create_dir_all(dir.join("empty")).unwrap();
        check_eval_folder(&dir.join("empty"), &plan(10)).unwrap();
        std::fs::write(dir.join("empty/.config.json.tmp123"), "{").unwrap();
        check_eval_folder(&dir.join("empty"), &plan(10)).unwrap();
        // Its own plan: resumed.
        let ours = dir.join("ours");
        std::fs::create_dir_all(ours.join("scenes")).unwrap();
        std::fs::write(ours.join("config.json"), plan(10).to_string()).unwrap();
        check_eval_folder(&ours, &plan(10)).unwrap();
        // Another plan: refused, naming what differs.
        let e = check_eval_folder(&ours, &plan(20)).unwrap_err().to_string();
        assert!(e.contains("other settings") && e.contains("train"), "{e}");
        // The user's MANO and HTML are part of the plan; a plan without them (the procedural
        // models, also every folder made before the key) is not theirs.
        let mut mano = plan(10);
        mano["models"] = serde_json::json!({"hands": {"mano": {"dir": "/m"}}});
        let e = check_eval_folder(&ours, &mano).unwrap_err().to_string();
        assert!(e.contains("(models differ"), "{e}");
        std::fs::write(ours.join("config.json"), mano.to_string()).unwrap();
        check_eval_folder(&ours, &mano).unwrap();
        let e = check_eval_folder(&ours, &plan(10)).unwrap_err().to_string();
        assert!(e.contains("(models differ"), "{e}");
        // A user's folder, even with a config.json of its own: refused, untouched.
        let mine = dir.join("mine");
        std::fs::create_dir_all(&mine).unwrap();
        std::fs::write(mine.join("results.json"), "mine").unwrap();
        std::fs::write(mine.join("config.json"), "{\"theme\": \"dark\"}").unwrap();
        let e = check_eval_folder(&mine, &plan(10)).unwrap_err().to_string();
        assert!(e.contains("not an evaluation"), "{e}");
        assert_eq!(std::fs::read(mine.join("results.json")).unwrap(), b"mine");
        std::fs::write(dir.join("file"), "x").unwrap();
        assert!(check_eval_folder(&dir.join("file"), &plan(10)).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bitt-folder-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("scenes")).unwrap();
        dir
    }

    fn result(seed: u64, setting: MeshSetting, preset: &str) -> SceneResult {
        SceneResult {
            format: SCENE_RESULT_FORMAT.into(),
            seed,
            setting,
            preset: preset.into(),
            iterations: 1,
            stats: bitt_synth::TexelStats::from_masks(&[true, false], &[true, true]).unwrap(),
            methods: Default::default(),
            photos: None,
        }
    }

    #[test]
    fn shards_parse_and_partition_the_scenes() {
        assert_eq!(parse_shard("1/3").unwrap(), (1, 3));
        assert_eq!(parse_shard(" 0 / 1 ").unwrap(), (0, 1));
        for bad in ["3", "3/3", "0/0", "a/2", "1/b"] {
            let e = parse_shard(bad).unwrap_err().to_string();
            assert!(e.starts_with(&format!("--shard {bad}:")), "{e}");
        }
        let all = shard_seeds(5, (0, 1));
        assert_eq!(all, bitt_synth::benchmark_seeds(5));
        let mut parts: Vec<u64> = (0..2).flat_map(|i| shard_seeds(5, (i, 2))).collect();
        assert_eq!(parts.len(), 5);
        parts.sort();
        let mut sorted = all.clone();
        sorted.sort();
        assert_eq!(parts, sorted);
        assert_eq!(shard_seeds(5, (1, 2)), vec![all[1], all[3]]);
    }

    #[test]
    fn interhand_ids_are_stable_and_distinct() {
        let a = interhand_scene_id("test", 0, 10, "400262");
        assert_eq!(a, interhand_scene_id("test", 0, 10, "400262"));
        assert_ne!(a, interhand_scene_id("test", 1, 10, "400262"));
        assert_ne!(a, interhand_scene_id("val", 0, 10, "400262"));
    }

    /// Finished scenes are skipped; merging shard folders of one plan keeps one result of
    /// each scene and setting. Issue 38, class 7: folders of other plans, folders without a
    /// plan and two disagreeing results of one scene are refused, writing nothing.
    #[test]
    fn resume_skips_finished_scenes_and_merge_refuses_mismatches() {
        let (a, b) = (scratch("a"), scratch("b"));
        let plan = |scenes: usize| {
            serde_json::json!({
                "train": "t", "baseline": "b", "methods": ["bitt"], "settings": ["gt-mesh"],
                "scenes": scenes, "dataset": "synthetic",
            })
        };
        for d in [&a, &b] {
            write_json(&d.join("config.json"), &plan(2)).unwrap();
        }
        let settings = MeshSetting::ALL;
        let done = result(7, MeshSetting::GtMesh, "first");
        write_json(&result_path(&a, done.setting, done.seed), &done).unwrap();
        assert_eq!(
            pending(&a, &[7, 8], &settings),
            vec![
                (7, MeshSetting::NoisyMesh),
                (8, MeshSetting::GtMesh),
                (8, MeshSetting::NoisyMesh)
            ]
        );
        // The same scene in both shards, with the same scores: kept once.
        for r in [done.clone(), result(8, MeshSetting::GtMesh, "b")] {
            write_json(&result_path(&b, r.setting, r.seed), &r).unwrap();
        }
        merge(&[a.clone(), b.clone()]).unwrap();
        let merged: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(a.join("results.json")).unwrap())
                .unwrap();
        let presets: Vec<&str> = merged["scenes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["preset"].as_str().unwrap())
            .collect();
        assert_eq!(presets, ["first", "b"]);
        assert!(a.join("results.md").is_file());
        let before = std::fs::read(a.join("results.json")).unwrap();
        // Two results of one scene that disagree: both files named, nothing written.
        let other = result(7, MeshSetting::GtMesh, "second");
        write_json(&result_path(&b, other.setting, other.seed), &other).unwrap();
        let e = merge(&[a.clone(), b.clone()]).unwrap_err().to_string();
        assert!(
            e.contains("disagree") && e.contains("bitt-folder-a") && e.contains("bitt-folder-b"),
            "{e}"
        );
        assert_eq!(std::fs::read(a.join("results.json")).unwrap(), before);
        write_json(&result_path(&b, done.setting, done.seed), &done).unwrap();
        // A shard of another plan.
        write_json(&b.join("config.json"), &plan(3)).unwrap();
        let e = merge(&[a.clone(), b.clone()]).unwrap_err().to_string();
        assert!(e.contains("scenes differ"), "{e}");
        // A folder without a plan.
        std::fs::remove_file(b.join("config.json")).unwrap();
        let e = merge(&[a.clone(), b.clone()]).unwrap_err().to_string();
        assert!(e.contains("not an evaluation folder"), "{e}");
        assert_eq!(std::fs::read(a.join("results.json")).unwrap(), before);
        write_json(&b.join("config.json"), &plan(2)).unwrap();
        // A wrong format is refused; an empty folder has nothing to merge.
        let mut old = result(9, MeshSetting::GtMesh, "old");
        old.format = "old".into();
        write_json(&result_path(&b, old.setting, old.seed), &old).unwrap();
        let e = merge(std::slice::from_ref(&b)).unwrap_err().to_string();
        assert!(e.contains("expected bitt-eval-scene-1"), "{e}");
        let empty = scratch("empty");
        write_json(&empty.join("config.json"), &plan(2)).unwrap();
        let e = merge(std::slice::from_ref(&empty)).unwrap_err().to_string();
        assert!(e.contains("no scene results"), "{e}");
        for d in [a, b, empty] {
            let _ = std::fs::remove_dir_all(d);
        }
    }
}
