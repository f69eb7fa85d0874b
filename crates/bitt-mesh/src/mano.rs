//! Loading the user's MANO models: `MANO_{LEFT,RIGHT}.pkl` as distributed, and this project's
//! safetensors conversion of them (`cargo xtask convert-mano`), which loads without the pickle.
//!
//! Facts about the files are in the project's `formats.md` notes: protocol-2 pickles with
//! latin-1 keys, a csc `J_regressor`, chumpy `shapedirs`, and a left file whose shapedirs
//! carry the well-known x-sign bug.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use bitt_pickle::{NdArray, Value};
use glam::{DVec2, DVec3};
use safetensors::Dtype;

use crate::MeshError;
use crate::model::{
    HandModel, MANO_FINGERTIPS, NUM_BETAS, NUM_JOINTS, NUM_POSE, NUM_POSE_FEATURES, Side, UvLayout,
};
use bitt_stdx::FileErrorExt;
use bitt_stdx::st::{self, Entry, f64_bytes, u32_bytes};

/// Value of `kintree_table[0, 0]` in MANO files: the root's "no parent" marker (`u32::MAX`).
const MANO_ROOT_PARENT: i64 = 4_294_967_295;

/// A left and a right hand model loaded together.
#[derive(Debug, Clone, PartialEq)]
pub struct HandPair {
    /// The left hand.
    pub left: HandModel,
    /// The right hand.
    pub right: HandModel,
}

impl HandPair {
    /// The model of one side.
    pub fn get(&self, side: Side) -> &HandModel {
        match side {
            Side::Left => &self.left,
            Side::Right => &self.right,
        }
    }
}

fn key<'a>(root: &'a Value, name: &str, path: &Path) -> Result<&'a Value, MeshError> {
    root.get(name).ok_or_else(|| {
        MeshError::format(
            path,
            format!("missing key `{name}` (is this a MANO model file?)"),
        )
    })
}

fn array<'a>(
    root: &'a Value,
    name: &str,
    shape: &[usize],
    path: &Path,
) -> Result<&'a NdArray, MeshError> {
    let v = key(root, name, path)?;
    let a = v.as_array().ok_or_else(|| {
        MeshError::format(
            path,
            format!("`{name}` is a {}, expected a numpy array", v.type_name()),
        )
    })?;
    if a.shape != shape {
        return Err(MeshError::format(
            path,
            format!("`{name}` has shape {:?}, expected {shape:?}", a.shape),
        ));
    }
    Ok(a)
}

/// Builds a [`HandModel`] from a parsed MANO pickle.
///
/// `path` is only used in error messages. The vertex count is read from `v_template`, so any
/// MANO-structured file loads; the fingertip vertices are MANO's and must exist.
pub(crate) fn hand_model_from_pickle(
    root: &Value,
    side: Side,
    path: &Path,
) -> Result<HandModel, MeshError> {
    let v_template = key(root, "v_template", path)?
        .as_array()
        .ok_or_else(|| MeshError::format(path, "`v_template` is not a numpy array"))?;
    let nv = match v_template.shape.as_slice() {
        [n, 3] => *n,
        s => {
            return Err(MeshError::format(
                path,
                format!("`v_template` has shape {s:?}, expected [V, 3]"),
            ));
        }
    };
    let to_vec3 = |a: &NdArray| {
        a.to_f64()
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect::<Vec<_>>()
    };

    let faces_a = key(root, "f", path)?
        .as_array()
        .ok_or_else(|| MeshError::format(path, "`f` is not a numpy array"))?;
    if faces_a.shape.len() != 2 || faces_a.shape[1] != 3 {
        return Err(MeshError::format(
            path,
            format!("`f` has shape {:?}, expected [F, 3]", faces_a.shape),
        ));
    }
    let mut faces = Vec::with_capacity(faces_a.shape[0]);
    for c in faces_a.to_i64().chunks_exact(3) {
        let idx = |x: i64| {
            u32::try_from(x)
                .ok()
                .filter(|&i| (i as usize) < nv)
                .ok_or_else(|| {
                    MeshError::format(path, format!("`f` holds vertex index {x}, outside 0..{nv}"))
                })
        };
        faces.push([idx(c[0])?, idx(c[1])?, idx(c[2])?]);
    }

    let weights = array(root, "weights", &[nv, NUM_JOINTS], path)?.to_f64();
    let posedirs = array(root, "posedirs", &[nv, 3, NUM_POSE_FEATURES], path)?.to_f64();
    let components = array(root, "hands_components", &[NUM_POSE, NUM_POSE], path)?.to_f64();
    let mean = array(root, "hands_mean", &[NUM_POSE], path)?.to_f64();

    // shapedirs: the chumpy Select resolves to [V, 3, 10]; plain arrays with more betas are cut.
    let shapedirs_v = key(root, "shapedirs", path)?;
    let shapedirs_a = shapedirs_v.as_array().ok_or_else(|| {
        MeshError::format(
            path,
            format!(
                "`shapedirs` is a {}, expected an array",
                shapedirs_v.type_name()
            ),
        )
    })?;
    let nb = match shapedirs_a.shape.as_slice() {
        [n, 3, b] if *n == nv && *b >= NUM_BETAS => *b,
        s => {
            return Err(MeshError::format(
                path,
                format!("`shapedirs` has shape {s:?}, expected [{nv}, 3, >={NUM_BETAS}]"),
            ));
        }
    };
    let all = shapedirs_a.to_f64();
    let shape_dirs: Vec<f64> = all
        .chunks_exact(nb)
        .flat_map(|row| row[..NUM_BETAS].iter().copied())
        .collect();

    // J_regressor: csc (or dense) [16, V].
    let jr = key(root, "J_regressor", path)?;
    let joint_regressor = match jr {
        Value::Sparse(csc) => {
            if csc.shape != (NUM_JOINTS, nv) {
                return Err(MeshError::format(
                    path,
                    format!(
                        "`J_regressor` has shape {:?}, expected ({NUM_JOINTS}, {nv})",
                        csc.shape
                    ),
                ));
            }
            csc.to_dense_row_major()
                .map_err(|e| MeshError::format(path, format!("`J_regressor`: {e}")))?
        }
        Value::Array(a) if a.shape == [NUM_JOINTS, nv] => a.to_f64(),
        other => {
            return Err(MeshError::format(
                path,
                format!(
                    "`J_regressor` is a {}, expected a [{NUM_JOINTS}, {nv}] sparse matrix",
                    other.type_name()
                ),
            ));
        }
    };

    let kintree = array(root, "kintree_table", &[2, NUM_JOINTS], path)?.to_i64();
    let mut parents = Vec::with_capacity(NUM_JOINTS);
    for (j, &p) in kintree[..NUM_JOINTS].iter().enumerate() {
        parents.push(match p {
            MANO_ROOT_PARENT | -1 if j == 0 => None,
            p if p >= 0 && (p as usize) < j => Some(p as usize),
            p => {
                return Err(MeshError::format(
                    path,
                    format!("`kintree_table` gives joint {j} the parent {p}"),
                ));
            }
        });
    }

    let model = HandModel {
        side,
        source: path.display().to_string(),
        v_template: to_vec3(v_template),
        faces,
        joint_regressor,
        skinning_weights: weights,
        parents,
        shape_dirs,
        pose_dirs: posedirs,
        pose_pca_components: components,
        pose_pca_mean: mean,
        fingertips: MANO_FINGERTIPS,
        uv: None,
    };
    model.validate()?;
    Ok(model)
}

/// Loads one `MANO_*.pkl` file as distributed.
pub fn load_mano_pkl(path: &Path, side: Side) -> Result<HandModel, MeshError> {
    let root = bitt_pickle::from_path(path)?;
    hand_model_from_pickle(&root, side, path)
}

/// Applies the well-known left-hand fix: when the left model's x shape directions equal the
/// right's (`sum |L - R| < 1` over `shapedirs[:, 0, :]`), the left ones are negated.
///
/// Returns whether the fix was applied. Idempotent: after the fix the two differ.
pub(crate) fn fix_left_shapedirs(left: &mut HandModel, right: &HandModel) -> bool {
    if left.shape_dirs.len() != right.shape_dirs.len() {
        return false;
    }
    let x_rows = |v: usize| (v * 3) * NUM_BETAS..(v * 3 + 1) * NUM_BETAS;
    let diff: f64 = (0..left.num_vertices())
        .flat_map(x_rows)
        .map(|i| (left.shape_dirs[i] - right.shape_dirs[i]).abs())
        .sum();
    if diff >= 1.0 {
        return false;
    }
    for v in 0..left.num_vertices() {
        for i in x_rows(v) {
            left.shape_dirs[i] = -left.shape_dirs[i];
        }
    }
    true
}

/// The files a model directory may hold for `side`, in the order they are tried.
fn candidates(dir: &Path, side: Side) -> [PathBuf; 2] {
    let stem = match side {
        Side::Left => "MANO_LEFT",
        Side::Right => "MANO_RIGHT",
    };
    [
        dir.join(format!("{stem}.safetensors")),
        dir.join(format!("{stem}.pkl")),
    ]
}

/// `bitt convert-mano`: reads `MANO_LEFT.pkl` and `MANO_RIGHT.pkl` in `model_dir` (checking
/// them fully), fixes the left shapedirs' x-sign when needed, and writes both as
/// safetensors into `out`; `say` is told of the fix. Returns the files written.
///
/// # Errors
/// A pickle missing or not a MANO model, or a file that cannot be written.
pub fn convert_mano_dir(
    model_dir: &Path,
    out: &Path,
    mut say: impl FnMut(&str),
) -> Result<Vec<PathBuf>, MeshError> {
    let mut written = Vec::new();
    let mut pair = Vec::new();
    for (side, name) in [(Side::Left, "MANO_LEFT"), (Side::Right, "MANO_RIGHT")] {
        let src = model_dir.join(format!("{name}.pkl"));
        if !src.is_file() {
            return Err(MeshError::Invalid(format!(
                "{} not found (expected MANO_LEFT.pkl and MANO_RIGHT.pkl as distributed)",
                src.display()
            )));
        }
        pair.push((load_mano_pkl(&src, side)?, name));
    }
    let right = pair[1].0.clone();
    if fix_left_shapedirs(&mut pair[0].0, &right) {
        say("left shapedirs: applied the well-known x-sign fix");
    }
    for (model, name) in &pair {
        let dst = out.join(format!("{name}.safetensors"));
        save_safetensors(model, &dst)?;
        written.push(dst);
    }
    Ok(written)
}

/// Loads a hand model from a `.pkl` (MANO as distributed) or `.safetensors` (converted) file.
pub(crate) fn load_hand_model(path: &Path, side: Side) -> Result<HandModel, MeshError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("safetensors") => load_safetensors(path),
        _ => load_mano_pkl(path, side),
    }
}

/// Loads both hands from a folder holding `MANO_LEFT`/`MANO_RIGHT` as `.safetensors`
/// (preferred, faster) or `.pkl`, and applies [`fix_left_shapedirs`].
pub fn load_model_dir(dir: &Path) -> Result<HandPair, MeshError> {
    if !dir.is_dir() {
        return Err(MeshError::format(
            dir,
            "is not a folder (expected one holding MANO_LEFT.pkl and MANO_RIGHT.pkl)",
        ));
    }
    // Find both files before parsing either, so a missing one is reported at once.
    let find = |side: Side| {
        candidates(dir, side)
            .into_iter()
            .find(|p| p.is_file())
            .ok_or_else(|| {
                let [a, b] = candidates(dir, side);
                MeshError::format(
                    dir,
                    format!("holds neither {} nor {}", file_name(&a), file_name(&b)),
                )
            })
    };
    let (left_path, right_path) = (find(Side::Left)?, find(Side::Right)?);
    let load = |side: Side| {
        load_hand_model(
            if side == Side::Left {
                &left_path
            } else {
                &right_path
            },
            side,
        )
    };
    let right = load(Side::Right)?;
    let mut left = load(Side::Left)?;
    if left.side != Side::Left || right.side != Side::Right {
        return Err(MeshError::format(
            dir,
            "a converted model file holds the wrong hand",
        ));
    }
    fix_left_shapedirs(&mut left, &right);
    Ok(HandPair { left, right })
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Format tag written into the metadata of this project's model files.
pub(crate) const SAFETENSORS_FORMAT: &str = "bitt-hand-model/1";

/// Serializes a hand model to safetensors bytes (f64 arrays, u32 indices, i64 parents).
pub fn to_safetensors(model: &HandModel) -> Result<Vec<u8>, MeshError> {
    let nv = model.num_vertices();
    let nf = model.faces.len();
    let mut tensors: Vec<Entry> = vec![
        (
            "v_template".into(),
            Dtype::F64,
            vec![nv, 3],
            f64_bytes(model.v_template.iter().flat_map(|p| p.to_array())),
        ),
        (
            "faces".into(),
            Dtype::U32,
            vec![nf, 3],
            u32_bytes(model.faces.iter().flatten().copied()),
        ),
        (
            "joint_regressor".into(),
            Dtype::F64,
            vec![NUM_JOINTS, nv],
            f64_bytes(model.joint_regressor.iter().copied()),
        ),
        (
            "skinning_weights".into(),
            Dtype::F64,
            vec![nv, NUM_JOINTS],
            f64_bytes(model.skinning_weights.iter().copied()),
        ),
        (
            "parents".into(),
            Dtype::I64,
            vec![NUM_JOINTS],
            model
                .parents
                .iter()
                .flat_map(|p| p.map_or(-1i64, |p| p as i64).to_le_bytes())
                .collect(),
        ),
        (
            "shape_dirs".into(),
            Dtype::F64,
            vec![nv, 3, NUM_BETAS],
            f64_bytes(model.shape_dirs.iter().copied()),
        ),
        (
            "pose_dirs".into(),
            Dtype::F64,
            vec![nv, 3, NUM_POSE_FEATURES],
            f64_bytes(model.pose_dirs.iter().copied()),
        ),
        (
            "pose_pca_components".into(),
            Dtype::F64,
            vec![NUM_POSE, NUM_POSE],
            f64_bytes(model.pose_pca_components.iter().copied()),
        ),
        (
            "pose_pca_mean".into(),
            Dtype::F64,
            vec![NUM_POSE],
            f64_bytes(model.pose_pca_mean.iter().copied()),
        ),
        (
            "fingertips".into(),
            Dtype::U32,
            vec![5],
            u32_bytes(model.fingertips),
        ),
    ];
    if let Some(uv) = &model.uv {
        tensors.push((
            "uv_coords".into(),
            Dtype::F64,
            vec![uv.uvs.len(), 2],
            f64_bytes(uv.uvs.iter().flat_map(|p| p.to_array())),
        ));
        tensors.push((
            "uv_faces".into(),
            Dtype::U32,
            vec![uv.faces.len(), 3],
            u32_bytes(uv.faces.iter().flatten().copied()),
        ));
    }
    let metadata = HashMap::from([
        ("format".to_string(), SAFETENSORS_FORMAT.to_string()),
        ("side".to_string(), model.side.as_str().to_string()),
        ("source".to_string(), model.source.clone()),
    ]);
    Ok(st::serialize(Path::new(&model.source), &tensors, metadata)?)
}

/// Writes a hand model as safetensors, atomically (a temporary file renamed into place).
pub fn save_safetensors(model: &HandModel, path: &Path) -> Result<(), MeshError> {
    let bytes = to_safetensors(model)?;
    bitt_stdx::write_atomically(path, &bytes)?;
    Ok(())
}

/// Loads a hand model written by [`save_safetensors`].
pub fn load_safetensors(path: &Path) -> Result<HandModel, MeshError> {
    let bytes = std::fs::read(path).map_err(|e| MeshError::io(path, e))?;
    from_safetensors(&bytes, path)
}

/// Parses safetensors bytes written by [`to_safetensors`]; `path` names them in errors.
pub fn from_safetensors(bytes: &[u8], path: &Path) -> Result<HandModel, MeshError> {
    let r = st::Reader::open(bytes, path)?;
    let meta = r.metadata();
    if meta.get("format").map(String::as_str) != Some(SAFETENSORS_FORMAT) {
        return Err(r
            .err(format!(
                "is not a bitt hand model (metadata format {:?}, expected {SAFETENSORS_FORMAT:?})",
                meta.get("format")
            ))
            .into());
    }
    let side = match meta.get("side").map(String::as_str) {
        Some("left") => Side::Left,
        Some("right") => Side::Right,
        other => {
            return Err(r
                .err(format!(
                    "metadata `side` is {other:?}, expected \"left\" or \"right\""
                ))
                .into());
        }
    };
    let (vs, v) = r.values::<f64>("v_template", &[None, Some(3)])?;
    let nv = vs[0];
    let (_, faces) = r.values::<u32>("faces", &[None, Some(3)])?;
    let (_, joint_regressor) = r.values::<f64>("joint_regressor", &[Some(NUM_JOINTS), Some(nv)])?;
    let (_, skinning_weights) =
        r.values::<f64>("skinning_weights", &[Some(nv), Some(NUM_JOINTS)])?;
    let (_, parents) = r.values::<i64>("parents", &[Some(NUM_JOINTS)])?;
    let parents = parents
        .into_iter()
        .map(|p| usize::try_from(p).ok())
        .collect();
    let (_, shape_dirs) = r.values::<f64>("shape_dirs", &[Some(nv), Some(3), Some(NUM_BETAS)])?;
    let (_, pose_dirs) =
        r.values::<f64>("pose_dirs", &[Some(nv), Some(3), Some(NUM_POSE_FEATURES)])?;
    let (_, pose_pca_components) =
        r.values::<f64>("pose_pca_components", &[Some(NUM_POSE), Some(NUM_POSE)])?;
    let (_, pose_pca_mean) = r.values::<f64>("pose_pca_mean", &[Some(NUM_POSE)])?;
    let (_, tips) = r.values::<u32>("fingertips", &[Some(5)])?;
    let uv = if r.has("uv_coords") {
        let (_, uvs) = r.values::<f64>("uv_coords", &[None, Some(2)])?;
        let (_, uv_faces) = r.values::<u32>("uv_faces", &[None, Some(3)])?;
        Some(UvLayout {
            uvs: uvs
                .chunks_exact(2)
                .map(|c| DVec2::new(c[0], c[1]))
                .collect(),
            faces: uv_faces
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        })
    } else {
        None
    };
    let model = HandModel {
        side,
        source: path.display().to_string(),
        v_template: v
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect(),
        faces: faces.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        joint_regressor,
        skinning_weights,
        parents,
        shape_dirs,
        pose_dirs,
        pose_pca_components,
        pose_pca_mean,
        fingertips: [tips[0], tips[1], tips[2], tips[3], tips[4]],
        uv,
    };
    model.validate()?;
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::default_hand;

    #[test]
    fn safetensors_round_trip_is_exact() {
        let model = default_hand(Side::Left);
        let bytes = to_safetensors(&model).unwrap();
        let back = from_safetensors(&bytes, Path::new("mem.safetensors")).unwrap();
        assert_eq!(back.side, Side::Left);
        assert_eq!(back.v_template, model.v_template);
        assert_eq!(back.faces, model.faces);
        assert_eq!(back.skinning_weights, model.skinning_weights);
        assert_eq!(back.parents, model.parents);
        assert_eq!(back.uv, model.uv);
        assert_eq!(back.fingertips, model.fingertips);
    }

    #[test]
    fn corrupt_safetensors_are_named_errors() {
        let model = default_hand(Side::Right);
        let bytes = to_safetensors(&model).unwrap();
        let e =
            from_safetensors(&bytes[..bytes.len() / 2], Path::new("half.safetensors")).unwrap_err();
        assert!(e.to_string().contains("half.safetensors"), "{e}");
        let e = from_safetensors(b"not at all", Path::new("junk.safetensors")).unwrap_err();
        assert!(e.to_string().contains("junk.safetensors"), "{e}");
    }

    #[test]
    fn left_fix_applies_once() {
        let right = default_hand(Side::Right);
        let mut left = right.clone();
        left.side = Side::Left;
        assert!(fix_left_shapedirs(&mut left, &right));
        assert!(
            !fix_left_shapedirs(&mut left, &right),
            "fix must be idempotent"
        );
        // Any non-zero x direction flips sign; y and z rows are untouched.
        let i = (0..left.shape_dirs.len())
            .find(|&i| (i / NUM_BETAS).is_multiple_of(3) && right.shape_dirs[i] != 0.0)
            .unwrap();
        assert_eq!(left.shape_dirs[i], -right.shape_dirs[i]);
        let j = (0..left.shape_dirs.len())
            .find(|&i| (i / NUM_BETAS) % 3 == 1)
            .unwrap();
        assert_eq!(left.shape_dirs[j], right.shape_dirs[j]);
    }
}
