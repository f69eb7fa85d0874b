//! Torch typed storages: their element types and strided tensor views of their bytes.
//!
//! Shared by the pickle machine (which names storages while it runs) and the torch
//! checkpoint reader (which hands their bytes over), so neither needs the other for it.

use crate::error::PickleErrorKind;
use crate::value::{ArrayData, NdArray};

/// The element type of a torch typed storage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TorchDtype {
    F32,
    F64,
    F16,
    BF16,
    I64,
    I32,
    I16,
    I8,
    U8,
    Bool,
}

impl TorchDtype {
    pub(crate) fn from_storage_name(name: &str) -> Option<TorchDtype> {
        Some(match name {
            "FloatStorage" => TorchDtype::F32,
            "DoubleStorage" => TorchDtype::F64,
            "HalfStorage" => TorchDtype::F16,
            "BFloat16Storage" => TorchDtype::BF16,
            "LongStorage" => TorchDtype::I64,
            "IntStorage" => TorchDtype::I32,
            "ShortStorage" => TorchDtype::I16,
            "CharStorage" => TorchDtype::I8,
            "ByteStorage" => TorchDtype::U8,
            "BoolStorage" => TorchDtype::Bool,
            _ => return None,
        })
    }

    pub(crate) fn storage_name(self) -> &'static str {
        match self {
            TorchDtype::F32 => "torch.FloatStorage",
            TorchDtype::F64 => "torch.DoubleStorage",
            TorchDtype::F16 => "torch.HalfStorage",
            TorchDtype::BF16 => "torch.BFloat16Storage",
            TorchDtype::I64 => "torch.LongStorage",
            TorchDtype::I32 => "torch.IntStorage",
            TorchDtype::I16 => "torch.ShortStorage",
            TorchDtype::I8 => "torch.CharStorage",
            TorchDtype::U8 => "torch.ByteStorage",
            TorchDtype::Bool => "torch.BoolStorage",
        }
    }

    pub(crate) fn itemsize(self) -> usize {
        match self {
            TorchDtype::F64 | TorchDtype::I64 => 8,
            TorchDtype::F32 | TorchDtype::I32 => 4,
            TorchDtype::F16 | TorchDtype::BF16 | TorchDtype::I16 => 2,
            TorchDtype::I8 | TorchDtype::U8 | TorchDtype::Bool => 1,
        }
    }

    /// The elements at byte offsets `offsets` (each `offset .. offset + itemsize` is inside
    /// `bytes`, which the caller checked).
    pub(crate) fn gather(self, bytes: &[u8], offsets: &[usize]) -> ArrayData {
        fn take<const N: usize>(bytes: &[u8], o: usize) -> [u8; N] {
            let mut b = [0u8; N];
            b.copy_from_slice(&bytes[o..o + N]);
            b
        }
        let it = offsets.iter().copied();
        match self {
            TorchDtype::F32 => {
                ArrayData::F32(it.map(|o| f32::from_le_bytes(take(bytes, o))).collect())
            }
            TorchDtype::F64 => {
                ArrayData::F64(it.map(|o| f64::from_le_bytes(take(bytes, o))).collect())
            }
            TorchDtype::F16 => ArrayData::F32(
                it.map(|o| f16_to_f32(u16::from_le_bytes(take(bytes, o))))
                    .collect(),
            ),
            TorchDtype::BF16 => ArrayData::F32(
                it.map(|o| f32::from_bits(u32::from(u16::from_le_bytes(take(bytes, o))) << 16))
                    .collect(),
            ),
            TorchDtype::I64 => {
                ArrayData::I64(it.map(|o| i64::from_le_bytes(take(bytes, o))).collect())
            }
            TorchDtype::I32 => {
                ArrayData::I32(it.map(|o| i32::from_le_bytes(take(bytes, o))).collect())
            }
            TorchDtype::I16 => ArrayData::I32(
                it.map(|o| i32::from(i16::from_le_bytes(take(bytes, o))))
                    .collect(),
            ),
            TorchDtype::I8 => ArrayData::I32(it.map(|o| i32::from(bytes[o] as i8)).collect()),
            TorchDtype::U8 => ArrayData::U8(it.map(|o| bytes[o]).collect()),
            TorchDtype::Bool => ArrayData::Bool(it.map(|o| bytes[o] != 0).collect()),
        }
    }
}

/// IEEE half to single precision (exact).
fn f16_to_f32(h: u16) -> f32 {
    let sign = u32::from(h >> 15) << 31;
    let exp = u32::from((h >> 10) & 0x1f);
    let man = u32::from(h & 0x3ff);
    let bits = match (exp, man) {
        (0, 0) => sign,
        (0, m) => {
            // Subnormal: value m * 2^-24.
            let v = m as f32 * f32::from_bits(0x3380_0000); // 2^-24
            return if sign != 0 { -v } else { v };
        }
        (0x1f, 0) => sign | 0x7f80_0000,
        (0x1f, m) => sign | 0x7fc0_0000 | (m << 13),
        (e, m) => sign | ((e + 112) << 23) | (m << 13),
    };
    f32::from_bits(bits)
}

/// Builds a tensor's elements: the strided view `spec` of `bytes` (checked by the machine
/// to lie inside the storage of `numel` elements; `bytes` is checked here).
pub(crate) fn tensor_data(
    dtype: TorchDtype,
    bytes: &[u8],
    numel: usize,
    offset: usize,
    shape: &[usize],
    stride: &[usize],
) -> Result<NdArray, PickleErrorKind> {
    let size = dtype.itemsize();
    if numel.checked_mul(size) != Some(bytes.len()) {
        return Err(PickleErrorKind::SizeMismatch(format!(
            "{} of {numel} elements needs {} bytes but the checkpoint holds {}",
            dtype.storage_name(),
            numel.saturating_mul(size),
            bytes.len()
        )));
    }
    let count = crate::numpy::element_count(shape)?;
    if shape.len() != stride.len() {
        return Err(PickleErrorKind::BadArgument(
            "tensor size and stride differ in length".into(),
        ));
    }
    if count > 0 {
        let last = shape.iter().zip(stride).try_fold(offset, |acc, (&n, &s)| {
            (n - 1).checked_mul(s)?.checked_add(acc)
        });
        if last.is_none_or(|l| l >= numel) {
            return Err(PickleErrorKind::SizeMismatch(format!(
                "tensor view (offset {offset}, size {shape:?}, stride {stride:?}) leaves its \
                 storage of {numel} elements"
            )));
        }
    }
    let mut offsets = Vec::with_capacity(count);
    let mut idx = vec![0usize; shape.len()];
    let mut at = offset;
    for _ in 0..count {
        offsets.push(at * size);
        // Next multi-index, last dimension fastest.
        for d in (0..shape.len()).rev() {
            idx[d] += 1;
            at += stride[d];
            if idx[d] < shape[d] {
                break;
            }
            at -= stride[d] * shape[d];
            idx[d] = 0;
        }
    }
    Ok(NdArray {
        shape: shape.to_vec(),
        data: dtype.gather(bytes, &offsets),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_precision_widening() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x7bff), 65504.0);
        assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(f16_to_f32(0x8000).to_bits(), 0x8000_0000);
        assert!(f16_to_f32(0x7c00).is_infinite());
        assert!(f16_to_f32(0x7e00).is_nan());
        assert_eq!(f16_to_f32(0x3555), 0.333_251_95);
    }

    #[test]
    fn strided_views() {
        // Storage 0..12 as f32; a [3, 2] view with stride (1, 3) at offset 1 (a transpose).
        let bytes: Vec<u8> = (0..12).flat_map(|i| (i as f32).to_le_bytes()).collect();
        let a = tensor_data(TorchDtype::F32, &bytes, 12, 1, &[3, 2], &[1, 3]).unwrap();
        assert_eq!(a.data, ArrayData::F32(vec![1.0, 4.0, 2.0, 5.0, 3.0, 6.0]));
        // 0-d tensor.
        let s = tensor_data(TorchDtype::F32, &bytes, 12, 7, &[], &[]).unwrap();
        assert_eq!(s.data, ArrayData::F32(vec![7.0]));
        // Empty tensor.
        let e = tensor_data(TorchDtype::F32, &bytes, 12, 0, &[0, 4], &[4, 1]).unwrap();
        assert_eq!(e.data, ArrayData::F32(vec![]));
        // A broadcast (stride 0) dimension.
        let b = tensor_data(TorchDtype::F32, &bytes, 12, 2, &[2, 2], &[0, 1]).unwrap();
        assert_eq!(b.data, ArrayData::F32(vec![2.0, 3.0, 2.0, 3.0]));
        // Storage of the wrong byte length.
        assert!(tensor_data(TorchDtype::F32, &bytes[..40], 12, 0, &[1], &[1]).is_err());
    }
}
