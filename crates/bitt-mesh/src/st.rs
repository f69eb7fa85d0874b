//! Safetensors files: the one checked reader (metadata format, dtype, shape, finite values)
//! and the one writer (encoded, then written atomically) that every crate's files go through.
//! Errors are [`FileError::Format`] naming the file and the tensor.

use std::collections::HashMap;
use std::path::Path;

use safetensors::{Dtype, SafeTensors};

use crate::{FileError, MeshError};

/// One tensor to write: name, dtype, shape, little-endian bytes.
pub type Entry = (String, Dtype, Vec<usize>, Vec<u8>);

/// `f32` values as little-endian bytes.
pub fn f32_bytes(values: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(values.len() * 4);
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// `f64` values as little-endian bytes.
pub fn f64_bytes(values: impl IntoIterator<Item = f64>) -> Vec<u8> {
    values.into_iter().flat_map(f64::to_le_bytes).collect()
}

/// `u32` values as little-endian bytes.
pub fn u32_bytes(values: impl IntoIterator<Item = u32>) -> Vec<u8> {
    values.into_iter().flat_map(u32::to_le_bytes).collect()
}

/// Serializes `tensors` with `metadata`; `path` names the file in errors.
///
/// # Errors
/// A tensor whose bytes do not fit its dtype and shape.
pub fn serialize(
    path: &Path,
    tensors: &[Entry],
    metadata: HashMap<String, String>,
) -> Result<Vec<u8>, FileError> {
    let mut views = Vec::with_capacity(tensors.len());
    for (name, dtype, shape, bytes) in tensors {
        let view = safetensors::tensor::TensorView::new(*dtype, shape.clone(), bytes)
            .map_err(|e| FileError::format(path, format!("cannot encode `{name}`: {e}")))?;
        views.push((name.clone(), view));
    }
    let bytes = safetensors::serialize(views, Some(metadata))
        .map_err(|e| FileError::format(path, format!("cannot encode: {e}")))?;
    Ok(sorted_header(bytes))
}

/// The same file with its JSON header's keys in sorted order. `safetensors` writes the
/// metadata from a `HashMap`, whose order changes from one map to the next, so the same
/// content would give different bytes; sorted, equal content gives equal files. The
/// header keeps its length (the same keys and values, reordered), so the tensor data and
/// their offsets are untouched.
fn sorted_header(mut bytes: Vec<u8>) -> Vec<u8> {
    let Some(len) = bytes
        .get(..8)
        .and_then(|b| <[u8; 8]>::try_from(b).ok())
        .and_then(|b| usize::try_from(u64::from_le_bytes(b)).ok())
    else {
        return bytes;
    };
    let Some(header) = bytes.get(8..8 + len) else {
        return bytes;
    };
    // serde_json's `Map` is a `BTreeMap` here (no `preserve_order`): keys come out sorted.
    let Ok(value) = serde_json::from_slice::<serde_json::Value>(header) else {
        return bytes;
    };
    let Ok(mut sorted) = serde_json::to_vec(&value) else {
        return bytes;
    };
    if sorted.len() > len {
        return bytes;
    }
    sorted.resize(len, b' ');
    bytes[8..8 + len].copy_from_slice(&sorted);
    bytes
}

/// Serializes `tensors` with `metadata` and writes them to `path` atomically
/// ([`crate::export::write_atomically`]).
///
/// # Errors
/// As [`serialize`], or the file cannot be written.
pub fn write(
    path: &Path,
    tensors: &[Entry],
    metadata: HashMap<String, String>,
) -> Result<(), MeshError> {
    let bytes = serialize(path, tensors, metadata)?;
    crate::export::write_atomically(path, &bytes)
}

/// Reads a whole file, naming it in the error.
///
/// # Errors
/// The file cannot be read.
pub fn read_file(path: &Path) -> Result<Vec<u8>, FileError> {
    std::fs::read(path).map_err(|e| FileError::io(path, e))
}

/// `Ok` when `got` has `want`'s rank and every `Some` size of `want`; otherwise what differs,
/// naming the tensor.
///
/// # Errors
/// The shapes differ.
pub fn check_shape(name: &str, got: &[usize], want: &[Option<usize>]) -> Result<(), String> {
    let ok =
        got.len() == want.len() && got.iter().zip(want).all(|(g, w)| w.is_none_or(|w| w == *g));
    if ok {
        return Ok(());
    }
    let want: Vec<String> = want
        .iter()
        .map(|w| w.map_or("N".to_string(), |w| w.to_string()))
        .collect();
    Err(format!(
        "tensor `{name}` has shape {got:?}, expected [{}]",
        want.join(", ")
    ))
}

/// A parsed safetensors file, with its metadata.
#[derive(Debug)]
pub struct Reader<'a> {
    st: SafeTensors<'a>,
    meta: HashMap<String, String>,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    /// Parses `bytes` (read from `path`) and checks that the metadata `format` is `format`.
    ///
    /// # Errors
    /// Not a safetensors file, or another format.
    pub fn new(bytes: &'a [u8], path: &'a Path, format: &str) -> Result<Self, FileError> {
        let reader = Self::open(bytes, path)?;
        let found = reader.meta.get("format").cloned();
        if found.as_deref() != Some(format) {
            return Err(reader.err(format!("metadata format is {found:?}, expected {format:?}")));
        }
        Ok(reader)
    }

    /// Parses `bytes` (read from `path`) whatever its metadata.
    ///
    /// # Errors
    /// Not a safetensors file.
    pub fn open(bytes: &'a [u8], path: &'a Path) -> Result<Self, FileError> {
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| FileError::format(path, format!("not a safetensors file: {e}")))?;
        let (_, meta) = SafeTensors::read_metadata(bytes)
            .map_err(|e| FileError::format(path, format!("bad safetensors header: {e}")))?;
        let meta = meta.metadata().clone().unwrap_or_default();
        Ok(Reader { st, meta, path })
    }

    /// A [`FileError::Format`] naming this file.
    pub fn err(&self, detail: impl Into<String>) -> FileError {
        FileError::format(self.path, detail)
    }

    /// Whether the file holds tensor `name`.
    pub fn has(&self, name: &str) -> bool {
        self.st.names().contains(&name)
    }

    /// The names of the tensors the file holds.
    pub fn names(&self) -> Vec<&str> {
        self.st.names()
    }

    /// The metadata (empty when the file has none).
    pub fn metadata(&self) -> &HashMap<String, String> {
        &self.meta
    }

    /// A metadata entry parsed as `T`.
    ///
    /// # Errors
    /// The entry is missing or does not parse.
    pub fn meta<T: std::str::FromStr>(&self, key: &str) -> Result<T, FileError> {
        let v = self
            .meta
            .get(key)
            .ok_or_else(|| self.err(format!("missing metadata `{key}`")))?;
        v.parse()
            .map_err(|_| self.err(format!("metadata `{key}` = {v:?} is not valid")))
    }

    /// The bytes of tensor `name`, whatever its dtype and shape.
    ///
    /// # Errors
    /// The tensor is missing.
    pub fn bytes(&self, name: &str) -> Result<&'a [u8], FileError> {
        self.st
            .tensor(name)
            .map(|t| t.data())
            .map_err(|_| self.err(format!("missing tensor `{name}`")))
    }

    /// The raw bytes of tensor `name` after checking its dtype and shape (`None` entries
    /// of `want`, or `want` itself, match any size); returns the shape too.
    fn raw(
        &self,
        name: &str,
        dtype: Dtype,
        want: Option<&[Option<usize>]>,
    ) -> Result<(Vec<usize>, &'a [u8]), FileError> {
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
        if let Some(want) = want {
            check_shape(name, &shape, want).map_err(|d| self.err(d))?;
        }
        Ok((shape, t.data()))
    }

    /// Tensor `name` as values of `T`, checked to be of `T`'s dtype and of shape `want`.
    ///
    /// # Errors
    /// A missing tensor, another dtype or shape.
    pub fn values<T: Element>(
        &self,
        name: &str,
        want: &[Option<usize>],
    ) -> Result<(Vec<usize>, Vec<T>), FileError> {
        let (shape, b) = self.raw(name, T::DTYPE, Some(want))?;
        Ok((shape, from_le(b)))
    }

    /// Tensor `name` as finite `f32` values of any shape (`want = None`) or of shape `want`.
    ///
    /// # Errors
    /// A missing tensor, another dtype or shape, a non-finite value (its index named).
    pub fn finite_f32s(
        &self,
        name: &str,
        want: Option<&[Option<usize>]>,
    ) -> Result<(Vec<usize>, Vec<f32>), FileError> {
        let (shape, b) = self.raw(name, Dtype::F32, want)?;
        let v: Vec<f32> = from_le(b);
        match v.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(self.err(format!("tensor `{name}` has a non-finite value at {i}"))),
            None => Ok((shape, v)),
        }
    }
}

/// An element type tensors are read as: its dtype and its little-endian decoding.
pub trait Element: Sized {
    /// The dtype a tensor of this element type has.
    const DTYPE: Dtype;
    /// One element from its little-endian bytes (`size_of::<Self>()` of them).
    fn from_le(bytes: &[u8]) -> Self;
}

macro_rules! element {
    ($($t:ty => $dtype:ident),*) => {$(
        impl Element for $t {
            const DTYPE: Dtype = Dtype::$dtype;
            fn from_le(bytes: &[u8]) -> Self {
                <$t>::from_le_bytes(bytes.try_into().unwrap_or_default())
            }
        }
    )*};
}

element!(f32 => F32, f64 => F64, i64 => I64, u32 => U32);

/// Little-endian bytes as elements.
fn from_le<T: Element>(bytes: &[u8]) -> Vec<T> {
    bytes
        .chunks_exact(std::mem::size_of::<T>())
        .map(T::from_le)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Equal content gives equal bytes, whatever order the metadata map iterates in, and the
    /// file still reads with its tensors and metadata.
    #[test]
    fn equal_content_gives_equal_files() {
        let path = Path::new("x.safetensors");
        let entries: Vec<Entry> = vec![
            ("b".into(), Dtype::F32, vec![2], f32_bytes(&[1.0, 2.0])),
            ("a".into(), Dtype::U32, vec![1], u32_bytes([7])),
        ];
        let meta = || -> HashMap<String, String> {
            (0..8)
                .map(|i| (format!("key{i}"), format!("value{i}")))
                .collect()
        };
        let first = serialize(path, &entries, meta()).unwrap();
        for _ in 0..20 {
            assert_eq!(serialize(path, &entries, meta()).unwrap(), first);
        }
        let r = Reader::open(&first, path).unwrap();
        assert_eq!(r.metadata(), &meta());
        assert_eq!(
            r.values::<f32>("b", &[Some(2)]).unwrap(),
            (vec![2], vec![1.0, 2.0])
        );
        assert_eq!(
            r.values::<u32>("a", &[Some(1)]).unwrap(),
            (vec![1], vec![7])
        );
    }
}
