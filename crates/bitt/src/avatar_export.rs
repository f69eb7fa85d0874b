//! The avatar files a run hands its users: the rigged `avatar.glb` (one skin per hand, the
//! input pose through joint rotations, pose correctives as morph targets, a clip of the
//! scene's novel poses), `avatar_static.glb` (the posed meshes, for tools without skinning)
//! and the OBJ with its textures.
//!
//! Material: the renderer's Phong material (the reference's: ambient and diffuse reflectance
//! 1, specular 0, exponent 64) becomes a glTF metallic-roughness material with metallic 0
//! (skin is a dielectric) and, with no specular reflectance, roughness 1 (no highlight); with a
//! specular term, roughness `sqrt(alpha)` where `alpha = sqrt(2 / (4 n + 2))` is the Beckmann
//! width matching the Blinn-Phong exponent `4 n` of a Phong exponent `n`. The base colour is the
//! fine texture as the photo's pixel values, i.e. sRGB, as glTF reads a base-colour PNG.

use std::path::Path;

use bitt_mesh::export::{
    ExportHand, PbrMaterial, RiggedHand, RiggedScene, glb_bytes_with_material, rigged_glb_bytes,
    write_atomically,
};
use bitt_mesh::{HandPair, HandParams, Side, TwoHandScene};
use bitt_render::scene::Material;

use crate::BittError;

/// Names of the avatar files in a run folder.
pub mod files {
    /// The rigged avatar.
    pub const RIGGED: &str = "avatar.glb";
    /// The posed meshes without a rig.
    pub const STATIC: &str = "avatar_static.glb";
}

/// Seconds between the poses of the avatar's clip.
pub const SECONDS_PER_POSE: f64 = 1.0;

/// The name of the avatar's clip.
pub const CLIP_NAME: &str = "novel_poses";

/// The glTF material of a Phong `material` (see the module docs).
pub fn pbr_material(material: &Material) -> PbrMaterial {
    let specular = material.specular.iter().copied().fold(0.0f32, f32::max);
    let roughness = if specular <= 0.0 {
        1.0
    } else {
        let alpha = (2.0 / (4.0 * f64::from(material.shininess) + 2.0)).sqrt();
        alpha.sqrt().clamp(0.0, 1.0)
    };
    PbrMaterial {
        roughness,
        metallic: 0.0,
    }
}

/// A trained avatar, ready to be written.
#[derive(Debug, Clone)]
pub struct AvatarFiles<'a> {
    /// The hand models.
    pub models: &'a HandPair,
    /// The pose the avatar stands in, with the camera it is seen from (its extrinsics place
    /// the hands; the intrinsics are not used).
    pub hands: &'a TwoHandScene,
    /// Fine textures as images, left then right.
    pub textures: [&'a image::RgbImage; 2],
    /// The material the renderer used.
    pub material: Material,
    /// Poses for the clip (the world of `hands`' camera); empty for no clip. The clip plays
    /// `hands`, then these, then `hands` again.
    pub clip: Vec<TwoHandScene>,
}

const NAMES: [&str; 2] = ["left_hand", "right_hand"];

impl AvatarFiles<'_> {
    fn params(scene: &TwoHandScene, side: Side) -> Result<&HandParams, BittError> {
        scene.hand(side).ok_or_else(|| {
            BittError::Invalid(format!(
                "the scene has no {side} hand; the avatar needs both"
            ))
        })
    }

    /// The rigged avatar's glTF binary.
    pub fn rigged_glb(&self) -> Result<Vec<u8>, BittError> {
        let mut hands = Vec::new();
        for (i, side) in Side::BOTH.into_iter().enumerate() {
            hands.push(RiggedHand {
                name: NAMES[i],
                joint_prefix: side.as_str(),
                model: self.models.get(side),
                params: Self::params(self.hands, side)?,
                texture: Some(self.textures[i]),
            });
        }
        let mut clip = Vec::new();
        if !self.clip.is_empty() {
            let keyframe = |s: &TwoHandScene| -> Result<Vec<HandParams>, BittError> {
                let mut k = Vec::new();
                for (side, hand) in Side::BOTH.into_iter().zip(&hands) {
                    // The avatar keeps its own shape in every keyframe.
                    let p = Self::params(s, side)?;
                    k.push(HandParams {
                        betas: hand.params.betas.clone(),
                        ..p.clone()
                    });
                }
                Ok(k)
            };
            clip.push(keyframe(self.hands)?);
            for s in &self.clip {
                clip.push(keyframe(s)?);
            }
            clip.push(keyframe(self.hands)?);
        }
        let scene = RiggedScene {
            hands,
            camera_rotation: self.hands.camera.rotation,
            camera_translation: self.hands.camera.translation,
            material: pbr_material(&self.material),
            clip,
            seconds_per_pose: SECONDS_PER_POSE,
            clip_name: CLIP_NAME,
        };
        Ok(rigged_glb_bytes(&scene)?)
    }

    /// The posed meshes (camera frame) as a glTF binary without a rig.
    pub fn static_glb(&self) -> Result<Vec<u8>, BittError> {
        let posed = self.posed()?;
        let hands = self.export_hands(&posed);
        Ok(glb_bytes_with_material(
            &hands,
            &pbr_material(&self.material),
        )?)
    }

    /// Both posed hands, camera frame, left then right.
    fn posed(&self) -> Result<[Vec<bitt_mesh::glam::DVec3>; 2], BittError> {
        let posed = self.hands.pose_in_camera(self.models)?;
        let get = |side: Side| -> Result<_, BittError> {
            Ok(posed
                .get(side)
                .ok_or_else(|| {
                    BittError::Invalid(format!(
                        "the scene has no {side} hand; the avatar needs both"
                    ))
                })?
                .vertices
                .clone())
        };
        Ok([get(Side::Left)?, get(Side::Right)?])
    }

    fn export_hands<'b>(
        &'b self,
        posed: &'b [Vec<bitt_mesh::glam::DVec3>; 2],
    ) -> Vec<ExportHand<'b>> {
        Side::BOTH
            .into_iter()
            .enumerate()
            .map(|(i, side)| {
                let model = self.models.get(side);
                ExportHand {
                    name: NAMES[i],
                    vertices: &posed[i],
                    faces: &model.faces,
                    uv: model.uv.as_ref(),
                    texture: Some(self.textures[i]),
                }
            })
            .collect()
    }

    /// Writes `avatar.glb` (rigged) and `avatar_static.glb` into `dir`, each atomically.
    pub fn write(&self, dir: &Path) -> Result<(), BittError> {
        let rigged = self.rigged_glb()?;
        let fixed = self.static_glb()?;
        write_atomically(&dir.join(files::RIGGED), &rigged)?;
        write_atomically(&dir.join(files::STATIC), &fixed)?;
        Ok(())
    }

    /// Writes the posed hands as `path` (`.obj`) with a material library and one texture PNG
    /// per hand next to it (`STEM.mtl`, `STEM_left_hand.png`, `STEM_right_hand.png`).
    pub fn write_obj(&self, path: &Path) -> Result<(), BittError> {
        let posed = self.posed()?;
        Ok(bitt_mesh::export::write_obj(
            path,
            &self.export_hands(&posed),
        )?)
    }
}

/// What [`SavedRun::export`](crate::saved::SavedRun::export) writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportKind {
    /// The rigged glTF binary (the run's `avatar.glb`).
    Rigged,
    /// The posed meshes as a glTF binary without a rig (`avatar_static.glb`).
    Static,
    /// The posed meshes as OBJ, with a material library and the textures as PNGs.
    Obj,
}

impl ExportKind {
    /// What [`SavedRun::export`](crate::saved::SavedRun::export) wrote, for the user: `clip_poses` novel poses in the rigged clip
    /// (0 for another pose, which has no clip).
    pub fn written(self, clip_poses: usize) -> String {
        match self {
            ExportKind::Rigged if clip_poses > 0 => {
                format!("rigged avatar with a clip of {clip_poses} novel poses")
            }
            ExportKind::Rigged => "rigged avatar".to_string(),
            ExportKind::Static => "posed meshes (glTF, no rig)".to_string(),
            ExportKind::Obj => "posed meshes (OBJ, MTL and textures)".to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_material_is_rough_and_not_metallic() {
        let m = pbr_material(&Material::default());
        assert_eq!((m.roughness, m.metallic), (1.0, 0.0));
        let shiny = pbr_material(&Material {
            specular: [0.5; 3],
            ..Material::default()
        });
        // Phong 64 -> Blinn-Phong 256 -> Beckmann alpha 0.088 -> roughness 0.297.
        assert!(
            (shiny.roughness - 0.2970).abs() < 1e-3,
            "{}",
            shiny.roughness
        );
    }
}
