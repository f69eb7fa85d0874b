//! [`crate::scene::SceneGeometry`] on its dense path against its covered-pixel path: the
//! same image and gradients, and no host readback on wgpu for making, shading and
//! differentiating a geometry.

use bitt_testkit::{autodiff_devices, to_vec};
use burn::tensor::{Device, Tensor, TensorData};

use super::Rng;
use super::scene::{hand_scene, vertex_tensor};
use crate::ops::thread_host_readbacks;
use crate::scene::{GeometryPath, LightValues, PointLight, RenderSettings, Scene, SceneGeometry};

/// Image, then gradients (left texture, right texture, light, left vertices, right
/// vertices) of a weighted sum of the shaded image, on one path; with the thread's host
/// readbacks over making, shading and differentiating the geometry, and whether it is dense.
fn render_both(
    path: GeometryPath,
    size: u32,
    antialias: bool,
    device: &Device,
) -> (Vec<Vec<f32>>, u64, bool) {
    let s = hand_scene(size);
    let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
    let verts = [
        vertex_tensor(&s.vertices[0], device).require_grad(),
        vertex_tensor(&s.vertices[1], device).require_grad(),
    ];
    let mut rng = Rng::new(21);
    let mut tex = |side: usize| {
        let v = (0..3 * side * side)
            .map(|_| rng.uniform(0.0, 1.0) as f32)
            .collect();
        Tensor::<3>::from_data(TensorData::new(v, [3, side, side]), device).require_grad()
    };
    // Textures of different sizes: each mesh must sample its own.
    let textures = [tex(8), tex(6)];
    let n = (size * size) as usize;
    let weights: Vec<f32> = (0..3 * n).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    let weights = Tensor::<3>::from_data(
        TensorData::new(weights, [3, size as usize, size as usize]),
        device,
    );
    let light_t = Tensor::<1>::from_data(
        TensorData::new(LightValues::default().to_array().to_vec(), [12]),
        device,
    )
    .require_grad();
    let light = PointLight::from_tensor(light_t.clone()).unwrap();
    let settings = RenderSettings {
        antialias,
        background: [0.2, 0.3, 0.4],
        material: crate::scene::Material {
            specular: [0.3; 3],
            ..Default::default()
        },
        ..Default::default()
    };
    let before = thread_host_readbacks();
    let g = SceneGeometry::with_path(
        &scene,
        &verts,
        &s.camera,
        &settings,
        &[[8, 8], [6, 6]],
        path,
    )
    .unwrap();
    let image = g
        .shade(&textures, &light, &settings.material, settings.background)
        .unwrap();
    let grads = (image.clone() * weights).sum().backward();
    let readbacks = thread_host_readbacks() - before;
    let out = vec![
        to_vec(image),
        to_vec(textures[0].grad(&grads).unwrap()),
        to_vec(textures[1].grad(&grads).unwrap()),
        to_vec(light_t.grad(&grads).unwrap()),
        to_vec(verts[0].grad(&grads).unwrap()),
        to_vec(verts[1].grad(&grads).unwrap()),
    ];
    (out, readbacks, g.is_dense())
}

#[test]
fn dense_scene_geometry_shades_like_the_covered_one() {
    let names = [
        "image",
        "left texture",
        "right texture",
        "light",
        "left",
        "right",
    ];
    for (device_name, device) in autodiff_devices() {
        if device_name == "ndarray" {
            continue; // flex covers the CPU backends; ndarray would repeat it slowly
        }
        for antialias in [false, true] {
            let what = format!("{device_name} antialias {antialias}");
            let (want, covered_readbacks, dense) =
                render_both(GeometryPath::Covered, 24, antialias, &device);
            assert!(!dense);
            assert!(
                covered_readbacks >= 1,
                "{what}: the covered path reads clip"
            );
            let (got, _, dense) = render_both(GeometryPath::Dense, 24, antialias, &device);
            assert!(dense);
            for (k, (x, y)) in got.iter().zip(&want).enumerate() {
                assert_eq!(x.len(), y.len());
                let max = x
                    .iter()
                    .zip(y)
                    .map(|(p, q)| (p - q).abs())
                    .fold(0.0, f32::max);
                let scale = y.iter().map(|v| v.abs()).fold(1.0, f32::max);
                assert!(
                    x.iter().all(|v| v.is_finite()),
                    "{what}: {} not finite",
                    names[k]
                );
                let tol = if k == 0 { 1e-5 } else { 1e-4 };
                assert!(
                    max <= tol * scale,
                    "{what}: {} differs by {max} (scale {scale})",
                    names[k]
                );
            }
        }
    }
}

/// On wgpu the default path is the dense one, and making, shading and differentiating a
/// geometry from vertices that change (every call here uploads new ones) reads nothing back;
/// the covered path reads the clip positions back.
#[test]
fn dense_scene_geometry_makes_no_host_readback_on_wgpu() {
    let Some(device) = bitt_testkit::wgpu() else {
        return;
    };
    let device = device.autodiff();
    let (_, auto, dense) = render_both(GeometryPath::Auto, 16, true, &device);
    assert!(dense, "wgpu takes the dense path");
    assert_eq!(auto, 0, "dense geometry + shade + backward");
    let (_, covered, dense) = render_both(GeometryPath::Covered, 16, true, &device);
    assert!(!dense);
    assert!(covered >= 1, "covered path: {covered}");
}

/// flex and ndarray keep the covered-pixel path (the CPU training step is unchanged).
#[test]
fn cpu_backends_keep_the_covered_path() {
    for (name, device) in bitt_testkit::cpu_devices() {
        let (_, readbacks, dense) = render_both(GeometryPath::Auto, 16, true, &device.autodiff());
        assert!(!dense, "{name}");
        assert!(readbacks >= 1, "{name}");
    }
}

/// A light visibility per vertex scales each pixel's shaded colour by its interpolated
/// value: a constant one scales the whole image, and a varying one gives the same image on
/// both paths, darker where the vertices are, and the same gradient to the textures as the
/// plain image weighted by it.
#[test]
fn occlusion_scales_the_shading_on_both_paths() {
    for (device_name, device) in bitt_testkit::devices() {
        if device_name == "ndarray" {
            continue;
        }
        let s = hand_scene(24);
        let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let verts = [
            vertex_tensor(&s.vertices[0], &device),
            vertex_tensor(&s.vertices[1], &device),
        ];
        let nv = s.vertices[0].len() + s.vertices[1].len();
        let texture = Tensor::<3>::full([3, 8, 8], 0.6, &device);
        let textures = [texture.clone(), texture];
        let light = LightValues::default();
        let light = PointLight::from_tensor(Tensor::<1>::from_data(
            TensorData::new(light.to_array().to_vec(), [12]),
            &device,
        ))
        .unwrap();
        let settings = RenderSettings {
            antialias: false,
            ..Default::default()
        };
        let shade = |occlusion: Option<Vec<f32>>, path: GeometryPath| {
            let occlusion =
                occlusion.map(|o| Tensor::<2>::from_data(TensorData::new(o, [nv, 1]), &device));
            let g = SceneGeometry::with_occlusion(
                &scene,
                &verts,
                occlusion,
                &s.camera,
                &settings,
                &[[8, 8]; 2],
                path,
            )
            .unwrap();
            to_vec(
                g.shade(&textures, &light, &settings.material, settings.background)
                    .unwrap(),
            )
        };
        for path in [GeometryPath::Covered, GeometryPath::Dense] {
            let plain = shade(None, path);
            let half = shade(Some(vec![0.5; nv]), path);
            assert!(plain.iter().any(|&v| v > 0.1), "{device_name}: hands drawn");
            for (p, h) in plain.iter().zip(&half) {
                assert!(
                    (0.5 * p - h).abs() < 1e-6,
                    "{device_name} {path:?}: {p} vs {h}"
                );
            }
        }
        // The right hand's vertices half lit, the left's fully: the right hand's pixels
        // halve, the left's stay.
        let varying: Vec<f32> = (0..nv)
            .map(|i| if i < s.vertices[0].len() { 1.0 } else { 0.5 })
            .collect();
        let covered = shade(Some(varying.clone()), GeometryPath::Covered);
        let dense = shade(Some(varying), GeometryPath::Dense);
        let plain = shade(None, GeometryPath::Covered);
        let max = covered
            .iter()
            .zip(&dense)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(max < 1e-5, "{device_name}: paths differ by {max}");
        let (mut halved, mut kept) = (0, 0);
        for (p, c) in plain.iter().zip(&covered) {
            if *p > 0.05 {
                if (0.5 * p - c).abs() < 1e-5 {
                    halved += 1;
                } else if (p - c).abs() < 1e-5 {
                    kept += 1;
                }
            }
        }
        assert!(
            halved > 30 && kept > 30,
            "{device_name}: {halved} halved, {kept} kept"
        );
    }
}

/// An occlusion of the wrong length is refused, naming it.
#[test]
fn an_occlusion_of_the_wrong_size_is_named() {
    let device = bitt_testkit::devices().remove(0).1;
    let s = hand_scene(16);
    let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
    let verts = [
        vertex_tensor(&s.vertices[0], &device),
        vertex_tensor(&s.vertices[1], &device),
    ];
    let e = SceneGeometry::with_occlusion(
        &scene,
        &verts,
        Some(Tensor::<2>::ones([5, 1], &device)),
        &s.camera,
        &RenderSettings::default(),
        &[[8, 8]; 2],
        GeometryPath::Covered,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("occlusion"), "{e}");
}
