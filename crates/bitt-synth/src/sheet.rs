//! A contact sheet of scenes: one row per scene with the training view, the first novel
//! view, the first novel pose and both GT textures.

use bitt_mesh::procedural_pair;

use crate::{SynthError, SynthScene, texture_layouts};

/// Side of a contact-sheet panel (pixels).
pub const PANEL: usize = 128;

/// Box-resamples a `[3, h, w]` image to `[3, PANEL, PANEL]` (area average; nearest when
/// enlarging).
fn panel(image: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; 3 * PANEL * PANEL];
    let span = |i: usize, n: usize| {
        let a = i * n / PANEL;
        (a, ((i + 1) * n / PANEL).max(a + 1))
    };
    for c in 0..3 {
        for y in 0..PANEL {
            let (y0, y1) = span(y, h);
            for x in 0..PANEL {
                let (x0, x1) = span(x, w);
                let mut s = 0.0;
                for yy in y0..y1 {
                    for xx in x0..x1 {
                        s += image[(c * h + yy) * w + xx];
                    }
                }
                out[(c * PANEL + y) * PANEL + x] = s / ((y1 - y0) * (x1 - x0)) as f32;
            }
        }
    }
    out
}

/// The contact sheet of `scenes`: `[3, H, W]` with `W = 5 PANEL`, `H = scenes x PANEL`;
/// columns: training view (as given to the method), novel view 0, novel pose 0, left and
/// right GT texture (UV images, unused texels black). Returns `(image, width, height)`.
///
/// # Errors
/// No scenes, or textures that do not fit their configuration's layout.
pub fn contact_sheet(scenes: &[SynthScene]) -> Result<(Vec<f32>, usize, usize), SynthError> {
    if scenes.is_empty() {
        return Err(SynthError::Generate("a contact sheet needs a scene".into()));
    }
    let models = procedural_pair();
    let cols = 5;
    let (w, h) = (cols * PANEL, scenes.len() * PANEL);
    let mut sheet = vec![0.0f32; 3 * w * h];
    for (row, scene) in scenes.iter().enumerate() {
        let size = scene.config.size as usize;
        let layouts = texture_layouts(&models, scene.config.texture_size)?;
        let mut panels = vec![panel(&scene.train.image, size, size)];
        for v in [scene.novel_views.first(), scene.novel_poses.first()] {
            panels.push(match v {
                Some(v) => panel(&v.image, size, size),
                None => vec![0.0; 3 * PANEL * PANEL],
            });
        }
        for (k, layout) in layouts.iter().enumerate() {
            let img = layout.compact_to_image(&scene.textures[k], [0.0; 3])?;
            panels.push(panel(&img, layout.width, layout.height));
        }
        for (col, p) in panels.iter().enumerate() {
            for c in 0..3 {
                for y in 0..PANEL {
                    let dst = (c * h + row * PANEL + y) * w + col * PANEL;
                    sheet[dst..dst + PANEL].copy_from_slice(&p[(c * PANEL + y) * PANEL..][..PANEL]);
                }
            }
        }
    }
    Ok((sheet, w, h))
}
