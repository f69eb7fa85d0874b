//! Real-data inputs built in the test: a miniature InterHand2.6M folder (selection rule,
//! crop / intrinsics consistency, clear errors) and a BiTT annotation pickle with its image
//! (a trainer at the `tiny` preset, the run record, resume, the saved avatar in other poses).

use std::path::Path;

use bitt::TrainConfig;
use bitt::real::{
    HandSource, PriorSource, REFERENCE_HAND_BOX_RATIO, RealAvatar, RealInput, RealRunSettings,
    annotation_pose, annotation_setup, hands_box, interhand_setup, interhand_views, orbit_hands,
    parse_pose_family, procedural_pose, render_textures, score_real,
};
use bitt::trainer::Silent;
use bitt_mesh::glam::{DVec2, DVec3};
use bitt_mesh::interhand::{InterHandDataset, InterHandSelection};
use bitt_mesh::procedural_pair;
use bitt_nets::Preset;
use bitt_tests::real_fixture::{
    AnnotationOptions, MINI_W, scratch, write_annotation, write_image, write_mano_html_folders,
    write_mini_interhand,
};
use burn::tensor::Device;

fn tiny(iterations: usize) -> TrainConfig {
    let mut c = TrainConfig::preset(Preset::Tiny);
    c.iterations = iterations;
    c
}

fn err<T: std::fmt::Debug, E: std::fmt::Display>(r: Result<T, E>) -> String {
    r.expect_err("must fail").to_string()
}

// ---------------------------------------------------------------------------------------------
// InterHand2.6M.

#[test]
fn interhand_selection_follows_the_documented_rule() {
    let root = write_mini_interhand(&scratch("ih-select"));
    let ds = InterHandDataset::open(&root, "test").unwrap();
    assert_eq!(ds.counts.images, 11);
    assert_eq!(ds.counts.interacting, 9); // frame 103 is single-handed, capture 1 invalid
    assert_eq!(ds.counts.camera_kept, 7); // 410001 and 400015 dropped
    assert_eq!(ds.counts.candidates, 6); // frame 104 lacks the left hand's fit
    assert_eq!(ds.captures(), vec![0]);
    assert_eq!(ds.frames(0), vec![100, 101, 102]);

    let sel = InterHandSelection::default();
    let scene = ds.select(&sel).unwrap();
    assert_eq!(scene.capture, 0);
    // The frame with the most candidate cameras; its camera with the largest hand box.
    assert_eq!(scene.train.entry.frame_idx, 100);
    assert_eq!(scene.train.entry.camera, "400263");
    // Novel views: the other cameras of frame 100 except the dark 400264.
    let views: Vec<&str> = scene
        .novel_views
        .iter()
        .map(|v| v.entry.camera.as_str())
        .collect();
    assert_eq!(views, vec!["400262"]);
    // Novel poses: frames 101 (largest box: 400264) and 102 (the training camera).
    let poses: Vec<(i64, &str)> = scene
        .novel_poses
        .iter()
        .map(|v| (v.entry.frame_idx, v.entry.camera.as_str()))
        .collect();
    assert_eq!(poses, vec![(101, "400264"), (102, "400263")]);
    // Each view has both hands and the full frame's camera.
    for v in std::iter::once(&scene.train).chain(&scene.novel_views) {
        assert!(v.scene.left.is_some() && v.scene.right.is_some());
        assert_eq!(v.scene.camera.width, MINI_W);
        assert!(v.image_path.is_file(), "{}", v.image_path.display());
    }
    // Deterministic.
    assert_eq!(ds.select(&sel).unwrap(), scene);
    // Asking for fewer and for explicit choices.
    let one = ds
        .select(&InterHandSelection {
            frame: Some(101),
            camera: Some("400262".into()),
            novel_views: 1,
            novel_poses: 1,
            ..sel.clone()
        })
        .unwrap();
    assert_eq!(one.train.entry.camera, "400262");
    assert_eq!(one.novel_views.len(), 1);
    assert_eq!(one.novel_views[0].entry.camera, "400264");
    assert_eq!(one.novel_poses.len(), 1);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn interhand_errors_name_the_file_and_what_is_missing() {
    let root = write_mini_interhand(&scratch("ih-errors"));
    let ds = InterHandDataset::open(&root, "test").unwrap();
    let pick = |capture: Option<i64>, frame: Option<i64>, camera: Option<&str>| {
        ds.select(&InterHandSelection {
            capture,
            frame,
            camera: camera.map(str::to_owned),
            ..InterHandSelection::default()
        })
    };
    let e = err(pick(Some(1), None, None));
    assert!(e.contains("_data.json") && e.contains("capture 1"), "{e}");
    let e = err(pick(Some(9), None, None));
    assert!(
        e.contains("capture 9") && e.contains("not in the file"),
        "{e}"
    );
    let e = err(pick(Some(0), Some(104), None));
    assert!(e.contains("frame 104") && e.contains("MANO"), "{e}");
    let e = err(pick(Some(0), Some(100), Some("400999")));
    assert!(e.contains("400999") && e.contains("400262"), "{e}");
    // A missing training image is named.
    let img = root.join("images/test/Capture0/0000_seq/cam400263/image100.png");
    std::fs::remove_file(&img).unwrap();
    let e = err(pick(None, None, Some("400263")));
    assert!(e.contains("image100.png") && e.contains("missing"), "{e}");
    // A wrong split / missing annotation file names the file.
    let e = err(InterHandDataset::open(&root, "val"));
    assert!(e.contains("InterHand2.6M_val_data.json"), "{e}");
    let mano = root.join("annotations/test/InterHand2.6M_test_MANO_NeuralAnnot.json");
    std::fs::remove_file(&mano).unwrap();
    let e = err(InterHandDataset::open(&root, "test"));
    assert!(e.contains("MANO_NeuralAnnot.json"), "{e}");
    // A data file without a required field names the file and the field.
    let data = root.join("annotations/test/InterHand2.6M_test_data.json");
    std::fs::write(
        &data,
        r#"{"images": [{"id": 1, "file_name": "a.png", "width": 4, "height": 4, "camera": "400262", "frame_idx": 1}], "annotations": []}"#,
    )
    .unwrap();
    std::fs::write(&mano, "{}").unwrap();
    let e = err(InterHandDataset::open(&root, "test"));
    assert!(e.contains("_data.json") && e.contains("capture"), "{e}");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn interhand_views_are_cropped_with_consistent_intrinsics() {
    let root = write_mini_interhand(&scratch("ih-crop"));
    let ds = InterHandDataset::open(&root, "test").unwrap();
    let scene = ds.select(&InterHandSelection::default()).unwrap();
    let models = procedural_pair();
    let size = 32;
    let views = interhand_views(&scene, &models, size).unwrap();
    let full = &scene.train.scene.camera;
    let crop = &views.train.hands.camera;
    assert_eq!([crop.width, crop.height], [size as u32; 2]);
    // A known 3-D point projects to the same place before and after the crop.
    let b = hands_box(&scene.train.scene, &models).unwrap();
    let side = (b[2] - b[0]).max(b[3] - b[1]) / REFERENCE_HAND_BOX_RATIO;
    let origin = DVec2::new((b[0] + b[2] - side) / 2.0, (b[1] + b[3] - side) / 2.0);
    let p = full.camera_to_world(DVec3::new(0.01, -0.02, 0.6));
    let before = full.project(p).unwrap();
    let after = crop.project(p).unwrap();
    let expect = (before - origin) * (size as f64 / side);
    assert!((after - expect).length() < 1e-9, "{after} vs {expect}");
    // The pixels agree with the intrinsics: the frames are a horizontal ramp
    // (value = x / W at continuous x), so each cropped pixel's value says which source x it
    // came from; that x is where the crop camera's ray through the pixel centre lands in
    // the full frame.
    let hw = size * size;
    let mut checked = 0;
    for r in (2..size - 2).step_by(5) {
        for c in (2..size - 2).step_by(5) {
            let ray = crop.unproject(DVec2::new(c as f64 + 0.5, r as f64 + 0.5), 1.0);
            let src = full.project(crop.camera_to_world(ray)).unwrap();
            if src.x < 1.0 || src.x > f64::from(MINI_W) - 1.0 || src.y < 1.0 || src.y > 47.0 {
                continue; // near or outside the frame's border: black padding blends in
            }
            let v = f64::from(views.train.image[r * size + c]);
            assert!(
                (v * f64::from(MINI_W) - src.x).abs() < 0.6,
                "pixel ({r}, {c}): value says x = {}, the camera says {}",
                v * f64::from(MINI_W),
                src.x
            );
            assert_eq!(
                views.train.image[hw + r * size + c],
                views.train.image[r * size + c]
            );
            checked += 1;
        }
    }
    assert!(checked >= 4, "only {checked} pixels inside the frame");
    assert_eq!(views.novel_views.len(), 1);
    assert_eq!(views.novel_poses.len(), 2);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn interhand_scene_trains_and_scores_its_novel_views() {
    let root = write_mini_interhand(&scratch("ih-train"));
    let ds = InterHandDataset::open(&root, "test").unwrap();
    let scene = ds.select(&InterHandSelection::default()).unwrap();
    let device = Device::flex().autodiff();
    let mut setup = interhand_setup(
        &scene,
        &ds.paths,
        RealRunSettings::new(
            &HandSource::Procedural,
            &PriorSource::Procedural,
            tiny(2),
            &device,
        ),
    )
    .unwrap();
    setup.trainer.train(None, &mut Silent).unwrap();
    let scores = score_real(&setup.trainer, &setup.scene).unwrap();
    assert_eq!(scores.novel_views.unwrap().count, 1);
    assert_eq!(scores.novel_poses.unwrap().count, 2);
    assert!(scores.views.iter().all(|(_, s)| s.fine.psnr.is_finite()));
    match &setup.input.source {
        bitt::real::RealSource::InterHand {
            capture,
            frame,
            camera,
            ..
        } => {
            assert_eq!((*capture, *frame, camera.as_str()), (0, 100, "400263"));
        }
        s => panic!("unexpected source {s:?}"),
    }
    let _ = std::fs::remove_dir_all(&root);
}

// ---------------------------------------------------------------------------------------------
// An annotation pickle and its image.

fn demo_pair(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let (img, pkl) = (dir.join("01.jpg"), dir.join("01.pkl"));
    write_image(&img, 256, 256, None);
    write_annotation(&pkl, AnnotationOptions::default());
    (img, pkl)
}

#[test]
fn annotation_run_trains_resumes_and_renders_in_other_poses() {
    let dir = scratch("ann-run");
    let (img, pkl) = demo_pair(&dir);
    let other = dir.join("02.pkl");
    write_annotation(
        &other,
        AnnotationOptions {
            turn: 0.4,
            ..AnnotationOptions::default()
        },
    );
    let device = Device::flex().autodiff();
    let run = dir.join("run");
    let (hands, prior) = (HandSource::Procedural, PriorSource::Procedural);
    let mut setup = annotation_setup(
        &img,
        &pkl,
        RealRunSettings::new(&hands, &prior, tiny(3), &device),
    )
    .unwrap();
    assert_eq!(setup.trainer.view.image.dims(), [1, 3, 32, 32]);
    // Both hands are seen (32 x 32 pixels cover few of the 128² layout's texels).
    let [lv, rv] = setup.trainer.view.visible_fraction();
    assert!(lv > 0.01 && rv > 0.01, "{lv} {rv}");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(
        run.join("config.json"),
        serde_json::to_string(&setup.trainer.config).unwrap(),
    )
    .unwrap();
    setup.input.write(&run, &setup.scene).unwrap();
    // Train 2 iterations, checkpoint, then resume from the folder for the third: the same
    // result as 3 straight iterations.
    let mut straight = annotation_setup(
        &img,
        &pkl,
        RealRunSettings::new(&hands, &prior, tiny(3), &device),
    )
    .unwrap();
    straight.trainer.train(None, &mut Silent).unwrap();
    setup.trainer.config.iterations = 2;
    let ckpt = run.join("checkpoint.safetensors");
    setup.trainer.train(Some(&ckpt), &mut Silent).unwrap();
    let (input, _, mut resumed) = RealInput::resume_trainer(&run, tiny(3), None, &device).unwrap();
    assert_eq!(input, setup.input);
    resumed
        .restore(&bitt::checkpoint::Checkpoint::load(&ckpt).unwrap())
        .unwrap();
    resumed.train(None, &mut Silent).unwrap();
    assert_eq!(resumed.history.len(), 3);
    assert_eq!(resumed.history[2].total, straight.trainer.history[2].total);
    // The run folder, written as for synthetic runs minus ground-truth scores.
    let summary = bitt::run::write_run(&run, &resumed, None, 2, &[]).unwrap();
    assert!(summary.synthetic.is_none());
    for f in [
        "report.html",
        "avatar.glb",
        "light.json",
        "metrics.json",
        "input.json",
        "input/images.safetensors",
        "input/train.png",
        "renders/turntable/frame_001.png",
        "textures/textures.safetensors",
    ] {
        assert!(run.join(f).is_file(), "{f} missing");
    }
    // The light's location was chosen from the photo, the same on resuming, and light.json
    // says so.
    let searched = setup
        .trainer
        .view
        .light_location
        .expect("searched for a photo");
    assert_eq!(resumed.view.light_location, Some(searched));
    let light_file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("light.json")).unwrap()).unwrap();
    assert!(
        light_file["location_from"]
            .as_str()
            .is_some_and(|s| s.contains("photo")),
        "{light_file}"
    );
    let location: Vec<f32> = serde_json::from_value(light_file["location"].clone()).unwrap();
    assert_eq!(location, searched.to_vec());
    // The saved avatar renders the training view as the trainer does.
    let avatar = RealAvatar::load(&run).unwrap();
    let assets = avatar.assets().unwrap();
    let host = Device::flex();
    let light = bitt::evaluate::Avatar::from_trainer(&resumed)
        .unwrap()
        .light;
    let image = render_textures(
        &assets,
        &avatar.fine,
        &avatar.input.train.hands,
        &light,
        avatar.config.loss.photo_occlusion,
        &host,
    )
    .unwrap();
    let fine = bitt_stdx::to_host(resumed.forward().unwrap().fine_image.inner()).unwrap();
    let diff = image
        .iter()
        .zip(&fine)
        .map(|(a, b)| (a - b).abs())
        .sum::<f32>()
        / fine.len() as f32;
    assert!(diff < 1e-4, "saved avatar render differs by {diff}");
    // Another annotation's pose and a procedural pose render the hands.
    let models = procedural_pair();
    let pose = annotation_pose(&other, &models, 32).unwrap();
    let family = parse_pose_family("interlaced").unwrap();
    let betas = vec![0.0; 10];
    let proc_pose = procedural_pose(&models, family, [&betas, &betas], 1, 32).unwrap();
    for hands in [pose, orbit_hands(&proc_pose, &models, 0.6, 0.2).unwrap()] {
        let img = render_textures(
            &assets,
            &avatar.fine,
            &hands,
            &light,
            avatar.config.loss.photo_occlusion,
            &host,
        )
        .unwrap();
        let lit = img.iter().filter(|&&v| v > 0.0).count();
        assert!(lit > 50, "only {lit} lit values");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_annotation_inputs_are_named() {
    let dir = scratch("ann-bad");
    let (img, pkl) = demo_pair(&dir);
    let device = Device::flex().autodiff();
    let (hands, prior) = (HandSource::Procedural, PriorSource::Procedural);
    let setup = |img: &Path, pkl: &Path| {
        annotation_setup(
            img,
            pkl,
            RealRunSettings::new(&hands, &prior, tiny(1), &device),
        )
        .map(|_| ())
    };
    // Wrong image size.
    let small = dir.join("small.png");
    write_image(&small, 200, 180, None);
    let e = err(setup(&small, &pkl));
    assert!(
        e.contains("small.png") && e.contains("200x180") && e.contains("256x256"),
        "{e}"
    );
    // NaN in the annotation.
    let nan = dir.join("nan.pkl");
    write_annotation(&nan, AnnotationOptions::NAN);
    let e = err(setup(&img, &nan));
    assert!(e.contains("nan.pkl") && e.contains("NaN"), "{e}");
    // One hand only.
    let single = dir.join("single.pkl");
    write_annotation(&single, AnnotationOptions::RIGHT_ONLY);
    let e = err(setup(&img, &single));
    assert!(e.contains("single.pkl") && e.contains("left"), "{e}");
    // Missing files.
    let e = err(setup(&dir.join("none.jpg"), &pkl));
    assert!(e.contains("none.jpg"), "{e}");
    let e = err(setup(&img, &dir.join("none.pkl")));
    assert!(e.contains("none.pkl"), "{e}");
    // Hands and prior that do not go together.
    let html = PriorSource::Html {
        dir: dir.join("html"),
    };
    let e = err(annotation_setup(
        &img,
        &pkl,
        RealRunSettings::new(&HandSource::Procedural, &html, tiny(1), &device),
    ));
    assert!(e.contains("MANO"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The real demo frames (`../shared/data/interhand_demo/0N.jpg` + `0N.pkl`, when the shared
/// folder is beside the checkout) train with the procedural hands, trusting the photos at
/// their hand pixels only, with no fine texel outside skin's saturation; the avatar of `01`
/// renders in the pose of `02.pkl`. Skipped, saying so, where the frames are absent.
#[test]
fn demo_frame_trains_with_procedural_hands_if_present() {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/interhand_demo");
    if !demo.join("01.pkl").is_file() || !demo.join("01.jpg").is_file() {
        eprintln!(
            "SKIPPED demo_frame_trains_with_procedural_hands_if_present: the InterHand demo \
             frames are not at {} (they are not part of the project)",
            demo.display()
        );
        return;
    }
    let device = Device::flex().autodiff();
    for frame in ["01", "02"] {
        let mut setup = annotation_setup(
            &demo.join(format!("{frame}.jpg")),
            &demo.join(format!("{frame}.pkl")),
            RealRunSettings::new(
                &HandSource::Procedural,
                &PriorSource::Procedural,
                tiny(2),
                &device,
            ),
        )
        .unwrap();
        // The photo is trusted at its hand pixels only (issue 34, bleeding): the meshes
        // overhang dark pixels, which the losses ignore.
        let view = &setup.trainer.view;
        let read = |t: burn::tensor::Tensor<4>| bitt_stdx::to_host(t.inner()).unwrap();
        let (weight, drawn, image) = (
            read(view.weight.clone().expect("the photo mask applies")),
            read(view.mask.clone()),
            read(view.image.clone()),
        );
        let hw = weight.len();
        let dark = |p: usize| (image[p] + image[hw + p] + image[2 * hw + p]) / 3.0 <= 0.15;
        let expect = (0..hw).filter(|&p| drawn[p] > 0.5 && dark(p)).count();
        let ignored = weight.iter().filter(|&&w| w == 0.0).count();
        assert_eq!(ignored, expect, "{frame}");
        if frame == "01" {
            assert!(ignored > 0, "{frame}: the meshes overhang no dark pixel");
        }
        setup.trainer.train(None, &mut Silent).unwrap();
        let h = &setup.trainer.history;
        assert!(h.iter().all(|t| t.is_finite()), "{frame}: {h:?}");
        let [lv, rv] = setup.trainer.view.visible_fraction();
        assert!(lv > 0.01 && rv > 0.01, "{frame}: {lv} {rv}");
        let avatar = bitt::evaluate::Avatar::from_trainer(&setup.trainer).unwrap();
        // No texel of either fine texture is outside skin's saturation (issue 34, outliers).
        for fine in &avatar.fine {
            let worst = bitt::evaluate::max_hsv_saturation(fine);
            assert!(
                worst <= bitt::evaluate::MAX_SKIN_SATURATION,
                "{frame}: saturation {worst}"
            );
        }
        if frame == "01" {
            let models = procedural_pair();
            let pose = annotation_pose(&demo.join("02.pkl"), &models, 32).unwrap();
            let img = render_textures(
                &setup.trainer.assets,
                &avatar.fine,
                &pose,
                &avatar.light,
                setup.trainer.config.loss.photo_occlusion,
                &Device::flex(),
            )
            .unwrap();
            assert!(img.iter().filter(|&&v| v > 0.0).count() > 50);
        }
    }
}

/// A MANO folder (the procedural hands saved as the project's MANO safetensors, without UV
/// layouts) and an HTML folder (`uvs.pkl` and an `html.safetensors` texture PCA at 256²
/// with 12 components): the HTML UVs go on both hands (the left's derived from the winding),
/// the prior is resampled to the `tiny` preset's 128² layout, the HTML network is built for
/// 12 coefficients, and the run's avatar reloads its hands from the recorded folders.
#[test]
fn mano_and_html_folders_train_with_the_html_prior() {
    let dir = scratch("mano-html");
    let (mano, html) = write_mano_html_folders(&dir);

    let (img, pkl) = demo_pair(&dir);
    let device = Device::flex().autodiff();
    let (hands, prior) = (
        HandSource::Mano { dir: mano.clone() },
        PriorSource::Html { dir: html.clone() },
    );
    let mut setup = annotation_setup(
        &img,
        &pkl,
        RealRunSettings::new(&hands, &prior, tiny(2), &device),
    )
    .unwrap();
    assert_eq!(setup.trainer.config.nets.html.coefficients_per_hand, 12);
    assert_eq!(setup.trainer.config.texture.components, 12);
    setup.trainer.config.validate().unwrap();
    // The prior's mean (150 / 190 / 230 of 255) is on the hands' 128² layout.
    let t = setup.trainer.assets.num_texels();
    let coarse = bitt_stdx::to_host(setup.trainer.pca.mean.clone().inner()).unwrap();
    assert_eq!(coarse.len(), 3 * t);
    assert!((coarse[t / 2] - 150.0).abs() < 1e-3 && (coarse[2 * t + 5] - 230.0).abs() < 1e-3);
    setup.trainer.train(None, &mut Silent).unwrap();
    let run = dir.join("run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(
        run.join("config.json"),
        serde_json::to_string(&setup.trainer.config).unwrap(),
    )
    .unwrap();
    setup.input.write(&run, &setup.scene).unwrap();
    bitt::run::write_run(&run, &setup.trainer, None, 0, &[]).unwrap();
    let avatar = RealAvatar::load(&run).unwrap();
    assert_eq!(avatar.input.hands, hands.absolute());
    let assets = avatar.assets().unwrap();
    assert_eq!(assets.num_texels(), t);
    // MANO without HTML is refused.
    let e = err(annotation_setup(
        &img,
        &pkl,
        RealRunSettings::new(&hands, &PriorSource::Procedural, tiny(1), &device),
    ));
    assert!(e.contains("HTML"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
