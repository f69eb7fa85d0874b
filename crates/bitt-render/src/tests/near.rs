//! Near-plane clipping: barycentrics of the visible part match a ray–triangle intersection.

use super::{Camera, pixel_ndc};
use crate::cpu::rasterize;

const CAM: Camera = Camera {
    focal: 1.2,
    near: 1.0,
    far: 50.0,
};

/// Checks every pixel of a single-triangle render against the ray–triangle intersection.
/// Returns the number of covered pixels.
fn check_against_rays(tri: [[f64; 3]; 3], width: usize, height: usize) -> usize {
    let clip: Vec<_> = tri.iter().map(|&p| CAM.project(p)).collect();
    let frags = rasterize(&clip, &[[0, 1, 2]], width, height).unwrap();
    let mut covered = 0;
    for p in 0..width * height {
        let (x, y) = pixel_ndc(p, width, height);
        let hit = CAM.ray_bary(&tri, x, y).filter(|&(_, z)| z > 0.0);
        if frags.face[p] == 0 {
            covered += 1;
            let (b, z) = hit.expect("covered pixel must hit the triangle in front of the eye");
            assert!(
                z >= CAM.near * (1.0 - 1e-4),
                "pixel {p} hit at Z = {z} before the near plane"
            );
            for k in 0..3 {
                assert!(b[k] > -1e-4, "pixel {p}: {b:?}");
                assert!(
                    (f64::from(frags.bary[p][k]) - b[k]).abs() < 1e-4,
                    "pixel {p}: {:?} vs {b:?}",
                    frags.bary[p]
                );
            }
        } else if let Some((b, z)) = hit {
            let clearly_inside = b.iter().all(|&v| v > 1e-3) && z > CAM.near * (1.0 + 1e-3);
            assert!(!clearly_inside, "pixel {p} dropped: bary {b:?}, Z {z}");
        }
    }
    covered
}

#[test]
fn triangle_crossing_the_near_plane_keeps_original_barycentrics() {
    // One vertex in front, one between the eye and the near plane, one behind the eye (w < 0):
    // both clip planes are exercised.
    let tri = [[-1.5, -1.0, 4.0], [2.0, -0.5, 0.4], [0.3, 2.5, -2.0]];
    let covered = check_against_rays(tri, 40, 32);
    assert!(covered > 50, "covered {covered}");
    // Two vertices behind the near plane.
    let tri = [[-1.0, -1.0, 0.5], [1.5, -0.2, 6.0], [0.0, 1.5, 0.2]];
    let covered = check_against_rays(tri, 40, 32);
    assert!(covered > 50, "covered {covered}");
    // Unclipped reference in the same harness.
    let tri = [[-1.0, -1.0, 3.0], [1.5, -0.2, 6.0], [0.0, 1.5, 2.0]];
    assert!(check_against_rays(tri, 40, 32) > 50);
}

#[test]
fn triangle_fully_behind_the_near_plane_or_eye_is_empty() {
    for tri in [
        [[-1.0, -1.0, 0.9], [1.0, -1.0, 0.5], [0.0, 1.0, 0.2]],
        [[-1.0, -1.0, -0.9], [1.0, -1.0, -3.0], [0.0, 1.0, -0.2]],
    ] {
        let clip: Vec<_> = tri.iter().map(|&p| CAM.project(p)).collect();
        let frags = rasterize(&clip, &[[0, 1, 2]], 24, 24).unwrap();
        assert!(frags.face.iter().all(|&f| f == -1));
    }
}
