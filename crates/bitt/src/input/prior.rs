//! A real run's hand models and texture prior: sources, MANO / HTML loading, adapted config.

use std::path::{Path, PathBuf};

use bitt_mesh::{HandPair, Side, UvLayout, procedural_pair};
use bitt_texture::resample::resample_pca;
use bitt_texture::{TexturePca, load_html_model, load_html_uvs};
use burn::tensor::Device;

use super::absolute;
use crate::BittError;
use crate::assets::HandAssets;
use crate::config::TrainConfig;

/// Where the hand models come from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HandSource {
    /// The project's procedural hands.
    Procedural,
    /// A folder with `MANO_LEFT` / `MANO_RIGHT` (`.pkl` or `.safetensors`).
    Mano {
        /// The folder (absolute when recorded).
        dir: PathBuf,
    },
}

/// Where the texture prior comes from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PriorSource {
    /// The procedural PCA of `config.texture`.
    Procedural,
    /// An HTML folder (see the [module docs](super)).
    Html {
        /// The folder (absolute when recorded).
        dir: PathBuf,
    },
}

impl HandSource {
    /// The same source with an absolute path.
    pub fn absolute(&self) -> Self {
        match self {
            HandSource::Procedural => HandSource::Procedural,
            HandSource::Mano { dir } => HandSource::Mano { dir: absolute(dir) },
        }
    }
}

impl PriorSource {
    /// The same source with an absolute path.
    pub fn absolute(&self) -> Self {
        match self {
            PriorSource::Procedural => PriorSource::Procedural,
            PriorSource::Html { dir } => PriorSource::Html { dir: absolute(dir) },
        }
    }
}

/// The hand models and texture prior of a MANO folder and an HTML folder (the procedural
/// hands and PCA without them).
pub fn sources(model_dir: Option<&Path>, html_dir: Option<&Path>) -> (HandSource, PriorSource) {
    let hands = match model_dir {
        Some(dir) => HandSource::Mano {
            dir: dir.to_path_buf(),
        },
        None => HandSource::Procedural,
    };
    let prior = match html_dir {
        Some(dir) => PriorSource::Html {
            dir: dir.to_path_buf(),
        },
        None => PriorSource::Procedural,
    };
    (hands, prior)
}

/// Checks that hands and prior go together (HTML needs MANO's faces; MANO needs HTML's UVs).
pub fn check_sources(hands: &HandSource, prior: &PriorSource) -> Result<(), BittError> {
    match (hands, prior) {
        (HandSource::Procedural, PriorSource::Html { dir }) => Err(BittError::Invalid(format!(
            "the HTML texture model ({}) is defined on MANO's UV layout; use it with MANO hands \
             (a MANO folder), or drop it to use the procedural hands with the procedural prior",
            dir.display()
        ))),
        (HandSource::Mano { dir }, PriorSource::Procedural) => Err(BittError::Invalid(format!(
            "MANO hands ({}) have no UV layout of their own; give the HTML folder (uvs.pkl and \
             model_wosr/model.pkl or html.safetensors) as the texture prior",
            dir.display()
        ))),
        _ => Ok(()),
    }
}

/// HTML's native model file in `dir`: `html.safetensors`, `model_wosr/model.pkl` or
/// `model.pkl`.
fn html_model_path(dir: &Path) -> Result<PathBuf, BittError> {
    let candidates = [
        dir.join(bitt_texture::html::HTML_SAFETENSORS),
        dir.join("model_wosr").join("model.pkl"),
        dir.join("model.pkl"),
    ];
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| {
            BittError::Invalid(format!(
                "{}: no HTML texture model (looked for {})",
                dir.display(),
                candidates
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
}

/// Loads HTML's native model (1024 x 1024 texels, 101 components, scale 1/255).
pub fn load_html_prior(dir: &Path) -> Result<TexturePca, BittError> {
    let path = html_model_path(dir)?;
    Ok(
        if path.extension().and_then(|e| e.to_str()) == Some("safetensors") {
            TexturePca::load_safetensors(&path)?
        } else {
            load_html_model(&path)?
        },
    )
}

/// The left hand's UV faces from the right hand's: corner `k` of left face `f` gets the UV of
/// the right face's corner on the same vertex (the meshes share vertex indices; only the
/// winding differs).
pub fn left_uv_from_right(
    right_uv: &UvLayout,
    right_faces: &[[u32; 3]],
    left_faces: &[[u32; 3]],
) -> Result<UvLayout, BittError> {
    if right_faces.len() != left_faces.len() || right_uv.faces.len() != right_faces.len() {
        return Err(BittError::Invalid(format!(
            "cannot derive the left hand's UV faces: {} right faces, {} left faces, {} UV faces",
            right_faces.len(),
            left_faces.len(),
            right_uv.faces.len()
        )));
    }
    let mut faces = Vec::with_capacity(left_faces.len());
    for (f, (l, r)) in left_faces.iter().zip(right_faces).enumerate() {
        let mut uv = [0u32; 3];
        for k in 0..3 {
            let j = r.iter().position(|&v| v == l[k]).ok_or_else(|| {
                BittError::Invalid(format!(
                    "cannot derive the left hand's UV faces: face {f} uses vertices {l:?} on \
                     the left and {r:?} on the right (give uvs_left.pkl)"
                ))
            })?;
            uv[k] = right_uv.faces[f][j];
        }
        faces.push(uv);
    }
    Ok(UvLayout {
        uvs: right_uv.uvs.clone(),
        faces,
    })
}

/// Puts HTML's UV layouts on both hands: `uvs_right.pkl` or `uvs.pkl` (else the layout stored
/// in `html.safetensors`) for the right hand, `uvs_left.pkl` or [`left_uv_from_right`] for
/// the left.
pub fn attach_html_uvs(models: &mut HandPair, dir: &Path) -> Result<(), BittError> {
    let right_file = ["uvs_right.pkl", "uvs.pkl"]
        .iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file());
    let right = match right_file {
        Some(p) => load_html_uvs(&p)?,
        None => {
            let st = dir.join(bitt_texture::html::HTML_SAFETENSORS);
            let stored = if st.is_file() {
                TexturePca::load_safetensors(&st)?.layout.uv
            } else {
                None
            };
            stored.ok_or_else(|| {
                BittError::Invalid(format!(
                    "{}: no HTML UV layout (uvs_right.pkl, uvs.pkl, or html.safetensors with \
                     a stored layout)",
                    dir.display()
                ))
            })?
        }
    };
    let left = match dir.join("uvs_left.pkl") {
        p if p.is_file() => load_html_uvs(&p)?,
        _ => left_uv_from_right(&right, &models.right.faces, &models.left.faces)?,
    };
    for (side, uv) in [(Side::Left, left), (Side::Right, right)] {
        let model = match side {
            Side::Left => &mut models.left,
            Side::Right => &mut models.right,
        };
        if uv.faces.len() != model.faces.len() {
            return Err(BittError::Invalid(format!(
                "{}: the HTML UV layout has {} faces but the {side} hand mesh ({}) has {}",
                dir.display(),
                uv.faces.len(),
                model.source,
                model.faces.len()
            )));
        }
        model.uv = Some(uv);
    }
    Ok(())
}

/// The hand models of `hands`, with HTML's UV layouts attached when `prior` is HTML.
pub fn load_models(hands: &HandSource, prior: &PriorSource) -> Result<HandPair, BittError> {
    check_sources(hands, prior)?;
    let mut models = match hands {
        HandSource::Procedural => procedural_pair(),
        HandSource::Mano { dir } => bitt_mesh::load_model_dir(dir)?,
    };
    if let PriorSource::Html { dir } = prior {
        attach_html_uvs(&mut models, dir)?;
    }
    Ok(models)
}

/// Builds the HTML network for the prior's component count (see the [module docs](super)).
pub fn adapt_config_to_prior(config: &mut TrainConfig, components: usize) -> Result<(), BittError> {
    config.nets.html.coefficients_per_hand = components;
    config.texture.components = components;
    config.texture.identities = config.texture.identities.max(components.div_ceil(2) + 1);
    Ok(config.validate()?)
}

/// The texture prior for `assets`: HTML resampled onto the assets' layout (the configuration
/// adapted to its component count), or the procedural PCA of `config.texture` (cached in
/// `cache`).
pub fn texture_model(
    config: &mut TrainConfig,
    prior: &PriorSource,
    assets: &HandAssets,
    cache: Option<&Path>,
    device: &Device,
) -> Result<TexturePca, BittError> {
    match prior {
        PriorSource::Procedural => crate::texture_model::texture_prior(config, cache, device),
        PriorSource::Html { dir } => {
            let html = load_html_prior(dir)?;
            let pca = resample_pca(&html, &assets.layouts[1])?;
            adapt_config_to_prior(config, pca.num_components)?;
            Ok(pca)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn left_uv_faces_follow_the_winding() {
        let right_faces = vec![[0, 1, 2], [2, 1, 3]];
        let left_faces = vec![[0, 2, 1], [2, 3, 1]];
        let uv = UvLayout {
            uvs: vec![bitt_mesh::glam::DVec2::ZERO; 6],
            faces: vec![[10, 11, 12], [20, 21, 22]],
        };
        let left = left_uv_from_right(&uv, &right_faces, &left_faces).unwrap();
        assert_eq!(left.faces, vec![[10, 12, 11], [20, 22, 21]]);
        let bad = vec![[0, 1, 5], [2, 3, 1]];
        assert!(left_uv_from_right(&uv, &right_faces, &bad).is_err());
    }

    #[test]
    fn sources_must_fit_together() {
        let html = PriorSource::Html {
            dir: "/x/html".into(),
        };
        let mano = HandSource::Mano {
            dir: "/x/mano".into(),
        };
        assert!(check_sources(&HandSource::Procedural, &html).is_err());
        assert!(check_sources(&mano, &PriorSource::Procedural).is_err());
        assert!(check_sources(&mano, &html).is_ok());
        assert!(check_sources(&HandSource::Procedural, &PriorSource::Procedural).is_ok());
    }
}
