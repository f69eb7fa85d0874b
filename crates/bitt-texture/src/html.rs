//! Loaders for HTML, the hand texture PCA model (Qian et al., ECCV 2020), from the user's own
//! licensed pickles (see `shared/formats.md`).
//!
//! - `model.pkl` (`model_wosr/` is the one BiTT uses): `mean` `(3T,)` on a 0..255 scale,
//!   `basis` `(3T, K)`, `index_map` `(3T,)` integers placing the compact vector into a flat
//!   `3 x S x S` image (`S = 1024`, `T = 206330`, `K = 101`).
//! - `uvs.pkl` / `uvs_right.pkl` / `uvs_left.pkl`: `verts_uvs` `(907, 2)` and `faces_uvs`
//!   `(1538, 3)`, one UV triangle per MANO face.
//!
//! # Row convention
//!
//! `index_map` entry `flat = c*S*S + col*S + row`: the reference code scatters the compact
//! vector into `img1d[index_map]`, then `img1d.reshape(3, S, S).transpose(2, 1, 0)` is the
//! `[row][col][c]` texture image it saves (row 0 first, i.e. at the top of the PNG) and
//! samples at `(2u - 1, 1 - 2v)` in `grid_sample` space, where `y = -1` is row 0. So HTML's
//! `row` *is* the image row with row 0 at the top (`v = 1`), exactly this crate's texel row:
//! texel `(row, col)` of the layout is `(flat % S, (flat / S) % S)`, with no flip.
//!
//! # Memory
//!
//! The pickle reader holds the whole file and the decoded arrays at once, so for HTML's
//! `f8` basis (618990 x 101, 500 MB) loading peaks at about 1.0 GB (file + `f8` arrays);
//! the `f8 -> f32` conversion then holds 750 MB (`f8` + `f32`), and the loaded model keeps
//! 250 MB. A texel order that differs between channels costs one more `f32` copy (+250 MB).

use std::path::{Path, PathBuf};

use bitt_mesh::UvLayout;
use bitt_mesh::glam::DVec2;
use bitt_pickle::{ArrayData, NdArray, Value};
use bitt_stdx::FileErrorExt;

use crate::TextureError;
use crate::layout::TextureLayout;
use crate::pca::TexturePca;

/// Side of HTML's square texture, in texels.
pub const HTML_TEXTURE_SIZE: usize = 1024;

/// HTML's colour scale: its mean and basis are on a 0..255 scale.
pub const HTML_SCALE: f32 = 1.0 / 255.0;

/// File name [`convert_html`] writes.
pub const HTML_SAFETENSORS: &str = "html.safetensors";

/// Loads an HTML `model.pkl` with a 1024 x 1024 texture (see [`load_html_model_sized`]).
pub fn load_html_model(path: &Path) -> Result<TexturePca, TextureError> {
    load_html_model_sized(path, HTML_TEXTURE_SIZE)
}

/// Loads an HTML-structured `model.pkl` whose `index_map` addresses a `3 x size x size`
/// image, as a [`TexturePca`] with scale 1/255.
///
/// The compact vector must hold the same set of texels in each of the three channels; the
/// layout takes the texel order of the red entries, and rows of `mean` / `basis` are
/// permuted into this crate's channel-major `[3, T]` order when the file orders channels
/// or texels differently (HTML itself writes three channel blocks in one texel order, which
/// needs no permutation). Fails with a [`bitt_stdx::FileError::Format`] naming the file and key when
/// a key is missing, an array has the wrong dtype or shape, or `index_map` is out of range,
/// repeats an entry or gives channels different texels.
pub fn load_html_model_sized(path: &Path, size: usize) -> Result<TexturePca, TextureError> {
    let fmt = |d: String| TextureError::format(path, d);
    let mut root = bitt_pickle::from_path(path)?;
    if root.as_dict().is_none() {
        return Err(fmt(format!(
            "is a {}, expected a dict with `mean`, `basis` and `index_map`",
            root.type_name()
        )));
    }
    let mean = take_array(&mut root, "mean", path)?;
    let basis = take_array(&mut root, "basis", path)?;
    let index_map = take_array(&mut root, "index_map", path)?;
    drop(root);

    let n = match mean.shape[..] {
        [n] if n > 0 && n % 3 == 0 => n,
        _ => {
            return Err(fmt(format!(
                "`mean` has shape {:?}, expected (3T,)",
                mean.shape
            )));
        }
    };
    let k = match basis.shape[..] {
        [rows, k] if rows == n && k > 0 => k,
        _ => {
            return Err(fmt(format!(
                "`basis` has shape {:?}, expected ({n}, K)",
                basis.shape
            )));
        }
    };
    if index_map.shape[..] != [n] {
        return Err(fmt(format!(
            "`index_map` has shape {:?}, expected ({n},)",
            index_map.shape
        )));
    }
    for (name, a) in [("mean", &mean), ("basis", &basis)] {
        if !matches!(a.data, ArrayData::F32(_) | ArrayData::F64(_)) {
            return Err(fmt(format!(
                "`{name}` has dtype {}, expected a float array",
                a.dtype()
            )));
        }
    }
    if matches!(
        index_map.data,
        ArrayData::F32(_) | ArrayData::F64(_) | ArrayData::Bool(_)
    ) {
        return Err(fmt(format!(
            "`index_map` has dtype {}, expected an integer array",
            index_map.dtype()
        )));
    }
    let flat = index_map.to_i64();
    drop(index_map);
    let (texels, row_for) = channel_blocks(&flat, size).map_err(fmt)?;
    drop(flat);

    let identity = row_for.iter().enumerate().all(|(j, &i)| i == j);
    let mut mean = mean.into_f32();
    if !identity {
        mean = row_for.iter().map(|&i| mean[i]).collect();
    }
    let mut basis = basis.into_f32();
    if !identity {
        let mut permuted = Vec::with_capacity(basis.len());
        for &i in &row_for {
            permuted.extend_from_slice(&basis[i * k..(i + 1) * k]);
        }
        basis = permuted;
    }
    let layout = TextureLayout::from_texels(size, size, texels, None)
        .map_err(|e| fmt(format!("`index_map`: {e}")))?;
    TexturePca::new(layout, mean, basis, k, HTML_SCALE).map_err(|e| fmt(e.to_string()))
}

/// Splits `index_map` into channels. Returns the layout texels (the red entries' order) and,
/// for each row `c*T + t` of the channel-major compact vector, the row of the file it comes
/// from.
/// What [`channel_blocks`] finds: the layout texels and the source row of each compact row.
type ChannelBlocks = (Vec<(u32, u32)>, Vec<usize>);

fn channel_blocks(flat: &[i64], size: usize) -> Result<ChannelBlocks, String> {
    let n = flat.len();
    let t = n / 3;
    let ss = size
        .checked_mul(size)
        .filter(|&s| s > 0 && s.checked_mul(3).is_some_and(|x| x < u32::MAX as usize))
        .ok_or_else(|| format!("texture size {size} is empty or too large"))?;
    let total = 3 * ss;
    // First entry seen at each flat position (duplicates) and compact texel of each pixel.
    let mut seen = vec![false; total];
    let mut texel_index = vec![u32::MAX; ss];
    let mut texels = Vec::with_capacity(t);
    let mut counts = [0usize; 3];
    let mut row_for = vec![usize::MAX; n];
    for (i, &f) in flat.iter().enumerate() {
        let fu = usize::try_from(f)
            .ok()
            .filter(|&fu| fu < total)
            .ok_or_else(|| {
                format!("`index_map` entry {i} = {f} is outside the 3x{size}x{size} image")
            })?;
        if std::mem::replace(&mut seen[fu], true) {
            return Err(format!(
                "`index_map` entry {i} = {f} repeats an earlier entry"
            ));
        }
        let (c, pixel) = (fu / ss, fu % ss);
        counts[c] += 1;
        if c == 0 {
            if texels.len() == t {
                return Err(format!(
                    "`index_map` has more than {t} red entries (a third of {n})"
                ));
            }
            texel_index[pixel] = texels.len() as u32;
            row_for[texels.len()] = i;
            // flat = c*S*S + col*S + row
            texels.push(((pixel % size) as u32, (pixel / size) as u32));
        }
    }
    if counts != [t; 3] {
        return Err(format!(
            "`index_map` has {} red, {} green and {} blue entries; expected {t} each",
            counts[0], counts[1], counts[2]
        ));
    }
    for (i, &f) in flat.iter().enumerate() {
        let fu = f as usize; // checked above
        let (c, pixel) = (fu / ss, fu % ss);
        if c == 0 {
            continue;
        }
        let ti = texel_index[pixel];
        if ti == u32::MAX {
            return Err(format!(
                "`index_map` entry {i} (channel {c}, row {}, col {}) is a texel the red \
                 channel does not have",
                pixel % size,
                pixel / size
            ));
        }
        row_for[c * t + ti as usize] = i;
    }
    Ok((texels, row_for))
}

/// Removes `key` from a pickled dict and returns its array (moved, not copied).
fn take_array(root: &mut Value, key: &str, path: &Path) -> Result<NdArray, TextureError> {
    let Value::Dict(items) = root else {
        return Err(TextureError::format(path, "expected a dict"));
    };
    let value = items
        .iter_mut()
        .find(|(k, _)| match k {
            Value::Str(s) => s == key,
            Value::Bytes(b) => b == key.as_bytes(),
            _ => false,
        })
        .map(|(_, v)| std::mem::replace(v, Value::None))
        .ok_or_else(|| TextureError::format(path, format!("missing key `{key}`")))?;
    match value {
        Value::Array(a) => Ok(a),
        other => Err(TextureError::format(
            path,
            format!("`{key}` is a {}, expected a numpy array", other.type_name()),
        )),
    }
}

/// Loads an HTML UV file (`uvs.pkl`, `uvs_right.pkl` or `uvs_left.pkl`): `verts_uvs`
/// `(n, 2)` floats (`v = 0` at the image bottom) and `faces_uvs` `(F, 3)` integers, one UV
/// triangle per mesh face. Fails when a key is missing, a shape or dtype is wrong, a
/// coordinate is not finite or a face indexes a missing UV vertex.
pub fn load_html_uvs(path: &Path) -> Result<UvLayout, TextureError> {
    let fmt = |d: String| TextureError::format(path, d);
    let mut root = bitt_pickle::from_path(path)?;
    if root.as_dict().is_none() {
        return Err(fmt(format!(
            "is a {}, expected a dict with `verts_uvs` and `faces_uvs`",
            root.type_name()
        )));
    }
    let verts = take_array(&mut root, "verts_uvs", path)?;
    let faces = take_array(&mut root, "faces_uvs", path)?;
    let nv = match verts.shape[..] {
        [nv, 2] if matches!(verts.data, ArrayData::F32(_) | ArrayData::F64(_)) => nv,
        _ => {
            return Err(fmt(format!(
                "`verts_uvs` is {} {:?}, expected floats (n, 2)",
                verts.dtype(),
                verts.shape
            )));
        }
    };
    if !matches!(faces.shape[..], [_, 3])
        || matches!(
            faces.data,
            ArrayData::F32(_) | ArrayData::F64(_) | ArrayData::Bool(_)
        )
    {
        return Err(fmt(format!(
            "`faces_uvs` is {} {:?}, expected integers (F, 3)",
            faces.dtype(),
            faces.shape
        )));
    }
    let uv = verts.into_f64();
    if let Some(i) = uv.iter().position(|x| !x.is_finite()) {
        return Err(fmt(format!(
            "`verts_uvs` value {i} is not finite ({})",
            uv[i]
        )));
    }
    let idx = faces.to_i64();
    let mut face_list = Vec::with_capacity(idx.len() / 3);
    for (f, c) in idx.chunks_exact(3).enumerate() {
        let mut tri = [0u32; 3];
        for (slot, &i) in tri.iter_mut().zip(c) {
            *slot = u32::try_from(i)
                .ok()
                .filter(|&i| (i as usize) < nv)
                .ok_or_else(|| {
                    fmt(format!(
                        "`faces_uvs` face {f} uses UV vertex {i}, but there are {nv}"
                    ))
                })?;
        }
        face_list.push(tri);
    }
    Ok(UvLayout {
        uvs: uv.chunks_exact(2).map(|p| DVec2::new(p[0], p[1])).collect(),
        faces: face_list,
    })
}

/// Converts the user's HTML `TextureBasis` folder to `out_dir/html.safetensors`: the model
/// from `model_dir/model_wosr/model.pkl` (or `model_dir/model.pkl`), with the right hand's
/// UV layout from `uvs_right.pkl` or `uvs.pkl` when one is there (both hands share UV
/// coordinates; only the left hand's face winding differs). Returns the path written.
pub fn convert_html(model_dir: &Path, out_dir: &Path) -> Result<PathBuf, TextureError> {
    let candidates = [
        model_dir.join("model_wosr").join("model.pkl"),
        model_dir.join("model.pkl"),
    ];
    let model_path = candidates.iter().find(|p| p.is_file()).ok_or_else(|| {
        TextureError::io(
            &candidates[0],
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no HTML model (also tried {})", candidates[1].display()),
            ),
        )
    })?;
    let mut model = load_html_model(model_path)?;
    let uv_path = ["uvs_right.pkl", "uvs.pkl"]
        .iter()
        .map(|n| model_dir.join(n))
        .find(|p| p.is_file());
    if let Some(p) = uv_path {
        model.layout.uv = Some(load_html_uvs(&p)?);
    }
    let out = out_dir.join(HTML_SAFETENSORS);
    model.save_safetensors(&out)?;
    Ok(out)
}
