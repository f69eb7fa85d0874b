//! What `bitt render`'s figures are made of, read and checked: the light (inline JSON or a
//! file), the hands' UV layouts, texture and photo images as tensors, and the default
//! procedural skin textures.

use std::path::Path;

use bitt_mesh::{HandModel, HandPair, Side, UvLayout};
use bitt_render::scene::LightValues;
use bitt_texture::{SkinIdentity, TextureLayout, generate_texture, load_html_uvs, load_image};
use burn::tensor::{Device, Tensor, TensorData};

use crate::BittError;
use crate::error::WithContext;

/// The light of `arg`: inline JSON when it looks like JSON (an object, an array, or anything
/// else that parses as JSON and is not a file's name), else a JSON file.
///
/// # Errors
/// An unreadable file, text that is not a light, or a light value that is not finite.
pub fn read_light(arg: &str) -> Result<LightValues, BittError> {
    let t = arg.trim_start();
    let inline = t.starts_with('{')
        || t.starts_with('[')
        || (!Path::new(arg).exists() && serde_json::from_str::<serde_json::Value>(arg).is_ok());
    let (text, source) = if inline {
        (arg.to_string(), "--light".to_string())
    } else {
        let text = std::fs::read_to_string(arg)
            .context_with(|| format!("--light: cannot read light file {arg}"))?;
        (text, arg.to_string())
    };
    let light: LightValues = serde_json::from_str(&text).context_with(|| {
        format!(
            "{source}: expected JSON {{\"ambient\": [r, g, b], \"diffuse\": [r, g, b], \
             \"specular\": [r, g, b], \"location\": [x, y, z]}}"
        )
    })?;
    light.validate().map_err(|e| {
        BittError::Invalid(format!("{source}: {e} (every light value must be finite)"))
    })?;
    Ok(light)
}

/// Both hands' UV layouts, `[left, right]`: HTML's UV file (`uvs_left` for the left hand
/// when given, else `uvs`), else the model's own layout.
///
/// # Errors
/// A hand without a UV layout and no file, an unreadable file, or a layout whose face count
/// is not its mesh's.
pub fn hand_uvs(
    models: &HandPair,
    uvs: Option<&Path>,
    uvs_left: Option<&Path>,
) -> Result<[UvLayout; 2], BittError> {
    let uv_for = |side: Side, model: &HandModel| -> Result<UvLayout, BittError> {
        let file = match side {
            Side::Left => uvs_left.or(uvs),
            Side::Right => uvs,
        };
        let uv = match (file, &model.uv) {
            (Some(f), _) => load_html_uvs(f)?,
            (None, Some(uv)) => uv.clone(),
            (None, None) => {
                return Err(BittError::Invalid(format!(
                    "the {side} hand model ({}) has no UV layout; give --uvs FILE (HTML's uvs.pkl)",
                    model.source
                )));
            }
        };
        if uv.faces.len() != model.faces.len() {
            return Err(BittError::Invalid(format!(
                "the {side} hand's UV layout has {} faces but its mesh has {}",
                uv.faces.len(),
                model.faces.len()
            )));
        }
        Ok(uv)
    };
    Ok([
        uv_for(Side::Left, &models.left)?,
        uv_for(Side::Right, &models.right)?,
    ])
}

/// A planar `[3, H, W]` image tensor read from `path`, and `[H, W]`; `what` names the option
/// in errors.
///
/// # Errors
/// An unreadable image, or one smaller than 2x2.
pub fn image_tensor(
    path: &Path,
    what: &str,
    device: &Device,
) -> Result<(Tensor<3>, [usize; 2]), BittError> {
    let img =
        load_image(path).context_with(|| format!("{what}: cannot load {}", path.display()))?;
    let (w, h) = (img.width, img.height);
    if w < 2 || h < 2 {
        return Err(BittError::Invalid(format!(
            "{what}: {} is {w}x{h}; it must be at least 2x2",
            path.display()
        )));
    }
    Ok((
        Tensor::from_data(TensorData::new(img.data, [3, h, w]), device),
        [h, w],
    ))
}

/// The default per-hand textures: procedural skin of person `skin_seed`, `[3, S, S]` each
/// (`S = uv_size`), `[left, right]`.
///
/// # Errors
/// A hand that is not the procedural hand (its skin needs the procedural anatomy).
pub fn procedural_textures(
    models: &HandPair,
    uvs: &[UvLayout; 2],
    skin_seed: u64,
    uv_size: usize,
    device: &Device,
) -> Result<Vec<Tensor<3>>, BittError> {
    let id = SkinIdentity::sample(skin_seed);
    let s = uv_size;
    [Side::Left, Side::Right]
        .iter()
        .zip(uvs)
        .map(|(&side, uv)| {
            let layout = TextureLayout::from_uv(uv, s, s, 2)?;
            let compact =
                generate_texture(&layout, models.get(side), &id, side).context_with(|| {
                    format!(
                        "the procedural skin texture needs the procedural hand; \
                         give --texture FILE for the {side} hand of {}",
                        models.get(side).source
                    )
                })?;
            let image = layout.compact_to_image(&compact, [0.0; 3])?;
            Ok(Tensor::from_data(TensorData::new(image, [3, s, s]), device))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::error_chain;

    #[test]
    fn light_json_is_checked() {
        let ok = read_light(
            r#"{"ambient":[0.5,0.5,0.5],"diffuse":[0.1,0.1,0.1],"specular":[0,0,0],"location":[0,1,0]}"#,
        )
        .unwrap();
        assert_eq!(ok.location, [0.0, 1.0, 0.0]);
        let e = error_chain(&read_light(r#"{"ambient":[0.5,0.5,0.5]}"#).unwrap_err());
        assert!(e.contains("--light") && e.contains("diffuse"), "{e}");
        let e = error_chain(&read_light(r#"{"ambient":[NaN,0,0]}"#).unwrap_err());
        assert!(e.contains("--light"), "{e}");
        // Too large for f32: becomes infinite, which the check rejects.
        let e = error_chain(
            &read_light(
                r#"{"ambient":[1e39,0,0],"diffuse":[0,0,0],"specular":[0,0,0],"location":[0,1,0]}"#,
            )
            .unwrap_err(),
        );
        assert!(e.contains("ambient") && e.contains("finite"), "{e}");
        let e = error_chain(&read_light("/nonexistent/light.json").unwrap_err());
        assert!(e.contains("/nonexistent/light.json"), "{e}");
        // Inline JSON that is not a light object is named as --light, not read as a file.
        for wrong in ["[1,2]", " [1, 2, 3]", "42", "\"sun\""] {
            let e = error_chain(&read_light(wrong).unwrap_err());
            assert!(
                e.starts_with("--light: expected JSON") && !e.contains("cannot read"),
                "{wrong}: {e}"
            );
        }
    }
}
