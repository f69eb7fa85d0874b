//! `cargo xtask kill-test [--times N] [--seed S] [--only CASE]`: kills the release `bitt` with
//! SIGKILL at random moments while it writes its outputs, and checks after every kill that
//! the output is absent or complete (every file whole), and that rerunning the same command
//! into the same place then succeeds with a complete output (issue 38, class 9). Not in CI:
//! it runs each case `N + 1` times (about 15 minutes for the default 20 on 2 cores).
//!
//! Cases: `fit-hands`, `refine-hands` (whole folders), `export` to a `.glb` and to an `.obj`
//! with its `.mtl` and textures, and `eval` (a resumable folder: every file in it must be
//! whole, and the rerun finishes it). The inputs are made here (`bitt synth`, a short
//! `train-scene`), so nothing licensed or downloaded is needed. Kill moments are drawn
//! uniformly over 30-105 % of the case's uninterrupted wall clock, where the writes are.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use crate::{build_bitt, root};

const USAGE: &str = "usage: cargo xtask kill-test [--times N] [--seed S] [--only CASE] \
                     (CASE: fit-hands, refine-hands, export-glb, export-obj, eval)";

/// One command under test.
struct Case {
    name: &'static str,
    /// The arguments of `bitt`, given where the output goes.
    args: Vec<String>,
    /// The output: a folder, or one file (`.glb`), or the `.obj` whose companions share its
    /// folder.
    out: PathBuf,
    kind: OutKind,
}

#[derive(Clone, Copy, PartialEq)]
enum OutKind {
    /// A folder written whole (`fit-hands`, `refine-hands`).
    Folder,
    /// A folder that fills up scene by scene and is resumed (`eval`).
    Resumable,
    /// One file.
    File,
    /// An OBJ and its companions in their own folder.
    Obj,
}

/// What a killed command left.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Left {
    Absent,
    Complete,
    /// A resumable folder with whole files but not finished.
    Resumable,
}

/// SplitMix64: the kill moments, reproducible from `--seed`.
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

pub fn kill_test(args: &[String]) -> Result<()> {
    let (mut times, mut seed, mut only) = (20usize, 1u64, None::<String>);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || it.next().context(USAGE);
        match a.as_str() {
            "--times" => times = value()?.parse().context(USAGE)?,
            "--seed" => seed = value()?.parse().context(USAGE)?,
            "--only" => only = Some(value()?.clone()),
            _ => bail!("unexpected argument `{a}`; {USAGE}"),
        }
    }
    if times == 0 {
        bail!("--times must be at least 1; {USAGE}");
    }
    let bin = build_bitt()?;
    let dir = root().join("target/kill-test");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let cases = prepare(&bin, &dir)?;
    let mut rng = Rng(seed);
    let mut failures = Vec::new();
    for case in cases
        .iter()
        .filter(|c| only.as_deref().is_none_or(|o| o == c.name))
    {
        let (expected, wall) = reference(&bin, case)?;
        let mut counts = std::collections::BTreeMap::<Left, usize>::new();
        let mut reruns = 0;
        for k in 0..times {
            remove(&case.out)?;
            let at = wall.mul_f64(0.3 + 0.75 * rng.next_f64());
            let mut child = Command::new(&bin)
                .args(&case.args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()?;
            std::thread::sleep(at);
            let _ = child.kill(); // SIGKILL on Unix
            let _ = child.wait();
            match state(case, &expected) {
                Ok(left) => *counts.entry(left).or_default() += 1,
                Err(e) => failures.push(format!("{} kill {k} at {at:?}: {e:#}", case.name)),
            }
            let status = Command::new(&bin)
                .args(&case.args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()?;
            match (status.success(), state(case, &expected)) {
                (true, Ok(Left::Complete)) => reruns += 1,
                (ok, s) => failures.push(format!(
                    "{} rerun after kill {k}: exit ok {ok}, output {s:?}",
                    case.name
                )),
            }
        }
        println!(
            "{:<13} {times} kills at 30-105% of {:.1} s: absent {}, complete {}, resumable {}; \
             reruns complete {reruns}/{times}",
            case.name,
            wall.as_secs_f64(),
            counts.get(&Left::Absent).unwrap_or(&0),
            counts.get(&Left::Complete).unwrap_or(&0),
            counts.get(&Left::Resumable).unwrap_or(&0),
        );
    }
    if !failures.is_empty() {
        for f in &failures {
            println!("FAILED: {f}");
        }
        bail!(
            "{} kills left a broken output or a failed rerun",
            failures.len()
        );
    }
    Ok(())
}

/// Makes the inputs (one synthetic scene, its keypoints, a fit, a short run) and the cases.
fn prepare(bin: &Path, dir: &Path) -> Result<Vec<Case>> {
    let s = |p: &Path| p.display().to_string();
    let run = |args: &[String]| -> Result<()> {
        let out = Command::new(bin).args(args).output()?;
        if !out.status.success() {
            bail!(
                "bitt {}: {}",
                args.join(" "),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        Ok(())
    };
    let strings = |a: &[&str]| a.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let synth = dir.join("synth");
    run(&strings(&["synth", "--scenes", "1", "--out", &s(&synth)]))?;
    let scene = synth.join("scene_000");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scene.join("scene.json"))?)?;
    let keypoints = dir.join("keypoints.json");
    std::fs::write(
        &keypoints,
        serde_json::to_string(&json["train"]["keypoints_2d"])?,
    )?;
    let image = scene.join("train.png");
    let fit = dir.join("fit");
    run(&strings(&[
        "fit-hands",
        "--image",
        &s(&image),
        "--keypoints",
        &s(&keypoints),
        "--out",
        &s(&fit),
    ]))?;
    let trained = dir.join("run");
    run(&strings(&[
        "train-scene",
        "--preset",
        "tiny",
        "--iterations",
        "3",
        "--turntable",
        "0",
        "--cache",
        &s(&dir.join("cache")),
        "--out",
        &s(&trained),
    ]))?;
    let out = |name: &str| dir.join("out").join(name);
    Ok(vec![
        Case {
            name: "fit-hands",
            args: strings(&[
                "fit-hands",
                "--image",
                &s(&image),
                "--keypoints",
                &s(&keypoints),
                "--out",
                &s(&out("fit")),
            ]),
            out: out("fit"),
            kind: OutKind::Folder,
        },
        Case {
            name: "refine-hands",
            args: strings(&[
                "refine-hands",
                "--image",
                &s(&image),
                "--annotation",
                &s(&fit.join("hands.json")),
                "--cache",
                &s(&dir.join("cache")),
                "--out",
                &s(&out("refine")),
            ]),
            out: out("refine"),
            kind: OutKind::Folder,
        },
        Case {
            name: "export-glb",
            args: strings(&[
                "export",
                "--run",
                &s(&trained),
                "--out",
                &s(&out("avatar.glb")),
            ]),
            out: out("avatar.glb"),
            kind: OutKind::File,
        },
        Case {
            name: "export-obj",
            args: strings(&[
                "export",
                "--run",
                &s(&trained),
                "--format",
                "obj",
                "--out",
                &s(&out("obj").join("hands.obj")),
            ]),
            out: out("obj").join("hands.obj"),
            kind: OutKind::Obj,
        },
        Case {
            name: "eval",
            args: strings(&[
                "eval",
                "--preset",
                "tiny",
                "--iterations",
                "3",
                "--baseline-iterations",
                "3",
                "--methods",
                "bitt,harp-like",
                "--scenes",
                "1",
                "--cache",
                &s(&dir.join("cache")),
                "--out",
                &s(&out("eval")),
            ]),
            out: out("eval"),
            kind: OutKind::Resumable,
        },
    ])
}

/// Runs a case uninterrupted, twice (the first fills the caches): the files of its complete
/// output and the second run's wall clock.
fn reference(bin: &Path, case: &Case) -> Result<(BTreeSet<String>, Duration)> {
    let mut wall = Duration::ZERO;
    for _ in 0..2 {
        remove(&case.out)?;
        let t = Instant::now();
        let out = Command::new(bin).args(&case.args).output()?;
        wall = t.elapsed();
        if !out.status.success() {
            bail!(
                "{}: the uninterrupted run failed: {}",
                case.name,
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
    let files = visible_files(&output_root(case))?;
    for f in &files {
        whole(&output_root(case).join(f))?;
    }
    Ok((files, wall))
}

/// The folder holding a case's output files.
fn output_root(case: &Case) -> PathBuf {
    match case.kind {
        OutKind::Folder | OutKind::Resumable => case.out.clone(),
        OutKind::File | OutKind::Obj => {
            case.out.parent().map(Path::to_path_buf).unwrap_or_default()
        }
    }
}

/// Removes a case's output (and the temporaries a killed run left beside it).
fn remove(out: &Path) -> Result<()> {
    let target = match out.extension() {
        Some(_) => out.parent().map(Path::to_path_buf).unwrap_or_default(),
        None => out.to_path_buf(),
    };
    if target.exists() {
        std::fs::remove_dir_all(&target)?;
    }
    if let Some(parent) = target.parent() {
        std::fs::create_dir_all(parent)?;
        if out.extension().is_some() {
            std::fs::create_dir_all(&target)?;
        }
    }
    Ok(())
}

/// Every file below `dir` that is not hidden (relative paths), none for a missing folder.
fn visible_files(dir: &Path) -> Result<BTreeSet<String>> {
    let mut out = BTreeSet::new();
    if !dir.exists() {
        return Ok(out);
    }
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d)? {
            let p = e?.path();
            let name = p
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .to_string();
            if name.starts_with('.') {
                continue;
            }
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.strip_prefix(dir)?.display().to_string());
            }
        }
    }
    Ok(out)
}

/// Classifies what a killed run left: absent, complete (the reference's files, each whole),
/// or, for a resumable folder, a subset of whole files; anything else is an error.
fn state(case: &Case, expected: &BTreeSet<String>) -> Result<Left> {
    let root = output_root(case);
    let files = visible_files(&root)?;
    if files.is_empty() {
        return Ok(Left::Absent);
    }
    for f in &files {
        whole(&root.join(f)).with_context(|| format!("{f} is not whole"))?;
    }
    if &files == expected {
        return Ok(Left::Complete);
    }
    if case.kind == OutKind::Resumable && files.is_subset(expected) {
        return Ok(Left::Resumable);
    }
    bail!(
        "a partial output: has {:?}, the complete one {:?}",
        files,
        expected
    )
}

/// Checks that a file is whole: JSON parses, a PNG ends with its IEND chunk, a GLB's
/// header length is the file's, an OBJ or MTL ends with a newline; other files must not be
/// empty.
fn whole(path: &Path) -> Result<()> {
    let bytes = std::fs::read(path)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default();
    match ext {
        "json" => {
            serde_json::from_slice::<serde_json::Value>(&bytes)?;
        }
        "png" => {
            let iend = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];
            if !(bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.ends_with(&iend)) {
                bail!("not a whole PNG ({} bytes)", bytes.len());
            }
        }
        "glb" => {
            let len = bytes
                .get(8..12)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
            if !(bytes.starts_with(b"glTF") && len == Some(bytes.len())) {
                bail!(
                    "not a whole GLB ({} bytes, header says {len:?})",
                    bytes.len()
                );
            }
        }
        "obj" | "mtl" | "md" => {
            if !bytes.ends_with(b"\n") {
                bail!("text without its final newline ({} bytes)", bytes.len());
            }
        }
        _ => {
            if bytes.is_empty() {
                bail!("empty");
            }
        }
    }
    Ok(())
}
