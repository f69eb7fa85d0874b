//! `cargo xtask fuzz [TARGET|all] [--seconds N | --runs N]`: runs the cargo-fuzz targets of
//! `fuzz/` (its own workspace, never built with the main one), one after the other.
//!
//! New inputs go to a scratch corpus per target (`fuzz/target/corpus-work/TARGET`, ignored by
//! git); the committed corpora (`fuzz/corpus/TARGET`, minimised, replayed by
//! `tests/tests/fuzz_corpus.rs`) are only read. Crashes land in `fuzz/artifacts/TARGET`.

use std::process::Command;

use anyhow::{Context, Result, bail};

use crate::{check, root};

/// Every target with its `-max_len` (a little above its largest seed).
const TARGETS: [(&str, usize, &str); 8] = [
    ("from_bytes", 4096, "pickles (bitt-pickle from_bytes)"),
    (
        "torch",
        8192,
        "torch checkpoints (bitt-pickle torch_from_bytes)",
    ),
    (
        "mano_safetensors",
        32768,
        "MANO safetensors (bitt-mesh mano::from_safetensors)",
    ),
    (
        "annotation",
        4096,
        "annotation pickles and hands.json (bitt-mesh bitt_annotation_from_bytes)",
    ),
    (
        "interhand",
        16384,
        "InterHand2.6M JSON (bitt-mesh InterHandDataset::from_json_bytes)",
    ),
    (
        "keypoints",
        4096,
        "2D keypoint JSON and its plausibility checks (bitt-mesh parse_keypoints, \
         check_plausible)",
    ),
    (
        "camera_values",
        256,
        "--intrinsics and --view (bitt-mesh camera::parse_intrinsics, \
         check_intrinsics_for_image, parse_orbit_view)",
    ),
    ("light", 512, "--light text (bitt-mesh light::parse_light)"),
];

const USAGE: &str = "usage: cargo xtask fuzz [TARGET|all] [--seconds N | --runs N] \
                     (TARGET: from_bytes, torch, mano_safetensors, annotation, interhand, \
                     keypoints, camera_values, light; default: all, 60 seconds each)";

/// How long each target runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Budget {
    Seconds(u64),
    Runs(u64),
}

/// Parses `[TARGET|all] [--seconds N | --runs N]` (in any order).
fn parse(args: &[String]) -> Result<(Vec<&'static str>, Budget)> {
    let mut target: Option<&str> = None;
    let mut budget: Option<Budget> = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--seconds" | "--runs" => {
                let n: u64 = it
                    .next()
                    .with_context(|| format!("{a} takes a number; {USAGE}"))?
                    .parse()
                    .with_context(|| format!("{a} takes a number; {USAGE}"))?;
                if n == 0 || budget.is_some() {
                    bail!("give one positive --seconds or --runs; {USAGE}");
                }
                budget = Some(if a == "--seconds" {
                    Budget::Seconds(n)
                } else {
                    Budget::Runs(n)
                });
            }
            t if target.is_none() && !t.starts_with('-') => target = Some(t),
            other => bail!("unexpected argument `{other}`; {USAGE}"),
        }
    }
    let targets = match target.unwrap_or("all") {
        "all" => TARGETS.iter().map(|t| t.0).collect(),
        t => vec![
            TARGETS
                .iter()
                .find(|x| x.0 == t)
                .map(|x| x.0)
                .with_context(|| format!("unknown fuzz target `{t}`; {USAGE}"))?,
        ],
    };
    Ok((targets, budget.unwrap_or(Budget::Seconds(60))))
}

pub fn fuzz(args: &[String]) -> Result<()> {
    let (targets, budget) = parse(args)?;
    let have = Command::new("cargo")
        .args(["fuzz", "--version"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !have {
        bail!("cargo-fuzz is not installed: `cargo install cargo-fuzz`");
    }
    let dir = root().join("fuzz");
    for name in targets {
        let (_, max_len, what) = TARGETS
            .iter()
            .find(|t| t.0 == name)
            .context("target listed")?;
        println!("== fuzz {name}: {what}");
        let work = dir.join("target/corpus-work").join(name);
        std::fs::create_dir_all(&work)?;
        let limit = match budget {
            Budget::Seconds(s) => format!("-max_total_time={s}"),
            Budget::Runs(n) => format!("-runs={n}"),
        };
        let status = Command::new("cargo")
            .current_dir(&dir)
            // cargo-fuzz needs nightly flags; the stable toolchain accepts them with this switch.
            .env("RUSTC_BOOTSTRAP", "1")
            .args(["fuzz", "run", name])
            .arg(&work)
            .arg(format!("corpus/{name}"))
            .arg("--")
            .arg(limit)
            .arg(format!("-max_len={max_len}"))
            .arg("-timeout=10")
            .arg("-print_final_stats=1")
            .status()?;
        check(status, &format!("cargo fuzz run {name}"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn arguments() {
        let (t, b) = parse(&[]).unwrap();
        assert_eq!((t.len(), b), (TARGETS.len(), Budget::Seconds(60)));
        let (t, b) = parse(&args(&["torch", "--runs", "1000"])).unwrap();
        assert_eq!((t, b), (vec!["torch"], Budget::Runs(1000)));
        let (t, b) = parse(&args(&["--seconds", "5", "all"])).unwrap();
        assert_eq!((t.len(), b), (TARGETS.len(), Budget::Seconds(5)));
        assert!(parse(&args(&["nope"])).is_err());
        assert!(parse(&args(&["--runs"])).is_err());
        assert!(parse(&args(&["--runs", "1", "--seconds", "2"])).is_err());
        assert!(parse(&args(&["torch", "keypoints"])).is_err());
    }
}
