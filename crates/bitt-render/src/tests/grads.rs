//! Analytic gradients vs central finite differences.

use super::{Camera, Rng};
use crate::cpu::{Fragments, interpolate, interpolate_backward, rasterize, rasterize_backward};

const W: usize = 24;
const H: usize = 20;

/// Loss `sum_p g_p . bary_p + gd_p depth_p` over the pixels in `mask` (which must stay
/// covered by the same face).
fn loss(frags: &Fragments, mask: &[usize], g: &[[f32; 3]], gd: &[f32]) -> f64 {
    mask.iter()
        .map(|&p| {
            let b = frags.bary[p];
            (0..3)
                .map(|k| f64::from(g[p][k]) * f64::from(b[k]))
                .sum::<f64>()
                + f64::from(gd[p]) * f64::from(frags.depth[p])
        })
        .sum()
}

fn check_rasterize_backward(tri: [[f64; 3]; 3], rng: &mut Rng, with_depth: bool) {
    let cam = Camera {
        focal: 1.5,
        near: 1.0,
        far: 20.0,
    };
    let clip: Vec<[f32; 4]> = tri.iter().map(|&p| cam.project(p)).collect();
    let faces = [[0u32, 1, 2]];
    let frags = rasterize(&clip, &faces, W, H).unwrap();
    // Interior pixels only: the analytic gradient has no coverage (silhouette) terms.
    let mask: Vec<usize> = (0..W * H)
        .filter(|&p| frags.face[p] == 0 && frags.bary[p].iter().all(|&b| b > 0.05))
        .collect();
    assert!(mask.len() >= 3, "triangle too small: {}", mask.len());
    let mut g = vec![[0.0f32; 3]; W * H];
    let mut gd = vec![0.0f32; W * H];
    for &p in &mask {
        g[p] = std::array::from_fn(|_| rng.uniform(-1.0, 1.0) as f32);
        if with_depth {
            gd[p] = rng.uniform(-1.0, 1.0) as f32;
        }
    }
    let grad =
        rasterize_backward(&clip, &faces, &frags, &g, with_depth.then_some(&gd[..])).unwrap();
    let norm: f64 = grad.iter().flatten().map(|x| f64::from(x.abs())).sum();
    assert!(norm > 0.1, "gradient suspiciously small: {grad:?}");
    let h = 1e-3f32;
    for v in 0..3 {
        for a in 0..4 {
            let eval = |delta: f32| {
                let mut c = clip.clone();
                c[v][a] += delta;
                let fr = rasterize(&c, &faces, W, H).unwrap();
                assert!(mask.iter().all(|&p| fr.face[p] == 0));
                loss(&fr, &mask, &g, &gd)
            };
            let fd = (eval(h) - eval(-h)) / (2.0 * f64::from(h));
            let an = f64::from(grad[v][a]);
            assert!(
                (fd - an).abs() <= 2e-2 + 1e-2 * fd.abs(),
                "vertex {v} coord {a}: analytic {an} vs fd {fd} (tri {tri:?})"
            );
            if a == 2 && !with_depth {
                assert_eq!(an, 0.0, "barycentrics do not depend on z");
            }
        }
    }
}

#[test]
fn rasterize_backward_matches_finite_differences_on_random_triangles() {
    let mut rng = Rng::new(3);
    let mut done = 0;
    while done < 12 {
        let centre = [
            rng.uniform(-0.8, 0.8),
            rng.uniform(-0.8, 0.8),
            rng.uniform(2.5, 5.0),
        ];
        let tri: [[f64; 3]; 3] = std::array::from_fn(|_| {
            [
                centre[0] + rng.uniform(-1.0, 1.0),
                centre[1] + rng.uniform(-1.0, 1.0),
                centre[2] + rng.uniform(-1.5, 1.5),
            ]
        });
        let cam = Camera {
            focal: 1.5,
            near: 1.0,
            far: 20.0,
        };
        let clip: Vec<_> = tri.iter().map(|&p| cam.project(p)).collect();
        let frags = rasterize(&clip, &[[0, 1, 2]], W, H).unwrap();
        let interior =
            (0..W * H).filter(|&p| frags.face[p] == 0 && frags.bary[p].iter().all(|&b| b > 0.05));
        if interior.count() < 8 {
            continue; // too thin or off-screen: draw another
        }
        check_rasterize_backward(tri, &mut rng, done % 2 == 1);
        done += 1;
    }
}

#[test]
fn rasterize_backward_handles_near_clipped_faces() {
    let mut rng = Rng::new(5);
    // Vertex 1 lies between the eye and the near plane (Z = 1).
    check_rasterize_backward(
        [[-1.5, -1.0, 4.0], [1.0, 0.2, 0.6], [0.2, 1.8, 3.0]],
        &mut rng,
        true,
    );
    check_rasterize_backward(
        [[-1.5, -1.0, 4.0], [1.0, 0.2, 0.6], [0.2, 1.8, 3.0]],
        &mut rng,
        false,
    );
}

#[test]
fn interpolate_matches_hand_value_and_backward_matches_finite_differences() {
    let cam = Camera {
        focal: 1.5,
        near: 1.0,
        far: 20.0,
    };
    let world = [
        [-1.0, -1.0, 3.0],
        [1.2, -0.8, 4.0],
        [0.9, 1.1, 3.5],
        [-1.1, 1.0, 2.5],
    ];
    let clip: Vec<_> = world.iter().map(|&p| cam.project(p)).collect();
    let faces = [[0u32, 1, 2], [0, 2, 3]];
    let frags = rasterize(&clip, &faces, W, H).unwrap();
    let a = 3;
    let mut rng = Rng::new(9);
    let attrs: Vec<f32> = (0..4 * a).map(|_| rng.uniform(-2.0, 2.0) as f32).collect();
    let out = interpolate(&attrs, a, &faces, &frags).unwrap();
    // Hand value at one covered pixel, and zeros at an empty one.
    let p = (0..W * H).find(|&p| frags.face[p] == 1).unwrap();
    let f = faces[1];
    for c in 0..a {
        let want: f32 = (0..3)
            .map(|k| frags.bary[p][k] * attrs[f[k] as usize * a + c])
            .sum();
        assert!((out[p * a + c] - want).abs() < 1e-6);
    }
    let empty = (0..W * H).find(|&p| frags.face[p] < 0).unwrap();
    assert_eq!(&out[empty * a..(empty + 1) * a], &[0.0; 3]);

    let go: Vec<f32> = (0..W * H * a)
        .map(|_| rng.uniform(-1.0, 1.0) as f32)
        .collect();
    let (ga, gb) = interpolate_backward(&attrs, a, &faces, &frags, &go).unwrap();
    let loss = |attrs: &[f32], frags: &Fragments| -> f64 {
        let out = interpolate(attrs, a, &faces, frags).unwrap();
        out.iter()
            .zip(&go)
            .map(|(o, g)| f64::from(*o) * f64::from(*g))
            .sum()
    };
    let h = 1e-2f32;
    for i in 0..attrs.len() {
        let (mut up, mut dn) = (attrs.clone(), attrs.clone());
        up[i] += h;
        dn[i] -= h;
        let fd = (loss(&up, &frags) - loss(&dn, &frags)) / (2.0 * f64::from(h));
        assert!(
            (fd - f64::from(ga[i])).abs() < 1e-3 * (1.0 + fd.abs()),
            "attr {i}: {fd} vs {}",
            ga[i]
        );
    }
    for p in (0..W * H).step_by(7) {
        for k in 0..3 {
            let (mut up, mut dn) = (frags.clone(), frags.clone());
            up.bary[p][k] += h;
            dn.bary[p][k] -= h;
            let fd = (loss(&attrs, &up) - loss(&attrs, &dn)) / (2.0 * f64::from(h));
            assert!(
                (fd - f64::from(gb[p][k])).abs() < 1e-3 * (1.0 + fd.abs()),
                "bary {p},{k}"
            );
        }
        if frags.face[p] < 0 {
            assert_eq!(gb[p], [0.0; 3]);
        }
    }
}
