//! The burn primitives against the CPU core (values and hand-written backward passes) and
//! against finite differences, on flex, ndarray and wgpu.

use bitt_testkit::{assert_close, autodiff_devices, to_vec};
use burn::tensor::{Device, Tensor, TensorData};

use super::{Camera, Rng};
use crate::{Raster, Topology, antialias, cpu, interpolate, rasterize, texture};

fn tensor2(values: &[f32], shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values.to_vec(), shape), device)
}

fn flat(clip: &[[f32; 4]]) -> Vec<f32> {
    clip.iter().flatten().copied().collect()
}

/// Random overlapping perspective triangles (camera-space depth 2..5) and their clip
/// positions.
pub(super) fn scene(seed: u64, faces: usize) -> (Vec<[f32; 4]>, Vec<[u32; 3]>) {
    let cam = Camera {
        focal: 1.6,
        near: 0.1,
        far: 100.0,
    };
    let mut rng = Rng::new(seed);
    let mut clip = Vec::new();
    let mut tris = Vec::new();
    for f in 0..faces {
        let z = rng.uniform(2.0, 5.0);
        let (cx, cy) = (rng.uniform(-0.6, 0.6) * z, rng.uniform(-0.6, 0.6) * z);
        for _ in 0..3 {
            let p = [
                cx + rng.uniform(-0.7, 0.7) * z,
                cy + rng.uniform(-0.7, 0.7) * z,
                z + rng.uniform(-0.8, 0.8),
            ];
            clip.push(cam.project(p));
        }
        let b = 3 * f as u32;
        tris.push([b, b + 1, b + 2]);
    }
    (clip, tris)
}

/// Unit cube (12 faces, shared vertices) seen at an angle.
pub(super) fn cube() -> (Vec<[f32; 4]>, Vec<[u32; 3]>) {
    let cam = Camera {
        focal: 1.5,
        near: 0.1,
        far: 100.0,
    };
    let (s, c) = (0.5f64.sin(), 0.5f64.cos());
    let (s2, c2) = (0.4f64.sin(), 0.4f64.cos());
    let clip = (0..8)
        .map(|i| {
            let p = [
                if i & 1 == 0 { -0.5 } else { 0.5 },
                if i & 2 == 0 { -0.5 } else { 0.5 },
                if i & 4 == 0 { -0.5 } else { 0.5 },
            ];
            let x = c * p[0] + s * p[2];
            let z = -s * p[0] + c * p[2];
            let y = c2 * p[1] - s2 * z;
            let z = s2 * p[1] + c2 * z;
            cam.project([x, y, z + 3.0])
        })
        .collect();
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    let faces = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    (clip, faces)
}

fn raster(clip: &[[f32; 4]], topo: &Topology, size: usize, device: &Device) -> (Tensor<2>, Raster) {
    let t = tensor2(&flat(clip), [clip.len(), 4], device).require_grad();
    let r = rasterize(t.clone(), topo, size, size).expect("rasterize");
    (t, r)
}

#[test]
fn rasterize_matches_the_cpu_core() {
    for (name, device) in autodiff_devices() {
        for (clip, faces) in [scene(3, 6), cube()] {
            let topo = Topology::new(faces.clone(), clip.len()).unwrap();
            let (_, r) = raster(&clip, &topo, 40, &device);
            let frags = cpu::rasterize(&clip, &faces, 40, 40).unwrap();
            assert_eq!(r.fragments, frags, "{name}");
            assert!(r.num_covered() > 100, "{name}: scene covers too little");
            let want_bary: Vec<f32> = r
                .covered()
                .iter()
                .flat_map(|&p| frags.bary[p as usize])
                .collect();
            let want_depth: Vec<f32> = r
                .covered()
                .iter()
                .map(|&p| frags.depth[p as usize])
                .collect();
            assert_close(&to_vec(r.bary.clone()), &want_bary, 1e-4, name);
            assert_close(&to_vec(r.depth.clone()), &want_depth, 1e-4, name);
        }
    }
}

#[test]
fn rasterize_gradient_matches_the_analytic_backward() {
    for (name, device) in autodiff_devices() {
        let (clip, faces) = scene(11, 5);
        let topo = Topology::new(faces.clone(), clip.len()).unwrap();
        let (t, r) = raster(&clip, &topo, 32, &device);
        let n = r.num_covered();
        let mut rng = Rng::new(5);
        let gb: Vec<f32> = (0..3 * n).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let gd: Vec<f32> = (0..n).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let loss = (r.bary.clone() * tensor2(&gb, [n, 3], &device)).sum()
            + (r.depth.clone() * Tensor::<1>::from_data(TensorData::new(gd.clone(), [n]), &device))
                .sum();
        let grads = loss.backward();
        let got = to_vec(t.grad(&grads).expect("clip gradient"));

        let frags = &r.fragments;
        let mut full_gb = vec![[0.0f32; 3]; 32 * 32];
        let mut full_gd = vec![0.0f32; 32 * 32];
        for (k, &p) in r.covered().iter().enumerate() {
            full_gb[p as usize] = [gb[3 * k], gb[3 * k + 1], gb[3 * k + 2]];
            full_gd[p as usize] = gd[k];
        }
        let want = cpu::rasterize_backward(&clip, &faces, frags, &full_gb, Some(&full_gd)).unwrap();
        assert_close(&got, &flat(&want), 2e-3, name);
    }
}

#[test]
fn interpolate_matches_the_cpu_core_in_values_and_gradients() {
    for (name, device) in autodiff_devices() {
        let (clip, faces) = scene(21, 4);
        let topo = Topology::new(faces.clone(), clip.len()).unwrap();
        let (t, r) = raster(&clip, &topo, 28, &device);
        let mut rng = Rng::new(9);
        let attrs: Vec<f32> = (0..clip.len() * 2)
            .map(|_| rng.uniform(-2.0, 2.0) as f32)
            .collect();
        let a = tensor2(&attrs, [clip.len(), 2], &device).require_grad();
        let out = interpolate(a.clone(), &r).unwrap();
        let n = r.num_covered();
        let want = cpu::interpolate(&attrs, 2, &faces, &r.fragments).unwrap();
        let want_rows: Vec<f32> = r
            .covered()
            .iter()
            .flat_map(|&p| want[2 * p as usize..2 * p as usize + 2].to_vec())
            .collect();
        assert_close(&to_vec(out.clone()), &want_rows, 1e-4, name);

        let g: Vec<f32> = (0..2 * n).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let grads = (out * tensor2(&g, [n, 2], &device)).sum().backward();
        let mut full_g = vec![0.0f32; 28 * 28 * 2];
        for (k, &p) in r.covered().iter().enumerate() {
            full_g[2 * p as usize] = g[2 * k];
            full_g[2 * p as usize + 1] = g[2 * k + 1];
        }
        let (want_ga, want_gb) =
            cpu::interpolate_backward(&attrs, 2, &faces, &r.fragments, &full_g).unwrap();
        assert_close(&to_vec(a.grad(&grads).unwrap()), &want_ga, 1e-4, name);
        let want_gclip =
            cpu::rasterize_backward(&clip, &faces, &r.fragments, &want_gb, None).unwrap();
        assert_close(
            &to_vec(t.grad(&grads).unwrap()),
            &flat(&want_gclip),
            2e-3,
            name,
        );
    }
}

#[test]
fn texture_matches_the_cpu_core_in_values_and_gradients() {
    for (name, device) in autodiff_devices() {
        let (c, ht, wt, n) = (3, 7, 9, 40);
        let mut rng = Rng::new(31);
        let image: Vec<f32> = (0..c * ht * wt)
            .map(|_| rng.uniform(0.0, 1.0) as f32)
            .collect();
        // Interior samples plus a few outside the texture (border padding).
        let uv: Vec<f32> = (0..2 * n)
            .map(|i| {
                if i < 8 {
                    rng.uniform(-0.5, 1.5) as f32
                } else {
                    rng.uniform(0.02, 0.98) as f32
                }
            })
            .collect();
        let img = Tensor::<3>::from_data(TensorData::new(image.clone(), [c, ht, wt]), &device)
            .require_grad();
        let uvt = tensor2(&uv, [n, 2], &device).require_grad();
        let out = texture(img.clone(), uvt.clone()).unwrap();
        let uv2: Vec<[f32; 2]> = uv.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
        let want = cpu::texture(&image, c, ht, wt, &uv2, None).unwrap();
        assert_close(&to_vec(out.clone()), &want, 1e-5, name);

        let g: Vec<f32> = (0..n * c).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let grads = (out * tensor2(&g, [n, c], &device)).sum().backward();
        let (want_gi, want_guv) = cpu::texture_backward(&image, c, ht, wt, &uv2, None, &g).unwrap();
        assert_close(&to_vec(img.grad(&grads).unwrap()), &want_gi, 1e-4, name);
        let want_guv: Vec<f32> = want_guv.into_iter().flatten().collect();
        assert_close(&to_vec(uvt.grad(&grads).unwrap()), &want_guv, 1e-3, name);
    }
}

/// Renders per-vertex colours with antialiasing and returns a weighted sum of the image.
fn aa_loss(
    clip: &Tensor<2>,
    topo: &Topology,
    colors: &Tensor<2>,
    weights: &Tensor<3>,
    size: usize,
) -> (Tensor<1>, Raster) {
    let r = rasterize(clip.clone(), topo, size, size).unwrap();
    let per_pixel = interpolate(colors.clone(), &r).unwrap();
    let image = r.to_image(per_pixel, &[0.1, 0.2, 0.3]);
    let image = antialias(image, &r, clip.clone(), topo).unwrap();
    ((image * weights.clone()).sum(), r)
}

#[test]
fn antialias_gradient_matches_finite_differences() {
    for (name, device) in autodiff_devices() {
        let (clip, faces) = scene(41, 3);
        let size = 24;
        let topo = Topology::new(faces.clone(), clip.len()).unwrap();
        let mut rng = Rng::new(77);
        let colors: Vec<f32> = (0..clip.len() * 3)
            .map(|_| rng.uniform(0.0, 1.0) as f32)
            .collect();
        let weights: Vec<f32> = (0..3 * size * size)
            .map(|_| rng.uniform(-1.0, 1.0) as f32)
            .collect();
        let colors = tensor2(&colors, [clip.len(), 3], &device);
        let weights = Tensor::<3>::from_data(TensorData::new(weights, [3, size, size]), &device);
        let t = tensor2(&flat(&clip), [clip.len(), 4], &device).require_grad();
        let (loss, r0) = aa_loss(&t, &topo, &colors, &weights, size);
        let pairs = crate::silhouette_pairs(&r0, &topo).unwrap();
        assert!(
            pairs.len() > 20,
            "{name}: only {} silhouette pairs",
            pairs.len()
        );
        let grad = to_vec(t.grad(&loss.backward()).unwrap());

        let eps = 2e-3f32;
        let mut checked = 0;
        let mut silhouette_only = 0;
        for i in 0..clip.len() {
            for k in [0, 1, 3] {
                let mut plus = clip.clone();
                let mut minus = clip.clone();
                plus[i][k] += eps;
                minus[i][k] -= eps;
                let eval = |c: &[[f32; 4]]| {
                    let t = tensor2(&flat(c), [c.len(), 4], &device);
                    let (l, r) = aa_loss(&t, &topo, &colors, &weights, size);
                    (to_vec(l.reshape([1]))[0], r)
                };
                let (lp, rp) = eval(&plus);
                let (lm, rm) = eval(&minus);
                if rp.fragments.face != r0.fragments.face || rm.fragments.face != r0.fragments.face
                {
                    continue; // a pixel centre changed sides: not differentiable here
                }
                let fd = (lp - lm) / (2.0 * eps);
                let g = grad[4 * i + k];
                assert!(
                    (fd - g).abs() <= 2e-2 * fd.abs().max(1.0),
                    "{name}: d loss / d clip[{i}][{k}]: autodiff {g} vs finite difference {fd}"
                );
                checked += 1;
                if g.abs() > 1e-3 {
                    silhouette_only += 1;
                }
            }
        }
        assert!(checked >= 20, "{name}: only {checked} coordinates checked");
        assert!(silhouette_only >= 10, "{name}: gradients are mostly zero");
    }
}

#[test]
fn antialias_moves_a_flat_coloured_silhouette() {
    // A constant-colour triangle over a black background has no interior gradient at all;
    // every position gradient comes from the silhouette.
    for (name, device) in autodiff_devices() {
        let clip = vec![
            [-0.61, -0.53, 0.0, 1.0],
            [0.57, -0.38, 0.0, 1.0],
            [-0.12, 0.66, 0.0, 1.0],
        ];
        let topo = Topology::new(vec![[0, 1, 2]], 3).unwrap();
        let t = tensor2(&flat(&clip), [3, 4], &device).require_grad();
        let r = rasterize(t.clone(), &topo, 16, 16).unwrap();
        let white = Tensor::<2>::ones([r.num_covered(), 1], &device);
        let image = r.to_image(white, &[0.0]);
        let image = antialias(image, &r, t.clone(), &topo).unwrap();
        // Coverage grows when the triangle grows: moving vertex 1 right increases the sum.
        let grads = image.sum().backward();
        let g = to_vec(t.grad(&grads).unwrap());
        assert!(g[4] > 0.5, "{name}: d coverage / d x1 = {}", g[4]);
        assert!(g[0] < -0.5, "{name}: d coverage / d x0 = {}", g[0]);
        // Total coverage approximates the triangle's area in pixels (16 x 16 image).
        let area = 0.5
            * ((clip[1][0] - clip[0][0]) * (clip[2][1] - clip[0][1])
                - (clip[2][0] - clip[0][0]) * (clip[1][1] - clip[0][1]))
                .abs()
            * 64.0;
        let sum: f32 = to_vec(image_sum(&r, &t, &topo)).iter().sum();
        assert!(
            (sum - area).abs() < 0.05 * area,
            "{name}: coverage {sum} vs area {area}"
        );
    }
}

fn image_sum(r: &Raster, t: &Tensor<2>, topo: &Topology) -> Tensor<3> {
    let white = Tensor::<2>::ones([r.num_covered(), 1], &t.device());
    antialias(r.to_image(white, &[0.0]), r, t.clone(), topo).unwrap()
}

#[test]
fn closed_mesh_silhouettes_are_only_on_its_outline() {
    for (name, device) in autodiff_devices() {
        let (clip, faces) = cube();
        let topo = Topology::new(faces, clip.len()).unwrap();
        let (_, r) = raster(&clip, &topo, 48, &device);
        let pairs = crate::silhouette_pairs(&r, &topo).unwrap();
        assert!(!pairs.is_empty(), "{name}");
        // Every pair has the background on its back side: the cube's own visible edges
        // between front faces are not silhouettes.
        for (&front, &back) in pairs.front.iter().zip(&pairs.back) {
            assert!(r.fragments.face[front as usize] >= 0, "{name}");
            assert_eq!(
                r.fragments.face[back as usize], -1,
                "{name}: pair {front}-{back}"
            );
        }
        let outline = (0..48 * 48)
            .filter(|&p| {
                r.fragments.face[p] >= 0
                    && [p.wrapping_sub(1), p + 1, p.wrapping_sub(48), p + 48]
                        .iter()
                        .any(|&q| q < 48 * 48 && r.fragments.face[q] < 0)
            })
            .count();
        assert!(
            pairs.len() >= outline,
            "{name}: {} pairs for {outline} outline pixels",
            pairs.len()
        );
    }
}

#[test]
fn two_meshes_share_one_depth_test() {
    for (name, device) in autodiff_devices() {
        let (clip_a, faces_a) = scene(51, 2);
        let (clip_b, faces_b) = scene(52, 2);
        let ta = Topology::new(faces_a, clip_a.len()).unwrap();
        let tb = Topology::new(faces_b, clip_b.len()).unwrap();
        let both = Topology::concat(&[&ta, &tb]).unwrap();
        let clip: Vec<[f32; 4]> = clip_a.iter().chain(&clip_b).copied().collect();
        let (_, r) = raster(&clip, &both, 32, &device);
        let frags_a = cpu::rasterize(&clip_a, ta.faces(), 32, 32).unwrap();
        let frags_b = cpu::rasterize(&clip_b, tb.faces(), 32, 32).unwrap();
        let mask_a = to_vec(r.face_range_mask(0..2, &device));
        for p in 0..32 * 32 {
            let a_wins = frags_a.face[p] >= 0 && frags_a.depth[p] <= frags_b.depth[p];
            assert_eq!(mask_a[p] == 1.0, a_wins, "{name}: pixel {p}");
        }
    }
}

#[test]
fn empty_rasters_and_bad_shapes() {
    for (name, device) in autodiff_devices() {
        let topo = Topology::new(vec![[0, 1, 2]], 3).unwrap();
        // Behind the camera: nothing covered.
        let clip = tensor2(
            &[
                0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0, -1.0,
            ],
            [3, 4],
            &device,
        );
        let r = rasterize(clip.clone(), &topo, 8, 8).unwrap();
        assert_eq!(r.num_covered(), 0, "{name}");
        let colors = interpolate(Tensor::ones([3, 3], &device), &r).unwrap();
        let image = r.to_image(colors, &[0.5, 0.5, 0.5]);
        let image = antialias(image, &r, clip, &topo).unwrap();
        assert!(to_vec(image).iter().all(|&x| x == 0.5), "{name}");

        let wrong = tensor2(&[0.0; 8], [2, 4], &device);
        let err = rasterize(wrong, &topo, 8, 8).unwrap_err();
        assert!(err.to_string().contains("clip"), "{name}: {err}");
        let bad_uv = tensor2(&[0.0; 6], [2, 3], &device);
        let err = texture(Tensor::ones([3, 4, 4], &device), bad_uv).unwrap_err();
        assert!(err.to_string().contains("uv"), "{name}: {err}");
        assert!(Topology::new(vec![[0, 1, 5]], 3).is_err());
    }
}
