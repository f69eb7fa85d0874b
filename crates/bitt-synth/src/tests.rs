//! Scene-level tests: shapes, determinism, round trips, caching, errors.

use std::path::{Path, PathBuf};

use burn::tensor::Device;

use super::*;

fn small() -> SynthConfig {
    SynthConfig {
        size: 64,
        texture_size: 64,
        novel_views: 2,
        novel_poses: 2,
        mesh_noise: None,
        degrade: true,
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bitt-synth-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Every file of a folder, name -> bytes, sorted.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    out.sort();
    out
}

/// Asserts two scenes are equal, naming the first field that differs (no huge dumps).
fn assert_same(a: &SynthScene, b: &SynthScene) {
    assert!(a.config == b.config, "config differs");
    assert!(a.seed == b.seed, "seed differs");
    assert!(a.identity == b.identity, "identity differs");
    assert!(a.studio_light == b.studio_light, "studio light differs");
    assert!(
        a.train_degradation == b.train_degradation,
        "degradation differs"
    );
    assert!(a.given == b.given, "given meshes differ");
    assert!(a.textures == b.textures, "textures differ");
    assert!(
        a.stats == b.stats,
        "stats differ: {:?} vs {:?}",
        a.stats,
        b.stats
    );
    let (va, vb): (Vec<_>, Vec<_>) = (a.views().collect(), b.views().collect());
    assert_eq!(va.len(), vb.len());
    for (x, y) in va.iter().zip(&vb) {
        assert!(x.name == y.name, "view names {} vs {}", x.name, y.name);
        assert!(x.family == y.family, "{}: family differs", x.name);
        assert!(x.hands == y.hands, "{}: hands differ", x.name);
        assert!(x.light == y.light, "{}: light differs", x.name);
        assert!(x.image == y.image, "{}: image differs", x.name);
        assert!(x.masks == y.masks, "{}: masks differ", x.name);
    }
    assert!(a == b);
}

#[test]
fn scene_has_every_view_with_consistent_shapes() {
    let device = Device::flex();
    let scene = generate_scene(&small(), 11, &device).unwrap();
    assert_eq!(scene.novel_views.len(), 2);
    assert_eq!(scene.novel_poses.len(), 2);
    let names: Vec<&str> = scene.views().map(|v| v.name.as_str()).collect();
    assert_eq!(names, ["train", "view_00", "view_01", "pose_00", "pose_01"]);
    let hw = 64 * 64;
    for v in scene.views() {
        assert_eq!(v.image.len(), 3 * hw);
        assert!(v.image.iter().all(|x| (0.0..=1.0).contains(x)));
        for m in &v.masks {
            assert_eq!(m.len(), hw);
            assert!(m.iter().all(|&x| x == 0.0 || x == 1.0));
        }
        // Both hands are seen, the masks never overlap, and the hands fill a good part of
        // the frame.
        let (l, r) = (
            v.masks[0].iter().sum::<f32>(),
            v.masks[1].iter().sum::<f32>(),
        );
        assert!(l > 20.0 && r > 20.0, "{}: masks {l} {r}", v.name);
        assert!(
            v.masks[0]
                .iter()
                .zip(&v.masks[1])
                .all(|(a, b)| a * b == 0.0),
            "{}",
            v.name
        );
        assert!(
            (l + r) / hw as f32 > 0.1,
            "{}: coverage {}",
            v.name,
            (l + r) / hw as f32
        );
        assert!(v.hands.left.is_some() && v.hands.right.is_some());
    }
    assert_eq!(scene.given, scene.train.hands);
    let layouts = texture_layouts(&procedural_pair(), 64).unwrap();
    for t in &scene.textures {
        assert_eq!(t.len(), 3 * layouts[0].num_texels());
    }
    // One-sided details make the textures differ somewhere beyond the generator's asymmetry.
    assert_ne!(scene.textures[0], scene.textures[1]);
    let s = scene.stats.table3;
    assert!(s.left_visible > 0.05 && s.right_visible > 0.05, "{s:?}");
    assert!(s.invisible < 0.95, "{s:?}");
}

#[test]
fn images_are_exactly_the_documented_render() {
    let device = Device::flex();
    let scene = generate_scene(&small(), 5, &device).unwrap();
    let models = procedural_pair();
    let layouts = texture_layouts(&models, 64).unwrap();
    let renderer = HandRenderer::new(&models, &layouts, &scene.textures, &device).unwrap();
    for v in scene.novel_views.iter().chain(&scene.novel_poses) {
        let r = renderer.render(&v.hands, &v.light).unwrap();
        assert_eq!(crate::degrade::to_8bit(&r.image), v.image, "{}", v.name);
        assert_eq!(r.masks, v.masks, "{}", v.name);
    }
    // The training image is the degraded render; its masks are the render's.
    let r = renderer
        .render(&scene.train.hands, &scene.train.light)
        .unwrap();
    assert_eq!(r.masks, scene.train.masks);
    let d = scene.train_degradation.expect("degraded by default");
    assert_eq!(d.apply(&r.image, 64).unwrap(), scene.train.image);
    assert_eq!(scene_stats(&scene, &device).unwrap(), scene.stats);
}

#[test]
fn same_seed_same_bytes_different_seed_different_scene() {
    let device = Device::flex();
    let cfg = small();
    let a = generate_scene(&cfg, 3, &device).unwrap();
    let b = generate_scene(&cfg, 3, &device).unwrap();
    let (da, db) = (scratch("same-a"), scratch("same-b"));
    a.write(&da).unwrap();
    b.write(&db).unwrap();
    let (fa, fb) = (files(&da), files(&db));
    assert_eq!(
        fa.len(),
        5 * 2 + 4,
        "one PNG and one mask PNG per view, two textures, data, json"
    );
    assert_same(&a, &b);
    assert_eq!(fa.len(), fb.len());
    for ((na, ba), (nb, bb)) in fa.iter().zip(&fb) {
        assert_eq!(na, nb);
        assert!(ba == bb, "{na}: the same seed wrote different bytes");
    }
    let c = generate_scene(&cfg, 4, &device).unwrap();
    assert_ne!(a.identity.betas, c.identity.betas);
    assert_ne!(a.identity.skin, c.identity.skin);
    assert_ne!(a.train.hands.right, c.train.hands.right);
    assert_ne!(a.textures, c.textures);
    assert_ne!(a.train.image, c.train.image);
    let _ = std::fs::remove_dir_all(&da);
    let _ = std::fs::remove_dir_all(&db);
}

#[test]
fn write_read_round_trip_is_exact_and_errors_name_the_file() {
    let device = Device::flex();
    let cfg = SynthConfig {
        mesh_noise: Some(MeshNoise::default()),
        ..small()
    };
    let scene = generate_scene(&cfg, 9, &device).unwrap();
    assert_ne!(scene.given, scene.train.hands);
    assert_eq!(scene.given.camera, scene.train.hands.camera);
    let dir = scratch("roundtrip");
    scene.write(&dir).unwrap();
    let back = SynthScene::read(&dir).unwrap();
    assert_same(&back, &scene);

    // Every view's true 2D joints are in scene.json as a plain keypoint file, and read back
    // as the projections of the view's joints.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("scene.json")).unwrap()).unwrap();
    let kp = &json["train"]["keypoints_2d"];
    let options = bitt_mesh::keypoints::KeypointOptions {
        format: None,
        image_size: [cfg.size, cfg.size],
        labels_as_is: false,
    };
    let read = bitt_mesh::keypoints::parse_keypoints(
        kp.to_string().as_bytes(),
        std::path::Path::new("scene.json"),
        &options,
    )
    .unwrap();
    let posed = scene
        .train
        .hands
        .pose_in_camera(&procedural_pair())
        .unwrap();
    for side in Side::BOTH {
        let points = read.hand(side).unwrap();
        assert_eq!(points.len(), 21);
        for (k, j) in points.iter().zip(&posed.get(side).unwrap().joints) {
            let q = scene.train.hands.camera.camera_to_pixel(*j).unwrap();
            assert!((k.x - q.x).abs() < 1e-9 && (k.y - q.y).abs() < 1e-9);
            assert_eq!(k.confidence, 1.0);
        }
    }
    assert_eq!(
        json["novel_poses"][0]["keypoints_2d"]["left"]
            .as_array()
            .map(Vec::len),
        Some(21)
    );

    // Missing folder.
    let e = SynthScene::read(&dir.join("nope")).unwrap_err().to_string();
    assert!(e.contains("nope") && e.contains("scene.json"), "{e}");
    // Corrupt data.
    let data = dir.join("data.safetensors");
    let good = std::fs::read(&data).unwrap();
    std::fs::write(&data, b"garbage").unwrap();
    let e = SynthScene::read(&dir).unwrap_err().to_string();
    assert!(e.contains("data.safetensors"), "{e}");
    std::fs::write(&data, &good).unwrap();
    // Corrupt JSON, another version.
    let json = dir.join("scene.json");
    let text = std::fs::read_to_string(&json).unwrap();
    std::fs::write(&json, &text[..text.len() / 2]).unwrap();
    let e = SynthScene::read(&dir).unwrap_err().to_string();
    assert!(e.contains("scene.json"), "{e}");
    let other = text.replace(
        &format!("\"generator_version\": {GENERATOR_VERSION}"),
        "\"generator_version\": 999",
    );
    std::fs::write(&json, other).unwrap();
    let e = SynthScene::read(&dir).unwrap_err().to_string();
    assert!(e.contains("version 999"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cache_generates_once_then_reads() {
    let device = Device::flex();
    let cfg = SynthConfig {
        novel_views: 1,
        novel_poses: 1,
        ..small()
    };
    let cache = scratch("cache");
    let a = cached_scene(&cfg, 21, &cache, &device).unwrap();
    let dir = scene_cache_dir(&cfg, 21, &cache);
    assert!(dir.join("scene.json").is_file());
    let stamp = std::fs::metadata(dir.join("data.safetensors"))
        .unwrap()
        .modified()
        .unwrap();
    let b = cached_scene(&cfg, 21, &cache, &device).unwrap();
    assert_same(&a, &b);
    let again = std::fs::metadata(dir.join("data.safetensors"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(stamp, again, "the cached scene was regenerated");
    // Another seed or configuration has another key.
    assert_ne!(scene_cache_dir(&cfg, 22, &cache), dir);
    let other = SynthConfig {
        degrade: false,
        ..cfg.clone()
    };
    assert_ne!(scene_cache_dir(&other, 21, &cache), dir);
    // A corrupt entry is regenerated.
    std::fs::write(dir.join("data.safetensors"), b"x").unwrap();
    let c = cached_scene(&cfg, 21, &cache, &device).unwrap();
    assert_same(&a, &c);
    let _ = std::fs::remove_dir_all(&cache);
}

#[test]
fn bad_configurations_are_rejected() {
    let device = Device::flex();
    for cfg in [
        SynthConfig { size: 8, ..small() },
        SynthConfig {
            texture_size: 10,
            ..small()
        },
        SynthConfig {
            novel_views: 1000,
            ..small()
        },
        SynthConfig {
            mesh_noise: Some(MeshNoise {
                pose_std: f64::NAN,
                ..MeshNoise::default()
            }),
            ..small()
        },
    ] {
        let e = generate_scene(&cfg, 1, &device).unwrap_err();
        assert!(matches!(e, SynthError::Config(_)), "{e}");
    }
}

#[test]
fn seeds_are_fixed_and_distinct() {
    let s = benchmark_seeds(BENCHMARK_SCENES);
    assert_eq!(s.len(), 24);
    assert_eq!(s[..4], benchmark_seeds(4)[..]);
    let mut u = s.clone();
    u.sort_unstable();
    u.dedup();
    assert_eq!(u.len(), 24);
    assert!(!s.contains(&demo_scene_seed()));
}
