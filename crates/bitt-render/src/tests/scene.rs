//! The scene layer: projection, Phong shading against an independent implementation, two
//! procedural hands in one depth test, unwrapping and texel statistics.

use crate::scene::LightValuesExt;

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::lbs::{HandParams, HandPose};
use bitt_mesh::model::{NUM_BETAS, NUM_POSE};
use bitt_mesh::{HandModel, OrthographicCamera, PinholeCamera, Side, procedural_pair};
use bitt_testkit::{autodiff_devices, to_vec};
use bitt_texture::TextureLayout;
use burn::tensor::{Device, Tensor, TensorData};

use super::Rng;
use crate::scene::{
    Camera, DepthRange, GeometryPath, LightValues, Material, PointLight, RenderSettings, Scene,
    SceneGeometry, TexelSurface, TexelVisibilityStats, TexturedMesh, UnwrapPlan, UnwrapSettings,
    phong, render, unwrap,
};

fn tensor2(values: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

#[test]
fn pinhole_and_orthographic_projection_match_the_cameras() {
    let device = Device::flex();
    let mut cam = PinholeCamera::looking_down_z(500.0, 200, 160);
    cam.rotation = DMat3::from_rotation_y(0.3) * DMat3::from_rotation_x(-0.2);
    cam.translation = DVec3::new(0.02, -0.01, 0.6);
    cam.intrinsics.z_axis.x = 93.0;
    cam.intrinsics.y_axis.x = 1.5; // skew
    let ortho = OrthographicCamera {
        rotation: DMat3::from_rotation_z(0.4),
        translation: DVec3::new(0.0, 0.0, 1.0),
        scale: 900.0,
        offset: bitt_mesh::glam::DVec2::new(101.0, 77.0),
        width: 200,
        height: 160,
    };
    let mut rng = Rng::new(3);
    let points: Vec<DVec3> = (0..20)
        .map(|_| {
            DVec3::new(
                rng.uniform(-0.1, 0.1),
                rng.uniform(-0.1, 0.1),
                rng.uniform(-0.1, 0.1),
            )
        })
        .collect();
    let flat: Vec<f32> = points
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let depth = DepthRange::default();
    for camera in [Camera::Pinhole(cam), Camera::Orthographic(ortho)] {
        let clip = camera
            .clip_positions(tensor2(flat.clone(), [20, 3], &device), depth)
            .unwrap();
        let clip = to_vec(clip);
        for (i, p) in points.iter().enumerate() {
            let (pixel, z) = match camera {
                Camera::Pinhole(c) => (c.project(*p).unwrap(), c.world_to_camera(*p).z),
                Camera::Orthographic(c) => (c.project(*p), c.world_to_camera(*p).z),
            };
            let c = &clip[4 * i..4 * i + 4];
            let ndc = [c[0] / c[3], c[1] / c[3], c[2] / c[3]];
            let want_x = 2.0 * pixel.x / 200.0 - 1.0;
            let want_y = 2.0 * pixel.y / 160.0 - 1.0;
            assert!((f64::from(ndc[0]) - want_x).abs() < 1e-5, "{camera:?}: x");
            assert!((f64::from(ndc[1]) - want_y).abs() < 1e-5, "{camera:?}: y");
            let back = camera.view_depth(f64::from(ndc[2]), depth);
            assert!(
                (back - z).abs() < 1e-3 * z.abs().max(1.0),
                "{camera:?}: depth {back} vs {z}"
            );
        }
    }
}

/// PyTorch3D's Phong formula, written out per pixel in f64.
fn phong_reference(
    texel: [f64; 3],
    normal: [f64; 3],
    point: [f64; 3],
    camera: [f64; 3],
    light: &LightValues,
    material: &Material,
) -> [f64; 3] {
    let unit = |v: [f64; 3]| {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-6);
        [v[0] / n, v[1] / n, v[2] / n]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let n = unit(normal);
    let loc = light.location.map(f64::from);
    let l = unit([loc[0] - point[0], loc[1] - point[1], loc[2] - point[2]]);
    let v = unit([
        camera[0] - point[0],
        camera[1] - point[1],
        camera[2] - point[2],
    ]);
    let cos = dot(n, l);
    let r = [
        2.0 * cos * n[0] - l[0],
        2.0 * cos * n[1] - l[1],
        2.0 * cos * n[2] - l[2],
    ];
    let spec = if cos > 0.0 {
        dot(v, r).max(0.0).powf(f64::from(material.shininess))
    } else {
        0.0
    };
    std::array::from_fn(|c| {
        let ambient = f64::from(light.ambient[c]) * f64::from(material.ambient[c]);
        let diffuse = f64::from(light.diffuse[c]) * f64::from(material.diffuse[c]) * cos.max(0.0);
        (ambient + diffuse) * texel[c]
            + f64::from(light.specular[c]) * f64::from(material.specular[c]) * spec
    })
}

#[test]
fn phong_matches_an_independent_implementation() {
    for (name, device) in autodiff_devices() {
        let light = LightValues {
            ambient: [0.3, 0.35, 0.4],
            diffuse: [0.7, 0.6, 0.5],
            specular: [0.4, 0.3, 0.2],
            location: [0.3, -0.5, -0.2],
        };
        for material in [
            Material::default(),
            Material {
                ambient: [0.9, 1.0, 0.8],
                diffuse: [1.0, 0.7, 0.9],
                specular: [0.6, 0.5, 0.4],
                shininess: 8.0,
            },
        ] {
            let n = 64;
            let mut rng = Rng::new(17);
            let mut draw = |lo: f64, hi: f64| -> Vec<f64> {
                (0..3 * n).map(|_| rng.uniform(lo, hi)).collect()
            };
            let (texels, normals, points) = (draw(0.0, 1.0), draw(-1.0, 1.0), draw(-0.2, 0.2));
            let camera = [0.05, 0.02, -0.7];
            let to_cam: Vec<f64> = (0..3 * n).map(|i| camera[i % 3] - points[i]).collect();
            let t = |v: &[f64]| tensor2(v.iter().map(|&x| x as f32).collect(), [n, 3], &device);
            let out = phong(
                t(&texels),
                t(&normals),
                t(&points),
                t(&to_cam),
                &light.to_light(&device),
                &material,
            );
            let out = to_vec(out);
            for k in 0..n {
                let p = |v: &[f64]| [v[3 * k], v[3 * k + 1], v[3 * k + 2]];
                let want = phong_reference(
                    p(&texels),
                    p(&normals),
                    p(&points),
                    camera,
                    &light,
                    &material,
                );
                for c in 0..3 {
                    assert!(
                        (f64::from(out[3 * k + c]) - want[c]).abs() < 1e-4,
                        "{name}: pixel {k} channel {c}: {} vs {}",
                        out[3 * k + c],
                        want[c]
                    );
                }
            }
        }
    }
}

/// Two procedural hands facing each other, fingers up, the right one in front of the left
/// one's fingers, in front of a 96x96 pinhole camera.
pub(super) struct HandScene {
    pub meshes: [TexturedMesh; 2],
    pub vertices: [Vec<DVec3>; 2],
    pub camera: Camera,
    /// Per hand: the 64x64 layout and the mesh faces (the left hand's corners are in
    /// mirrored order, so each hand needs its own texel barycentrics).
    pub layouts: [TextureLayout; 2],
    pub faces: [Vec<[u32; 3]>; 2],
}

pub(super) fn hand_scene(size: u32) -> HandScene {
    let pair = procedural_pair();
    let facing = DMat3::from_cols(DVec3::Y, DVec3::X, DVec3::NEG_Z);
    let mirror = DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0));
    let right_root = DMat3::from_rotation_y(0.5) * facing;
    let pose = |model: &HandModel, root: DMat3, wrist: DVec3| {
        let rest = model.regress_joints(&model.shaped_vertices(&[0.0; NUM_BETAS]))[0];
        let params = HandParams {
            root_rotation: root,
            pose: HandPose::Pca(vec![0.0; NUM_POSE]),
            betas: vec![0.0; NUM_BETAS],
            trans: wrist - rest,
        };
        model.forward(&params).unwrap().vertices
    };
    let left = pose(
        pair.get(Side::Left),
        mirror * right_root * mirror,
        DVec3::new(-0.02, 0.08, 0.5),
    );
    let right = pose(
        pair.get(Side::Right),
        right_root,
        DVec3::new(0.02, 0.085, 0.47),
    );
    let mesh = |model: &HandModel| {
        let uv = model.uv.as_ref().expect("procedural hands have UVs");
        TexturedMesh::new(
            model.faces.clone(),
            model.num_vertices(),
            uv.faces.clone(),
            uv.uvs.iter().map(|p| [p.x as f32, p.y as f32]).collect(),
        )
        .unwrap()
    };
    let right_model = pair.get(Side::Right);
    let left_model = pair.get(Side::Left);
    let layout = |m: &HandModel| TextureLayout::from_uv(m.uv.as_ref().unwrap(), 64, 64, 1).unwrap();
    HandScene {
        meshes: [mesh(left_model), mesh(right_model)],
        vertices: [left, right],
        camera: Camera::Pinhole(PinholeCamera::looking_down_z(
            240.0 * f64::from(size) / 96.0,
            size,
            size,
        )),
        layouts: [layout(left_model), layout(right_model)],
        faces: [left_model.faces.clone(), right_model.faces.clone()],
    }
}

pub(super) fn vertex_tensor(v: &[DVec3], device: &Device) -> Tensor<2> {
    tensor2(
        v.iter()
            .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect(),
        [v.len(), 3],
        device,
    )
}

#[test]
fn two_procedural_hands_render_with_mutual_occlusion() {
    for (name, device) in autodiff_devices() {
        let s = hand_scene(96);
        let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let verts = [
            vertex_tensor(&s.vertices[0], &device),
            vertex_tensor(&s.vertices[1], &device),
        ];
        let white = || Tensor::<3>::ones([3, 4, 4], &device);
        let light = LightValues {
            ambient: [0.4; 3],
            diffuse: [0.6; 3],
            specular: [0.0; 3],
            location: [0.0, 0.0, 0.0],
        }
        .to_light(&device);
        let settings = RenderSettings {
            antialias: false,
            ..RenderSettings::default()
        };
        let both = render(
            &scene,
            &verts,
            &[white(), white()],
            &s.camera,
            &light,
            &settings,
        )
        .unwrap();
        let alone = |i: usize| {
            let one = Scene::new(&[&s.meshes[i]]).unwrap();
            render(
                &one,
                &verts[i..i + 1],
                &[white()],
                &s.camera,
                &light,
                &settings,
            )
            .unwrap()
        };
        let (left, right) = (alone(0), alone(1));
        let ml = to_vec(both.masks[0].clone());
        let mr = to_vec(both.masks[1].clone());
        let (mut overlap, mut n_left, mut n_right) = (0, 0, 0);
        for p in 0..96 * 96 {
            let (dl, dr) = (
                left.raster.fragments.depth[p],
                right.raster.fragments.depth[p],
            );
            assert!(
                !(ml[p] == 1.0 && mr[p] == 1.0),
                "{name}: masks overlap at {p}"
            );
            if dl.is_finite() && dr.is_finite() {
                overlap += 1;
                let left_wins = dl < dr;
                assert_eq!(ml[p] == 1.0, left_wins, "{name}: pixel {p}");
            }
            n_left += usize::from(ml[p] == 1.0);
            n_right += usize::from(mr[p] == 1.0);
        }
        assert!(
            overlap > 50,
            "{name}: the hands should overlap in the image ({overlap} px)"
        );
        assert!(
            n_left > 300 && n_right > 300,
            "{name}: {n_left} / {n_right} px"
        );
        // Outward normals: a light at the camera lights the visible surface (shaded value
        // above the ambient level) almost everywhere.
        let img = to_vec(both.image.clone());
        let covered: Vec<usize> = (0..96 * 96).filter(|&p| ml[p] + mr[p] > 0.0).collect();
        let lit = covered.iter().filter(|&&p| img[p] > 0.45).count();
        assert!(
            lit as f64 > 0.9 * covered.len() as f64,
            "{name}: {lit} of {} lit",
            covered.len()
        );
    }
}

#[test]
fn unwrapping_a_render_recovers_the_texture_on_visible_texels() {
    for (name, device) in autodiff_devices() {
        let s = hand_scene(160);
        let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let verts = [
            vertex_tensor(&s.vertices[0], &device),
            vertex_tensor(&s.vertices[1], &device),
        ];
        // A texture that is smooth on the surface, also across UV chart seams: each texel's
        // colour is a linear ramp of its 3D point on the right hand (gutter texels sit on
        // chart borders, so the texture image is continuous across seams too).
        let (th, tw) = (64, 64);
        let right_surface =
            TexelSurface::new(&s.layouts[1], &s.faces[1], s.vertices[1].len()).unwrap();
        let pts = right_surface.points(&s.vertices[1]).unwrap();
        let t = pts.len();
        let centre = pts.iter().copied().sum::<DVec3>() / t as f64;
        let mut truth = vec![0.0f32; 3 * t];
        for (k, p) in pts.iter().enumerate() {
            let d = (*p - centre) * 4.0;
            truth[k] = (0.5 + d.x).clamp(0.0, 1.0) as f32;
            truth[t + k] = (0.5 + d.y).clamp(0.0, 1.0) as f32;
            truth[2 * t + k] = (0.5 + d.z).clamp(0.0, 1.0) as f32;
        }
        let tex = s.layouts[1].compact_to_image(&truth, [0.0; 3]).unwrap();
        let texture = Tensor::<3>::from_data(TensorData::new(tex.clone(), [3, th, tw]), &device);
        // Pure ambient light: the render is the texture itself.
        let light = LightValues {
            ambient: [1.0; 3],
            diffuse: [0.0; 3],
            specular: [0.0; 3],
            location: [0.0; 3],
        }
        .to_light(&device);
        let settings = RenderSettings {
            antialias: false,
            ..RenderSettings::default()
        };
        let out = render(
            &scene,
            &verts,
            &[texture.clone(), texture.clone()],
            &s.camera,
            &light,
            &settings,
        )
        .unwrap();
        assert_eq!(
            s.layouts[0].texels, s.layouts[1].texels,
            "one layout serves both hands"
        );
        let mut masks = Vec::new();
        for hand in 0..2 {
            let surface =
                TexelSurface::new(&s.layouts[hand], &s.faces[hand], s.vertices[hand].len())
                    .unwrap();
            let un = unwrap(
                out.image.clone(),
                &s.camera,
                &surface,
                &s.vertices[hand],
                &out.raster,
                &UnwrapSettings::default(),
            )
            .unwrap();
            let u = to_vec(un.texels.clone());
            let visible = un.visible_host.clone();
            let count = visible.iter().filter(|&&v| v).count();
            assert!(
                count > t / 20,
                "{name}: hand {hand}: only {count} of {t} texels visible"
            );
            assert!(
                count < 3 * t / 4,
                "{name}: hand {hand}: {count} of {t} visible (too many)"
            );
            // Most visible texels get their own colour back (bilinear resampling twice, a
            // 64x64 texture on a 160x160 image); texels on chart seams or silhouettes pick up
            // a neighbour's colour, so the tail is looser.
            let mut errs: Vec<f32> = (0..t)
                .filter(|&k| visible[k])
                .map(|k| {
                    (0..3)
                        .map(|c| (u[c * t + k] - truth[c * t + k]).abs())
                        .fold(0.0, f32::max)
                })
                .collect();
            errs.sort_by(f32::total_cmp);
            let (median, p90) = (errs[errs.len() / 2], errs[errs.len() * 9 / 10]);
            eprintln!("{name}: hand {hand}: {count} visible, error median {median} p90 {p90}");
            assert!(
                median < 0.01 && p90 < 0.05,
                "{name}: hand {hand}: median {median}, p90 {p90}"
            );
            // Invisible texels are zero in u.
            assert!(
                (0..t).filter(|&k| !visible[k]).all(|k| u[k] == 0.0),
                "{name}"
            );
            masks.push(visible);
        }
        let stats = TexelVisibilityStats::from_masks(&masks[0], &masks[1]).unwrap();
        let sum = stats.invisible
            + stats.symmetric_usable
            + (stats.left_visible + stats.right_visible - stats.symmetric_usable) / 2.0;
        assert!((sum - 1.0).abs() < 1e-9, "{name}: {stats:?}");
        assert!(stats.invisible > 0.05, "{name}: {stats:?}");
    }
}

/// Both hands of `s`, white, rendered in its camera (for the unwrap tests' rasters).
fn white_render(s: &HandScene, device: &Device) -> crate::scene::SceneRender {
    let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
    let verts = [
        vertex_tensor(&s.vertices[0], device),
        vertex_tensor(&s.vertices[1], device),
    ];
    let white = Tensor::<3>::ones([3, 4, 4], device);
    let light = LightValues::default().to_light(device);
    render(
        &scene,
        &verts,
        &[white.clone(), white],
        &s.camera,
        &light,
        &RenderSettings::default(),
    )
    .unwrap()
}

#[test]
fn unwrap_is_differentiable_in_the_image() {
    let device = Device::flex().autodiff();
    let s = hand_scene(64);
    let out = white_render(&s, &device);
    let image = Tensor::<3>::ones([3, 64, 64], &device).require_grad();
    let surface = TexelSurface::new(&s.layouts[0], &s.faces[0], s.vertices[0].len()).unwrap();
    let un = unwrap(
        image.clone(),
        &s.camera,
        &surface,
        &s.vertices[0],
        &out.raster,
        &UnwrapSettings::default(),
    )
    .unwrap();
    let visible = un.visible_host.iter().filter(|&&v| v).count() as f32;
    let grads = un.texels.sum().backward();
    let g = to_vec(image.grad(&grads).unwrap());
    // Each visible texel spreads a total weight of 1 per channel over the image.
    let total: f32 = g.iter().sum();
    assert!(
        (total - 3.0 * visible).abs() < 1e-2 * visible,
        "{total} vs {}",
        3.0 * visible
    );
}

#[test]
fn render_gradients_reach_the_light_and_the_texture() {
    for (name, device) in autodiff_devices() {
        let s = hand_scene(48);
        let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let verts = [
            vertex_tensor(&s.vertices[0], &device),
            vertex_tensor(&s.vertices[1], &device),
        ];
        let values = LightValues {
            ambient: [0.3; 3],
            diffuse: [0.6; 3],
            specular: [0.2; 3],
            location: [0.05, -0.1, 0.2],
        };
        let light_t =
            Tensor::<1>::from_data(TensorData::new(values.to_array().to_vec(), [12]), &device)
                .require_grad();
        let tex =
            Tensor::<3>::from_data(TensorData::new(vec![0.6f32; 3 * 8 * 8], [3, 8, 8]), &device)
                .require_grad();
        let material = Material {
            specular: [0.5; 3],
            shininess: 4.0,
            ..Material::default()
        };
        let settings = RenderSettings {
            material,
            ..RenderSettings::default()
        };
        let eval = |light: Tensor<1>, tex: Tensor<3>| {
            let light = PointLight::from_tensor(light).unwrap();
            let out = render(
                &scene,
                &verts,
                &[tex.clone(), tex],
                &s.camera,
                &light,
                &settings,
            )
            .unwrap();
            out.image.sum()
        };
        let grads = eval(light_t.clone(), tex.clone()).backward();
        let g = to_vec(light_t.grad(&grads).unwrap());
        let gt = to_vec(tex.grad(&grads).unwrap());
        assert!(
            gt.iter().sum::<f32>() > 1.0,
            "{name}: texture gradient {gt:?}"
        );
        let base = values.to_array();
        for i in 0..12 {
            let eps = 1e-2;
            let at = |d: f32| {
                let mut v = base;
                v[i] += d;
                let l = Tensor::<1>::from_data(TensorData::new(v.to_vec(), [12]), &device);
                to_vec(eval(l, tex.clone()).reshape([1]))[0]
            };
            let fd = (at(eps) - at(-eps)) / (2.0 * eps);
            assert!(
                (fd - g[i]).abs() <= 2e-2 * fd.abs().max(1.0),
                "{name}: d image / d light[{i}]: autodiff {} vs finite difference {fd}",
                g[i]
            );
        }
    }
}

/// A geometry made once and shaded many times gives what [`render`] gives, in values and in
/// the gradients to the texture, the light and (made from vertices with gradients) the
/// vertices; a texture of another size than it was made for is an error.
#[test]
fn a_reused_scene_geometry_shades_like_render() {
    for (name, device) in autodiff_devices() {
        let s = hand_scene(40);
        let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let verts = [
            vertex_tensor(&s.vertices[0], &device).require_grad(),
            vertex_tensor(&s.vertices[1], &device).require_grad(),
        ];
        let mut rng = Rng::new(7);
        let tex = |rng: &mut Rng| {
            let v = (0..3 * 8 * 8)
                .map(|_| rng.uniform(0.0, 1.0) as f32)
                .collect();
            Tensor::<3>::from_data(TensorData::new(v, [3, 8, 8]), &device).require_grad()
        };
        let (left, right) = (tex(&mut rng), tex(&mut rng));
        let light_t = Tensor::<1>::from_data(
            TensorData::new(LightValues::default().to_array().to_vec(), [12]),
            &device,
        )
        .require_grad();
        let light = PointLight::from_tensor(light_t.clone()).unwrap();
        let settings = RenderSettings::default();
        let once = SceneGeometry::new(&scene, &verts, &s.camera, &settings, &[[8, 8]; 2]).unwrap();
        assert!(
            once.raster().unwrap().num_covered() > 50,
            "{name}: hands cover the image"
        );
        let weights = Tensor::<3>::from_data(
            TensorData::new(
                (0..3 * 40 * 40)
                    .map(|_| rng.uniform(0.0, 1.0) as f32)
                    .collect(),
                [3, 40, 40],
            ),
            &device,
        );
        let textures = [left.clone(), right.clone()];
        let direct = render(&scene, &verts, &textures, &s.camera, &light, &settings).unwrap();
        let light = PointLight::from_tensor(light_t.clone().detach()).unwrap();
        // Shade the same geometry twice: the second use must not differ from the first.
        let first = once
            .shade(&textures, &light, &settings.material, settings.background)
            .unwrap();
        let second = once
            .shade(&textures, &light, &settings.material, settings.background)
            .unwrap();
        let (d, a, b) = (
            to_vec(direct.image.clone()),
            to_vec(first.clone()),
            to_vec(second.clone()),
        );
        assert_eq!(a, b, "{name}: reuse changes nothing");
        let max = d
            .iter()
            .zip(&a)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max);
        assert!(
            max < 1e-6,
            "{name}: geometry + shade vs render differ by {max}"
        );
        // Gradients: a geometry made from vertices with gradients serves one backward pass
        // (burn keeps no graph after it), so both shadings enter one loss, which must have
        // twice the gradients of one render.
        let grads_of = |image: Tensor<3>| {
            let g = (image * weights.clone()).sum().backward();
            [
                to_vec(left.grad(&g).unwrap()),
                to_vec(right.grad(&g).unwrap()),
                to_vec(light_t.grad(&g).unwrap()),
                to_vec(verts[0].grad(&g).unwrap()),
                to_vec(verts[1].grad(&g).unwrap()),
            ]
        };
        let gd = grads_of(direct.image);
        let light = PointLight::from_tensor(light_t.clone()).unwrap();
        let shade = || {
            once.shade(&textures, &light, &settings.material, settings.background)
                .unwrap()
        };
        let gs = grads_of(shade() + shade());
        for (k, (x, y)) in gd.iter().zip(&gs).enumerate() {
            let max = x
                .iter()
                .zip(y)
                .map(|(p, q)| (2.0 * p - q).abs())
                .fold(0.0, f32::max);
            let scale = x.iter().map(|v| v.abs()).fold(1e-3, f32::max);
            assert!(
                max <= 1e-5 * scale,
                "{name}: gradient {k} differs by {max} (scale {scale})"
            );
        }
        let small = Tensor::<3>::zeros([3, 4, 4], &device);
        let err = once
            .shade(
                &[small.clone(), small],
                &light,
                &settings.material,
                [0.0; 3],
            )
            .unwrap_err();
        assert!(err.to_string().contains("texture"), "{name}: {err}");
    }
}

/// A geometry prepared for compact textures ([`SceneGeometry::with_compact_textures`])
/// shades a layout's compact texels as the plain geometry shades the texture images they
/// expand to (unused texels black), on both per-pixel paths: the same image, and the same
/// gradients to the texels, the light and the vertices. Mixing the two kinds of texture, a
/// compact texture of the wrong size and a layout of the wrong size are errors.
#[test]
fn compact_textures_shade_like_the_images_they_expand_to() {
    for (name, device) in autodiff_devices() {
        let s = hand_scene(40);
        let scene = Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let mut rng = Rng::new(11);
        let t = s.layouts[0].num_texels();
        assert_eq!(t, s.layouts[1].num_texels(), "{name}: one texel order");
        let compact = |rng: &mut Rng| {
            let v = (0..3 * t).map(|_| rng.uniform(0.0, 1.0) as f32).collect();
            Tensor::<2>::from_data(TensorData::new(v, [3, t]), &device).require_grad()
        };
        let textures = [compact(&mut rng), compact(&mut rng)];
        let weights = Tensor::<3>::from_data(
            TensorData::new(
                (0..3 * 40 * 40)
                    .map(|_| rng.uniform(0.0, 1.0) as f32)
                    .collect(),
                [3, 40, 40],
            ),
            &device,
        );
        let settings = RenderSettings::default();
        let layouts = [&s.layouts[0], &s.layouts[1]];
        for path in [GeometryPath::Covered, GeometryPath::Dense] {
            let verts = [
                vertex_tensor(&s.vertices[0], &device).require_grad(),
                vertex_tensor(&s.vertices[1], &device).require_grad(),
            ];
            let light_t = Tensor::<1>::from_data(
                TensorData::new(LightValues::default().to_array().to_vec(), [12]),
                &device,
            )
            .require_grad();
            let light = PointLight::from_tensor(light_t.clone()).unwrap();
            let geometry = || {
                SceneGeometry::with_path(&scene, &verts, &s.camera, &settings, &[[64, 64]; 2], path)
                    .unwrap()
            };
            let plain = geometry();
            let prepared = geometry().with_compact_textures(&layouts).unwrap();
            let images: Vec<Tensor<3>> = textures
                .iter()
                .zip(layouts)
                .map(|(c, l)| l.compact_to_image_tensor(c.clone(), [0.0; 3]))
                .collect();
            let expanded = plain
                .shade(&images, &light, &settings.material, settings.background)
                .unwrap();
            let direct = prepared
                .shade_compact(&textures, &light, &settings.material, settings.background)
                .unwrap();
            let (a, b) = (to_vec(expanded.clone()), to_vec(direct.clone()));
            assert!(
                a.iter().any(|&v| v > 0.05),
                "{name} {path:?}: the hands are lit"
            );
            let max = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f32::max);
            assert!(max <= 1e-6, "{name} {path:?}: images differ by {max}");
            // One loss over both images: each part's gradient is read from its own inputs.
            let g = ((expanded + direct) * weights.clone()).sum().backward();
            let both = [
                to_vec(textures[0].grad(&g).unwrap()),
                to_vec(textures[1].grad(&g).unwrap()),
                to_vec(light_t.grad(&g).unwrap()),
                to_vec(verts[0].grad(&g).unwrap()),
                to_vec(verts[1].grad(&g).unwrap()),
            ];
            // The expanded render alone, on fresh inputs of the same values.
            let fresh = |x: &Tensor<2>| x.clone().detach().require_grad();
            let alone_textures = [fresh(&textures[0]), fresh(&textures[1])];
            let alone_light = light_t.clone().detach().require_grad();
            let alone_verts = [fresh(&verts[0]), fresh(&verts[1])];
            let light = PointLight::from_tensor(alone_light.clone()).unwrap();
            let images: Vec<Tensor<3>> = alone_textures
                .iter()
                .zip(layouts)
                .map(|(c, l)| l.compact_to_image_tensor(c.clone(), [0.0; 3]))
                .collect();
            let alone = SceneGeometry::with_path(
                &scene,
                &alone_verts,
                &s.camera,
                &settings,
                &[[64, 64]; 2],
                path,
            )
            .unwrap()
            .shade(&images, &light, &settings.material, settings.background)
            .unwrap();
            let g = (alone * weights.clone()).sum().backward();
            let one = [
                to_vec(alone_textures[0].grad(&g).unwrap()),
                to_vec(alone_textures[1].grad(&g).unwrap()),
                to_vec(alone_light.grad(&g).unwrap()),
                to_vec(alone_verts[0].grad(&g).unwrap()),
                to_vec(alone_verts[1].grad(&g).unwrap()),
            ];
            for (k, (x, y)) in one.iter().zip(&both).enumerate() {
                let scale = x.iter().map(|v| v.abs()).fold(1e-3, f32::max);
                assert!(scale > 1e-3, "{name} {path:?}: gradient {k} is not zero");
                let max = x
                    .iter()
                    .zip(y)
                    .map(|(p, q)| (2.0 * p - q).abs())
                    .fold(0.0, f32::max);
                assert!(
                    max <= 1e-5 * scale,
                    "{name} {path:?}: gradient {k} differs by {max} (scale {scale})"
                );
            }
            let light = PointLight::from_tensor(light_t.clone().detach()).unwrap();
            let m = &settings.material;
            let err = prepared.shade(&images, &light, m, [0.0; 3]).unwrap_err();
            assert!(err.to_string().contains("compact"), "{name}: {err}");
            let err = plain
                .shade_compact(&textures, &light, m, [0.0; 3])
                .unwrap_err();
            assert!(err.to_string().contains("images"), "{name}: {err}");
            let err = prepared
                .clone()
                .with_compact_textures(&layouts)
                .unwrap_err();
            assert!(err.to_string().contains("already"), "{name}: {err}");
            let short = Tensor::<2>::zeros([3, t - 1], &device);
            let err = prepared
                .shade_compact(&[short.clone(), short], &light, m, [0.0; 3])
                .unwrap_err();
            assert!(
                err.to_string().contains(&format!("[3, {t}]")),
                "{name}: {err}"
            );
        }
        let right = procedural_pair();
        let uv = right.get(Side::Right).uv.as_ref().unwrap();
        let small = TextureLayout::from_uv(uv, 32, 32, 1).unwrap();
        let verts = [
            vertex_tensor(&s.vertices[0], &device),
            vertex_tensor(&s.vertices[1], &device),
        ];
        let err = SceneGeometry::new(&scene, &verts, &s.camera, &settings, &[[64, 64]; 2])
            .unwrap()
            .with_compact_textures(&[&small, &small])
            .unwrap_err();
        assert!(err.to_string().contains("32 x 32"), "{name}: {err}");
    }
}

/// `UnwrapPlan::restrict` drops exactly the visible texels with a bilinear tap on an
/// untrusted pixel: trusting every pixel drops none, trusting none drops all, and trusting
/// the left half keeps only texels whose taps all lie there.
#[test]
fn restricting_a_plan_drops_texels_on_untrusted_pixels() {
    let device = Device::flex();
    let s = hand_scene(64);
    let out = white_render(&s, &device);
    let surface = TexelSurface::new(&s.layouts[0], &s.faces[0], s.vertices[0].len()).unwrap();
    let plan = UnwrapPlan::new(
        &s.camera,
        &surface,
        &s.vertices[0],
        &out.raster,
        &UnwrapSettings::default(),
    )
    .unwrap();
    let visible = plan.visible().iter().filter(|&&v| v).count();
    assert!(visible > 0);
    let mut all = plan.clone();
    assert_eq!(all.restrict(&vec![true; 64 * 64]).unwrap(), 0);
    assert_eq!(all.visible(), plan.visible());
    let mut none = plan.clone();
    assert_eq!(none.restrict(&vec![false; 64 * 64]).unwrap(), visible);
    assert!(none.visible().iter().all(|&v| !v));
    // The left half (columns < 32): what stays visible samples there, with its right tap too.
    let left: Vec<bool> = (0..64 * 64).map(|p| p % 64 < 32).collect();
    let mut half = plan.clone();
    let dropped = half.restrict(&left).unwrap();
    let kept = half.visible().iter().filter(|&&v| v).count();
    assert_eq!(kept + dropped, visible);
    let image = Tensor::<3>::from_data(
        burn::tensor::TensorData::new(
            (0..3 * 64 * 64)
                .map(|i| (i % 64) as f32)
                .collect::<Vec<f32>>(),
            [3, 64, 64],
        ),
        &device,
    );
    let un = half.apply(image).unwrap();
    let cols = to_vec(un.texels.narrow(0, 0, 1));
    for (k, &v) in half.visible().iter().enumerate() {
        if v {
            // The sampled column (pixel centres at c + 1/2) lies left of 31.
            assert!(cols[k] <= 31.0, "texel {k} samples column {}", cols[k]);
        }
    }
    assert!(half.restrict(&[true; 3]).is_err(), "wrong mask size");
}
