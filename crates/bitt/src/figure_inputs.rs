//! What `bitt render`'s figures are made of, read and checked: the light (inline JSON or a
//! file), the hands' UV layouts, the scene and its posed hands, texture and photo images as
//! tensors, and the default procedural skin textures.

use std::path::Path;

use bitt_mesh::annotation::annotation_image_size;
use bitt_mesh::{HandModel, HandPair, PinholeCamera, Side, UvLayout};
use bitt_render::scene::LightValues;
use bitt_texture::{SkinIdentity, TextureLayout, generate_texture, load_html_uvs, load_image};
use burn::tensor::{Device, Tensor, TensorData};

use crate::BittError;
use crate::figure::FigureHand;
use bitt_stdx::WithContext;

/// The files and options `bitt render` makes a figure from (the hand models aside).
#[derive(Debug, Clone, Copy)]
pub struct FigureFiles<'a> {
    /// HTML's UV file for models without a UV layout (MANO).
    pub uvs: Option<&'a Path>,
    /// HTML's UV file for the left hand (default: `uvs`).
    pub uvs_left: Option<&'a Path>,
    /// A BiTT/InterHand annotation; `None`: the built-in demo scene.
    pub annotation: Option<&'a Path>,
    /// The image size the annotation's intrinsics refer to (default: the image beside it).
    pub image_size: Option<(u32, u32)>,
    /// A UV texture for both hands; `None`: procedural skin of person `skin_seed`.
    pub texture: Option<&'a Path>,
    /// Person of the procedural skin.
    pub skin_seed: u64,
    /// Side of the procedural textures.
    pub uv_size: usize,
    /// An image of the camera's size to unwrap onto both hands.
    pub unwrap: Option<&'a Path>,
}

/// What a figure is made of: both hands posed, their textures, the scene's camera and the
/// image to unwrap.
#[derive(Debug, Clone)]
pub struct FigureInputs {
    /// Both hands, posed in the camera frame.
    pub hands: [FigureHand; 2],
    /// One `[3, S, S]` texture per hand.
    pub textures: Vec<Tensor<3>>,
    /// The scene's camera.
    pub camera: PinholeCamera,
    /// The image to unwrap, `[3, H, W]` of the camera's size.
    pub unwrap: Option<Tensor<3>>,
}

/// Reads and checks everything `files` names, for `models`: UV layouts, the scene (both
/// hands posed), the textures and the image to unwrap.
///
/// # Errors
/// A file that cannot be read or is not what it should be, a scene without both hands, or an
/// image to unwrap that is not the camera's size.
pub fn figure_inputs(
    models: &HandPair,
    files: &FigureFiles<'_>,
    device: &Device,
) -> Result<FigureInputs, BittError> {
    let uvs = hand_uvs(models, files.uvs, files.uvs_left)?;
    let scene = match files.annotation {
        None => crate::demo::demo_scene(models),
        Some(path) => {
            let size = files
                .image_size
                .unwrap_or_else(|| annotation_image_size(path));
            bitt_mesh::load_bitt_annotation(path, size)?
        }
    };
    let posed = scene.pose_in_camera(models)?;
    let hand = |side: Side, uv: &UvLayout| -> Result<FigureHand, BittError> {
        let Some(posed) = posed.get(side) else {
            return Err(BittError::Invalid(format!(
                "{}: the scene has no {side} hand; bitt render needs both",
                files
                    .annotation
                    .map_or("the demo scene".into(), |p| p.display().to_string())
            )));
        };
        Ok(FigureHand {
            side,
            model: models.get(side).clone(),
            uv: uv.clone(),
            vertices: posed.vertices.clone(),
        })
    };
    let hands = [hand(Side::Left, &uvs[0])?, hand(Side::Right, &uvs[1])?];
    let textures = match files.texture {
        Some(path) => {
            let (t, _) = image_tensor(path, "--texture", device)?;
            vec![t.clone(), t]
        }
        None => procedural_textures(models, &uvs, files.skin_seed, files.uv_size, device)?,
    };
    let camera = scene.camera;
    let unwrap = match files.unwrap {
        Some(path) => {
            let (t, [h, w]) = image_tensor(path, "--unwrap", device)?;
            if [h, w] != [camera.height as usize, camera.width as usize] {
                return Err(BittError::Invalid(format!(
                    "--unwrap {}: the image is {w}x{h}, but the camera renders {}x{}; \
                     unwrap an image of the camera's size",
                    path.display(),
                    camera.width,
                    camera.height
                )));
            }
            Some(t)
        }
        None => None,
    };
    Ok(FigureInputs {
        hands,
        textures,
        camera,
        unwrap,
    })
}

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
    bitt_mesh::light::parse_light(&text, &source).map_err(BittError::Invalid)
}

/// Both hands' UV layouts, `[left, right]`: HTML's UV file (`uvs_left` for the left hand
/// when given, else `uvs`), else the model's own layout.
///
/// # Errors
/// A hand without a UV layout and no file, an unreadable file, or a layout whose face count
/// is not its mesh's.
pub(crate) fn hand_uvs(
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
pub(crate) fn image_tensor(
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
        // Negative colours, or no light at all, would render black (issue 38, class 6).
        let e = error_chain(
            &read_light(
                r#"{"ambient":[0.5,0.5,0.5],"diffuse":[0.1,-0.1,0.1],"specular":[0,0,0],"location":[0,1,0]}"#,
            )
            .unwrap_err(),
        );
        assert!(e.contains("diffuse") && e.contains("0 or more"), "{e}");
        let e = error_chain(
            &read_light(
                r#"{"ambient":[0,0,0],"diffuse":[0,0,0],"specular":[0,0,0],"location":[0,1,0]}"#,
            )
            .unwrap_err(),
        );
        assert!(e.contains("renders black"), "{e}");
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
