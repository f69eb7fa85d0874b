//! Safetensors files: the one checked reader (metadata format, dtype, shape, finite values,
//! checksums) and the one writer (encoded, checksummed, then written atomically) that every
//! crate's files go through. Errors are [`FileError::Format`] naming the file and the tensor.
//!
//! Every file written gets two metadata entries: [`CHECKSUMS`] (a JSON map from each tensor's
//! name to the XXH3-64 of its bytes, 16 hex digits) and [`METADATA_CHECKSUM`] (the XXH3-64 of
//! every other metadata entry, in key order). [`Reader::open`] verifies both when they are
//! present, so a file changed or damaged after it was written is named as such instead of
//! being trusted; files without them (written before) are read as they are.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use safetensors::{Dtype, SafeTensors};

use crate::FileError;

/// One tensor to write: name, dtype, shape, little-endian bytes.
pub type Entry = (String, Dtype, Vec<usize>, Vec<u8>);

/// The value a `U8` entry of [`unit_entry`] stands for: `k / 255`.
pub fn from_unit_byte(k: u8) -> f32 {
    f32::from(k) / 255.0
}

/// The byte an 8-bit image stores for `v`: clamped to [0, 1], times 255, rounded.
/// `from_unit_byte(unit_byte(v))` is exactly what [`unit_entry`] keeps as a byte.
pub fn unit_byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// `values` (of `shape`) as an entry that is 4x smaller where it can be: `U8` holding
/// `255 * value` when every value is exactly such a fraction `k / 255` (8-bit images, binary
/// masks), else `F32`. [`Reader::unit_f32s`] reads either back bit for bit.
pub fn unit_entry(name: impl Into<String>, shape: Vec<usize>, values: &[f32]) -> Entry {
    let bytes: Option<Vec<u8>> = values
        .iter()
        .map(|&v| {
            let k = (v * 255.0).round();
            // `k` in range first: the cast saturates, and a value outside [0, 1] must not
            // round-trip by accident.
            ((0.0..=255.0).contains(&k) && from_unit_byte(k as u8).to_bits() == v.to_bits())
                .then_some(k as u8)
        })
        .collect();
    match bytes {
        Some(b) => (name.into(), Dtype::U8, shape, b),
        None => (name.into(), Dtype::F32, shape, f32_bytes(values)),
    }
}

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

/// The metadata entry holding each tensor's checksum.
pub(crate) const CHECKSUMS: &str = "checksums";

/// The metadata entry holding the checksum of the other metadata entries.
pub(crate) const METADATA_CHECKSUM: &str = "metadata_checksum";

/// The checksum of some bytes: XXH3-64 as 16 hex digits.
pub fn checksum(bytes: &[u8]) -> String {
    format!("{:016x}", xxhash_rust::xxh3::xxh3_64(bytes))
}

/// The checksum of every metadata entry except [`METADATA_CHECKSUM`] itself, in key order.
pub fn metadata_checksum(meta: &HashMap<String, String>) -> String {
    let sorted: BTreeMap<&String, &String> = meta
        .iter()
        .filter(|(k, _)| k.as_str() != METADATA_CHECKSUM)
        .collect();
    let mut text = String::new();
    for (k, v) in sorted {
        text.push_str(k);
        text.push('\0');
        text.push_str(v);
        text.push('\0');
    }
    checksum(text.as_bytes())
}

/// Serializes `tensors` with `metadata` and the checksums of both (the module's
/// [`CHECKSUMS`] and [`METADATA_CHECKSUM`] entries, replacing any given); `path` names the
/// file in errors.
///
/// # Errors
/// A tensor whose bytes do not fit its dtype and shape.
pub fn serialize(
    path: &Path,
    tensors: &[Entry],
    mut metadata: HashMap<String, String>,
) -> Result<Vec<u8>, FileError> {
    let sums: BTreeMap<&str, String> = tensors
        .iter()
        .map(|(name, _, _, bytes)| (name.as_str(), checksum(bytes)))
        .collect();
    let sums = serde_json::to_string(&sums)
        .map_err(|e| FileError::format(path, format!("cannot encode the checksums: {e}")))?;
    metadata.insert(CHECKSUMS.to_string(), sums);
    let sum = metadata_checksum(&metadata);
    metadata.insert(METADATA_CHECKSUM.to_string(), sum);
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
/// ([`crate::write_atomically`]).
///
/// # Errors
/// As [`serialize`], or the file cannot be written.
pub fn write(
    path: &Path,
    tensors: &[Entry],
    metadata: HashMap<String, String>,
) -> Result<(), FileError> {
    let bytes = serialize(path, tensors, metadata)?;
    crate::write_atomically(path, &bytes)
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
    /// The metadata, without the checksum entries.
    meta: HashMap<String, String>,
    path: &'a Path,
    checksummed: bool,
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
        let mut reader = Reader {
            st,
            meta,
            path,
            checksummed: false,
        };
        reader.verify()?;
        reader.checksummed = reader.meta.remove(CHECKSUMS).is_some();
        reader.meta.remove(METADATA_CHECKSUM);
        Ok(reader)
    }

    /// Whether the file carried checksums (all verified by [`Reader::open`]); files written
    /// before checksums were added have none.
    pub fn checksummed(&self) -> bool {
        self.checksummed
    }

    /// Verifies the checksums [`serialize`] wrote, when the file has them: the metadata's,
    /// then every tensor's (each tensor listed, none unlisted).
    fn verify(&self) -> Result<(), FileError> {
        let (sums, stored) = match (self.meta.get(CHECKSUMS), self.meta.get(METADATA_CHECKSUM)) {
            (None, None) => return Ok(()),
            (Some(s), Some(m)) => (s, m),
            _ => {
                return Err(self.err(format!(
                    "the metadata is corrupt: it has only one of `{CHECKSUMS}` and \
                     `{METADATA_CHECKSUM}`"
                )));
            }
        };
        let actual = metadata_checksum(&self.meta);
        if &actual != stored {
            return Err(self.err(format!(
                "the metadata is corrupt: it was altered or damaged after the file was written \
                 (its checksum is {actual}, the file says {stored})"
            )));
        }
        let sums: BTreeMap<String, String> = serde_json::from_str(sums)
            .map_err(|e| self.err(format!("metadata `{CHECKSUMS}` is not valid: {e}")))?;
        let names = self.st.names();
        if let Some(extra) = names.iter().find(|n| !sums.contains_key(**n)) {
            return Err(self.err(format!(
                "tensor `{extra}` is corrupt: it has no checksum, so it was added after the \
                 file was written"
            )));
        }
        for (name, sum) in &sums {
            let actual = checksum(self.bytes(name)?);
            if &actual != sum {
                return Err(self.err(format!(
                    "tensor `{name}` is corrupt: it was altered or damaged after the file was \
                     written (its checksum is {actual}, the file says {sum})"
                )));
            }
        }
        Ok(())
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

    /// The metadata (empty when the file has none), without the checksum entries.
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

impl Reader<'_> {
    /// Tensor `name`, written by [`unit_entry`], as finite `f32` values of shape `want`: a
    /// `U8` tensor's bytes as `k / 255`, an `F32` tensor as it is.
    ///
    /// # Errors
    /// A missing tensor, another dtype or shape, a non-finite value.
    pub fn unit_f32s(
        &self,
        name: &str,
        want: Option<&[Option<usize>]>,
    ) -> Result<(Vec<usize>, Vec<f32>), FileError> {
        let is_u8 = self.st.tensor(name).is_ok_and(|t| t.dtype() == Dtype::U8);
        if !is_u8 {
            return self.finite_f32s(name, want);
        }
        let (shape, b) = self.raw(name, Dtype::U8, want)?;
        Ok((shape, b.iter().copied().map(from_unit_byte).collect()))
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

    /// 8-bit images and binary masks are stored as `U8` and read back bit for bit; anything
    /// else (a value between the 256 steps, negative zero, out of range, NaN) stays `F32`.
    #[test]
    fn unit_values_shrink_to_bytes_only_when_exact() {
        let path = Path::new("x.safetensors");
        let image: Vec<f32> = (0..=255u8).map(|k| f32::from(k) / 255.0).collect();
        // An image made 8-bit by `unit_byte` is kept as bytes, every value.
        assert!((0..=255u8).all(|k| unit_byte(from_unit_byte(k)) == k));
        assert_eq!(
            (unit_byte(-0.2), unit_byte(1.7), unit_byte(0.5)),
            (0, 255, 128)
        );
        let mask = vec![0.0, 1.0, 1.0, 0.0];
        let entries = [
            unit_entry("image", vec![256], &image),
            unit_entry("mask", vec![2, 2], &mask),
            unit_entry("between", vec![2], &[0.5, 0.25]),
            unit_entry("negative_zero", vec![1], &[-0.0]),
            unit_entry("above", vec![1], &[2.0]),
            unit_entry("nan", vec![1], &[f32::NAN]),
        ];
        let dtypes: Vec<Dtype> = entries.iter().map(|e| e.1).collect();
        assert_eq!(
            dtypes,
            [
                Dtype::U8,
                Dtype::U8,
                Dtype::F32,
                Dtype::F32,
                Dtype::F32,
                Dtype::F32
            ]
        );
        assert_eq!(entries[0].3.len(), 256);
        let bytes = serialize(path, &entries[..5], HashMap::new()).unwrap();
        let r = Reader::open(&bytes, path).unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (name, want) in [
            ("image", &image[..]),
            ("mask", &mask[..]),
            ("between", &[0.5, 0.25][..]),
            ("negative_zero", &[-0.0][..]),
        ] {
            assert_eq!(
                bits(&r.unit_f32s(name, None).unwrap().1),
                bits(want),
                "{name}"
            );
        }
        let e = r
            .unit_f32s("mask", Some(&[Some(4)]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("mask"), "{e}");
    }

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

    /// Issue 38, class 5: every file carries checksums, so a flipped byte in any tensor or in
    /// the metadata is named instead of trusted; files without checksums still read.
    #[test]
    fn altered_files_are_named_and_files_without_checksums_read() {
        let path = Path::new("textures.safetensors");
        let entries: Vec<Entry> = vec![
            (
                "albedo".into(),
                Dtype::F32,
                vec![3],
                f32_bytes(&[0.1, 0.2, 0.3]),
            ),
            ("light".into(), Dtype::F32, vec![2], f32_bytes(&[1.0, 0.5])),
        ];
        let meta = HashMap::from([("format".to_string(), "test".to_string())]);
        let good = serialize(path, &entries, meta.clone()).unwrap();
        let r = Reader::new(&good, path, "test").unwrap();
        assert!(r.checksummed());
        assert_eq!(r.metadata(), &meta);
        let header = u64::from_le_bytes(good[..8].try_into().unwrap()) as usize + 8;
        for at in header..good.len() {
            let mut bad = good.clone();
            bad[at] ^= 0x04;
            let e = Reader::open(&bad, path).unwrap_err().to_string();
            let tensor = if at < header + 12 { "albedo" } else { "light" };
            assert!(
                e.contains("textures.safetensors")
                    && e.contains(&format!("tensor `{tensor}` is corrupt")),
                "byte {at}: {e}"
            );
        }
        let text = String::from_utf8_lossy(&good[8..header]).to_string();
        let at = 8 + text.find("\"test\"").unwrap() + 1;
        let mut bad = good.clone();
        bad[at] = b'T';
        let e = Reader::open(&bad, path).unwrap_err().to_string();
        assert!(e.contains("the metadata is corrupt"), "{e}");
        // A file written without checksums (by safetensors itself) is read as it is.
        let views: Vec<(String, safetensors::tensor::TensorView)> = entries
            .iter()
            .map(|(n, d, sh, b)| {
                (
                    n.clone(),
                    safetensors::tensor::TensorView::new(*d, sh.clone(), b).unwrap(),
                )
            })
            .collect();
        let plain = safetensors::serialize(views, Some(meta.clone())).unwrap();
        let r = Reader::new(&plain, path, "test").unwrap();
        assert!(!r.checksummed());
        assert_eq!(r.finite_f32s("light", None).unwrap().1, vec![1.0, 0.5]);
    }
}
