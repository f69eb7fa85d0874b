//! numpy dtypes and the decoding of raw array bytes.

use crate::error::PickleErrorKind;
use crate::value::{ArrayData, NdArray};

/// The element types this reader decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    F4,
    F8,
    I4,
    I8,
    U4,
    U1,
    B1,
}

impl Kind {
    pub(crate) fn itemsize(self) -> usize {
        match self {
            Kind::F4 | Kind::I4 | Kind::U4 => 4,
            Kind::F8 | Kind::I8 => 8,
            Kind::U1 | Kind::B1 => 1,
        }
    }

    pub(crate) fn code(self) -> &'static str {
        match self {
            Kind::F4 => "f4",
            Kind::F8 => "f8",
            Kind::I4 => "i4",
            Kind::I8 => "i8",
            Kind::U4 => "u4",
            Kind::U1 => "u1",
            Kind::B1 => "b1",
        }
    }
}

/// A numpy dtype: element kind and byte order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Dtype {
    pub(crate) kind: Kind,
    pub(crate) big_endian: bool,
}

impl Dtype {
    /// Parses the first argument of `numpy.dtype(...)` as numpy's `__reduce__` writes it
    /// (`"f8"`, `"u4"`, `"b1"`, ...), optionally with a byte-order prefix.
    pub(crate) fn parse(s: &str) -> Result<Dtype, PickleErrorKind> {
        let (big_endian, rest) = match s.as_bytes().first() {
            Some(b'>') => (true, s.get(1..).unwrap_or("")),
            Some(b'<' | b'=' | b'|') => (false, s.get(1..).unwrap_or("")),
            _ => (false, s),
        };
        let kind = match rest {
            "f4" | "float32" => Kind::F4,
            "f8" | "float64" => Kind::F8,
            "i4" | "int32" => Kind::I4,
            "i8" | "int64" => Kind::I8,
            "u4" | "uint32" => Kind::U4,
            "u1" | "uint8" => Kind::U1,
            "b1" | "?" | "bool" => Kind::B1,
            _ => {
                return Err(PickleErrorKind::BadArgument(format!(
                    "unsupported numpy dtype {s:?} (supported: f4 f8 i4 i8 u4 u1 b1)"
                )));
            }
        };
        Ok(Dtype { kind, big_endian })
    }

    pub(crate) fn describe(self) -> String {
        let order = if self.kind.itemsize() == 1 {
            "|"
        } else if self.big_endian {
            ">"
        } else {
            "<"
        };
        format!("{order}{}", self.kind.code())
    }
}

/// Number of elements of `shape` (1 for a 0-d array), or an error on overflow.
pub(crate) fn element_count(shape: &[usize]) -> Result<usize, PickleErrorKind> {
    shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| {
            PickleErrorKind::TooLarge(format!("array shape {shape:?} has too many elements"))
        })
}

/// Checks that `data_len` bytes are exactly what an array of `shape` and `dtype` needs.
/// Done before anything is allocated.
pub(crate) fn check_size(
    shape: &[usize],
    dtype: Dtype,
    data_len: usize,
) -> Result<usize, PickleErrorKind> {
    let count = element_count(shape)?;
    let needed = count.checked_mul(dtype.kind.itemsize()).ok_or_else(|| {
        PickleErrorKind::TooLarge(format!(
            "array of shape {shape:?} and dtype {} is too large",
            dtype.describe()
        ))
    })?;
    if needed != data_len {
        return Err(PickleErrorKind::SizeMismatch(format!(
            "array of shape {} and dtype {} needs {needed} bytes but the pickle holds {data_len}",
            shape_str(shape),
            dtype.describe()
        )));
    }
    Ok(count)
}

/// Formats a shape like Python does: `(2, 3)`, `(5,)`, `()`.
pub(crate) fn shape_str(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => {
            let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
            format!("({})", parts.join(", "))
        }
    }
}

trait Elem: Sized {
    const SIZE: usize;
    fn read(b: &[u8], big: bool) -> Option<Self>;
}

macro_rules! elem {
    ($t:ty, $n:literal) => {
        impl Elem for $t {
            const SIZE: usize = $n;
            fn read(b: &[u8], big: bool) -> Option<Self> {
                let a = *b.first_chunk::<$n>()?;
                Some(if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                })
            }
        }
    };
}
elem!(f32, 4);
elem!(f64, 8);
elem!(i32, 4);
elem!(i64, 8);
elem!(u32, 4);
elem!(u8, 1);

impl Elem for bool {
    const SIZE: usize = 1;
    fn read(b: &[u8], _big: bool) -> Option<Self> {
        b.first().map(|&x| x != 0)
    }
}

fn internal() -> PickleErrorKind {
    PickleErrorKind::BadArgument("internal error: array data shorter than checked".to_string())
}

/// Decodes `bytes` (already checked by [`check_size`]) into C-order elements. With
/// `fortran`, `bytes` holds the elements in column-major order and they are reordered.
fn decode<T: Elem>(
    bytes: &[u8],
    big: bool,
    shape: &[usize],
    fortran: bool,
    count: usize,
) -> Result<Vec<T>, PickleErrorKind> {
    if count.checked_mul(T::SIZE) != Some(bytes.len()) {
        return Err(internal());
    }
    let mut out = Vec::with_capacity(count);
    if !fortran || shape.len() < 2 || count == 0 {
        for c in bytes.chunks_exact(T::SIZE) {
            out.push(T::read(c, big).ok_or_else(internal)?);
        }
        return Ok(out);
    }
    // Fortran strides (in elements): axis 0 varies fastest.
    let nd = shape.len();
    let mut fstride = Vec::with_capacity(nd);
    let mut s = 1usize;
    for &d in shape {
        fstride.push(s);
        s = s.checked_mul(d).ok_or_else(internal)?;
    }
    let mut idx = vec![0usize; nd];
    let mut src = 0usize;
    for _ in 0..count {
        let start = src.checked_mul(T::SIZE).ok_or_else(internal)?;
        let chunk = bytes.get(start..).ok_or_else(internal)?;
        out.push(T::read(chunk, big).ok_or_else(internal)?);
        // Advance the C-order multi-index (last axis fastest), keeping `src` in step.
        for k in (0..nd).rev() {
            let (Some(i), Some(&st), Some(&dim)) = (idx.get_mut(k), fstride.get(k), shape.get(k))
            else {
                return Err(internal());
            };
            *i += 1;
            src += st;
            if *i < dim {
                break;
            }
            src -= st * dim;
            *i = 0;
        }
    }
    Ok(out)
}

/// Decodes raw array bytes into an [`NdArray`] in C order.
pub(crate) fn to_ndarray(
    bytes: &[u8],
    dtype: Dtype,
    shape: &[usize],
    fortran: bool,
) -> Result<NdArray, PickleErrorKind> {
    let count = check_size(shape, dtype, bytes.len())?;
    let big = dtype.big_endian;
    let data = match dtype.kind {
        Kind::F4 => ArrayData::F32(decode(bytes, big, shape, fortran, count)?),
        Kind::F8 => ArrayData::F64(decode(bytes, big, shape, fortran, count)?),
        Kind::I4 => ArrayData::I32(decode(bytes, big, shape, fortran, count)?),
        Kind::I8 => ArrayData::I64(decode(bytes, big, shape, fortran, count)?),
        Kind::U4 => ArrayData::U32(decode(bytes, big, shape, fortran, count)?),
        Kind::U1 => ArrayData::U8(decode(bytes, big, shape, fortran, count)?),
        Kind::B1 => ArrayData::Bool(decode(bytes, big, shape, fortran, count)?),
    };
    Ok(NdArray {
        shape: shape.to_vec(),
        data,
    })
}

/// `data.flat[idxs]`, keeping the dtype. Every index must already be in range.
pub(crate) fn gather(data: &ArrayData, idxs: &[usize]) -> Option<ArrayData> {
    fn g<T: Copy>(v: &[T], idxs: &[usize]) -> Option<Vec<T>> {
        idxs.iter().map(|&i| v.get(i).copied()).collect()
    }
    Some(match data {
        ArrayData::F32(v) => ArrayData::F32(g(v, idxs)?),
        ArrayData::F64(v) => ArrayData::F64(g(v, idxs)?),
        ArrayData::I32(v) => ArrayData::I32(g(v, idxs)?),
        ArrayData::I64(v) => ArrayData::I64(g(v, idxs)?),
        ArrayData::U32(v) => ArrayData::U32(g(v, idxs)?),
        ArrayData::U8(v) => ArrayData::U8(g(v, idxs)?),
        ArrayData::Bool(v) => ArrayData::Bool(g(v, idxs)?),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dtype_parsing() {
        let d = Dtype::parse("f8").unwrap();
        assert_eq!((d.kind, d.big_endian), (Kind::F8, false));
        assert!(Dtype::parse(">i4").unwrap().big_endian);
        assert!(Dtype::parse("V16").is_err());
        assert!(Dtype::parse("").is_err());
        assert_eq!(Dtype::parse("u1").unwrap().describe(), "|u1");
    }

    #[test]
    fn fortran_3d_reorder() {
        // shape (2, 3, 2), element value = C-order linear index.
        let shape = [2usize, 3, 2];
        let mut f = vec![0u8; 12];
        for i in 0..2 {
            for j in 0..3 {
                for k in 0..2 {
                    let c = i * 6 + j * 2 + k;
                    let fo = i + 2 * j + 6 * k;
                    f[fo] = c as u8;
                }
            }
        }
        let dt = Dtype::parse("u1").unwrap();
        let a = to_ndarray(&f, dt, &shape, true).unwrap();
        assert_eq!(a.data, ArrayData::U8((0..12).collect()));
        // Zero-sized Fortran arrays are fine.
        let a = to_ndarray(&[], dt, &[0, 5], true).unwrap();
        assert!(a.is_empty());
    }

    #[test]
    fn size_checks_before_allocation() {
        let dt = Dtype::parse("f8").unwrap();
        let e = check_size(&[usize::MAX, 2], dt, 16).unwrap_err();
        assert!(matches!(e, PickleErrorKind::TooLarge(_)));
        let e = check_size(&[2, 3], dt, 40).unwrap_err();
        assert_eq!(
            e.to_string(),
            "size mismatch: array of shape (2, 3) and dtype <f8 needs 48 bytes but the pickle holds 40"
        );
        assert_eq!(shape_str(&[5]), "(5,)");
        assert_eq!(shape_str(&[]), "()");
    }
}
