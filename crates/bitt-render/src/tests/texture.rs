//! Bilinear texture sampling (`grid_sample`, bilinear, border padding, `align_corners=True`,
//! `v = 0` at the bottom row) and its backward pass.

use super::Rng;
use crate::RenderError;
use crate::cpu::{coverage_mask, interpolate, rasterize, texture, texture_backward};

/// `[C, Ht, Wt]` image with random values in `[0, 1)`.
fn random_image(rng: &mut Rng, c: usize, h: usize, w: usize) -> Vec<f32> {
    (0..c * h * w)
        .map(|_| rng.uniform(0.0, 1.0) as f32)
        .collect()
}

/// Distinct, exactly representable texel values: `100 c + 10 row + col`.
fn labelled_image(c: usize, h: usize, w: usize) -> Vec<f32> {
    let mut img = Vec::with_capacity(c * h * w);
    for ch in 0..c {
        for r in 0..h {
            for col in 0..w {
                img.push((100 * ch + 10 * r + col) as f32);
            }
        }
    }
    img
}

/// Independent port of PyTorch's CPU `grid_sampler_2d` (bilinear, `padding_mode='border'`,
/// `align_corners=True`) for one channel at grid point `(x, y)` in normalized coordinates
/// (`y = -1` is the top row). Returns the value and `(d/dx, d/dy)` of `sum g * value`.
fn grid_sample_ref(img: &[f32], h: usize, w: usize, x: f64, y: f64, g: f64) -> (f64, [f64; 2]) {
    // Unnormalize (align_corners=True), then clip with the gradient rule of
    // `clip_coordinates_set_grad` (borders count as clamped).
    let unnorm = |t: f64, size: usize| (t + 1.0) / 2.0 * (size as f64 - 1.0);
    let clip = |t: f64, size: usize| {
        let max = size as f64 - 1.0;
        if t <= 0.0 {
            (0.0, 0.0)
        } else if t >= max {
            (max, 0.0)
        } else {
            (t, 1.0)
        }
    };
    let (ix, gix_mult) = clip(unnorm(x, w), w);
    let (iy, giy_mult) = clip(unnorm(y, h), h);
    let ix_nw = ix.floor();
    let iy_nw = iy.floor();
    let (ix_ne, iy_ne) = (ix_nw + 1.0, iy_nw);
    let (ix_sw, iy_sw) = (ix_nw, iy_nw + 1.0);
    let (ix_se, iy_se) = (ix_nw + 1.0, iy_nw + 1.0);
    let nw = (ix_se - ix) * (iy_se - iy);
    let ne = (ix - ix_sw) * (iy_sw - iy);
    let sw = (ix_ne - ix) * (iy - iy_ne);
    let se = (ix - ix_nw) * (iy - iy_nw);
    let val = |xx: f64, yy: f64| {
        if xx >= 0.0 && yy >= 0.0 && xx < w as f64 && yy < h as f64 {
            f64::from(img[yy as usize * w + xx as usize])
        } else {
            0.0
        }
    };
    let (v_nw, v_ne) = (val(ix_nw, iy_nw), val(ix_ne, iy_ne));
    let (v_sw, v_se) = (val(ix_sw, iy_sw), val(ix_se, iy_se));
    let out = v_nw * nw + v_ne * ne + v_sw * sw + v_se * se;
    let mut gix = 0.0;
    let mut giy = 0.0;
    gix -= v_nw * (iy_se - iy) * g;
    giy -= v_nw * (ix_se - ix) * g;
    gix += v_ne * (iy_sw - iy) * g;
    giy -= v_ne * (ix - ix_sw) * g;
    gix -= v_sw * (iy - iy_ne) * g;
    giy += v_sw * (ix_ne - ix) * g;
    gix += v_se * (iy - iy_nw) * g;
    giy += v_se * (ix - ix_nw) * g;
    // d(ix)/dx = (W - 1) / 2 with align_corners=True.
    let gx = gix * gix_mult * (w as f64 - 1.0) / 2.0;
    let gy = giy * giy_mult * (h as f64 - 1.0) / 2.0;
    (out, [gx, gy])
}

#[test]
fn texel_centres_are_exact() {
    let (c, h, w) = (2, 3, 5);
    let img = labelled_image(c, h, w);
    let mut uv = Vec::new();
    let mut expected = Vec::new();
    for r in 0..h {
        for col in 0..w {
            uv.push([col as f32 / (w - 1) as f32, 1.0 - r as f32 / (h - 1) as f32]);
            for ch in 0..c {
                expected.push(img[(ch * h + r) * w + col]);
            }
        }
    }
    assert_eq!(texture(&img, c, h, w, &uv, None).unwrap(), expected);

    // Corners: (0, 0) is the bottom-left texel, (1, 1) the top-right one.
    let out = texture(
        &img,
        c,
        h,
        w,
        &[[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]],
        None,
    )
    .unwrap();
    assert_eq!(out, vec![20.0, 120.0, 4.0, 104.0, 0.0, 100.0, 24.0, 124.0]);

    // Non-power-of-two sizes: exact up to the f32 rounding of u and v.
    let (h, w) = (7, 6);
    let img = labelled_image(1, h, w);
    for r in 0..h {
        for col in 0..w {
            let uv = [col as f32 / (w - 1) as f32, 1.0 - r as f32 / (h - 1) as f32];
            let out = texture(&img, 1, h, w, &[uv], None).unwrap()[0];
            let want = img[r * w + col];
            assert!((out - want).abs() < 1e-4, "({col}, {r}): {out} vs {want}");
        }
    }
}

#[test]
fn midpoints_average_neighbours() {
    let (h, w) = (3, 5);
    let img = labelled_image(1, h, w);
    let at = |r: usize, col: usize| img[r * w + col];
    for r in 0..h - 1 {
        for col in 0..w - 1 {
            // Between columns col and col + 1 on row r.
            let u = (col as f32 + 0.5) / (w - 1) as f32;
            let v_row = 1.0 - r as f32 / (h - 1) as f32;
            let v_mid = 1.0 - (r as f32 + 0.5) / (h - 1) as f32;
            let out = texture(&img, 1, h, w, &[[u, v_row], [u, v_mid]], None).unwrap();
            assert_eq!(out[0], 0.5 * (at(r, col) + at(r, col + 1)));
            let four = 0.25 * (at(r, col) + at(r, col + 1) + at(r + 1, col) + at(r + 1, col + 1));
            assert_eq!(out[1], four);
        }
    }
}

#[test]
fn hand_computed_bilinear() {
    // Image rows (top first): [1, 2], [3, 4]. uv (0.25, 0.25): col 0.25, row 0.75.
    // top = 1 + 0.25 (2 - 1) = 1.25, bottom = 3 + 0.25 (4 - 3) = 3.25,
    // value = 1.25 + 0.75 (3.25 - 1.25) = 2.75.
    let img = [1.0, 2.0, 3.0, 4.0];
    let out = texture(&img, 1, 2, 2, &[[0.25, 0.25]], None).unwrap();
    assert_eq!(out, vec![2.75]);
    // d/du = d/dcol = (1 - 0.75) (2 - 1) + 0.75 (4 - 3) = 1;
    // d/dv = -d/drow = -((1 - 0.25) (3 - 1) + 0.25 (4 - 2)) = -2.
    let (gi, guv) = texture_backward(&img, 1, 2, 2, &[[0.25, 0.25]], None, &[1.0]).unwrap();
    assert_eq!(guv, vec![[1.0, -2.0]]);
    // Weights: (1 - 0.75)(1 - 0.25), (1 - 0.75) 0.25, 0.75 (1 - 0.25), 0.75 * 0.25.
    assert_eq!(gi, vec![0.1875, 0.0625, 0.5625, 0.1875]);
}

#[test]
fn border_padding_clamps() {
    let mut rng = Rng::new(3);
    let (c, h, w) = (3, 4, 6);
    let img = random_image(&mut rng, c, h, w);
    let g: Vec<f32> = (0..c).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    let pairs = [
        ([-0.3, 0.37], [0.0, 0.37]),
        ([1.4, 0.61], [1.0, 0.61]),
        ([0.29, 1.7], [0.29, 1.0]),
        ([0.71, -0.2], [0.71, 0.0]),
        ([-5.0, 9.0], [0.0, 1.0]),
    ];
    for (outside, inside) in pairs {
        let a = texture(&img, c, h, w, &[outside], None).unwrap();
        let b = texture(&img, c, h, w, &[inside], None).unwrap();
        assert_eq!(a, b, "{outside:?} vs {inside:?}");
        let (gi_a, guv_a) = texture_backward(&img, c, h, w, &[outside], None, &g).unwrap();
        let (gi_b, _) = texture_backward(&img, c, h, w, &[inside], None, &g).unwrap();
        assert_eq!(gi_a, gi_b);
        for k in 0..2 {
            let clamped = !(0.0..=1.0).contains(&outside[k]);
            if clamped {
                assert_eq!(guv_a[0][k], 0.0, "{outside:?} component {k}");
            } else {
                assert!(guv_a[0][k].abs() > 1e-6, "{outside:?} component {k}");
            }
        }
    }
    // Exactly on the border the gradient is zero too (PyTorch's rule).
    let (_, guv) = texture_backward(
        &img,
        c,
        h,
        w,
        &[[0.0, 1.0], [1.0, 0.0]],
        None,
        &[g.clone(), g].concat(),
    )
    .unwrap();
    assert_eq!(guv, vec![[0.0, 0.0], [0.0, 0.0]]);
}

#[test]
fn matches_independent_grid_sample() {
    let mut rng = Rng::new(11);
    for &(c, h, w) in &[(3, 4, 6), (1, 1, 5), (2, 7, 1), (1, 1, 1), (4, 9, 13)] {
        let img = random_image(&mut rng, c, h, w);
        let p = 200;
        let uv: Vec<[f32; 2]> = (0..p)
            .map(|_| [rng.uniform(-0.3, 1.3) as f32, rng.uniform(-0.3, 1.3) as f32])
            .collect();
        let g: Vec<f32> = (0..p * c).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let out = texture(&img, c, h, w, &uv, None).unwrap();
        let (gi, guv) = texture_backward(&img, c, h, w, &uv, None, &g).unwrap();
        for (pi, t) in uv.iter().enumerate() {
            let (x, y) = (2.0 * f64::from(t[0]) - 1.0, 1.0 - 2.0 * f64::from(t[1]));
            let mut grad = [0.0f64; 2];
            for ch in 0..c {
                let plane = &img[ch * h * w..(ch + 1) * h * w];
                let gc = f64::from(g[pi * c + ch]);
                let (val, [gx, gy]) = grid_sample_ref(plane, h, w, x, y, gc);
                let got = f64::from(out[pi * c + ch]);
                assert!(
                    (got - val).abs() < 1e-6,
                    "{c}x{h}x{w} p{pi} c{ch}: {got} vs {val}"
                );
                grad[0] += gx;
                grad[1] += gy;
            }
            // Chain rule: x = 2u - 1, y = 1 - 2v.
            let want = [2.0 * grad[0], -2.0 * grad[1]];
            for k in 0..2 {
                let got = f64::from(guv[pi][k]);
                assert!(
                    (got - want[k]).abs() < 1e-4 * (1.0 + want[k].abs()),
                    "{c}x{h}x{w} p{pi} uv{k}: {got} vs {}",
                    want[k]
                );
            }
        }
        assert_eq!(gi.len(), img.len());
    }
}

/// `sum g * texture(image, uv)` in `f64` from the `f32` forward.
fn loss(img: &[f32], c: usize, h: usize, w: usize, uv: &[[f32; 2]], g: &[f32]) -> f64 {
    let out = texture(img, c, h, w, uv, None).unwrap();
    out.iter()
        .zip(g)
        .map(|(&o, &gg)| f64::from(o) * f64::from(gg))
        .sum()
}

#[test]
fn backward_matches_finite_differences() {
    let mut rng = Rng::new(5);
    let (c, h, w) = (2, 5, 4);
    let img = random_image(&mut rng, c, h, w);
    // Texel positions kept away from texel boundaries (derivative kinks) and the border.
    let p = 30;
    let uv: Vec<[f32; 2]> = (0..p)
        .map(|_| {
            let col = rng.uniform(0.0, (w - 1) as f64).floor() + rng.uniform(0.1, 0.9);
            let row = rng.uniform(0.0, (h - 1) as f64).floor() + rng.uniform(0.1, 0.9);
            [
                (col / (w - 1) as f64) as f32,
                (1.0 - row / (h - 1) as f64) as f32,
            ]
        })
        .collect();
    let g: Vec<f32> = (0..p * c).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    let (gi, guv) = texture_backward(&img, c, h, w, &uv, None, &g).unwrap();

    // uv: the loss is smooth within a texel cell.
    let eps = 1e-3f32;
    for pi in 0..p {
        for k in 0..2 {
            let mut plus = uv.clone();
            let mut minus = uv.clone();
            plus[pi][k] += eps;
            minus[pi][k] -= eps;
            let step = f64::from(plus[pi][k]) - f64::from(minus[pi][k]);
            let fd = (loss(&img, c, h, w, &plus, &g) - loss(&img, c, h, w, &minus, &g)) / step;
            let got = f64::from(guv[pi][k]);
            assert!(
                (got - fd).abs() < 2e-3 * (1.0 + fd.abs()),
                "uv[{pi}][{k}]: {got} vs fd {fd}"
            );
        }
    }
    // image: the output is linear in the image.
    for i in 0..img.len() {
        let mut plus = img.clone();
        let mut minus = img.clone();
        plus[i] += 0.5;
        minus[i] -= 0.5;
        let fd = loss(&plus, c, h, w, &uv, &g) - loss(&minus, c, h, w, &uv, &g);
        let got = f64::from(gi[i]);
        assert!((got - fd).abs() < 1e-4, "image[{i}]: {got} vs fd {fd}");
    }
    assert!(gi.iter().any(|&x| x != 0.0));
}

#[test]
fn masked_pixels_get_zero_output_and_gradient() {
    let mut rng = Rng::new(9);
    let (c, h, w) = (3, 4, 4);
    let img = random_image(&mut rng, c, h, w);
    let mut uv: Vec<[f32; 2]> = (0..6)
        .map(|_| {
            [
                rng.uniform(0.05, 0.95) as f32,
                rng.uniform(0.05, 0.95) as f32,
            ]
        })
        .collect();
    uv[4] = [f32::NAN, f32::INFINITY]; // ignored: masked out
    let mask = [true, false, true, false, false, true];
    let g: Vec<f32> = (0..6 * c).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    let out = texture(&img, c, h, w, &uv, Some(&mask)).unwrap();
    let (gi, guv) = texture_backward(&img, c, h, w, &uv, Some(&mask), &g).unwrap();

    // Only unmasked pixels, sampled without a mask, give the same output and gradients.
    let keep: Vec<usize> = (0..6).filter(|&p| mask[p]).collect();
    let uv_kept: Vec<[f32; 2]> = keep.iter().map(|&p| uv[p]).collect();
    let g_kept: Vec<f32> = keep
        .iter()
        .flat_map(|&p| g[p * c..(p + 1) * c].to_vec())
        .collect();
    let out_kept = texture(&img, c, h, w, &uv_kept, None).unwrap();
    let (gi_kept, guv_kept) = texture_backward(&img, c, h, w, &uv_kept, None, &g_kept).unwrap();
    for p in 0..6 {
        if mask[p] {
            let k = keep.iter().position(|&q| q == p).unwrap();
            assert_eq!(&out[p * c..(p + 1) * c], &out_kept[k * c..(k + 1) * c]);
            assert_eq!(guv[p], guv_kept[k]);
            assert!(out[p * c..(p + 1) * c].iter().all(|&x| x != 0.0));
        } else {
            assert!(out[p * c..(p + 1) * c].iter().all(|&x| x == 0.0));
            assert_eq!(guv[p], [0.0, 0.0]);
        }
    }
    for (a, b) in gi.iter().zip(&gi_kept) {
        assert!((a - b).abs() < 1e-6);
    }
}

#[test]
fn composes_with_rasterize_and_interpolate() {
    // One triangle with uvs; the covered pixels sample the texture, the rest stay zero.
    let clip = [
        [-0.8, -0.8, 0.0, 1.0],
        [0.8, -0.8, 0.0, 1.0],
        [0.0, 0.8, 0.0, 1.0],
    ];
    let faces = [[0u32, 1, 2]];
    let (iw, ih) = (8, 8);
    let frags = rasterize(&clip, &faces, iw, ih).unwrap();
    let uv_attr = [0.0, 0.0, 1.0, 0.0, 0.5, 1.0];
    let uv_flat = interpolate(&uv_attr, 2, &faces, &frags).unwrap();
    let uv: Vec<[f32; 2]> = uv_flat.chunks_exact(2).map(|t| [t[0], t[1]]).collect();
    let mask = coverage_mask(&frags);
    assert!(mask.iter().any(|&m| m) && mask.iter().any(|&m| !m));
    // Texture value = 1 + column index, so the output is 1 + u (Wt - 1) inside.
    let (th, tw) = (3, 5);
    let img: Vec<f32> = (0..th * tw).map(|i| (1 + i % tw) as f32).collect();
    let out = texture(&img, 1, th, tw, &uv, Some(&mask)).unwrap();
    for p in 0..iw * ih {
        if mask[p] {
            let want = 1.0 + uv[p][0].clamp(0.0, 1.0) * (tw - 1) as f32;
            assert!(
                (out[p] - want).abs() < 1e-5,
                "pixel {p}: {} vs {want}",
                out[p]
            );
        } else {
            assert_eq!(out[p], 0.0);
        }
    }
}

#[test]
fn one_texel_axes() {
    // A 1 x W texture is constant along v; a H x 1 one along u, with zero gradients there.
    let img = [1.0, 3.0];
    let out = texture(&img, 1, 1, 2, &[[0.5, 0.1], [0.5, 0.9]], None).unwrap();
    assert_eq!(out, vec![2.0, 2.0]);
    let (gi, guv) = texture_backward(&img, 1, 1, 2, &[[0.5, 0.1]], None, &[1.0]).unwrap();
    assert_eq!(guv, vec![[2.0, 0.0]]);
    assert_eq!(gi, vec![0.5, 0.5]);
    let (gi, guv) = texture_backward(&img, 1, 2, 1, &[[0.3, 0.25]], None, &[1.0]).unwrap();
    // Column texture rows (top first) [1, 3]; v = 0.25 -> row 0.75 -> 2.5; d/dv = -(3 - 1).
    assert_eq!(guv, vec![[0.0, -2.0]]);
    assert_eq!(gi, vec![0.25, 0.75]);
}

#[test]
fn bad_input_is_rejected() {
    let img = vec![0.5f32; 2 * 3 * 4];
    let uv = [[0.5f32, 0.5]; 3];
    assert_eq!(
        texture(&img, 2, 3, 4, &uv, None).unwrap().len(),
        6,
        "valid input"
    );
    assert_eq!(
        texture(&img[1..], 2, 3, 4, &uv, None).unwrap_err(),
        RenderError::BufferLength {
            what: "image",
            expected: 24,
            actual: 23
        }
    );
    assert_eq!(
        texture(&[], 2, 0, 4, &uv, None).unwrap_err(),
        RenderError::ZeroSizeImage {
            width: 4,
            height: 0
        }
    );
    assert_eq!(
        texture(&[], 0, 3, 4, &uv, None).unwrap_err(),
        RenderError::ZeroChannels
    );
    assert_eq!(
        texture(&img, 2, 3, 4, &uv, Some(&[true, false])).unwrap_err(),
        RenderError::BufferLength {
            what: "mask",
            expected: 3,
            actual: 2
        }
    );
    let mut bad = uv;
    bad[1][1] = f32::NAN;
    let err = texture(&img, 2, 3, 4, &bad, None).unwrap_err();
    assert!(
        matches!(err, RenderError::NonFiniteUv { pixel: 1, value } if value[0] == 0.5 && value[1].is_nan()),
        "{err}"
    );
    assert!(err.to_string().contains("uv of pixel 1"), "{err}");
    bad[1] = [f32::NEG_INFINITY, 0.5];
    assert!(matches!(
        texture_backward(&img, 2, 3, 4, &bad, None, &[0.0; 6]).unwrap_err(),
        RenderError::NonFiniteUv { pixel: 1, .. }
    ));
    assert_eq!(
        texture_backward(&img, 2, 3, 4, &uv, None, &[0.0; 5]).unwrap_err(),
        RenderError::BufferLength {
            what: "grad_out",
            expected: 6,
            actual: 5
        }
    );
}
