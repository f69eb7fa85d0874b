//! The dense rasterizer op ([`crate::rasterize_dense`]) and the multithreaded CPU core against
//! the single-threaded CPU core, on scenes built to hit every rule: shared edges through
//! pixel centres (fill rule), overlapping perspective soups (depth test), exact duplicates
//! (ties), near-plane and eye crossings (clipping), the far plane, and the guard band.

use burn::tensor::{Device, Tensor, TensorData};

use super::{Camera, Rng, screen_clip};
use crate::raster::{Fragments, rasterize, rasterize_parallel};
use crate::{RasterKernel, Topology, rasterize_dense};

/// A named test scene: clip positions, faces, width, height.
pub(super) type TestScene = (&'static str, Vec<[f32; 4]>, Vec<[u32; 3]>, usize, usize);

/// Quads on a grid whose corners sit on pixel centres and edges, each split along a random
/// diagonal, at w = 1: every rule of the top-left convention is exercised.
fn tiling() -> TestScene {
    let (w, h) = (23, 17);
    let mut rng = Rng::new(11);
    let (nx, ny) = (6, 5);
    let mut clip = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let (sx, sy) = (1.5 + 3.5 * i as f64, 0.5 + 3.0 * j as f64);
            clip.push(screen_clip(sx, sy, 0.5, 1.0, w, h));
        }
    }
    let at = |i: u32, j: u32| j * (nx + 1) + i;
    let mut faces = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            if rng.uniform(0.0, 1.0) < 0.5 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    ("tiling", clip, faces, w, h)
}

/// Random triangles in front of a perspective camera, overlapping in depth.
pub(super) fn soup(seed: u64, n: usize, width: usize, height: usize) -> TestScene {
    let cam = Camera {
        focal: 1.2,
        near: 0.1,
        far: 10.0,
    };
    let mut rng = Rng::new(seed);
    let mut clip = Vec::new();
    let mut faces = Vec::new();
    for f in 0..n {
        let centre = [
            rng.uniform(-0.8, 0.8),
            rng.uniform(-0.8, 0.8),
            rng.uniform(1.5, 4.0),
        ];
        for _ in 0..3 {
            let p = [
                centre[0] + rng.uniform(-0.6, 0.6),
                centre[1] + rng.uniform(-0.6, 0.6),
                centre[2] + rng.uniform(-0.8, 0.8),
            ];
            clip.push(cam.project(p));
        }
        let b = 3 * f as u32;
        faces.push([b, b + 1, b + 2]);
    }
    ("soup", clip, faces, width, height)
}

/// Triangles crossing the near plane and the eye plane (w = 0), and one wholly behind.
pub(super) fn near_plane() -> TestScene {
    let cam = Camera {
        focal: 1.0,
        near: 0.5,
        far: 20.0,
    };
    let tris = [
        [[-1.0, -0.5, 0.2], [1.0, -0.4, 3.0], [0.2, 1.0, 2.0]],
        [[-0.3, 0.8, -0.5], [0.9, 0.1, 2.5], [-1.2, -0.9, 4.0]],
        [[0.5, 0.5, 0.3], [-0.5, 0.6, 0.45], [0.1, -0.7, 6.0]],
        [[0.0, 0.0, 0.1], [1.0, 0.0, 0.2], [0.0, 1.0, 0.3]],
    ];
    let clip = tris.iter().flatten().map(|&p| cam.project(p)).collect();
    let faces = (0..tris.len() as u32)
        .map(|f| [3 * f, 3 * f + 1, 3 * f + 2])
        .collect();
    ("near plane", clip, faces, 31, 27)
}

/// The soup with every face repeated (exact depth ties, which go to the lower face index),
/// one face beyond the far plane and one huge face reaching past the guard band.
fn ties_far_guard() -> TestScene {
    let (_, mut clip, mut faces, w, h) = soup(5, 12, 29, 21);
    let copies: Vec<[u32; 3]> = faces.clone();
    faces.extend(copies.iter().rev());
    let b = clip.len() as u32;
    // Beyond the far plane: z/w = 1.5.
    clip.extend([
        screen_clip(2.0, 2.0, 1.5, 2.0, w, h),
        screen_clip(25.0, 3.0, 1.5, 2.0, w, h),
        screen_clip(4.0, 19.0, 1.5, 2.0, w, h),
    ]);
    faces.push([b, b + 1, b + 2]);
    // Huge: NDC coordinates of +-1e9 (screen positions past 2^30 px are clamped), far behind.
    clip.extend([
        [-1.0e9, -1.0e9, 0.99, 1.0],
        [1.0e9, -3.0, 0.99, 1.0],
        [-2.0, 1.0e9, 0.99, 1.0],
    ]);
    faces.push([b + 3, b + 4, b + 5]);
    ("ties, far plane, guard band", clip, faces, w, h)
}

/// Every scene of this file.
fn scenes() -> Vec<TestScene> {
    vec![
        tiling(),
        soup(1, 40, 37, 29),
        soup(2, 150, 64, 48),
        near_plane(),
        ties_far_guard(),
    ]
}

#[test]
fn parallel_cpu_rasterizer_is_bit_identical_to_the_single_thread_one() {
    for (name, clip, faces, w, h) in scenes() {
        let one = rasterize(&clip, &faces, w, h).unwrap();
        let all = rasterize_parallel(&clip, &faces, w, h).unwrap();
        assert_eq!(one, all, "{name}");
        assert!(one.face.iter().any(|&f| f >= 0), "{name}: nothing drawn");
    }
}

/// Face ids, barycentrics and depth of a dense raster, on the host.
fn dense_host(
    clip: &[[f32; 4]],
    faces: &[[u32; 3]],
    w: usize,
    h: usize,
    device: &Device,
) -> (Fragments, RasterKernel) {
    let flat: Vec<f32> = clip.iter().flatten().copied().collect();
    let clip_t = Tensor::<2>::from_data(TensorData::new(flat, [clip.len(), 4]), device);
    let topology = Topology::new(faces.to_vec(), clip.len()).unwrap();
    let dense = rasterize_dense(clip_t, &topology, h, w).unwrap();
    assert_eq!(
        dense.host_reason.is_none(),
        dense.kernel == RasterKernel::Cube,
        "a host run says why, a kernel run does not"
    );
    assert_eq!(dense.depth.is_autodiff(), device.is_autodiff());
    assert_eq!(dense.face.dims(), [h, w]);
    assert_eq!(dense.bary.dims(), [h, w, 3]);
    assert_eq!(dense.depth.dims(), [h, w]);
    let face: Vec<i32> = dense
        .face
        .into_data()
        .convert::<i32>()
        .try_to_vec::<i32>()
        .unwrap();
    let bary: Vec<f32> = dense
        .bary
        .into_data()
        .convert::<f32>()
        .try_to_vec()
        .unwrap();
    let depth: Vec<f32> = dense
        .depth
        .into_data()
        .convert::<f32>()
        .try_to_vec()
        .unwrap();
    let frags = Fragments {
        width: w,
        height: h,
        face,
        bary: bary.chunks_exact(3).map(|b| [b[0], b[1], b[2]]).collect(),
        depth,
    };
    (frags, dense.kernel)
}

/// Pixels whose face differs, and the largest barycentric and depth differences elsewhere.
pub(crate) fn compare(reference: &Fragments, other: &Fragments) -> (usize, f32, f32) {
    let mut faces = 0;
    let (mut bary, mut depth) = (0.0f32, 0.0f32);
    for p in 0..reference.face.len() {
        if reference.face[p] != other.face[p] {
            faces += 1;
            continue;
        }
        for k in 0..3 {
            bary = bary.max((reference.bary[p][k] - other.bary[p][k]).abs());
        }
        let (a, b) = (reference.depth[p], other.depth[p]);
        if a != b {
            depth = depth.max((a - b).abs());
        }
    }
    (faces, bary, depth)
}

#[test]
fn dense_op_matches_the_cpu_core_on_every_device() {
    let devices = bitt_testkit::devices()
        .into_iter()
        .chain(bitt_testkit::autodiff_devices());
    for (device_name, device) in devices {
        for (name, clip, faces, w, h) in scenes() {
            let reference = rasterize(&clip, &faces, w, h).unwrap();
            let (dense, kernel) = dense_host(&clip, &faces, w, h, &device);
            let expected = if device_name == "wgpu" {
                RasterKernel::Cube
            } else {
                RasterKernel::Host
            };
            assert_eq!(kernel, expected, "{device_name} {name}");
            let (face_diff, bary_diff, depth_diff) = compare(&reference, &dense);
            assert_eq!(face_diff, 0, "{device_name} {name}: face ids differ");
            assert!(bary_diff <= 1e-5, "{device_name} {name}: bary {bary_diff}");
            assert!(
                depth_diff <= 1e-6,
                "{device_name} {name}: depth {depth_diff}"
            );
            // Empty pixels: -1, zero barycentrics, +inf depth.
            for p in 0..dense.face.len() {
                if dense.face[p] < 0 {
                    assert_eq!(dense.bary[p], [0.0; 3], "{device_name} {name}");
                    assert_eq!(dense.depth[p], f32::INFINITY, "{device_name} {name}");
                }
            }
        }
    }
}

#[test]
fn dense_op_rejects_bad_shapes_and_sizes() {
    let device = Device::flex();
    let topology = Topology::new(vec![[0, 1, 2]], 3).unwrap();
    let clip = Tensor::<2>::zeros([4, 4], &device);
    assert!(matches!(
        rasterize_dense(clip, &topology, 8, 8),
        Err(crate::RenderError::TensorShape { .. })
    ));
    let clip = Tensor::<2>::zeros([3, 3], &device);
    assert!(rasterize_dense(clip, &topology, 8, 8).is_err());
    let clip = Tensor::<2>::ones([3, 4], &device);
    assert!(matches!(
        rasterize_dense(clip, &topology, 0, 8),
        Err(crate::RenderError::ZeroSizeImage { .. })
    ));
}
