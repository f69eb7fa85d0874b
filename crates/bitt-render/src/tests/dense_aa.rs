//! [`crate::AntialiasPlan::from_dense`] (the silhouette search on the device) against the
//! host search ([`crate::silhouette_pairs`], [`crate::AntialiasPlan::new`]): the same pairs,
//! the same antialiased image and gradients, and no host readback on wgpu.

use bitt_testkit::{assert_close, autodiff_devices, to_vec};
use burn::tensor::{Device, Tensor, TensorData};

use super::Rng;
use super::dense::{near_plane, soup};
use crate::ops::thread_host_readbacks;
use crate::{AntialiasPlan, RasterKernel, Topology, rasterize, rasterize_dense, silhouette_pairs};

/// A named scene: clip positions, faces, width, height.
type Case = (String, Vec<[f32; 4]>, Vec<[u32; 3]>, usize, usize);

/// Small scenes with open and closed meshes, overlaps and near-plane crossings.
fn cases() -> Vec<Case> {
    let mut all: Vec<Case> = Vec::new();
    for (name, clip, faces, w, h) in [soup(3, 16, 20, 16), near_plane()] {
        all.push((name.to_string(), clip, faces, w, h));
    }
    let (clip, faces) = super::ops::scene(3, 6);
    all.push(("open soup".into(), clip, faces, 24, 24));
    let (clip, faces) = super::ops::cube();
    all.push(("cube".into(), clip, faces, 24, 20));
    all
}

fn clip_tensor(clip: &[[f32; 4]], device: &Device) -> Tensor<2> {
    let flat = clip.iter().flatten().copied().collect();
    Tensor::<2>::from_data(TensorData::new(flat, [clip.len(), 4]), device).require_grad()
}

/// Sorted `(front, back, edge)` triples.
fn triples(p: &crate::SilhouettePairs) -> Vec<(u32, u32, [u32; 2])> {
    let mut v: Vec<_> = (0..p.len())
        .map(|i| (p.front[i], p.back[i], p.edges[i]))
        .collect();
    v.sort_unstable();
    v
}

#[test]
fn dense_silhouette_search_finds_the_host_pairs_with_the_same_image_and_gradients() {
    for (device_name, device) in autodiff_devices() {
        for (name, clip, faces, w, h) in cases() {
            let what = format!("{device_name} {name}");
            let topo = Topology::new(faces.clone(), clip.len()).unwrap();
            let mut rng = Rng::new(13);
            let colour: Vec<f32> = (0..3 * w * h)
                .map(|_| rng.uniform(0.0, 1.0) as f32)
                .collect();
            let weights: Vec<f32> = (0..3 * w * h)
                .map(|_| rng.uniform(-1.0, 1.0) as f32)
                .collect();
            let image = || {
                Tensor::<3>::from_data(TensorData::new(colour.clone(), [3, h, w]), &device)
                    .require_grad()
            };
            let g = Tensor::<3>::from_data(TensorData::new(weights.clone(), [3, h, w]), &device);

            let t = clip_tensor(&clip, &device);
            let r = rasterize(t.clone(), &topo, h, w).unwrap();
            let host_pairs = silhouette_pairs(&r, &topo).unwrap();
            let plan = AntialiasPlan::new(&r, t.clone(), &topo).unwrap();
            let c = image();
            let out = plan.apply(c.clone()).unwrap();
            let grads = (out.clone() * g.clone()).sum().backward();
            let want = (
                to_vec(out),
                to_vec(c.grad(&grads).unwrap()),
                to_vec(t.grad(&grads).unwrap()),
            );

            let t = clip_tensor(&clip, &device);
            let c = image();
            let before = thread_host_readbacks();
            let dense = rasterize_dense(t.clone(), &topo, h, w).unwrap();
            let plan = AntialiasPlan::from_dense(&dense, t.clone(), &topo).unwrap();
            let out = plan.apply(c.clone()).unwrap();
            let grads = (out.clone() * g).sum().backward();
            let readbacks = thread_host_readbacks() - before;
            if dense.kernel == RasterKernel::Cube {
                assert_eq!(readbacks, 0, "{what}: the dense search read back");
            }
            assert_eq!(plan.num_pairs(), h * (w - 1) + (h - 1) * w, "{what}");
            let got_pairs = plan.dense_pairs_on_host().expect("a dense plan");
            let (hp, dp) = (triples(&host_pairs), triples(&got_pairs));
            assert!(hp.len() >= 10, "{what}: only {} silhouette pairs", hp.len());
            let only_host = hp.iter().filter(|p| !dp.contains(p)).count();
            let only_dense = dp.iter().filter(|p| !hp.contains(p)).count();
            assert_eq!(
                (only_host, only_dense),
                (0, 0),
                "{what}: pairs found by one search only (of {} host pairs)",
                hp.len()
            );
            let out = to_vec(out);
            let gc = to_vec(c.grad(&grads).unwrap());
            assert_close(&out, &want.0, 1e-5, &format!("{what} image"));
            assert_close(&gc, &want.1, 1e-5, &format!("{what} colour grad"));
            let gt = to_vec(t.grad(&grads).unwrap());
            assert!(gt.iter().all(|x| x.is_finite()), "{what}: clip grad");
            assert_close(&gt, &want.2, 1e-4, &format!("{what} clip grad"));
        }
    }
}

/// The two procedural hands at 192x192 (thousands of faces, closed-ish meshes with interior
/// silhouettes where fingers overlap): the device search in `f32` finds the host's pairs, on
/// flex (host rasterizer) and wgpu (the kernel).
#[test]
fn dense_silhouette_search_finds_the_host_pairs_on_the_hand_scene() {
    for (name, device) in bitt_testkit::devices() {
        if name == "ndarray" {
            continue; // the same host path as flex
        }
        let s = super::scene::hand_scene(192);
        let scene = crate::scene::Scene::new(&[&s.meshes[0], &s.meshes[1]]).unwrap();
        let all = Tensor::cat(
            vec![
                super::scene::vertex_tensor(&s.vertices[0], &device),
                super::scene::vertex_tensor(&s.vertices[1], &device),
            ],
            0,
        );
        let clip = s
            .camera
            .clip_positions(all, crate::scene::DepthRange::default())
            .unwrap();
        let topo = scene.topology();
        let r = rasterize(clip.clone(), topo, 192, 192).unwrap();
        let hp = triples(&silhouette_pairs(&r, topo).unwrap());
        let dense = rasterize_dense(clip.clone(), topo, 192, 192).unwrap();
        let plan = AntialiasPlan::from_dense(&dense, clip, topo).unwrap();
        let dp = triples(&plan.dense_pairs_on_host().unwrap());
        let only_host = hp.iter().filter(|p| !dp.contains(p)).count();
        let only_dense = dp.iter().filter(|p| !hp.contains(p)).count();
        assert!(hp.len() > 100, "{name}: {} pairs", hp.len());
        assert_eq!(
            (only_host, only_dense),
            (0, 0),
            "{name}: of {} pairs",
            hp.len()
        );
    }
}
