//! Scenes on disk, and the scene cache.
//!
//! One folder per scene:
//!
//! - `scene.json`: format tag, [`GENERATOR_VERSION`], configuration, seed, identity, studio
//!   light, training degradation, Table-3 statistics, the given meshes, and per view its name,
//!   pose family, hand parameters with camera ([`TwoHandScene`]) and light (camera frame);
//! - `data.safetensors`: exact tensors `<view>/image` `[3, H, W]`, `<view>/masks`
//!   `[2, H, W]` (left, right; both `U8` holding `255 * value` when that is exact, as for the
//!   generator's 8-bit images and binary masks, else `f32`: `st::unit_entry`) and
//!   `texture_left`, `texture_right` (`f32` `[3, T]`), and
//!   `scene_exact_json` (`U8`): `scene.json` again with every float as its bit pattern, which
//!   reading uses (serde_json's float parsing is not always exact to the last bit); its only
//!   metadata is `format` (a single key, so the bytes are deterministic);
//! - for looking at (never read back): `<view>.png` (8-bit), `<view>.mask.png` (red = left,
//!   green = right) and `texture_left.png`, `texture_right.png` (the UV images, unused texels
//!   black).
//!
//! Every file is written atomically; the same scene always gives the same bytes.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use bitt_mesh::TwoHandScene;
use bitt_render::scene::LightValues;
use bitt_stdx::FileErrorExt;
use bitt_stdx::st::{self, f32_bytes};
use bitt_stdx::write_atomically;
use burn::tensor::Device;
use safetensors::Dtype;

use crate::{
    Degradation, Identity, PoseFamily, StudioLight, SynthConfig, SynthError, SynthScene, SynthView,
    TexelStats, generate_scene, texture_layouts,
};

/// Version of the generator: part of the cache key and of `scene.json`; bump it whenever the
/// same configuration and seed would produce a different scene.
///
/// - 1: first release.
/// - 2: personal appearance patches ([`crate::AppearancePatch`]) on both hands.
/// - 3: the procedural hand's rounder wrist cap (issue 34).
/// - 4: every image 8-bit, as a PNG holds it (`degrade::to_8bit`; the training image was
///   already, through its JPEG degradation).
pub const GENERATOR_VERSION: u32 = 4;

/// The `format` of `scene.json` and `data.safetensors`.
const FORMAT: &str = "bitt-synth-scene";
/// The `data.safetensors` tensor (`U8`) holding the exact copy of `scene.json`.
const EXACT: &str = "scene_exact_json";
/// Prefix of a float written as its bit pattern in the exact copy.
const BITS: &str = "f64bits:";

/// Replaces every float of a JSON tree by a string of its bit pattern.
fn floats_to_bits(v: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::Number(n) if n.is_f64() => Value::String(format!(
            "{BITS}{:016x}",
            n.as_f64().unwrap_or(f64::NAN).to_bits()
        )),
        Value::Array(a) => Value::Array(a.into_iter().map(floats_to_bits).collect()),
        Value::Object(o) => {
            Value::Object(o.into_iter().map(|(k, v)| (k, floats_to_bits(v))).collect())
        }
        v => v,
    }
}

/// The inverse of [`floats_to_bits`].
fn bits_to_floats(v: serde_json::Value) -> Result<serde_json::Value, String> {
    use serde_json::Value;
    Ok(match v {
        Value::String(s) if s.starts_with(BITS) => {
            let bits = u64::from_str_radix(&s[BITS.len()..], 16)
                .map_err(|_| format!("bad float bits {s:?}"))?;
            let x = f64::from_bits(bits);
            Value::Number(
                serde_json::Number::from_f64(x).ok_or_else(|| format!("non-finite float {s:?}"))?,
            )
        }
        Value::Array(a) => Value::Array(
            a.into_iter()
                .map(bits_to_floats)
                .collect::<Result<_, _>>()?,
        ),
        Value::Object(o) => Value::Object(
            o.into_iter()
                .map(|(k, v)| bits_to_floats(v).map(|v| (k, v)))
                .collect::<Result<_, _>>()?,
        ),
        v => v,
    })
}

#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct ViewFile {
    name: String,
    family: PoseFamily,
    hands: TwoHandScene,
    light: LightValues,
    /// Each hand's 21 true 2D joints (pixels, OpenPose order): a plain keypoint file's
    /// content. Written for users and tools; recomputed from `hands` when read.
    #[serde(default, skip_deserializing)]
    keypoints_2d: Option<serde_json::Value>,
}

#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct SceneFile {
    format: String,
    generator_version: u32,
    config: SynthConfig,
    seed: u64,
    identity: Identity,
    studio_light: StudioLight,
    train_degradation: Option<Degradation>,
    stats: TexelStats,
    given: TwoHandScene,
    num_texels: usize,
    train: ViewFile,
    novel_views: Vec<ViewFile>,
    novel_poses: Vec<ViewFile>,
}

fn view_file(v: &SynthView) -> Result<ViewFile, SynthError> {
    let keypoints = v.keypoints_2d()?;
    let plain = serde_json::from_str(&keypoints.to_plain_json())
        .map_err(|e| SynthError::Generate(format!("encoding the keypoints of {}: {e}", v.name)))?;
    Ok(ViewFile {
        name: v.name.clone(),
        family: v.family,
        hands: v.hands.clone(),
        light: v.light,
        keypoints_2d: Some(plain),
    })
}

/// Writes `scene` into `dir` (see the module docs).
pub(crate) fn write(scene: &SynthScene, dir: &Path) -> Result<(), SynthError> {
    std::fs::create_dir_all(dir).map_err(|e| SynthError::io(dir, e))?;
    let size = scene.config.size as usize;
    let t = scene.textures[0].len() / 3;
    let file = SceneFile {
        format: FORMAT.into(),
        generator_version: GENERATOR_VERSION,
        config: scene.config.clone(),
        seed: scene.seed,
        identity: scene.identity.clone(),
        studio_light: scene.studio_light,
        train_degradation: scene.train_degradation,
        stats: scene.stats,
        given: scene.given.clone(),
        num_texels: t,
        train: view_file(&scene.train)?,
        novel_views: scene
            .novel_views
            .iter()
            .map(view_file)
            .collect::<Result<_, _>>()?,
        novel_poses: scene
            .novel_poses
            .iter()
            .map(view_file)
            .collect::<Result<_, _>>()?,
    };
    let json_path = dir.join("scene.json");
    let json = serde_json::to_string_pretty(&file)
        .map_err(|e| SynthError::format(&json_path, format!("cannot encode: {e}")))?;

    // Exact data.
    let data_path = dir.join("data.safetensors");
    let mut entries: Vec<st::Entry> = Vec::new();
    for v in scene.views() {
        if v.image.len() != 3 * size * size || v.masks.iter().any(|m| m.len() != size * size) {
            return Err(SynthError::Generate(format!(
                "view {}: image or masks do not match the configured size {size}",
                v.name
            )));
        }
        entries.push(st::unit_entry(
            format!("{}/image", v.name),
            vec![3, size, size],
            &v.image,
        ));
        let mut masks = v.masks[0].clone();
        masks.extend_from_slice(&v.masks[1]);
        entries.push(st::unit_entry(
            format!("{}/masks", v.name),
            vec![2, size, size],
            &masks,
        ));
    }
    for (k, name) in ["texture_left", "texture_right"].iter().enumerate() {
        if scene.textures[k].len() != 3 * t {
            return Err(SynthError::Generate(
                "the two textures have different lengths".into(),
            ));
        }
        entries.push((
            name.to_string(),
            Dtype::F32,
            vec![3, t],
            f32_bytes(&scene.textures[k]),
        ));
    }
    // The exact copy of scene.json: every float as its bit pattern (serde_json's parser may be
    // off by an ulp; these strings are not parsed as numbers).
    let exact = serde_json::to_value(&file)
        .map(|v| serde_json::to_vec(&floats_to_bits(v)))
        .and_then(|r| r)
        .map_err(|e| SynthError::format(&data_path, format!("cannot encode the scene: {e}")))?;
    entries.push((EXACT.to_string(), Dtype::U8, vec![exact.len()], exact));
    let meta = HashMap::from([("format".to_string(), FORMAT.to_string())]);
    let bytes = st::serialize(&data_path, &entries, meta)?;

    // Pictures.
    let models = bitt_mesh::procedural_pair();
    let layouts = texture_layouts(&models, scene.config.texture_size)?;
    for v in scene.views() {
        bitt_texture::save_png8(&dir.join(format!("{}.png", v.name)), &v.image, size, size)?;
        let mut rgb = v.masks[0].clone();
        rgb.extend_from_slice(&v.masks[1]);
        rgb.extend(std::iter::repeat_n(0.0, size * size));
        bitt_texture::save_png8(&dir.join(format!("{}.mask.png", v.name)), &rgb, size, size)?;
    }
    for (k, name) in ["texture_left", "texture_right"].iter().enumerate() {
        let layout = &layouts[k];
        if layout.num_texels() != t {
            return Err(SynthError::Generate(format!(
                "the textures have {t} texels but the layout of texture_size {} has {}",
                scene.config.texture_size,
                layout.num_texels()
            )));
        }
        let img = layout.compact_to_image(&scene.textures[k], [0.0; 3])?;
        bitt_texture::save_png8(
            &dir.join(format!("{name}.png")),
            &img,
            layout.width,
            layout.height,
        )?;
    }
    write_atomically(&data_path, &bytes)?;
    // scene.json last: a folder with it is complete.
    write_atomically(&json_path, json.as_bytes())?;
    Ok(())
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, SynthError> {
    std::fs::read(path).map_err(|e| SynthError::io(path, e))
}

/// Reads a scene folder (see the module docs).
pub(crate) fn read(dir: &Path) -> Result<SynthScene, SynthError> {
    let json_path = dir.join("scene.json");
    let text = read_bytes(&json_path)?;
    let file: SceneFile = serde_json::from_slice(&text)
        .map_err(|e| SynthError::format(&json_path, format!("not a synthetic scene: {e}")))?;
    if file.format != FORMAT {
        return Err(SynthError::format(
            &json_path,
            format!("format is {:?}, expected {FORMAT:?}", file.format),
        ));
    }
    if file.generator_version != GENERATOR_VERSION {
        return Err(SynthError::format(
            &json_path,
            format!(
                "written by generator version {}, this is version {GENERATOR_VERSION}; \
                 regenerate the scene",
                file.generator_version
            ),
        ));
    }
    file.config
        .validate()
        .map_err(|e| SynthError::format(&json_path, e.to_string()))?;
    let seed = file.seed;
    let data_path = dir.join("data.safetensors");
    let bytes = read_bytes(&data_path)?;
    let r = st::Reader::open(&bytes, &data_path)?;
    let tensor = |name: &str, shape: &[usize]| -> Result<Vec<f32>, SynthError> {
        let want: Vec<Option<usize>> = shape.iter().copied().map(Some).collect();
        Ok(r.unit_f32s(name, Some(&want))?.1)
    };
    let exact = r.bytes(EXACT)?;
    let file: SceneFile = serde_json::from_slice::<serde_json::Value>(exact)
        .map_err(|e| e.to_string())
        .and_then(bits_to_floats)
        .and_then(|v| serde_json::from_value(v).map_err(|e| e.to_string()))
        .map_err(|e| SynthError::format(&data_path, format!("bad `{EXACT}`: {e}")))?;
    if file.generator_version != GENERATOR_VERSION || file.seed != seed {
        return Err(SynthError::format(
            &data_path,
            "does not belong to the scene.json beside it (version or seed differ)",
        ));
    }
    let size = file.config.size as usize;
    let view = |v: ViewFile| -> Result<SynthView, SynthError> {
        let image = tensor(&format!("{}/image", v.name), &[3, size, size])?;
        let mut masks = tensor(&format!("{}/masks", v.name), &[2, size, size])?;
        let right = masks.split_off(size * size);
        Ok(SynthView {
            name: v.name,
            family: v.family,
            hands: v.hands,
            light: v.light,
            image,
            masks: [masks, right],
        })
    };
    let t = file.num_texels;
    let textures = [
        tensor("texture_left", &[3, t])?,
        tensor("texture_right", &[3, t])?,
    ];
    if file.novel_views.len() != file.config.novel_views
        || file.novel_poses.len() != file.config.novel_poses
    {
        return Err(SynthError::format(
            &json_path,
            format!(
                "{} novel views and {} novel poses, but the configuration asks for {} and {}",
                file.novel_views.len(),
                file.novel_poses.len(),
                file.config.novel_views,
                file.config.novel_poses
            ),
        ));
    }
    Ok(SynthScene {
        train: view(file.train)?,
        novel_views: file
            .novel_views
            .into_iter()
            .map(view)
            .collect::<Result<_, _>>()?,
        novel_poses: file
            .novel_poses
            .into_iter()
            .map(view)
            .collect::<Result<_, _>>()?,
        config: file.config,
        seed: file.seed,
        identity: file.identity,
        studio_light: file.studio_light,
        train_degradation: file.train_degradation,
        given: file.given,
        textures,
        stats: file.stats,
    })
}

/// 64-bit FNV-1a.
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The folder under `cache_dir` that caches the scene of `config` and `seed` (the key
/// covers the configuration, the seed and [`GENERATOR_VERSION`]).
pub fn scene_cache_dir(config: &SynthConfig, seed: u64, cache_dir: &Path) -> PathBuf {
    let key = serde_json::to_string(config).unwrap_or_default();
    let hash = fnv1a(format!("{key}|{seed}|{GENERATOR_VERSION}").as_bytes());
    cache_dir.join(format!(
        "synth-v{GENERATOR_VERSION}-{seed:016x}-{hash:016x}"
    ))
}

/// The scene of `config` and `seed`: read from the cache under `cache_dir` when it is there
/// and readable, else generated on `device` and written there (into a temporary folder
/// renamed into place, so a half-written scene is never read).
///
/// # Errors
/// Generation failures, an unwritable cache folder.
pub fn cached_scene(
    config: &SynthConfig,
    seed: u64,
    cache_dir: &Path,
    device: &Device,
) -> Result<SynthScene, SynthError> {
    let dir = scene_cache_dir(config, seed, cache_dir);
    if dir.join("scene.json").is_file()
        && let Ok(scene) = read(&dir)
        && scene.config == *config
        && scene.seed == seed
    {
        return Ok(scene);
    }
    let scene = generate_scene(config, seed, device)?;
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = cache_dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    write(&scene, &tmp)?;
    if dir.exists() {
        // A stale or corrupt entry (or another process got there first): replace it.
        let _ = std::fs::remove_dir_all(&dir);
    }
    if let Err(e) = std::fs::rename(&tmp, &dir) {
        let _ = std::fs::remove_dir_all(&tmp);
        if !dir.join("scene.json").is_file() {
            return Err(SynthError::io(&dir, e));
        }
    }
    Ok(scene)
}
