//! The differentiable dense path ([`crate::dense_barycentrics`], [`crate::interpolate_dense`],
//! [`crate::TexturePlan`] on dense UVs) against the covered-pixel path: values on covered
//! pixels, zeros on empty ones, the same gradients, and no host readback on wgpu.

use bitt_testkit::{assert_close, autodiff_devices, to_vec};
use burn::tensor::{Device, Tensor, TensorData};

use super::Rng;
use super::dense::{TestScene, near_plane, soup};
use crate::ops::thread_host_readbacks;
use crate::{
    RasterKernel, TexturePlan, Topology, dense_barycentrics, interpolate, interpolate_dense,
    interpolate_dense_with_faces, rasterize, rasterize_dense,
};

fn tensor2(values: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

fn clip_tensor(clip: &[[f32; 4]], device: &Device) -> Tensor<2> {
    tensor2(
        clip.iter().flatten().copied().collect(),
        [clip.len(), 4],
        device,
    )
    .require_grad()
}

fn random(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.uniform(-1.0, 1.0) as f32).collect()
}

/// Small scenes (wgpu runs on a software rasterizer in CI).
fn scenes() -> Vec<TestScene> {
    vec![soup(3, 16, 20, 16), near_plane()]
}

/// Rows `rows` of a row-major `[N, C]` buffer.
fn rows_of(values: &[f32], c: usize, rows: &[u32]) -> Vec<f32> {
    rows.iter()
        .flat_map(|&r| values[r as usize * c..(r as usize + 1) * c].to_vec())
        .collect()
}

#[test]
fn dense_barycentrics_match_the_covered_path_with_the_same_gradients() {
    for (device_name, device) in autodiff_devices() {
        for (name, clip, faces, w, h) in scenes() {
            let what = format!("{device_name} {name}");
            let topo = Topology::new(faces.clone(), clip.len()).unwrap();
            let mut rng = Rng::new(7);
            let g_bary = random(&mut rng, 3 * w * h);
            let g_depth = random(&mut rng, w * h);

            let t = clip_tensor(&clip, &device);
            let r = rasterize(t.clone(), &topo, h, w).unwrap();
            let rows = r.covered().to_vec();
            let gb = tensor2(rows_of(&g_bary, 3, &rows), [rows.len(), 3], &device);
            let gd = Tensor::<1>::from_data(
                TensorData::new(rows_of(&g_depth, 1, &rows), [rows.len()]),
                &device,
            );
            let loss = (r.bary.clone() * gb).sum() + (r.depth.clone() * gd).sum();
            let want_grad = to_vec(t.grad(&loss.backward()).unwrap());

            let t = clip_tensor(&clip, &device);
            let before = thread_host_readbacks();
            let dense = rasterize_dense(t.clone(), &topo, h, w).unwrap();
            let d = dense_barycentrics(&dense, t.clone(), &topo).unwrap();
            let gb = tensor2(g_bary.clone(), [w * h, 3], &device);
            let gd = Tensor::<1>::from_data(TensorData::new(g_depth.clone(), [w * h]), &device);
            let loss = (d.bary.clone() * gb).sum() + (d.depth.clone() * gd).sum();
            let grads = loss.backward();
            let readbacks = thread_host_readbacks() - before;
            if dense.kernel == RasterKernel::Cube {
                assert_eq!(readbacks, 0, "{what}: the dense path read back");
            }
            let got_grad = to_vec(t.grad(&grads).unwrap());

            let bary = to_vec(d.bary.clone());
            let depth = to_vec(d.depth.clone());
            assert_close(
                &rows_of(&bary, 3, &rows),
                &to_vec(r.bary.clone()),
                1e-6,
                &what,
            );
            assert_close(
                &rows_of(&depth, 1, &rows),
                &to_vec(r.depth.clone()),
                1e-6,
                &what,
            );
            for p in 0..w * h {
                if r.fragments.face[p] < 0 {
                    assert_eq!(&bary[3 * p..3 * p + 3], &[0.0; 3], "{what}: empty {p}");
                    assert_eq!(depth[p], 0.0, "{what}: empty {p}");
                }
            }
            assert!(got_grad.iter().all(|g| g.is_finite()), "{what}");
            assert_close(&got_grad, &want_grad, 1e-4, &format!("{what} clip grad"));
        }
    }
}

#[test]
fn dense_interpolation_matches_the_covered_path_with_the_same_gradients() {
    for (device_name, device) in autodiff_devices() {
        for (name, clip, faces, w, h) in scenes() {
            let what = format!("{device_name} {name}");
            let topo = Topology::new(faces.clone(), clip.len()).unwrap();
            let mut rng = Rng::new(9);
            let attrs = random(&mut rng, 2 * clip.len());
            // Attributes on their own faces: a different numbering of the same corners.
            let uv_faces: Vec<[u32; 3]> = faces.iter().map(|f| [f[2], f[0], f[1]]).collect();
            let g = random(&mut rng, 4 * w * h);
            let run = |dense: bool| {
                let t = clip_tensor(&clip, &device);
                let a = tensor2(attrs.clone(), [clip.len(), 2], &device).require_grad();
                let (out, rows) = if dense {
                    let dr = rasterize_dense(t.clone(), &topo, h, w).unwrap();
                    let d = dense_barycentrics(&dr, t.clone(), &topo).unwrap();
                    let plain = interpolate_dense(a.clone(), &d).unwrap();
                    let own = interpolate_dense_with_faces(a.clone(), &uv_faces, &d).unwrap();
                    (
                        Tensor::cat(vec![plain, own], 1),
                        (0..(w * h) as u32).collect(),
                    )
                } else {
                    let r = rasterize(t.clone(), &topo, h, w).unwrap();
                    let plain = interpolate(a.clone(), &r).unwrap();
                    let own = crate::ops::interpolate_with_faces(a.clone(), &uv_faces, &r);
                    let rows: Vec<u32> = r.covered().to_vec();
                    (Tensor::cat(vec![plain, own.unwrap()], 1), rows)
                };
                let n = rows.len();
                let gt = tensor2(rows_of(&g, 4, &rows), [n, 4], &device);
                let grads = (out.clone() * gt).sum().backward();
                (
                    to_vec(out),
                    rows,
                    to_vec(t.grad(&grads).unwrap()),
                    to_vec(a.grad(&grads).unwrap()),
                )
            };
            let (want, rows, want_gc, want_ga) = run(false);
            let (got, _, got_gc, got_ga) = run(true);
            assert_close(&rows_of(&got, 4, &rows), &want, 1e-5, &what);
            let covered: std::collections::HashSet<u32> = rows.iter().copied().collect();
            for p in (0..(w * h) as u32).filter(|p| !covered.contains(p)) {
                let p = p as usize;
                assert_eq!(&got[4 * p..4 * p + 4], &[0.0; 4], "{what}: empty {p}");
            }
            assert_close(&got_gc, &want_gc, 1e-4, &format!("{what} clip grad"));
            assert_close(&got_ga, &want_ga, 1e-5, &format!("{what} attribute grad"));
        }
    }
}

#[test]
fn texture_plan_on_dense_uvs_matches_the_covered_path_without_readback() {
    for (device_name, device) in autodiff_devices() {
        let (name, clip, faces, w, h) = soup(3, 16, 20, 16);
        let what = format!("{device_name} {name}");
        let topo = Topology::new(faces.clone(), clip.len()).unwrap();
        let mut rng = Rng::new(5);
        // UVs reaching past the texture's border on both sides (clamped samples).
        let uvs: Vec<f32> = (0..2 * clip.len())
            .map(|_| rng.uniform(-0.2, 1.2) as f32)
            .collect();
        let (ht, wt) = (5, 7);
        let image = random(&mut rng, 3 * ht * wt);
        let g = random(&mut rng, 3 * w * h);
        let run = |dense: bool| {
            let t = clip_tensor(&clip, &device);
            let uv = tensor2(uvs.clone(), [clip.len(), 2], &device).require_grad();
            let img = Tensor::<3>::from_data(TensorData::new(image.clone(), [3, ht, wt]), &device)
                .require_grad();
            let before = thread_host_readbacks();
            let (out, rows, cube) = if dense {
                let dr = rasterize_dense(t.clone(), &topo, h, w).unwrap();
                let d = dense_barycentrics(&dr, t.clone(), &topo).unwrap();
                let at = interpolate_dense(uv.clone(), &d).unwrap();
                let plan = TexturePlan::new(at, ht, wt).unwrap();
                let mask = d.covered().float().reshape([w * h, 1]);
                let out = plan.sample(img.clone()).unwrap() * mask;
                (out, (0..(w * h) as u32).collect(), dr.kernel)
            } else {
                let r = rasterize(t.clone(), &topo, h, w).unwrap();
                let at = interpolate(uv.clone(), &r).unwrap();
                let out = TexturePlan::new(at, ht, wt).unwrap().sample(img.clone());
                (out.unwrap(), r.covered().to_vec(), RasterKernel::Host)
            };
            let n = rows.len();
            let gt = tensor2(rows_of(&g, 3, &rows), [n, 3], &device);
            let grads = (out.clone() * gt).sum().backward();
            let readbacks = thread_host_readbacks() - before;
            if cube == RasterKernel::Cube {
                assert_eq!(readbacks, 0, "{what}: the dense path read back");
            }
            (
                to_vec(out),
                rows,
                to_vec(t.grad(&grads).unwrap()),
                to_vec(uv.grad(&grads).unwrap()),
                to_vec(img.grad(&grads).unwrap()),
            )
        };
        let (want, rows, want_gc, want_guv, want_gi) = run(false);
        let (got, _, got_gc, got_guv, got_gi) = run(true);
        assert!(rows.len() > 30, "{what}: scene covers too little");
        assert_close(&rows_of(&got, 3, &rows), &want, 1e-5, &what);
        assert_close(&got_gc, &want_gc, 1e-4, &format!("{what} clip grad"));
        assert_close(&got_guv, &want_guv, 1e-4, &format!("{what} uv grad"));
        assert_close(&got_gi, &want_gi, 1e-5, &format!("{what} image grad"));
    }
}

#[test]
fn dense_ops_reject_bad_shapes() {
    let device = Device::flex().autodiff();
    let (_, clip, faces, w, h) = soup(3, 4, 8, 6);
    let topo = Topology::new(faces.clone(), clip.len()).unwrap();
    let t = clip_tensor(&clip, &device);
    let dense = rasterize_dense(t.clone(), &topo, h, w).unwrap();
    let short = Tensor::<2>::zeros([clip.len() - 1, 4], &device);
    assert!(matches!(
        dense_barycentrics(&dense, short.clone(), &topo),
        Err(crate::RenderError::TensorShape { .. })
    ));
    assert!(matches!(
        crate::AntialiasPlan::from_dense(&dense, short, &topo),
        Err(crate::RenderError::TensorShape { .. })
    ));
    let d = dense_barycentrics(&dense, t, &topo).unwrap();
    let attrs = Tensor::<2>::zeros([clip.len() + 1, 2], &device);
    assert!(matches!(
        interpolate_dense(attrs.clone(), &d),
        Err(crate::RenderError::TensorShape { .. })
    ));
    // One attribute triple short of the face count, and an index past the attributes.
    assert!(interpolate_dense_with_faces(attrs.clone(), &faces[1..], &d).is_err());
    let mut past = faces.clone();
    past[0][0] = (clip.len() + 1) as u32;
    assert!(interpolate_dense_with_faces(attrs, &past, &d).is_err());
}
