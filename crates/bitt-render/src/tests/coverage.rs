//! Shared edges: every pixel of a tiled region is drawn exactly once.

use super::{Rng, coverage, screen_clip};
use crate::cpu::rasterize;

const W: usize = 20;
const H: usize = 18;

/// Checks coverage of a convex screen polygon (given counter-clockwise or clockwise) tiled by
/// `faces` over `pts`: centres strictly inside covered once, none covered twice, none outside.
fn check_tiling(pts: &[(f64, f64)], faces: &[[u32; 3]], outline: &[(f64, f64)]) {
    let clip: Vec<_> = pts
        .iter()
        .map(|&(x, y)| screen_clip(x, y, 0.3, 1.0, W, H))
        .collect();
    let count = coverage(&clip, faces, W, H);
    // Signed distance-like test against the convex outline (orientation-independent).
    let n = outline.len();
    let sides = |px: f64, py: f64| -> Vec<f64> {
        (0..n)
            .map(|i| {
                let (a, b) = (outline[i], outline[(i + 1) % n]);
                let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
                ((b.0 - a.0) * (py - a.1) - (b.1 - a.1) * (px - a.0)) / len
            })
            .collect()
    };
    let orient = if sides(centroid(outline).0, centroid(outline).1)[0] > 0.0 {
        1.0
    } else {
        -1.0
    };
    let mut inside_total = 0;
    for row in 0..H {
        for col in 0..W {
            let c = count[row * W + col];
            assert!(c <= 1, "pixel ({col},{row}) drawn {c} times");
            let s = sides(col as f64 + 0.5, row as f64 + 0.5);
            if s.iter().all(|&d| d * orient > 1e-3) {
                assert_eq!(c, 1, "interior pixel ({col},{row}) dropped");
                inside_total += 1;
            } else if s.iter().any(|&d| d * orient < -1e-3) {
                assert_eq!(c, 0, "outside pixel ({col},{row}) drawn");
            }
        }
    }
    assert!(inside_total > 10);
    // The full rasterizer (same depth everywhere) draws the same pixel set.
    let frags = rasterize(&clip, faces, W, H).unwrap();
    for (p, &c) in count.iter().enumerate() {
        assert_eq!(frags.face[p] >= 0, c == 1);
    }
}

fn centroid(pts: &[(f64, f64)]) -> (f64, f64) {
    let n = pts.len() as f64;
    (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    )
}

#[test]
fn axis_aligned_shared_edges_through_pixel_centres() {
    // Two rectangles sharing the vertical edge x = 6.5 (through pixel centres), each split by
    // a diagonal of slope 2 that passes through centres; outer border also through centres.
    let pts = [
        (2.5, 1.5),
        (6.5, 1.5),
        (10.5, 1.5),
        (2.5, 9.5),
        (6.5, 9.5),
        (10.5, 9.5),
    ];
    let faces = [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]];
    check_tiling(&pts, &faces, &[pts[0], pts[2], pts[5], pts[3]]);
    // Same with a horizontal shared edge y = 5.5 and mixed windings.
    let pts = [
        (1.5, 1.5),
        (9.5, 1.5),
        (1.5, 5.5),
        (9.5, 5.5),
        (1.5, 9.5),
        (9.5, 9.5),
    ];
    let faces = [[0, 1, 3], [0, 2, 3], [2, 3, 5], [2, 4, 5]];
    check_tiling(&pts, &faces, &[pts[0], pts[1], pts[5], pts[4]]);
}

#[test]
fn diagonal_shared_edges_both_ways() {
    // Square with corners at pixel centres; both diagonals pass through centres.
    let pts = [(2.5, 2.5), (12.5, 2.5), (12.5, 12.5), (2.5, 12.5)];
    let outline = pts;
    check_tiling(&pts, &[[0, 1, 2], [0, 2, 3]], &outline);
    check_tiling(&pts, &[[1, 2, 3], [3, 0, 1]], &outline);
    // Four triangles meeting at the centre pixel centre (7.5, 7.5).
    let mut with_centre = pts.to_vec();
    with_centre.push((7.5, 7.5));
    check_tiling(
        &with_centre,
        &[[0, 1, 4], [4, 2, 1], [2, 3, 4], [4, 3, 0]],
        &outline,
    );
}

#[test]
fn random_quads_split_along_a_diagonal() {
    let mut rng = Rng::new(7);
    let mut done = 0;
    while done < 50 {
        // A random convex quad: four angles around a centre, random radii.
        let (cx, cy) = (rng.uniform(7.0, 13.0), rng.uniform(7.0, 11.0));
        let mut angles: Vec<f64> = (0..4)
            .map(|_| rng.uniform(0.0, std::f64::consts::TAU))
            .collect();
        angles.sort_by(f64::total_cmp);
        let pts: Vec<_> = angles
            .iter()
            .map(|a| (cx + 6.0 * a.cos(), cy + 6.0 * a.sin()))
            .collect();
        let convex = (0..4).all(|i| {
            let (a, b, c) = (pts[i], pts[(i + 1) % 4], pts[(i + 2) % 4]);
            (b.0 - a.0) * (c.1 - b.1) - (b.1 - a.1) * (c.0 - b.0) > 1.0
        });
        let area: f64 = (0..4)
            .map(|i| {
                let (a, b) = (pts[i], pts[(i + 1) % 4]);
                a.0 * b.1 - b.0 * a.1
            })
            .sum::<f64>()
            / 2.0;
        if !convex || area.abs() < 30.0 {
            continue; // a sliver: draw another
        }
        check_tiling(&pts, &[[0, 1, 2], [0, 2, 3]], &pts);
        check_tiling(&pts, &[[1, 2, 3], [1, 0, 3]], &pts);
        done += 1;
    }
}

#[test]
fn fan_around_a_pixel_centre_covers_each_pixel_once() {
    let mut rng = Rng::new(11);
    for _ in 0..20 {
        // Boundary of the square [3.5, 15.5]^2 (edges through centres): corners, edge
        // midpoints (fan edges from the centre along axes and diagonals through centres),
        // plus random points on the boundary.
        let (c, r) = (9.5, 6.0);
        let mut ring: Vec<(f64, f64)> = vec![
            (c - r, c - r),
            (c, c - r),
            (c + r, c - r),
            (c + r, c),
            (c + r, c + r),
            (c, c + r),
            (c - r, c + r),
            (c - r, c),
        ];
        for _ in 0..8 {
            let t = rng.uniform(-r, r);
            ring.push(match rng.uniform(0.0, 4.0) as u32 {
                0 => (c + t, c - r),
                1 => (c + r, c + t),
                2 => (c + t, c + r),
                _ => (c - r, c + t),
            });
        }
        ring.sort_by(|a, b| {
            (a.1 - c)
                .atan2(a.0 - c)
                .total_cmp(&(b.1 - c).atan2(b.0 - c))
        });
        ring.dedup();
        let mut pts = vec![(c, c)];
        pts.extend(&ring);
        let n = ring.len() as u32;
        // Alternate windings to show the fill rule does not depend on them.
        let faces: Vec<[u32; 3]> = (0..n)
            .map(|i| {
                let (a, b) = (1 + i, 1 + (i + 1) % n);
                if i % 2 == 0 { [0, a, b] } else { [b, a, 0] }
            })
            .collect();
        let outline = [
            (c - r, c - r),
            (c + r, c - r),
            (c + r, c + r),
            (c - r, c + r),
        ];
        check_tiling(&pts, &faces, &outline);
    }
}
