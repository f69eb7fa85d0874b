//! A single triangle: exact coverage, barycentrics, perspective correction.

use super::{Camera, covered_pixels, pixel_ndc, screen_clip};
use crate::cpu::rasterize;

const N: usize = 4;

/// Screen-space triangle (0,0), (4,0), (0,4) in a 4x4 image at constant depth and w.
fn lower(w: [f64; 3]) -> Vec<[f32; 4]> {
    let s = [(0.0, 0.0), (4.0, 0.0), (0.0, 4.0)];
    (0..3)
        .map(|k| screen_clip(s[k].0, s[k].1, 0.5, w[k], N, N))
        .collect()
}

#[test]
fn lower_triangle_covers_exactly_the_hand_computed_pixels() {
    let clip = lower([1.0; 3]);
    // Centres (c + 0.5, r + 0.5) with c + r = 3 lie on the hypotenuse, whose interior is up-left:
    // not a top/left edge, so excluded. Inside: c + r <= 2.
    let want = vec![(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (0, 2)];
    for faces in [[[0u32, 1, 2]], [[0, 2, 1]]] {
        let frags = rasterize(&clip, &faces, N, N).unwrap();
        let mut got = covered_pixels(&frags);
        got.sort_by_key(|&(c, r)| (r, c));
        assert_eq!(got, want, "winding {faces:?}");
        assert!(frags.depth.iter().zip(&frags.face).all(|(&d, &f)| {
            if f < 0 {
                d == f32::INFINITY
            } else {
                (d - 0.5).abs() < 1e-6
            }
        }));
    }
}

#[test]
fn upper_triangle_takes_the_shared_hypotenuse() {
    let s = [(4.0, 4.0), (0.0, 4.0), (4.0, 0.0)];
    let clip: Vec<_> = (0..3)
        .map(|k| screen_clip(s[k].0, s[k].1, 0.0, 1.0, N, N))
        .collect();
    let frags = rasterize(&clip, &[[0, 1, 2]], N, N).unwrap();
    let got = covered_pixels(&frags);
    assert_eq!(got.len(), 10);
    assert!(got.iter().all(|&(c, r)| c + r >= 3), "{got:?}");
}

#[test]
fn barycentrics_at_a_pixel_centre_match_hand_computation() {
    let frags = rasterize(&lower([1.0; 3]), &[[0, 1, 2]], N, N).unwrap();
    // Pixel (0,0), centre (0.5, 0.5): b1 = x/4, b2 = y/4, b0 = 1 - b1 - b2.
    let b = frags.bary[0];
    for (got, want) in b.iter().zip([0.75, 0.125, 0.125]) {
        assert!((got - want).abs() < 1e-6, "{b:?}");
    }
    // Pixel (1,1), centre (1.5, 1.5).
    let b = frags.bary[N + 1];
    for (got, want) in b.iter().zip([0.25, 0.375, 0.375]) {
        assert!((got - want).abs() < 1e-6, "{b:?}");
    }
    assert_eq!(frags.bary[3], [0.0; 3]);
}

#[test]
fn perspective_correct_barycentrics_differ_from_affine_and_match_inverse_projection() {
    let w = [1.0, 2.0, 4.0];
    let frags = rasterize(&lower(w), &[[0, 1, 2]], N, N).unwrap();
    // Affine (screen) barycentrics at pixel (0,0) are (0.75, 0.125, 0.125); dividing by w and
    // renormalising: (0.75, 0.0625, 0.03125) / 0.84375 = (24, 2, 1) / 27.
    let b = frags.bary[0];
    for (got, want) in b.iter().zip([24.0 / 27.0, 2.0 / 27.0, 1.0 / 27.0]) {
        assert!((f64::from(*got) - want).abs() < 1e-6, "{b:?}");
    }
    assert!((b[0] - 0.75).abs() > 0.1);
    // Analytic inverse projection: the camera-space triangle with Z = w and X = ndc_x * w
    // (focal 1) intersected with each pixel's ray gives the same barycentrics everywhere.
    let cam = Camera {
        focal: 1.0,
        near: 0.1,
        far: 10.0,
    };
    let ndc = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0)];
    let tri: [[f64; 3]; 3] = std::array::from_fn(|k| [ndc[k].0 * w[k], ndc[k].1 * w[k], w[k]]);
    let mut checked = 0;
    for p in 0..N * N {
        if frags.face[p] < 0 {
            continue;
        }
        let (x, y) = pixel_ndc(p, N, N);
        let (want, _) = cam.ray_bary(&tri, x, y).unwrap();
        for k in 0..3 {
            assert!(
                (f64::from(frags.bary[p][k]) - want[k]).abs() < 1e-6,
                "pixel {p}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 6);
}
