//! Tests of the skin generator, and the writer of the documentation images
//! (`cargo test --release --workspace write_docs_images -- --ignored`).

use std::sync::OnceLock;

use bitt_mesh::glam::{DVec2, DVec3};
use bitt_mesh::{HandModel, Side, default_hand};

use super::anatomy::{HandSkeleton, TexelGeometry};
use super::{SkinIdentity, generate_texture};
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
    // (from normals) should agree away from the seams.
    let f = fixture();
    let geo = TexelGeometry::new(&f.layout, &f.right).unwrap();
    let skel = HandSkeleton::new(&f.right).unwrap();
    let id = SkinIdentity::sample(0);
    let shader = super::generate::Shader::new(&skel, &id, Side::Right, geo.texel_size);
    let (mut agree, mut total) = (0, 0);
    for ((p, n), (_, col)) in geo.points.iter().zip(&geo.normals).zip(&f.layout.texels) {
        let w = shader.dorsal_at(*p, *n);
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
}

#[test]
fn mismatched_side_is_an_error() {
    let f = fixture();
    let err = generate_texture(&f.layout, &f.right, &SkinIdentity::sample(0), Side::Left);
    assert!(err.is_err());
}

// ---------------------------------------------------------------------------------------------
// Documentation images.

/// A texture image `[3, H, W]` sampled bilinearly at `uv` (`v = 0` at the bottom).
struct Image {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Image {
    fn sample(&self, uv: DVec2) -> DVec3 {
        let q = crate::layout::uv_to_texel(uv, self.w, self.h);
        let x = q.x.clamp(0.0, self.w as f64 - 1.0);
        let y = q.y.clamp(0.0, self.h as f64 - 1.0);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let hw = self.w * self.h;
        let px = |xx: usize, yy: usize| {
            let k = yy * self.w + xx;
            DVec3::new(
                f64::from(self.data[k]),
                f64::from(self.data[hw + k]),
                f64::from(self.data[2 * hw + k]),
            )
        };
        let top = px(x0, y0).lerp(px(x1, y0), fx);
        let bottom = px(x0, y1).lerp(px(x1, y1), fx);
        top.lerp(bottom, fy)
    }
}

/// Orthographic render of a textured hand: `toward` points from the hand to the viewer, `up`
/// is the screen's up. Lambert shading with smooth normals; white background.
fn render(hand: &HandModel, tex: &Image, toward: DVec3, up: DVec3, size: usize) -> Vec<[u8; 3]> {
    let right = up.cross(toward).normalize();
    let uv = hand.uv.as_ref().unwrap();
    let v = &hand.v_template;
    let mut normals = vec![DVec3::ZERO; v.len()];
    for f in &hand.faces {
        let [a, b, c] = f.map(|i| v[i as usize]);
        for i in f {
            normals[*i as usize] += (b - a).cross(c - a);
        }
    }
    let normals: Vec<DVec3> = normals.iter().map(|n| n.normalize_or_zero()).collect();
    let proj: Vec<DVec3> = v
        .iter()
        .map(|p| DVec3::new(p.dot(right), p.dot(up), p.dot(toward)))
        .collect();
    let lo = proj.iter().fold(DVec3::splat(f64::MAX), |a, b| a.min(*b));
    let hi = proj.iter().fold(DVec3::splat(f64::MIN), |a, b| a.max(*b));
    let scale = 0.94 * size as f64 / (hi.x - lo.x).max(hi.y - lo.y);
    let centre = (lo + hi) * 0.5;
    let px: Vec<DVec3> = proj
        .iter()
        .map(|p| {
            DVec3::new(
                (p.x - centre.x) * scale + 0.5 * size as f64,
                (centre.y - p.y) * scale + 0.5 * size as f64,
                p.z,
            )
        })
        .collect();
    let light = (toward + 0.35 * up + 0.25 * right).normalize();
    let mut img = vec![[255u8; 3]; size * size];
    let mut depth = vec![f64::MIN; size * size];
    for (fi, f) in hand.faces.iter().enumerate() {
        let [a, b, c] = f.map(|i| px[i as usize]);
        let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = a.x.min(b.x).min(c.x).floor().max(0.0) as usize;
        let x1 = (a.x.max(b.x).max(c.x).ceil() as usize).min(size - 1);
        let y0 = a.y.min(b.y).min(c.y).floor().max(0.0) as usize;
        let y1 = (a.y.max(b.y).max(c.y).ceil() as usize).min(size - 1);
        let uvf = uv.faces[fi].map(|i| uv.uvs[i as usize]);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (qx, qy) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = ((b.x - qx) * (c.y - qy) - (b.y - qy) * (c.x - qx)) / area;
                let w1 = ((c.x - qx) * (a.y - qy) - (c.y - qy) * (a.x - qx)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * a.z + w1 * b.z + w2 * c.z;
                let k = y * size + x;
                if z <= depth[k] {
                    continue;
                }
                depth[k] = z;
                let n = (normals[f[0] as usize] * w0
                    + normals[f[1] as usize] * w1
                    + normals[f[2] as usize] * w2)
                    .normalize_or_zero();
                let albedo = tex.sample(uvf[0] * w0 + uvf[1] * w1 + uvf[2] * w2);
                // Shade in linear light.
                let lin = albedo.powf(2.2);
                let shade = 0.3 + 0.85 * n.dot(light).max(0.0);
                let out = (lin * shade).powf(1.0 / 2.2);
                img[k] = [out.x, out.y, out.z].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
            }
        }
    }
    img
}

/// Writes `docs/images/procedural-skin-*.png`: per identity, the right hand's UV texture and
/// both hands rendered from the palm and the back side.
#[test]
#[ignore = "writes the documentation images into docs/images"]
fn write_docs_images() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/images");
    std::fs::create_dir_all(&dir).unwrap();
    let right = default_hand(Side::Right);
    let left = default_hand(Side::Left);
    let tex_res = 1024;
    let layout = TextureLayout::from_uv(right.uv.as_ref().unwrap(), tex_res, tex_res, 3).unwrap();
    let people = [("light", 11, 0.08), ("medium", 12, 0.5), ("dark", 13, 0.9)];
    for (name, seed, tone) in people {
        let id = SkinIdentity::sample(seed).with_tone(tone);
        let (view, uv_size) = (320, 512);
        let (width, height) = (uv_size + 2 * view, 2 * view);
        let top = (height - uv_size) / 2;
        let mut canvas =
            image::RgbImage::from_pixel(width as u32, height as u32, image::Rgb([255, 255, 255]));
        let mut right_image = None;
        for (col, (side, hand)) in [(Side::Left, &left), (Side::Right, &right)]
            .into_iter()
            .enumerate()
        {
            let compact = generate_texture(&layout, hand, &id, side).unwrap();
            let data = layout.compact_to_image(&compact, [1.0, 1.0, 1.0]).unwrap();
            let img = Image {
                w: tex_res,
                h: tex_res,
                data,
            };
            let fingers = if side == Side::Right {
                DVec3::NEG_X
            } else {
                DVec3::X
            };
            for (row, toward) in [DVec3::NEG_Y, DVec3::Y].into_iter().enumerate() {
                let pixels = render(hand, &img, toward, fingers, view);
                for (k, p) in pixels.iter().enumerate() {
                    let (x, y) = (uv_size + col * view + k % view, row * view + k / view);
                    canvas.put_pixel(x as u32, y as u32, image::Rgb(*p));
                }
            }
            if side == Side::Right {
                right_image = Some(img);
            }
        }
        // The UV texture, downsampled 2:1 (box filter) to `uv_size`.
        let img = right_image.unwrap();
        let f = tex_res / uv_size;
        let hw = tex_res * tex_res;
        for y in 0..uv_size {
            for x in 0..uv_size {
                let mut acc = [0.0f32; 3];
                for dy in 0..f {
                    for dx in 0..f {
                        let k = (y * f + dy) * tex_res + x * f + dx;
                        for (c, a) in acc.iter_mut().enumerate() {
                            *a += img.data[c * hw + k];
                        }
                    }
                }
                let px = acc.map(|a| (a / (f * f) as f32 * 255.0).round().clamp(0.0, 255.0) as u8);
                canvas.put_pixel(x as u32, (top + y) as u32, image::Rgb(px));
            }
        }
        canvas
            .save(dir.join(format!("procedural-skin-{name}.png")))
            .unwrap();
    }

    // Details at full texture resolution: palm creases, the back of the hand (veins, hair,
    // freckles, MCP wrinkles) and the backs of the fingers (knuckles, nails), for a hairy
    // person with visible veins.
    let mut id = SkinIdentity::sample(21).with_tone(0.25);
    id.hair_density = 1.3;
    id.hair_darkness = 0.9;
    id.vein_visibility = 1.1;
    let compact = generate_texture(&layout, &right, &id, Side::Right).unwrap();
    let data = layout.compact_to_image(&compact, [1.0, 1.0, 1.0]).unwrap();
    let crop = 320;
    let corners = [(100, 300), (610, 330), (650, 0)];
    let mut canvas = image::RgbImage::new((corners.len() * crop) as u32, crop as u32);
    let hw = tex_res * tex_res;
    for (i, (x0, y0)) in corners.into_iter().enumerate() {
        for y in 0..crop {
            for x in 0..crop {
                let k = (y0 + y) * tex_res + x0 + x;
                let px =
                    [0, 1, 2].map(|c| (data[c * hw + k] * 255.0).round().clamp(0.0, 255.0) as u8);
                canvas.put_pixel((i * crop + x) as u32, y as u32, image::Rgb(px));
            }
        }
    }
    canvas.save(dir.join("procedural-skin-detail.png")).unwrap();
}

/// Pastes a `size x size` render into `canvas` at `(x, y)`.
fn paste(canvas: &mut image::RgbImage, pixels: &[[u8; 3]], size: usize, x: usize, y: usize) {
    for (k, p) in pixels.iter().enumerate() {
        canvas.put_pixel((x + k % size) as u32, (y + k / size) as u32, image::Rgb(*p));
    }
}

/// Writes `docs/images/procedural-skin-population.png`: the back and the palm of the right
/// hand of the first eight training identities of the default configuration (top two rows),
/// and the fitted default model's mean texture and its first three components at -2 and +2
/// standard deviations (bottom two rows).
#[test]
#[ignore = "writes the documentation images into docs/images"]
fn write_docs_population_image() {
    use super::{ProceduralTextureConfig, procedural_texture_pca};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/images");
    std::fs::create_dir_all(&dir).unwrap();
    let right = default_hand(Side::Right);
    let config = ProceduralTextureConfig::default();
    let res = config.resolution;
    let layout =
        TextureLayout::from_uv(right.uv.as_ref().unwrap(), res, res, config.gutter).unwrap();
    let cell = 160;
    let mut canvas = image::RgbImage::from_pixel(
        8 * cell as u32,
        4 * cell as u32,
        image::Rgb([255, 255, 255]),
    );
    let image_of = |compact: &[f32]| Image {
        w: res,
        h: res,
        data: layout.compact_to_image(compact, [1.0, 1.0, 1.0]).unwrap(),
    };
    let draw = |canvas: &mut image::RgbImage, compact: &[f32], col: usize, row: usize| {
        let img = image_of(compact);
        for (r, toward) in [DVec3::Y, DVec3::NEG_Y].into_iter().enumerate() {
            let pixels = render(&right, &img, toward, DVec3::NEG_X, cell);
            paste(canvas, &pixels, cell, col * cell, (row + r) * cell);
        }
    };
    for i in 0..8 {
        let tex =
            generate_texture(&layout, &right, &config.training_identity(i), Side::Right).unwrap();
        draw(&mut canvas, &tex, i, 0);
    }
    let (pca, _, _) = procedural_texture_pca(&config, &burn::tensor::Device::flex()).unwrap();
    let k = pca.num_components;
    let mut params = vec![0.0f32; k];
    draw(&mut canvas, &pca.texture(&params).unwrap(), 0, 2);
    for c in 0..3 {
        for (j, v) in [-2.0f32, 2.0].into_iter().enumerate() {
            params.fill(0.0);
            params[c] = v;
            draw(
                &mut canvas,
                &pca.texture(&params).unwrap(),
                1 + 2 * c + j,
                2,
            );
        }
    }
    canvas
        .save(dir.join("procedural-skin-population.png"))
        .unwrap();
}
