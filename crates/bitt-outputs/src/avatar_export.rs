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

use crate::export::{
    ExportHand, PbrMaterial, RiggedHand, RiggedScene, XrConvention, XrHand, XrSkeleton,
    glb_bytes_with_material, rigged_glb_bytes, xr_glb_bytes,
};
use bitt_mesh::glam::{DMat4, DQuat};
use bitt_mesh::model::JOINT_NAMES;
use bitt_mesh::{HandPair, HandParams, Side, TwoHandScene};
use bitt_render::scene::Material;
use bitt_stdx::{write_atomically, write_folder_atomically};

use crate::OutputError;

/// Names of the avatar files in a run folder.
pub mod files {
    /// The rigged avatar.
    pub(crate) const RIGGED: &str = "avatar.glb";
    /// The posed meshes without a rig.
    pub const STATIC: &str = "avatar_static.glb";
}

/// Seconds between the poses of the avatar's clip.
pub(crate) const SECONDS_PER_POSE: f64 = 1.0;

/// The name of the avatar's clip.
pub(crate) const CLIP_NAME: &str = "novel_poses";

/// The glTF material of a Phong `material` (see the module docs).
pub(crate) fn pbr_material(material: &Material) -> PbrMaterial {
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
    fn params(scene: &TwoHandScene, side: Side) -> Result<&HandParams, OutputError> {
        scene.hand(side).ok_or_else(|| {
            OutputError::Invalid(format!(
                "the scene has no {side} hand; the avatar needs both"
            ))
        })
    }

    /// The rigged avatar's glTF binary.
    pub fn rigged_glb(&self) -> Result<Vec<u8>, OutputError> {
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
            let keyframe = |s: &TwoHandScene| -> Result<Vec<HandParams>, OutputError> {
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
        rigged_glb_bytes(&scene)
    }

    /// The posed meshes (camera frame) as a glTF binary without a rig.
    pub fn static_glb(&self) -> Result<Vec<u8>, OutputError> {
        let posed = self.posed()?;
        let hands = self.export_hands(&posed);
        glb_bytes_with_material(&hands, &pbr_material(&self.material))
    }

    /// Both posed hands, camera frame, left then right.
    fn posed(&self) -> Result<[Vec<bitt_mesh::glam::DVec3>; 2], OutputError> {
        let posed = self.hands.pose_in_camera(self.models)?;
        let get = |side: Side| -> Result<_, OutputError> {
            Ok(posed
                .get(side)
                .ok_or_else(|| {
                    OutputError::Invalid(format!(
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
    pub fn write(&self, dir: &Path) -> Result<(), OutputError> {
        let rigged = self.rigged_glb()?;
        let fixed = self.static_glb()?;
        write_atomically(&dir.join(files::RIGGED), &rigged)?;
        write_atomically(&dir.join(files::STATIC), &fixed)?;
        Ok(())
    }

    /// Writes the posed hands as `path` (`.obj`) with a material library and one texture PNG
    /// per hand next to it (`STEM.mtl`, `STEM_left_hand.png`, `STEM_right_hand.png`).
    pub fn write_obj(&self, path: &Path) -> Result<(), OutputError> {
        let posed = self.posed()?;
        crate::export::write_obj(path, &self.export_hands(&posed))
    }
}

/// What `bitt::saved::SavedRun::export` writes.
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
    /// What `bitt::saved::SavedRun::export` wrote, for the user: `clip_poses` novel poses in the rigged clip
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

/// Names of the files of an XR export folder (`bitt export --xr`, a run's `xr/`).
pub mod xr_files {
    /// The left hand.
    pub const LEFT: &str = "left.glb";
    /// The right hand.
    pub const RIGHT: &str = "right.glb";
    /// Which bone is which joint, how each was placed, the skinning rule and the vertex error.
    pub const JOINTS: &str = "joints.json";
    /// Joint poses of the run's poses, as a tracker reports them (for the page and for tests).
    pub(crate) const PLAYBACK: &str = "playback.json";
    /// The page that shows the two files driven (WebXR only).
    pub const PAGE: &str = "xr.html";
    /// The `format` of [`JOINTS`].
    pub(crate) const JOINTS_FORMAT: &str = "bitt-xr-joints";
}

/// A file of a folder to write: its name and its bytes.
pub(crate) type NamedFile = (String, Vec<u8>);

/// One pose the XR files are played in: its name, which novel pose it is (`None`: the
/// training pose) and the hands with the camera that sees them.
#[derive(Debug, Clone)]
pub struct XrFrame {
    /// `"training pose"`, `"novel pose 3"`.
    pub name: String,
    /// The run's novel pose it is (0-based, as `render-avatar --novel-pose`), if any.
    pub novel_pose: Option<usize>,
    /// The hands and their camera.
    pub hands: TwoHandScene,
}

/// How far the XR files, driven by the joint poses a tracker reports, are from the forward
/// pass, over every frame and both hands (metres).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct XrVertexError {
    /// Frames measured.
    pub frames: usize,
    /// Mean vertex distance to the forward pass without its pose correctives (what linear
    /// blend skinning of the model gives).
    pub mean_without_correctives: f64,
    /// Largest vertex distance to it.
    pub max_without_correctives: f64,
    /// Mean vertex distance to the forward pass with its pose correctives (the model's own
    /// mesh; a tracker cannot drive the correctives).
    pub mean_with_correctives: f64,
    /// Largest vertex distance to it.
    pub max_with_correctives: f64,
}

/// A trained avatar as two hands for a hand-tracking runtime
/// ([`crate::export::XrSkeleton`]): `left.glb`, `right.glb`, `joints.json`,
/// `playback.json` and, for WebXR, `xr.html`.
#[derive(Debug, Clone)]
pub struct XrAvatar<'a> {
    /// The convention.
    pub convention: XrConvention,
    /// The hand models.
    pub models: &'a HandPair,
    /// The training pose: the avatar's shapes come from it.
    pub hands: &'a TwoHandScene,
    /// Fine textures as images, left then right.
    pub textures: [&'a image::RgbImage; 2],
    /// The material the renderer used.
    pub material: Material,
    /// The poses of `playback.json` (and of the vertex error).
    pub frames: Vec<XrFrame>,
}

/// glTF's axes from OpenCV camera axes (a half turn about x).
fn opencv_to_gltf() -> DMat4 {
    DMat4::from_quat(DQuat::from_rotation_x(std::f64::consts::PI))
}

impl XrAvatar<'_> {
    /// The skeletons, left then right, with the avatar's shapes.
    fn skeletons(&self) -> Result<[XrSkeleton; 2], OutputError> {
        let sk = |side: Side| -> Result<XrSkeleton, OutputError> {
            let p = AvatarFiles::params(self.hands, side)?;
            XrSkeleton::new(self.models.get(side), &p.betas, self.convention)
        };
        Ok([sk(Side::Left)?, sk(Side::Right)?])
    }

    /// Every file of the export (name, bytes) and the vertex error over the frames.
    ///
    /// # Errors
    /// A pose the avatar's hands cannot take, or textures without a UV layout.
    pub fn files(&self) -> Result<(Vec<NamedFile>, XrVertexError), OutputError> {
        let skeletons = self.skeletons()?;
        let mut out = Vec::new();
        for (i, side) in Side::BOTH.into_iter().enumerate() {
            let glb = xr_glb_bytes(&XrHand {
                model: self.models.get(side),
                skeleton: &skeletons[i],
                texture: Some(self.textures[i]),
                material: pbr_material(&self.material),
            })?;
            let name = [xr_files::LEFT, xr_files::RIGHT][i];
            out.push((name.to_string(), glb));
        }
        let (playback, error) = self.playback(&skeletons)?;
        let joints = self.joints_json(&skeletons, &error);
        let json =
            |v: &serde_json::Value| serde_json::to_vec_pretty(v).expect("JSON of plain values");
        if self.convention == XrConvention::WebXr {
            let page = crate::xr_page::xr_html(&out[0].1, &out[1].1, &playback.to_string());
            out.push((xr_files::PAGE.to_string(), page.into_bytes()));
        }
        out.push((xr_files::PLAYBACK.to_string(), json(&playback)));
        out.push((xr_files::JOINTS.to_string(), json(&joints)));
        Ok((out, error))
    }

    /// Writes the export into `dir` as a whole (a new or empty folder, or an earlier XR
    /// export, which is replaced); returns the vertex error.
    ///
    /// # Errors
    /// As [`Self::files`]; `dir` a file or a foreign folder (untouched); a write failure.
    pub fn write(&self, dir: &Path) -> Result<XrVertexError, OutputError> {
        let (files, error) = self.files()?;
        write_folder_atomically(dir, &files, is_xr_export)?;
        Ok(error)
    }

    /// `playback.json`: per frame, the camera and each hand's joint poses as a tracker reports
    /// them (camera at the origin, glTF/WebXR axes, column-major 4x4), and the vertex error.
    fn playback(
        &self,
        skeletons: &[XrSkeleton; 2],
    ) -> Result<(serde_json::Value, XrVertexError), OutputError> {
        let mut frames = Vec::new();
        let mut sums = [0.0f64; 2];
        let mut maxes = [0.0f64; 2];
        let mut count = 0usize;
        for f in &self.frames {
            let c = &f.hands.camera;
            let world = opencv_to_gltf() * DMat4::from_mat3_translation(c.rotation, c.translation);
            let mut hands = serde_json::Map::new();
            for (i, side) in Side::BOTH.into_iter().enumerate() {
                let Some(p) = f.hands.hand(side) else {
                    hands.insert(side.as_str().into(), serde_json::Value::Null);
                    continue;
                };
                let model = self.models.get(side);
                let sk = &skeletons[i];
                let p = bitt_mesh::HandParams {
                    betas: AvatarFiles::params(self.hands, side)?.betas.clone(),
                    ..p.clone()
                };
                let posed = model.forward(&p)?;
                let tracked = sk.tracked_poses(&posed.joint_transforms, world);
                let matrices: Vec<Vec<f32>> = tracked
                    .iter()
                    .map(|m| m.to_cols_array().iter().map(|&x| x as f32).collect())
                    .collect();
                hands.insert(side.as_str().into(), serde_json::json!(matrices));
                // The file driven by these poses, against the forward pass (same frame).
                let skinned = sk.skin(&tracked);
                let lbs = sk.blend_skinning(model, &posed.joint_transforms, world);
                for (v, s) in skinned.iter().enumerate() {
                    let with = (*s - world.transform_point3(posed.vertices[v])).length();
                    let without = (*s - lbs[v]).length();
                    sums[0] += without;
                    sums[1] += with;
                    maxes[0] = maxes[0].max(without);
                    maxes[1] = maxes[1].max(with);
                    count += 1;
                }
            }
            let k = c.intrinsics;
            frames.push(serde_json::json!({
                "name": f.name,
                "novel_pose": f.novel_pose,
                "camera": {
                    "width": c.width, "height": c.height,
                    "fx": k.x_axis.x, "fy": k.y_axis.y, "cx": k.z_axis.x, "cy": k.z_axis.y,
                },
                "left": hands["left"],
                "right": hands["right"],
            }));
        }
        let n = count.max(1) as f64;
        let error = XrVertexError {
            frames: self.frames.len(),
            mean_without_correctives: sums[0] / n,
            max_without_correctives: maxes[0],
            mean_with_correctives: sums[1] / n,
            max_with_correctives: maxes[1],
        };
        let playback = serde_json::json!({
            "format": "bitt-xr-playback",
            "convention": self.convention.as_str(),
            "joints": self.convention.runtime_names().iter().map(|s| s.as_str()).collect::<Vec<_>>(),
            "space": "each frame's camera at the origin; x right, y up, looking down -z (glTF and \
                      WebXR axes); metres; matrices column-major, as XRFrame.getJointPose's \
                      transform.matrix",
            "frames": frames,
        });
        Ok((playback, error))
    }

    /// `joints.json`: the convention, each bone's joint, what it follows and how it was
    /// placed, its rest frame, the skinning rule and the measured vertex error.
    fn joints_json(&self, skeletons: &[XrSkeleton; 2], error: &XrVertexError) -> serde_json::Value {
        let hand = |sk: &XrSkeleton| -> Vec<serde_json::Value> {
            sk.joints
                .iter()
                .map(|x| {
                    let (_, r, t) = x.rest.to_scale_rotation_translation();
                    serde_json::json!({
                        "joint": x.runtime_name,
                        "bone": x.bone,
                        "follows": format!("{}_{}", sk.side.as_str(), JOINT_NAMES[x.follows]),
                        "placed": x.placed,
                        "rest_translation": [t.x, t.y, t.z],
                        "rest_rotation": [r.x, r.y, r.z, r.w],
                    })
                })
                .collect()
        };
        serde_json::json!({
            "format": xr_files::JOINTS_FORMAT,
            "convention": self.convention.as_str(),
            "files": {"left": xr_files::LEFT, "right": xr_files::RIGHT},
            "units": "metres",
            "axes": "each joint: -Z along its bone towards the fingertip, +Y out of the back of \
                     the hand, X = Y x Z (WebXR Hand Input and OpenXR XR_EXT_hand_tracking)",
            "rest_pose": "the avatar's own shape, unposed, in the hand model's frame",
            "follows": "the avatar.glb joint whose motion the joint follows",
            "skinning": "a finger or thumb bone takes its model joint's weight; the wrist's weight \
                         goes to the metacarpal bones by a share that grows linearly along the \
                         wrist-to-middle-knuckle axis from 0 at the middle metacarpal joint to 1 \
                         at the knuckles, split between the two nearest metacarpal bones by \
                         inverse squared distance; at most 4 bones per vertex (docs/avatar.md)",
            "left": hand(&skeletons[0]),
            "right": hand(&skeletons[1]),
            "vertex_error_m": error,
        })
    }
}

/// Whether `dir` is an earlier XR export (its `joints.json` says so).
pub(crate) fn is_xr_export(dir: &Path) -> bool {
    std::fs::read(dir.join(xr_files::JOINTS))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .is_some_and(|v| v["format"] == xr_files::JOINTS_FORMAT)
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
