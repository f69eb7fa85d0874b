//! The documentation images of the procedural skin (`docs/procedural-textures.md`):
//! `procedural-skin-{light,medium,dark,detail,population}.png`, written into the folder given
//! as the only argument (default `docs/images`). `cargo xtask docs-images` runs it.

use std::path::Path;

use bitt_mesh::glam::{DVec2, DVec3};
use bitt_mesh::{HandModel, Side, default_hand};
use bitt_texture::{
    ProceduralTextureConfig, SkinIdentity, TextureLayout, generate_texture, procedural_texture_pca,
};

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map_or_else(|| Path::new("docs/images").to_path_buf(), Into::into);
    std::fs::create_dir_all(&dir).unwrap();
    write_docs_images(&dir);
    write_docs_population_image(&dir);
    println!("wrote the procedural skin images into {}", dir.display());
}

/// A texture image `[3, H, W]` sampled bilinearly at `uv` (`v = 0` at the bottom).
struct Image {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Image {
    fn sample(&self, uv: DVec2) -> DVec3 {
        let q = bitt_texture::layout::uv_to_texel(uv, self.w, self.h);
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

/// Writes `procedural-skin-*.png`: per identity, the right hand's UV texture and both hands
/// rendered from the palm and the back side.
fn write_docs_images(dir: &Path) {
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

/// Writes `procedural-skin-population.png`: the back and the palm of the right
/// hand of the first eight training identities of the default configuration (top two rows),
/// and the fitted default model's mean texture and its first three components at -2 and +2
/// standard deviations (bottom two rows).
fn write_docs_population_image(dir: &Path) {
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
