//! Depth test: nearest wins, deterministic ties, cube front faces, far plane.

use super::{Camera, screen_clip};
use crate::cpu::rasterize;

const N: usize = 16;

/// Two overlapping screen triangles at NDC depths `za` and `zb`.
fn overlapping(za: f64, zb: f64) -> Vec<[f32; 4]> {
    let a = [(1.0, 1.0), (14.0, 2.0), (3.0, 15.0)];
    let b = [(15.0, 15.0), (2.0, 13.0), (13.0, 1.0)];
    let mut clip: Vec<_> = a
        .iter()
        .map(|&(x, y)| screen_clip(x, y, za, 1.0, N, N))
        .collect();
    // Vary w on the second one; depth z/w is unaffected.
    clip.extend(
        b.iter()
            .zip([1.0, 2.0, 0.5])
            .map(|(&(x, y), w)| screen_clip(x, y, zb, w, N, N)),
    );
    clip
}

#[test]
fn nearer_triangle_wins_regardless_of_order() {
    for (za, zb) in [(0.2, 0.5), (0.5, 0.2)] {
        let clip = overlapping(za, zb);
        let near_face = if za < zb { 0 } else { 1 };
        for faces in [[[0u32, 1, 2], [3, 4, 5]], [[3, 4, 5], [0, 1, 2]]] {
            let frags = rasterize(&clip, &faces, N, N).unwrap();
            // Pixel (7, 7) is inside both triangles.
            let p = 7 * N + 7;
            let nearest_index = faces.iter().position(|f| f[0] == 3 * near_face).unwrap();
            assert_eq!(
                frags.face[p], nearest_index as i32,
                "za={za} zb={zb} faces={faces:?}"
            );
            assert!((frags.depth[p] - za.min(zb) as f32).abs() < 1e-6);
            let covered_by: Vec<_> = (0..N * N).filter(|&q| frags.face[q] >= 0).collect();
            assert!(
                covered_by
                    .iter()
                    .all(|&q| frags.depth[q] <= za.max(zb) as f32 + 1e-6)
            );
        }
    }
}

#[test]
fn equal_depth_ties_go_to_the_lower_face_index() {
    let clip = overlapping(0.4, 0.4);
    let frags = rasterize(&clip, &[[3, 4, 5], [0, 1, 2]], N, N).unwrap();
    assert_eq!(frags.face[7 * N + 7], 0);
    let frags = rasterize(&clip, &[[0, 1, 2], [3, 4, 5]], N, N).unwrap();
    assert_eq!(frags.face[7 * N + 7], 0);
}

#[test]
fn fragments_beyond_the_far_plane_are_discarded() {
    let clip = overlapping(1.5, 0.5);
    let frags = rasterize(&clip, &[[0, 1, 2]], N, N).unwrap();
    assert!(frags.face.iter().all(|&f| f == -1));
    assert!(frags.depth.iter().all(|&d| d == f32::INFINITY));
}

#[test]
fn cube_shows_only_its_three_front_faces() {
    let cam = Camera {
        focal: 1.5,
        near: 0.5,
        far: 20.0,
    };
    // Unit cube corners, rotated so three faces point toward the camera, centred at Z = 5.
    let (ay, ax) = (0.6f64, -0.5f64);
    let rot = |p: [f64; 3]| {
        let (x, z) = (
            p[0] * ay.cos() + p[2] * ay.sin(),
            -p[0] * ay.sin() + p[2] * ay.cos(),
        );
        let (y, z) = (
            p[1] * ax.cos() - z * ax.sin(),
            p[1] * ax.sin() + z * ax.cos(),
        );
        [x, y, z]
    };
    let corner = |i: u32| {
        let b = |k: u32| if i >> k & 1 == 1 { 1.0 } else { -1.0 };
        [b(0), b(1), b(2)]
    };
    // Sides: -x, +x, -y, +y, -z, +z as corner-index quads; outward normals.
    let sides: [([u32; 4], [f64; 3]); 6] = [
        ([0, 2, 6, 4], [-1.0, 0.0, 0.0]),
        ([1, 3, 7, 5], [1.0, 0.0, 0.0]),
        ([0, 1, 5, 4], [0.0, -1.0, 0.0]),
        ([2, 3, 7, 6], [0.0, 1.0, 0.0]),
        ([0, 1, 3, 2], [0.0, 0.0, -1.0]),
        ([4, 5, 7, 6], [0.0, 0.0, 1.0]),
    ];
    let centre = [0.0, 0.0, 5.0];
    let world: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            let r = rot(corner(i));
            [r[0] + centre[0], r[1] + centre[1], r[2] + centre[2]]
        })
        .collect();
    let clip: Vec<_> = world.iter().map(|&p| cam.project(p)).collect();
    let faces: Vec<[u32; 3]> = sides
        .iter()
        .flat_map(|(q, _)| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    // A side faces the camera when its outward normal points toward the eye.
    let front: Vec<bool> = sides
        .iter()
        .map(|(q, nrm)| {
            let n = rot(*nrm);
            let p = world[q[0] as usize];
            n[0] * p[0] + n[1] * p[1] + n[2] * p[2] < 0.0
        })
        .collect();
    assert_eq!(front.iter().filter(|&&f| f).count(), 3);
    let (w, h) = (48, 40);
    let frags = rasterize(&clip, &faces, w, h).unwrap();
    let mut pixels_per_side = [0usize; 6];
    for &f in frags.face.iter().filter(|&&f| f >= 0) {
        pixels_per_side[f as usize / 2] += 1;
    }
    for side in 0..6 {
        if front[side] {
            assert!(
                pixels_per_side[side] > 20,
                "front side {side}: {pixels_per_side:?}"
            );
        } else {
            assert_eq!(
                pixels_per_side[side], 0,
                "back side {side} visible: {pixels_per_side:?}"
            );
        }
    }
    // Without the front sides, the back sides are what remains visible.
    let back_only: Vec<_> = faces
        .iter()
        .enumerate()
        .filter(|(i, _)| !front[i / 2])
        .map(|(_, f)| *f)
        .collect();
    let frags_back = rasterize(&clip, &back_only, w, h).unwrap();
    let covered = |fr: &crate::Fragments| fr.face.iter().filter(|&&f| f >= 0).count();
    assert_eq!(covered(&frags_back), covered(&frags));
}
