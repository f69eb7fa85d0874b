//! The bad-input battery, run against the real `bitt` binary: every case builds its inputs
//! here, runs one command, and asserts the exit code, that the message names the file and
//! the problem, and that nothing was left behind (the case's folder holds exactly what it
//! held before, byte for byte: no run folder, no temporaries, no user file touched).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use bitt_tests::real_fixture::{AnnotationOptions, scratch, write_annotation, write_image};

/// Every file below `dir` (relative path -> bytes), symbolic links as their target.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(dir).unwrap().to_path_buf();
            let meta = std::fs::symlink_metadata(&p).unwrap();
            if meta.file_type().is_symlink() {
                let target = std::fs::read_link(&p).unwrap();
                out.insert(rel, target.as_os_str().as_encoded_bytes().to_vec());
            } else if meta.is_dir() {
                out.insert(rel, b"<dir>".to_vec());
                stack.push(p);
            } else {
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// A case: a folder with its inputs, in which `bitt` runs.
struct Case {
    dir: PathBuf,
}

impl Case {
    fn new(name: &str) -> Case {
        Case {
            dir: scratch(&format!("bad-input-{name}")),
        }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    fn s(&self, name: &str) -> String {
        self.path(name).to_str().unwrap().to_string()
    }

    /// Runs `bitt args` in the case's folder and checks: exit code `code`, stderr holding
    /// every one of `expect`, and the folder unchanged.
    /// Runs `bitt` with `args` in the case's folder; it must succeed. Returns its stdout.
    fn succeeds(&self, args: &[&str]) -> String {
        let out = Command::new(env!("CARGO_BIN_EXE_bitt"))
            .args(args)
            .current_dir(&self.dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn fails(&self, args: &[&str], code: i32, expect: &[&str]) -> String {
        let before = snapshot(&self.dir);
        let out = Command::new(env!("CARGO_BIN_EXE_bitt"))
            .args(args)
            .current_dir(&self.dir)
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("running bitt");
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(
            out.status.code(),
            Some(code),
            "bitt {args:?}: exit code {:?}\n{stderr}",
            out.status.code()
        );
        for e in expect {
            assert!(stderr.contains(e), "bitt {args:?}: no {e:?} in\n{stderr}");
        }
        assert!(
            !stderr.contains("panicked"),
            "bitt {args:?} panicked:\n{stderr}"
        );
        let after = snapshot(&self.dir);
        let added: Vec<_> = after.keys().filter(|k| !before.contains_key(*k)).collect();
        let changed: Vec<_> = before
            .iter()
            .filter(|(k, v)| after.get(*k) != Some(v))
            .map(|(k, _)| k)
            .collect();
        assert!(
            added.is_empty() && changed.is_empty(),
            "bitt {args:?} left {added:?} and changed {changed:?}"
        );
        stderr
    }
}

impl Drop for Case {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A 256 x 256 photo and its annotation: the valid real input the cases break.
fn real_input(case: &Case) -> (String, String) {
    write_image(&case.path("01.jpg"), 256, 256, None);
    write_annotation(&case.path("01.pkl"), AnnotationOptions::default());
    (case.s("01.jpg"), case.s("01.pkl"))
}

fn train(case: &Case, extra: &[&str]) -> Vec<String> {
    let mut all: Vec<String> = ["train-scene", "--preset", "tiny", "--cache"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    all.push(case.s("cache"));
    all.extend(extra.iter().map(|s| s.to_string()));
    all
}

/// A tiny run of 5 iterations trained into the case's `run` folder; its path.
fn trained_run(case: &Case) -> String {
    let run = case.s("run");
    let args = train(
        case,
        &["--iterations", "5", "--turntable", "0", "--out", &run],
    );
    case.succeeds(&strs(&args));
    run
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

#[test]
fn output_folders_that_are_not_ours_are_never_written() {
    let case = Case::new("out");
    let (img, pkl) = real_input(&case);
    std::fs::create_dir_all(case.path("mine")).unwrap();
    std::fs::write(case.path("mine/notes.txt"), "my notes").unwrap();
    let mine = case.s("mine");
    let args = train(
        &case,
        &["--image", &img, "--annotation", &pkl, "--out", &mine],
    );
    case.fails(&strs(&args), 1, &["mine", "holds no run", "--force"]);
    // --force never overwrites a file of the user's.
    std::fs::write(case.path("mine/config.json"), "{\"mine\": true}").unwrap();
    let mut forced = args.clone();
    forced.push("--force".into());
    case.fails(&strs(&forced), 1, &["never overwrites", "config.json"]);
    // A dangling symbolic link is named as such.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(case.path("nowhere"), case.path("link")).unwrap();
        let link = case.s("link");
        let args = train(
            &case,
            &["--image", &img, "--annotation", &pkl, "--out", &link],
        );
        case.fails(&strs(&args), 1, &["link", "symbolic link to nothing"]);
    }
}

#[test]
fn broken_images_are_refused_naming_the_file() {
    let case = Case::new("images");
    let (img, pkl) = real_input(&case);
    let bytes = std::fs::read(&img).unwrap();
    std::fs::write(case.path("half.jpg"), &bytes[..bytes.len() / 2]).unwrap();
    write_image(&case.path("full.png"), 256, 256, None);
    let png = std::fs::read(case.path("full.png")).unwrap();
    std::fs::write(case.path("half.png"), &png[..png.len() / 2]).unwrap();
    std::fs::write(case.path("text.jpg"), "not an image").unwrap();
    write_image(&case.path("small.jpg"), 100, 80, None);
    // Issue 38, class 10: a photo that decodes but is black where the hands are (a corrupt
    // or wrong image) is named as such, not trained on.
    write_image(&case.path("black.png"), 256, 256, Some(&|_, _| [3, 3, 3]));
    let out = case.s("run");
    for (file, problem) in [
        ("black.png", "too dark where the hands are"),
        ("half.jpg", "truncated JPEG"),
        ("half.png", "half.png"),
        ("text.jpg", "text.jpg"),
        ("small.jpg", "100x80"),
        ("missing.jpg", "not found"),
    ] {
        let image = case.s(file);
        let args = train(
            &case,
            &["--image", &image, "--annotation", &pkl, "--out", &out],
        );
        case.fails(&strs(&args), 1, &[file, problem]);
    }
    case.fails(
        &["metrics", &case.s("half.jpg"), &img],
        1,
        &["half.jpg", "truncated JPEG"],
    );
}

#[test]
fn bad_annotations_are_refused_naming_the_file() {
    let case = Case::new("annotations");
    let (img, _) = real_input(&case);
    std::fs::write(case.path("noise.pkl"), [0x80, 0x04, 0x95, 0xff, 0x13, 0x00]).unwrap();
    let good = std::fs::read(case.path("01.pkl")).unwrap();
    std::fs::write(case.path("cut.pkl"), &good[..good.len() / 3]).unwrap();
    // A pickle that would run a shell command in Python.
    std::fs::write(
        case.path("evil.pkl"),
        b"\x80\x02cposix\nsystem\nq\x00(U\x02lsq\x01tR.",
    )
    .unwrap();
    write_annotation(&case.path("nan.pkl"), AnnotationOptions::NAN);
    write_annotation(&case.path("one.pkl"), AnnotationOptions::RIGHT_ONLY);
    let out = case.s("run");
    for (file, problem) in [
        ("noise.pkl", "noise.pkl"),
        ("cut.pkl", "cut.pkl"),
        ("evil.pkl", "global 'posix.system' is not allowed"),
        ("nan.pkl", "NaN"),
        ("one.pkl", "left hand is not annotated"),
        ("missing.pkl", "missing.pkl"),
    ] {
        let pkl = case.s(file);
        let args = train(
            &case,
            &["--image", &img, "--annotation", &pkl, "--out", &out],
        );
        case.fails(&strs(&args), 1, &[file, problem]);
    }
}

/// Defect 3: each hand is checked, not only the box of both.
#[test]
fn hands_off_the_image_or_behind_the_camera_are_refused() {
    let case = Case::new("placement");
    let (img, _) = real_input(&case);
    let out = case.s("run");
    for (name, offset, problem) in [
        ("far-x.pkl", [100.0, 0.0, 0.0], "only 0% of the left hand"),
        ("huge.pkl", [1e20, 0.0, 0.0], "only 0% of the left hand"),
        ("max.pkl", [3e38, 0.0, 0.0], "the left hand"),
        (
            "behind.pkl",
            [0.0, 0.0, -5.0],
            "left hand is behind the camera",
        ),
        (
            "deep.pkl",
            [0.0, 0.0, 1e20],
            "a photographed hand lies between",
        ),
    ] {
        write_annotation(
            &case.path(name),
            AnnotationOptions {
                left_offset: offset,
                ..AnnotationOptions::default()
            },
        );
        let pkl = case.s(name);
        let args = train(
            &case,
            &["--image", &img, "--annotation", &pkl, "--out", &out],
        );
        case.fails(&strs(&args), 1, &[name, problem]);
    }
}

/// Defect 8: configuration files: unknown fields, out-of-range values and broken JSON are
/// named with the file and the field.
#[test]
fn bad_configs_name_the_file_and_the_field() {
    let case = Case::new("configs");
    let (img, pkl) = real_input(&case);
    let out = case.s("run");
    let valid = serde_json::to_value(bitt::TrainConfig::preset(bitt_nets::Preset::Tiny)).unwrap();
    let mut typo = valid.clone();
    typo["optim"]["learnig_rate"] = serde_json::json!(0.01);
    let mut fast = valid.clone();
    fast["optim"]["learning_rate"] = serde_json::json!(1e4);
    let mut negative = valid.clone();
    negative["loss"]["nv"] = serde_json::json!(-0.2);
    std::fs::write(case.path("typo.json"), typo.to_string()).unwrap();
    std::fs::write(case.path("fast.json"), fast.to_string()).unwrap();
    std::fs::write(case.path("negative.json"), negative.to_string()).unwrap();
    std::fs::write(case.path("cut.json"), "{\"preset\": ").unwrap();
    for (file, problem) in [
        ("typo.json", "`optim.learnig_rate`"),
        ("fast.json", "optim.learning_rate = 10000 is out of range"),
        ("negative.json", "loss.nv = -0.2 is out of range"),
        ("cut.json", "not a training config"),
    ] {
        let config = case.s(file);
        let args = train(
            &case,
            &[
                "--image",
                &img,
                "--annotation",
                &pkl,
                "--out",
                &out,
                "--config",
                &config,
            ],
        );
        // `train` adds --preset; --config replaces it, so drop it.
        let args: Vec<String> = args
            .into_iter()
            .filter(|a| a != "--preset" && a != "tiny")
            .collect();
        case.fails(&strs(&args), 1, &[file, problem]);
    }
    // The same for the keypoint fit's and the refinement's configuration files.
    std::fs::write(case.path("fit.json"), r#"{"root_iteratons": 3}"#).unwrap();
    std::fs::write(case.path("kp.json"), r#"{"left": [], "right": []}"#).unwrap();
    case.fails(
        &[
            "fit-hands",
            "--image",
            &img,
            "--keypoints",
            &case.s("kp.json"),
            "--fit-config",
            &case.s("fit.json"),
            "--out",
            &out,
        ],
        1,
        &["fit.json", "`root_iteratons`"],
    );
}

/// Resuming what is not a run, a corrupt checkpoint, and a non-UTF-8 path (defect 7).
#[test]
fn bad_runs_and_paths_are_named() {
    let case = Case::new("runs");
    let (img, pkl) = real_input(&case);
    std::fs::create_dir_all(case.path("empty")).unwrap();
    let empty = case.s("empty");
    let args = train(&case, &["--resume", &empty]);
    case.fails(&strs(&args), 1, &["empty", "config.json"]);
    // A run folder whose checkpoint is garbage (and no previous one).
    std::fs::create_dir_all(case.path("broken/scene")).unwrap();
    let config =
        serde_json::to_string(&bitt::TrainConfig::preset(bitt_nets::Preset::Tiny)).unwrap();
    std::fs::write(case.path("broken/config.json"), config).unwrap();
    std::fs::write(case.path("broken/scene/scene.json"), "{}").unwrap();
    std::fs::write(case.path("broken/checkpoint.safetensors"), [7u8; 64]).unwrap();
    let broken = case.s("broken");
    let args = train(&case, &["--resume", &broken]);
    case.fails(
        &strs(&args),
        1,
        &["checkpoint.safetensors", "no usable checkpoint"],
    );
    // Neither input record: named as such (not as a missing scene/scene.json alone).
    std::fs::remove_dir_all(case.path("broken/scene")).unwrap();
    case.fails(&strs(&args), 1, &["input.json", "input is missing"]);
    // A path that is not UTF-8 is refused before anything is written.
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let odd = std::ffi::OsStr::from_bytes(b"caf\xe9.jpg");
        std::fs::copy(&img, case.dir.join(odd)).unwrap();
        let out = case.s("run");
        let before = snapshot(&case.dir);
        let status = Command::new(env!("CARGO_BIN_EXE_bitt"))
            .args([
                "train-scene",
                "--preset",
                "tiny",
                "--annotation",
                &pkl,
                "--out",
                &out,
            ])
            .arg("--image")
            .arg(odd)
            .current_dir(&case.dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&status.stderr);
        assert_eq!(status.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains("not valid UTF-8"), "{stderr}");
        assert_eq!(snapshot(&case.dir), before, "a refused run wrote files");
    }
    // A torch checkpoint that is not one.
    std::fs::write(case.path("vgg.pth"), b"PK\x03\x04 not really a zip").unwrap();
    case.fails(
        &[
            "convert-lpips",
            "--lin",
            &case.s("vgg.pth"),
            "--out",
            &case.s("lpips.safetensors"),
        ],
        1,
        &["vgg.pth"],
    );
    // Usage errors are clap's (exit 2), naming the missing option.
    case.fails(&["train-scene", "--mask", &img], 2, &["--image"]);
}

/// The photo-only path (`detect-hands`, `fit-hands` and `train-scene` given a photo alone)
/// on a photo without hands (a grey image), a file that is not an image and a missing photo:
/// each fails naming the photo, and nothing is written (not even the default folders).
#[test]
fn photos_without_hands_are_refused_naming_the_photo() {
    let case = Case::new("photo-only");
    write_image(
        &case.path("grey.png"),
        256,
        192,
        Some(&|_, _| [128, 128, 128]),
    );
    std::fs::write(case.path("text.jpg"), "not an image").unwrap();
    for (file, problem) in [
        ("grey.png", "no hand found"),
        ("text.jpg", "cannot decode image"),
        ("missing.jpg", "not found"),
    ] {
        let image = case.s(file);
        case.fails(&["detect-hands", "--image", &image], 1, &[file, problem]);
        case.fails(&["fit-hands", "--image", &image], 1, &[file, problem]);
        let args = train(&case, &["--image", &image]);
        case.fails(&strs(&args), 1, &[file, problem]);
    }
}

/// `export --xr` (issue 35): a run without a trained texture, an unknown convention, an
/// output that is an existing file or a folder of someone else's are refused with nothing
/// written; a good export writes the five files and replaces only an earlier XR export.
#[test]
fn xr_exports_refuse_bad_runs_and_outputs() {
    let case = Case::new("xr");
    let run = trained_run(&case);
    let xr = case.s("xr");
    let export = |run: &str, convention: &str, out: &str| -> Vec<String> {
        ["export", "--run", run, "--xr", convention, "--out", out]
            .iter()
            .map(|s| s.to_string())
            .collect()
    };
    // Unknown convention: clap's error, naming the accepted ones.
    case.fails(&strs(&export(&run, "vr", &xr)), 2, &["webxr", "openxr"]);
    // An existing file, and a folder that is not an XR export.
    std::fs::write(case.path("taken.glb"), "mine").unwrap();
    case.fails(
        &strs(&export(&run, "webxr", &case.s("taken.glb"))),
        1,
        &["taken.glb", "existing file"],
    );
    std::fs::create_dir_all(case.path("mine")).unwrap();
    std::fs::write(case.path("mine/notes.txt"), "my notes").unwrap();
    case.fails(
        &strs(&export(&run, "openxr", &case.s("mine"))),
        1,
        &["mine", "not an earlier output"],
    );
    // A run whose trained texture is gone.
    let textures = case.path("run/textures/textures.safetensors");
    let saved = std::fs::read(&textures).unwrap();
    std::fs::remove_file(&textures).unwrap();
    case.fails(
        &strs(&export(&run, "webxr", &xr)),
        1,
        &["textures.safetensors"],
    );
    std::fs::write(&textures, saved).unwrap();
    // A good export, then another convention over it.
    for convention in ["webxr", "openxr"] {
        let stdout = case.succeeds(&strs(&export(&run, convention, &xr)));
        assert!(stdout.contains("mean vertex error"), "{stdout}");
        let mut names: Vec<String> = std::fs::read_dir(&xr)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        let mut want = vec!["joints.json", "left.glb", "playback.json", "right.glb"];
        if convention == "webxr" {
            want.push("xr.html");
        }
        assert_eq!(names, want, "{convention}");
    }
    // Nothing but the export is left beside it (no temporary folders).
    let stray: Vec<_> = std::fs::read_dir(&case.dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(stray.is_empty(), "{stray:?}");
}

/// Issue 38, class 8 and 11: `export` and `render-avatar` replace only their own kind of
/// file, the OBJ's companions never a user's `.mtl` or PNG, and a space in the OBJ's name
/// does not break its `mtllib`.
#[test]
fn exports_and_renders_never_replace_users_files() {
    let case = Case::new("users-files");
    let run = trained_run(&case);
    // Files of the user's whose names the commands are given.
    std::fs::write(case.path("notes.glb"), "my notes").unwrap();
    std::fs::write(case.path("photo.png"), "not a png of ours").unwrap();
    std::fs::write(case.path("m.mtl"), "newmtl mine\n").unwrap();
    case.fails(
        &["export", "--run", &run, "--out", &case.s("notes.glb")],
        1,
        &["notes.glb", "untouched"],
    );
    case.fails(
        &[
            "export",
            "--run",
            &run,
            "--static",
            "--out",
            &case.s("notes.glb"),
        ],
        1,
        &["notes.glb", "untouched"],
    );
    case.fails(
        &[
            "render-avatar",
            "--run",
            &run,
            "--out",
            &case.s("photo.png"),
        ],
        1,
        &["photo.png", "untouched"],
    );
    case.fails(
        &[
            "export",
            "--run",
            &run,
            "--format",
            "obj",
            "--out",
            &case.s("m.obj"),
        ],
        1,
        &["m.mtl", "nothing was written"],
    );
    // Their own earlier outputs are replaced; an OBJ named with a space gets companions
    // named without one.
    let ok = |args: &[&str]| {
        case.succeeds(args);
    };
    for _ in 0..2 {
        ok(&["export", "--run", &run, "--out", &case.s("a.glb")]);
        ok(&["render-avatar", "--run", &run, "--out", &case.s("a.png")]);
        ok(&[
            "export",
            "--run",
            &run,
            "--format",
            "obj",
            "--out",
            &case.s("my hand.obj"),
        ]);
    }
    let obj = std::fs::read_to_string(case.path("my hand.obj")).unwrap();
    assert!(obj.contains("\nmtllib my_hand.mtl\n"), "{obj}");
    for f in [
        "my_hand.mtl",
        "my_hand_left_hand.png",
        "my_hand_right_hand.png",
    ] {
        assert!(case.path(f).is_file(), "{f}");
    }
}

/// Issue 38, class 5: a real run whose photo or textures were altered after they were written
/// is refused by `--resume`, `export` and `render-avatar`, naming the file and the tensor,
/// instead of being trained on or exported.
#[test]
fn altered_run_files_are_named_not_trusted() {
    let case = Case::new("altered");
    let (img, pkl) = real_input(&case);
    let run = case.s("run");
    let args = train(
        &case,
        &[
            "--image",
            &img,
            "--annotation",
            &pkl,
            "--iterations",
            "3",
            "--turntable",
            "0",
            "--out",
            &run,
            "--keep-checkpoints",
        ],
    );
    case.succeeds(&strs(&args));
    // Flips one bit near the end of a run file (inside its last tensor); returns the
    // original bytes.
    let flip = |name: &str| {
        let path = case.path(&format!("run/{name}"));
        let good = std::fs::read(&path).unwrap();
        let mut bad = good.clone();
        let at = bad.len() - 7;
        bad[at] ^= 0x40;
        std::fs::write(&path, bad).unwrap();
        (path, good)
    };
    let resume = train(&case, &["--resume", &run, "--iterations", "4"]);
    let glb = case.s("avatar.glb");
    let png = case.s("render.png");
    for file in ["input/images.safetensors", "textures/textures.safetensors"] {
        let (path, good) = flip(file);
        let name = file.rsplit('/').next().unwrap();
        if file.starts_with("input") {
            case.fails(&strs(&resume), 1, &[name, "is corrupt"]);
        }
        case.fails(
            &["export", "--run", &run, "--out", &glb],
            1,
            &[name, "is corrupt"],
        );
        case.fails(
            &["render-avatar", "--run", &run, "--out", &png],
            1,
            &[name, "is corrupt"],
        );
        std::fs::write(&path, good).unwrap();
    }
    case.succeeds(&["export", "--run", &run, "--out", &glb]);
    // Issue 38, class 10: a run without its input record is named as such (not as a missing
    // scene/scene.json, which a real run never has).
    std::fs::remove_file(case.path("run/input.json")).unwrap();
    case.fails(
        &["export", "--run", &run, "--out", &glb],
        1,
        &["input.json", "input is missing"],
    );
}
