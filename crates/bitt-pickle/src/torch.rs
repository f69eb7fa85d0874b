//! Reading torch checkpoints (`torch.save` files, `.pth` / `.pt`) without Python.
//!
//! Two container formats exist and both are read:
//!
//! - the zip format (torch >= 1.6): an archive `<name>/data.pkl`, `<name>/data/<key>` (one
//!   raw little-endian storage per key), `<name>/byteorder`, `<name>/version`; entries must
//!   be stored uncompressed, as `torch.save` writes them;
//! - the legacy format (torch < 1.6, e.g. the `lpips` package's weights and torchvision's
//!   `vgg16-397923af.pth`): five pickles in a row (magic number, protocol version 1001,
//!   system info, the object, the list of storage keys) followed by each storage as an
//!   8-byte element count and its raw bytes.
//!
//! The object pickle is interpreted by the same safe machine as other pickles (nothing is
//! executed), with these extra globals and nothing else: `torch._utils._rebuild_tensor_v2`,
//! `_rebuild_tensor`, `_rebuild_parameter`, the typed storages `torch.FloatStorage`,
//! `DoubleStorage`, `HalfStorage`, `BFloat16Storage`, `LongStorage`, `IntStorage`,
//! `ShortStorage`, `CharStorage`, `ByteStorage`, `BoolStorage`, and `collections.OrderedDict`
//! (whose attributes, such as a state dict's `_metadata`, are dropped). Persistent ids must
//! name storages. Tensors come out as [`Value::Array`] in C order: float16 and bfloat16 are
//! widened to `f32`, int16 and int8 to `i32`. Every tensor is checked to lie inside its
//! storage, every storage to have the size its id declares; big-endian checkpoints are
//! refused.

use std::borrow::Cow;
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

use crate::convert::Converter;
use crate::error::{PickleError, PickleErrorKind};
use crate::machine::Machine;
use crate::value::Value;

/// The magic number pickle of legacy checkpoints: protocol 2, `LONG1` of
/// `0x1950a86a20f9469cfc6c`, STOP.
const LEGACY_MAGIC: [u8; 15] = [
    0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19, 0x2e,
];

/// Reads a torch checkpoint file (zip or legacy format) into plain values: a state dict
/// comes out as a [`Value::Dict`] from parameter names to [`Value::Array`]s. Errors name the
/// file (and the archive member) and the byte offset.
pub fn load_torch(path: &Path) -> Result<Value, PickleError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path)
        .map_err(|e| PickleError::new(name.clone(), 0, PickleErrorKind::Io(e)))?;
    torch_from_bytes(&bytes, &name)
}

/// [`load_torch`] on bytes in memory; `source` names them in errors.
pub fn torch_from_bytes(bytes: &[u8], source: &str) -> Result<Value, PickleError> {
    if bytes.starts_with(b"PK\x03\x04") {
        from_zip(bytes, source)
    } else if bytes.starts_with(&LEGACY_MAGIC) {
        from_legacy(bytes, source)
    } else if bytes.len() > 262 && &bytes[257..262] == b"ustar" {
        Err(PickleError::new(
            source,
            0,
            PickleErrorKind::BadArgument(
                "a torch checkpoint in the old tar format (torch < 0.4); re-save it with a \
                 newer torch"
                    .into(),
            ),
        ))
    } else {
        Err(PickleError::new(
            source,
            0,
            PickleErrorKind::BadArgument(
                "not a torch checkpoint (neither a zip archive nor the legacy format's magic \
                 number)"
                    .into(),
            ),
        ))
    }
}

fn bad(source: &str, offset: usize, msg: impl Into<String>) -> PickleError {
    PickleError::new(source, offset, PickleErrorKind::BadArgument(msg.into()))
}

/// Runs one plain pickle at `start`; returns its value and the offset after it.
fn plain_pickle(bytes: &[u8], start: usize, source: &str) -> Result<(Value, usize), PickleError> {
    let input = bytes.get(start..).unwrap_or(&[]);
    let mut m = Machine::new(input);
    let root = m
        .run()
        .map_err(|(o, k)| PickleError::new(source, start + o, k))?;
    let end = start + m.position();
    let budget = input.len().min(1 << 20).saturating_mul(4) + (1 << 18);
    let v = Converter::new(&m, budget)
        .value(root, 0)
        .map_err(|(o, k)| PickleError::new(source, start + o, k))?;
    Ok((v, end))
}

/// The object pickle: runs it in torch mode and converts it with the storages.
fn object_pickle<'s>(
    input: &[u8],
    base: usize,
    source: &str,
    storages: impl FnOnce(&Machine<'_>) -> Result<HashMap<String, Cow<'s, [u8]>>, PickleError>,
) -> Result<(Value, usize), PickleError> {
    let mut m = Machine::new_torch(input);
    let root = m
        .run()
        .map_err(|(o, k)| PickleError::new(source, base + o, k))?;
    let end = m.position();
    let data = storages(&m)?;
    let total: usize = data.values().map(|v| v.len()).sum();
    let views: HashMap<String, &[u8]> = data.iter().map(|(k, v)| (k.clone(), &v[..])).collect();
    let budget = end
        .saturating_add(total)
        .saturating_mul(4)
        .saturating_add(1 << 18);
    let v = Converter::with_storages(&m, budget, &views)
        .value(root, 0)
        .map_err(|(o, k)| PickleError::new(source, base + o, k))?;
    Ok((v, end))
}

fn from_legacy(bytes: &[u8], source: &str) -> Result<Value, PickleError> {
    let mut pos = LEGACY_MAGIC.len();
    let (version, next) = plain_pickle(bytes, pos, source)?;
    if version.as_i64() != Some(1001) {
        return Err(bad(
            source,
            pos,
            format!("legacy torch checkpoint protocol {version:?}, expected 1001"),
        ));
    }
    pos = next;
    let (info, next) = plain_pickle(bytes, pos, source)?;
    if let Some(le) = info.get("little_endian")
        && le != &Value::Bool(true)
    {
        return Err(bad(
            source,
            pos,
            "big-endian torch checkpoints are not supported",
        ));
    }
    pos = next;
    let object_at = pos;
    let input = &bytes[object_at..];
    let (value, _) = object_pickle(input, object_at, source, |m| {
        let end = object_at + m.position();
        let (keys, mut at) = plain_pickle(bytes, end, source)?;
        let keys = keys
            .as_list()
            .ok_or_else(|| bad(source, end, "legacy storage key list is not a list"))?;
        let sizes = storage_sizes(m);
        let mut out = HashMap::new();
        for key in keys {
            let key = key
                .as_str()
                .ok_or_else(|| bad(source, end, "legacy storage key is not a str"))?;
            let &(itemsize, numel) = sizes.get(key).ok_or_else(|| {
                bad(
                    source,
                    at,
                    format!("storage {key:?} is listed but no tensor uses it"),
                )
            })?;
            let count = bytes
                .get(at..at + 8)
                .map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                .ok_or_else(|| PickleError::new(source, at, PickleErrorKind::Truncated))?;
            if usize::try_from(count).ok() != Some(numel) {
                return Err(PickleError::new(
                    source,
                    at,
                    PickleErrorKind::SizeMismatch(format!(
                        "storage {key:?} holds {count} elements but its id declares {numel}"
                    )),
                ));
            }
            let start = at + 8;
            let len = numel.checked_mul(itemsize).ok_or_else(|| {
                PickleError::new(source, at, PickleErrorKind::TooLarge("storage size".into()))
            })?;
            let data = bytes
                .get(start..start.saturating_add(len))
                .ok_or_else(|| PickleError::new(source, at, PickleErrorKind::Truncated))?;
            out.insert(key.to_string(), Cow::Borrowed(data));
            at = start + len;
        }
        Ok(out)
    })?;
    Ok(value)
}

/// `key -> (itemsize, numel)` of every storage the machine met.
fn storage_sizes(m: &Machine<'_>) -> HashMap<String, (usize, usize)> {
    m.slots
        .iter()
        .filter_map(|s| match &s.obj {
            crate::machine::Obj::Storage { dtype, key, numel } => {
                Some((key.clone(), (dtype.itemsize(), *numel)))
            }
            _ => None,
        })
        .collect()
}

fn from_zip(bytes: &[u8], source: &str) -> Result<Value, PickleError> {
    let zerr = |e: zip::result::ZipError| bad(source, 0, format!("torch zip archive: {e}"));
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(zerr)?;
    let names: Vec<String> = archive.file_names().map(str::to_string).collect();
    let pkl = names
        .iter()
        .filter(|n| *n == "data.pkl" || n.ends_with("/data.pkl"))
        .min_by_key(|n| n.len())
        .cloned()
        .ok_or_else(|| bad(source, 0, "torch zip archive without data.pkl"))?;
    let prefix = pkl.strip_suffix("data.pkl").unwrap_or("").to_string();
    let member = format!("{source}:{pkl}");
    let mut read = |name: &str| -> Result<Vec<u8>, PickleError> {
        let mut f = archive.by_name(name).map_err(zerr)?;
        let mut v = Vec::with_capacity(usize::try_from(f.size()).unwrap_or(0).min(bytes.len()));
        f.read_to_end(&mut v)
            .map_err(|e| bad(source, 0, format!("torch zip archive member {name}: {e}")))?;
        Ok(v)
    };
    if names.iter().any(|n| *n == format!("{prefix}byteorder")) {
        let order = read(&format!("{prefix}byteorder"))?;
        if order != b"little" {
            return Err(bad(
                source,
                0,
                format!(
                    "torch checkpoint byte order {:?} (only little-endian)",
                    String::from_utf8_lossy(&order)
                ),
            ));
        }
    }
    let pickle = read(&pkl)?;
    let (value, _) = object_pickle(&pickle, 0, &member, |m| {
        let mut out = HashMap::new();
        for (key, (itemsize, numel)) in storage_sizes(m) {
            let name = format!("{prefix}data/{key}");
            if !names.contains(&name) {
                return Err(bad(
                    source,
                    0,
                    format!("torch zip archive has no member {name} for storage {key:?}"),
                ));
            }
            let data = read(&name)?;
            if numel.checked_mul(itemsize) != Some(data.len()) {
                return Err(PickleError::new(
                    source,
                    0,
                    PickleErrorKind::SizeMismatch(format!(
                        "member {name} holds {} bytes but its storage id declares {numel} \
                         elements of {itemsize} bytes",
                        data.len()
                    )),
                ));
            }
            out.insert(key, Cow::Owned(data));
        }
        Ok(out)
    })?;
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::{ArrayData, NdArray};

    /// `tests-data/make_torch_checkpoints.py`: the same object in both formats.
    fn check_fixture(v: &Value) {
        let arr = |k: &str| -> &NdArray {
            v.get(k)
                .and_then(Value::as_array)
                .unwrap_or_else(|| panic!("{k} missing"))
        };
        let f32s = |k: &str| -> (Vec<usize>, Vec<f32>) {
            let a = arr(k);
            match &a.data {
                ArrayData::F32(d) => (a.shape.clone(), d.clone()),
                other => panic!("{k}: {other:?}"),
            }
        };
        assert_eq!(
            f32s("weight"),
            (vec![2, 3], vec![0.5, -1.0, 2.0, 0.25, 3.0, -0.125])
        );
        assert_eq!(f32s("bias"), (vec![2], vec![1.5, -2.5]));
        assert_eq!(f32s("full"), (vec![6], vec![0.0, 1.5, 3.0, 4.5, 6.0, 7.5]));
        assert_eq!(f32s("tail"), (vec![4], vec![3.0, 4.5, 6.0, 7.5]));
        assert_eq!(
            f32s("transposed"),
            (vec![3, 2], vec![0.0, 3.0, 1.0, 4.0, 2.0, 5.0])
        );
        assert_eq!(
            f32s("half"),
            (vec![4], vec![1.0, -2.0, 0.333_251_95, 65504.0])
        );
        assert_eq!(f32s("bf16"), (vec![2], vec![1.0, -0.5]));
        assert_eq!(arr("double").data, ArrayData::F64(vec![0.1, 1e300]));
        assert_eq!(arr("long").data, ArrayData::I64(vec![-3, 0, 1 << 40]));
        assert_eq!(arr("int").data, ArrayData::I32(vec![7, -8]));
        assert_eq!(arr("byte").data, ArrayData::U8(vec![0, 255]));
        assert_eq!(arr("bool").data, ArrayData::Bool(vec![true, false]));
        assert_eq!(f32s("scalar"), (vec![], vec![4.0]));
        assert_eq!(f32s("param"), (vec![2], vec![9.0, 10.0]));
        assert_eq!(v.as_dict().map(<[_]>::len), Some(14));
    }

    const ZIP: &[u8] = include_bytes!("../tests-data/torch_zip.pth");
    const LEGACY: &[u8] = include_bytes!("../tests-data/torch_legacy.pth");

    #[test]
    fn zip_checkpoint() {
        check_fixture(&torch_from_bytes(ZIP, "torch_zip.pth").unwrap());
    }

    #[test]
    fn legacy_checkpoint() {
        check_fixture(&torch_from_bytes(LEGACY, "torch_legacy.pth").unwrap());
    }

    #[test]
    fn plain_reader_refuses_torch_checkpoints() {
        // The object pickle of the legacy file (the fourth pickle), read as a plain pickle:
        // the torch globals are unknown there.
        let obj_at = LEGACY
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w == &[0x80, 0x02])
            .map(|(i, _)| i)
            .nth(3)
            .unwrap();
        let e = crate::from_bytes(&LEGACY[obj_at..], "x").unwrap_err();
        assert!(
            matches!(e.kind, PickleErrorKind::UnsupportedGlobal { .. }),
            "{e}"
        );
    }

    #[test]
    fn damaged_checkpoints_give_errors_not_panics() {
        // Every truncation and every single-byte change of the legacy file.
        for n in 0..LEGACY.len() {
            let r = torch_from_bytes(&LEGACY[..n], "cut.pth");
            assert!(r.is_err(), "truncated at {n} was accepted");
        }
        for i in 0..LEGACY.len() {
            for flip in [0x01u8, 0x80, 0xff] {
                let mut b = LEGACY.to_vec();
                b[i] ^= flip;
                let _ = torch_from_bytes(&b, "flipped.pth");
            }
        }
        // Zip: a truncated archive and one member renamed away.
        assert!(torch_from_bytes(&ZIP[..ZIP.len() - 30], "cut.pth").is_err());
        let mut renamed = ZIP.to_vec();
        let at = renamed
            .windows(16)
            .rposition(|w| w == b"torch_zip/data/3")
            .unwrap();
        renamed[at + 15] = b'x';
        let e = torch_from_bytes(&renamed, "renamed.pth")
            .unwrap_err()
            .to_string();
        assert!(e.contains("renamed.pth"), "{e}");
        // Not a checkpoint at all.
        let e = torch_from_bytes(b"hello", "hello.pth")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("hello.pth") && e.contains("not a torch checkpoint"),
            "{e}"
        );
        let e = load_torch(Path::new("/nonexistent/w.pth"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/w.pth"), "{e}");
    }
}
