//! Small safetensors helpers shared by the texture files of this crate: little-endian byte
//! conversions, an atomic writer and a reader that checks formats, dtypes and shapes.

use std::collections::HashMap;
use std::path::Path;

use safetensors::{Dtype, SafeTensors};

use crate::TextureError;

/// One tensor to write: name, dtype, shape, little-endian bytes.
pub(crate) type Entry = (String, Dtype, Vec<usize>, Vec<u8>);

pub(crate) fn f32_bytes(values: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(values.len() * 4);
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

pub(crate) fn f64_bytes(values: impl IntoIterator<Item = f64>) -> Vec<u8> {
    values.into_iter().flat_map(f64::to_le_bytes).collect()
}

pub(crate) fn u32_bytes(values: impl IntoIterator<Item = u32>) -> Vec<u8> {
    values.into_iter().flat_map(u32::to_le_bytes).collect()
}

/// Serializes `tensors` with `metadata` (which must name the `format`) and writes them to
/// `path` atomically.
pub(crate) fn write(
    path: &Path,
    tensors: &[Entry],
    metadata: HashMap<String, String>,
) -> Result<(), TextureError> {
    let mut views = Vec::with_capacity(tensors.len());
    for (name, dtype, shape, bytes) in tensors {
        let view = safetensors::tensor::TensorView::new(*dtype, shape.clone(), bytes)
            .map_err(|e| TextureError::format(path, format!("cannot encode `{name}`: {e}")))?;
        views.push((name.clone(), view));
    }
    let bytes = safetensors::serialize(views, Some(metadata))
        .map_err(|e| TextureError::format(path, format!("cannot encode: {e}")))?;
    bitt_mesh::export::write_atomically(path, &bytes)?;
    Ok(())
}

/// A parsed safetensors file of a known `format`.
pub(crate) struct Reader<'a> {
    st: SafeTensors<'a>,
    meta: HashMap<String, String>,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    /// Parses `bytes` (read from `path`) and checks that the metadata `format` is `format`.
    pub(crate) fn new(bytes: &'a [u8], path: &'a Path, format: &str) -> Result<Self, TextureError> {
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| TextureError::format(path, format!("not a safetensors file: {e}")))?;
        let (_, meta) = SafeTensors::read_metadata(bytes)
            .map_err(|e| TextureError::format(path, format!("bad safetensors header: {e}")))?;
        let meta = meta.metadata().clone().unwrap_or_default();
        let found = meta.get("format").cloned();
        if found.as_deref() != Some(format) {
            return Err(TextureError::format(
                path,
                format!("metadata format is {found:?}, expected {format:?}"),
            ));
        }
        Ok(Reader { st, meta, path })
    }

    pub(crate) fn err(&self, detail: impl Into<String>) -> TextureError {
        TextureError::format(self.path, detail)
    }

    pub(crate) fn has(&self, name: &str) -> bool {
        self.st.names().contains(&name)
    }

    /// A metadata entry parsed as `T`.
    pub(crate) fn meta<T: std::str::FromStr>(&self, key: &str) -> Result<T, TextureError> {
        let v = self
            .meta
            .get(key)
            .ok_or_else(|| self.err(format!("missing metadata `{key}`")))?;
        v.parse()
            .map_err(|_| self.err(format!("metadata `{key}` = {v:?} is not valid")))
    }

    /// The raw bytes of tensor `name` after checking its dtype and shape (`None` entries
    /// of `want` match any size); returns the shape too.
    fn raw(
        &self,
        name: &str,
        dtype: Dtype,
        want: &[Option<usize>],
    ) -> Result<(Vec<usize>, &'a [u8]), TextureError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| self.err(format!("missing tensor `{name}`")))?;
        if t.dtype() != dtype {
            return Err(self.err(format!(
                "tensor `{name}` is {:?}, expected {dtype:?}",
                t.dtype()
            )));
        }
        let shape = t.shape().to_vec();
        let ok = shape.len() == want.len()
            && shape
                .iter()
                .zip(want)
                .all(|(g, w)| w.is_none_or(|w| w == *g));
        if !ok {
            let want: Vec<String> = want
                .iter()
                .map(|w| w.map_or("N".to_string(), |w| w.to_string()))
                .collect();
            return Err(self.err(format!(
                "tensor `{name}` has shape {shape:?}, expected [{}]",
                want.join(", ")
            )));
        }
        Ok((shape, t.data()))
    }

    pub(crate) fn f32s(
        &self,
        name: &str,
        want: &[Option<usize>],
    ) -> Result<(Vec<usize>, Vec<f32>), TextureError> {
        let (shape, b) = self.raw(name, Dtype::F32, want)?;
        let v = b
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok((shape, v))
    }

    pub(crate) fn f64s(
        &self,
        name: &str,
        want: &[Option<usize>],
    ) -> Result<(Vec<usize>, Vec<f64>), TextureError> {
        let (shape, b) = self.raw(name, Dtype::F64, want)?;
        let v = b
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
            .collect();
        Ok((shape, v))
    }

    pub(crate) fn u32s(
        &self,
        name: &str,
        want: &[Option<usize>],
    ) -> Result<(Vec<usize>, Vec<u32>), TextureError> {
        let (shape, b) = self.raw(name, Dtype::U32, want)?;
        let v = b
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok((shape, v))
    }
}

/// Reads a whole file, naming it in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, TextureError> {
    std::fs::read(path).map_err(|e| TextureError::io(path, e))
}
