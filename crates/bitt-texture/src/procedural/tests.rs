//! Tests of the skin generator (its documentation images are the example `docs_images`,
//! `cargo xtask docs-images`).

use std::sync::OnceLock;

use bitt_mesh::{HandModel, Side, default_hand};

use super::anatomy::{HandSkeleton, TexelGeometry};
use super::{SkinIdentity, generate_texture, palm_side_texels};
use crate::layout::TextureLayout;

struct Fixture {
    layout: TextureLayout,
    right: HandModel,
    left: HandModel,
}

/// The procedural hands and their layout at 80 x 80 texels (shared by the tests).
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let right = default_hand(Side::Right);
        let left = default_hand(Side::Left);
        let layout = TextureLayout::from_uv(right.uv.as_ref().unwrap(), 80, 80, 2).unwrap();
        Fixture {
            layout,
            right,
            left,
        }
    })
}

fn texture(id: &SkinIdentity, side: Side) -> Vec<f32> {
    let f = fixture();
    let hand = if side == Side::Left {
        &f.left
    } else {
        &f.right
    };
    generate_texture(&f.layout, hand, id, side).unwrap()
}

/// Rec. 709 luma of each texel of a compact `[3, T]` texture.
fn luma(tex: &[f32]) -> Vec<f64> {
    let t = tex.len() / 3;
    (0..t)
        .map(|i| {
            0.2126 * f64::from(tex[i])
                + 0.7152 * f64::from(tex[t + i])
                + 0.0722 * f64::from(tex[2 * t + i])
        })
        .collect()
}

/// Mean luma of the palm-side charts (left half of the texture) and of the back-side charts.
fn palm_and_back_luma(tex: &[f32]) -> (f64, f64) {
    let f = fixture();
    let l = luma(tex);
    let (mut palm, mut back) = ((0.0, 0usize), (0.0, 0usize));
    for (v, (_, col)) in l.iter().zip(&f.layout.texels) {
        let acc = if (*col as usize) < f.layout.width / 2 {
            &mut palm
        } else {
            &mut back
        };
        acc.0 += v;
        acc.1 += 1;
    }
    (palm.0 / palm.1 as f64, back.0 / back.1 as f64)
}

fn pearson(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let ma = a.iter().map(|x| f64::from(*x)).sum::<f64>() / n;
    let mb = b.iter().map(|x| f64::from(*x)).sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (f64::from(*x) - ma, f64::from(*y) - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    sab / (saa * sbb).sqrt()
}

#[test]
fn same_seed_same_texture() {
    let id = SkinIdentity::sample(3);
    let a = texture(&id, Side::Right);
    let b = texture(&SkinIdentity::sample(3), Side::Right);
    assert_eq!(a, b);
    assert_eq!(a.len(), 3 * fixture().layout.num_texels());
    let c = texture(&SkinIdentity::sample(4), Side::Right);
    assert_ne!(a, c);
}

#[test]
fn colours_are_finite_and_in_range() {
    for seed in 0..6 {
        for side in Side::BOTH {
            let tex = texture(&SkinIdentity::sample(seed), side);
            assert!(tex.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
        }
    }
    // Extreme identities as well.
    let mut id = SkinIdentity::sample(9).with_tone(1.0);
    id.hair_density = 2.0;
    id.mole_density = 3.0;
    id.freckle_density = 3.0;
    let tex = texture(&id, Side::Left);
    assert!(tex.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
}

#[test]
fn palm_side_is_lighter_than_the_back_for_everyone() {
    for seed in 0..40 {
        let id = SkinIdentity::sample(seed);
        let (palm, back) = palm_and_back_luma(&texture(&id, Side::Right));
        assert!(
            palm > back + 0.01,
            "seed {seed} (tone {:.2}): palm {palm:.3} back {back:.3}",
            id.tone
        );
        // Dark skin: the palm is much lighter.
        if id.tone > 0.7 {
            assert!(
                palm > back + 0.12,
                "seed {seed}: palm {palm:.3} back {back:.3}"
            );
        }
    }
}

/// Hue (degrees, HSV) of a mean sRGB colour.
fn hue(c: [f64; 3]) -> f64 {
    let (max, min) = (c[0].max(c[1]).max(c[2]), c[0].min(c[1]).min(c[2]));
    assert!(c[0] == max, "skin should be reddest in red: {c:?}");
    60.0 * (c[1] - c[2]) / (max - min)
}

/// Mean sRGB colour of the palm-side and the back-side charts.
fn palm_and_back_colour(tex: &[f32]) -> ([f64; 3], [f64; 3]) {
    let f = fixture();
    let t = f.layout.num_texels();
    let (mut palm, mut back) = (([0.0; 3], 0.0), ([0.0; 3], 0.0));
    for (i, (_, col)) in f.layout.texels.iter().enumerate() {
        let acc = if (*col as usize) < f.layout.width / 2 {
            &mut palm
        } else {
            &mut back
        };
        for c in 0..3 {
            acc.0[c] += f64::from(tex[c * t + i]);
        }
        acc.1 += 1.0;
    }
    (palm.0.map(|v| v / palm.1), back.0.map(|v| v / back.1))
}

#[test]
fn palm_is_pinker_than_the_back() {
    // Pinker: a hue closer to red (less yellow/orange) than the back's.
    for seed in 0..16 {
        let id = SkinIdentity::sample(seed);
        let (palm, back) = palm_and_back_colour(&texture(&id, Side::Right));
        let (hp, hb) = (hue(palm), hue(back));
        assert!(
            hp < hb,
            "seed {seed} (tone {:.2}): palm hue {hp:.1}, back {hb:.1}",
            id.tone
        );
    }
}

#[test]
fn skin_tones_vary_across_identities() {
    let means: Vec<f64> = (0..16)
        .map(|seed| {
            let l = luma(&texture(&SkinIdentity::sample(seed), Side::Right));
            l.iter().sum::<f64>() / l.len() as f64
        })
        .collect();
    let lo = means.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = means.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(hi - lo > 0.3, "mean luma only spans {lo:.3}..{hi:.3}");
    let mean = means.iter().sum::<f64>() / means.len() as f64;
    let sd = (means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / means.len() as f64).sqrt();
    assert!(sd > 0.08, "luma spread {sd:.3}");
    // The back of the hand spans light to dark skin.
    let backs: Vec<f64> = (0..16)
        .map(|seed| palm_and_back_luma(&texture(&SkinIdentity::sample(seed), Side::Right)).1)
        .collect();
    let lo = backs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = backs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(
        hi - lo > 0.35 && lo < 0.45 && hi > 0.75,
        "back luma spans {lo:.3}..{hi:.3}"
    );
}

/// Root-mean-square difference of two textures of the same length.
fn rmse_between(a: &[f32], b: &[f32]) -> f64 {
    let sum: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    (sum / a.len() as f64).sqrt()
}

#[test]
fn left_and_right_are_highly_correlated_but_not_identical() {
    for seed in [1, 7, 12] {
        let id = SkinIdentity::sample(seed);
        let (l, r) = (texture(&id, Side::Left), texture(&id, Side::Right));
        let corr = pearson(&l, &r);
        assert!(corr > 0.9, "seed {seed}: correlation {corr:.3}");
        let rmse = rmse_between(&l, &r);
        assert!(
            rmse > 0.003,
            "seed {seed}: left and right nearly identical ({rmse:.4})"
        );
        // Another person is much less alike than the other hand.
        let other = texture(&SkinIdentity::sample(seed + 100), Side::Right);
        let other_rmse = rmse_between(&other, &r);
        assert!(
            other_rmse > 2.0 * rmse,
            "seed {seed}: {other_rmse:.4} vs {rmse:.4}"
        );
    }
}

#[test]
fn left_texels_are_the_mirror_of_right_texels() {
    let f = fixture();
    let r = TexelGeometry::new(&f.layout, &f.right).unwrap();
    let l = TexelGeometry::new(&f.layout, &f.left).unwrap();
    for (a, b) in r.points.iter().zip(&l.points) {
        assert!(a.distance(*b) < 1e-9, "{a} vs {b}");
    }
    for (a, b) in r.normals.iter().zip(&l.normals) {
        assert!(a.distance(*b) < 1e-9, "{a} vs {b}");
    }
    // One texel is about 0.34 m / 80 on this hand.
    assert!(
        (r.texel_size - 0.34 / 80.0).abs() < 0.0005,
        "{}",
        r.texel_size
    );
}

#[test]
fn dorsal_weight_agrees_with_the_uv_halves() {
    // The UV layout puts palm-side charts in the left half: the shader's own palm/back split
    // (from normals) should agree away from the seams; `palm_side_texels` is that split.
    let f = fixture();
    let geo = TexelGeometry::new(&f.layout, &f.right).unwrap();
    let skel = HandSkeleton::new(&f.right).unwrap();
    let id = SkinIdentity::sample(0);
    let shader = super::generate::Shader::new(&skel, &id, Side::Right, geo.texel_size);
    let palm = palm_side_texels(&f.layout, &f.right).unwrap();
    assert_eq!(palm.len(), f.layout.num_texels());
    let (mut agree, mut total) = (0, 0);
    for (((p, n), (_, col)), palm) in geo
        .points
        .iter()
        .zip(&geo.normals)
        .zip(&f.layout.texels)
        .zip(&palm)
    {
        let w = shader.dorsal_at(*p, *n);
        assert_eq!(*palm, w < 0.5);
        if (0.2..0.8).contains(&w) {
            continue;
        }
        total += 1;
        if (w > 0.5) == ((*col as usize) >= f.layout.width / 2) {
            agree += 1;
        }
    }
    let frac = f64::from(agree) / f64::from(total);
    assert!(frac > 0.95, "only {frac:.3} of {total} texels agree");
    // The left hand's split is the mirror image: the same texels.
    assert_eq!(palm_side_texels(&f.layout, &f.left).unwrap(), palm);
}

#[test]
fn mismatched_side_is_an_error() {
    let f = fixture();
    let err = generate_texture(&f.layout, &f.right, &SkinIdentity::sample(0), Side::Left);
    assert!(err.is_err());
}
