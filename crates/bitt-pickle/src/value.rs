//! The values a pickle is read into.

/// A Python value as read from a pickle.
///
/// Only plain data survives: numpy arrays and numpy scalars become [`Value::Array`]
/// (scalars as 0-d arrays, `shape == []`), scipy `csc_matrix` becomes [`Value::Sparse`],
/// and chumpy `Ch` / `Select` objects are resolved to the [`Value::Array`] they evaluate to.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// `None`.
    None,
    /// `True` / `False`.
    Bool(bool),
    /// An `int` (or Python 2 `long`) that fits in 64 bits.
    Int(i64),
    /// A `float`.
    Float(f64),
    /// A unicode `str`; also a Python 2 `str` (byte string), decoded as latin-1.
    Str(String),
    /// `bytes` or `bytearray`.
    Bytes(Vec<u8>),
    /// A `list`.
    List(Vec<Value>),
    /// A `tuple`.
    Tuple(Vec<Value>),
    /// A `set` or `frozenset`, elements in the order they were written.
    Set(Vec<Value>),
    /// A `dict`, in insertion order. A key written twice (same `str`, `bytes` or `int`)
    /// keeps its first position and its last value, as in Python.
    Dict(Vec<(Value, Value)>),
    /// A numpy `ndarray` (or a numpy scalar, as a 0-d array), or a resolved chumpy object.
    Array(NdArray),
    /// A scipy `csc_matrix`.
    Sparse(CscMatrix),
}

impl Value {
    /// Looks `key` up in a [`Value::Dict`]: matches `Str` keys equal to `key` and `Bytes`
    /// keys equal to the latin-1 encoding of `key`. `None` for other values or a missing key.
    pub fn get(&self, key: &str) -> Option<&Value> {
        let Value::Dict(items) = self else {
            return None;
        };
        items
            .iter()
            .find(|(k, _)| key_matches(k, key))
            .map(|(_, v)| v)
    }

    /// The items of a [`Value::Dict`].
    pub fn as_dict(&self) -> Option<&[(Value, Value)]> {
        match self {
            Value::Dict(items) => Some(items),
            _ => None,
        }
    }

    /// The array of a [`Value::Array`].
    pub fn as_array(&self) -> Option<&NdArray> {
        match self {
            Value::Array(a) => Some(a),
            _ => None,
        }
    }

    /// The matrix of a [`Value::Sparse`].
    pub fn as_sparse(&self) -> Option<&CscMatrix> {
        match self {
            Value::Sparse(m) => Some(m),
            _ => None,
        }
    }

    /// A number as `f64`: `Int`, `Float`, `Bool` (0 or 1) and arrays holding exactly one
    /// element (0-d arrays, numpy scalars, `(1,)`, `(1, 1)`, ...).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Int(i) => Some(*i as f64),
            Value::Float(f) => Some(*f),
            Value::Bool(b) => Some(f64::from(u8::from(*b))),
            Value::Array(a) if a.len() == 1 => a.to_f64().first().copied(),
            _ => None,
        }
    }

    /// An integer as `i64`: `Int`, `Bool` (0 or 1), a `Float` holding an exact integer in
    /// range, and one-element arrays of an integer or bool dtype.
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(*i),
            Value::Bool(b) => Some(i64::from(*b)),
            Value::Float(f) => float_to_exact_i64(*f),
            Value::Array(a) if a.len() == 1 => match &a.data {
                ArrayData::F32(_) | ArrayData::F64(_) => None,
                _ => a.to_i64().first().copied(),
            },
            _ => None,
        }
    }

    /// The text of a [`Value::Str`].
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The items of a [`Value::List`] or a [`Value::Tuple`].
    pub fn as_list(&self) -> Option<&[Value]> {
        match self {
            Value::List(v) | Value::Tuple(v) => Some(v),
            _ => None,
        }
    }

    /// A short name of the value's type, for error messages (`"dict"`, `"ndarray"`, ...).
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::None => "None",
            Value::Bool(_) => "bool",
            Value::Int(_) => "int",
            Value::Float(_) => "float",
            Value::Str(_) => "str",
            Value::Bytes(_) => "bytes",
            Value::List(_) => "list",
            Value::Tuple(_) => "tuple",
            Value::Set(_) => "set",
            Value::Dict(_) => "dict",
            Value::Array(_) => "ndarray",
            Value::Sparse(_) => "csc_matrix",
        }
    }
}

fn key_matches(k: &Value, key: &str) -> bool {
    match k {
        Value::Str(s) => s == key,
        Value::Bytes(b) => {
            b.len() == key.chars().count()
                && b.iter()
                    .zip(key.chars())
                    .all(|(&byte, c)| u32::from(byte) == u32::from(c))
        }
        _ => false,
    }
}

fn float_to_exact_i64(f: f64) -> Option<i64> {
    // 2^63 as f64 is exact; every finite float in [-2^63, 2^63) converts exactly.
    const LIMIT: f64 = 9_223_372_036_854_775_808.0;
    if f.is_finite() && f.fract() == 0.0 && (-LIMIT..LIMIT).contains(&f) {
        Some(f as i64)
    } else {
        None
    }
}

/// A numpy array: its shape and its elements in C (row-major) order.
///
/// Arrays stored in Fortran order are reordered into C order when read; big-endian
/// data is converted to native values. `shape == []` is a 0-d array (one element).
#[derive(Debug, Clone, PartialEq)]
pub struct NdArray {
    /// The dimensions.
    pub shape: Vec<usize>,
    /// The elements, always in C (row-major) order; `data.len() == shape.iter().product()`.
    pub data: ArrayData,
}

/// The typed elements of an [`NdArray`].
#[derive(Debug, Clone, PartialEq)]
pub enum ArrayData {
    /// numpy `float32` (`f4`).
    F32(Vec<f32>),
    /// numpy `float64` (`f8`).
    F64(Vec<f64>),
    /// numpy `int32` (`i4`).
    I32(Vec<i32>),
    /// numpy `int64` (`i8`).
    I64(Vec<i64>),
    /// numpy `uint32` (`u4`).
    U32(Vec<u32>),
    /// numpy `uint8` (`u1`).
    U8(Vec<u8>),
    /// numpy `bool` (`b1`).
    Bool(Vec<bool>),
}

impl ArrayData {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            ArrayData::F32(v) => v.len(),
            ArrayData::F64(v) => v.len(),
            ArrayData::I32(v) => v.len(),
            ArrayData::I64(v) => v.len(),
            ArrayData::U32(v) => v.len(),
            ArrayData::U8(v) => v.len(),
            ArrayData::Bool(v) => v.len(),
        }
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The numpy dtype code without byte order: `"f4"`, `"f8"`, `"i4"`, `"i8"`, `"u4"`,
    /// `"u1"` or `"b1"`.
    pub fn dtype(&self) -> &'static str {
        match self {
            ArrayData::F32(_) => "f4",
            ArrayData::F64(_) => "f8",
            ArrayData::I32(_) => "i4",
            ArrayData::I64(_) => "i8",
            ArrayData::U32(_) => "u4",
            ArrayData::U8(_) => "u1",
            ArrayData::Bool(_) => "b1",
        }
    }
}

impl NdArray {
    /// Number of elements (the product of the shape).
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Whether the array has no elements.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Number of dimensions.
    pub fn ndim(&self) -> usize {
        self.shape.len()
    }

    /// The numpy dtype code without byte order: `"f4"`, `"f8"`, `"i4"`, `"i8"`, `"u4"`,
    /// `"u1"` or `"b1"`.
    pub fn dtype(&self) -> &'static str {
        self.data.dtype()
    }

    /// The elements as `f64`, in C order (integers converted with `as`, so values beyond
    /// 2^53 round; bools are 0.0 / 1.0).
    pub fn to_f64(&self) -> Vec<f64> {
        match &self.data {
            ArrayData::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            ArrayData::F64(v) => v.clone(),
            ArrayData::I32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            ArrayData::I64(v) => v.iter().map(|&x| x as f64).collect(),
            ArrayData::U32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            ArrayData::U8(v) => v.iter().map(|&x| f64::from(x)).collect(),
            ArrayData::Bool(v) => v.iter().map(|&x| f64::from(u8::from(x))).collect(),
        }
    }

    /// The elements as `f32`, in C order, consuming the array: `f4` data is moved out
    /// without a copy; `f8` rounds to the nearest `f32` (out-of-range values become
    /// infinite), integers convert with `as`, bools are 0.0 / 1.0. Converting a large `f8`
    /// array holds both buffers until the `f8` one is dropped (1.5 x its size).
    pub fn into_f32(self) -> Vec<f32> {
        match self.data {
            ArrayData::F32(v) => v,
            ArrayData::F64(v) => v.into_iter().map(|x| x as f32).collect(),
            ArrayData::I32(v) => v.into_iter().map(|x| x as f32).collect(),
            ArrayData::I64(v) => v.into_iter().map(|x| x as f32).collect(),
            ArrayData::U32(v) => v.into_iter().map(|x| x as f32).collect(),
            ArrayData::U8(v) => v.into_iter().map(f32::from).collect(),
            ArrayData::Bool(v) => v.into_iter().map(|x| f32::from(u8::from(x))).collect(),
        }
    }

    /// The elements as `f64`, in C order, consuming the array: `f8` data is moved out
    /// without a copy; other dtypes convert as in [`NdArray::to_f64`].
    pub fn into_f64(self) -> Vec<f64> {
        match self.data {
            ArrayData::F64(v) => v,
            other => NdArray {
                shape: self.shape,
                data: other,
            }
            .to_f64(),
        }
    }

    /// The elements as `i64`, in C order. Floats are truncated toward zero with `as`
    /// (saturating at the `i64` range, NaN becomes 0); bools are 0 / 1.
    pub fn to_i64(&self) -> Vec<i64> {
        match &self.data {
            ArrayData::F32(v) => v.iter().map(|&x| x as i64).collect(),
            ArrayData::F64(v) => v.iter().map(|&x| x as i64).collect(),
            ArrayData::I32(v) => v.iter().map(|&x| i64::from(x)).collect(),
            ArrayData::I64(v) => v.clone(),
            ArrayData::U32(v) => v.iter().map(|&x| i64::from(x)).collect(),
            ArrayData::U8(v) => v.iter().map(|&x| i64::from(x)).collect(),
            ArrayData::Bool(v) => v.iter().map(|&x| i64::from(x)).collect(),
        }
    }
}

/// A scipy `csc_matrix` (compressed sparse columns) with `f64` values.
///
/// Column `c` holds the entries `data[k]` at rows `indices[k]` for
/// `k in indptr[c]..indptr[c + 1]`. The reader checks this structure; the fields are
/// public, so [`CscMatrix::to_dense_row_major`] checks it again.
#[derive(Debug, Clone, PartialEq)]
pub struct CscMatrix {
    /// `(rows, columns)`.
    pub shape: (usize, usize),
    /// The stored values.
    pub data: Vec<f64>,
    /// The row of each stored value.
    pub indices: Vec<i64>,
    /// Where each column starts in `data` / `indices` (`columns + 1` entries).
    pub indptr: Vec<i64>,
}

/// Largest dense matrix [`CscMatrix::to_dense_row_major`] agrees to build (2^30 elements).
pub const MAX_DENSE_ELEMENTS: usize = 1 << 30;

impl CscMatrix {
    /// Number of stored values.
    pub fn nnz(&self) -> usize {
        self.data.len()
    }

    /// Checks the structure: `indptr` has `columns + 1` entries, starts at 0, never
    /// decreases and ends at `data.len()`; `indices` has as many entries as `data`, each
    /// in `0..rows`.
    pub fn validate(&self) -> Result<(), String> {
        let (rows, cols) = self.shape;
        let nnz = self.data.len();
        if self.indices.len() != nnz {
            return Err(format!(
                "csc_matrix has {} indices but {} values",
                self.indices.len(),
                nnz
            ));
        }
        if cols.checked_add(1) != Some(self.indptr.len()) {
            return Err(format!(
                "csc_matrix of shape ({rows}, {cols}) needs {} indptr entries, found {}",
                cols as u128 + 1,
                self.indptr.len()
            ));
        }
        let mut prev = 0i64;
        for (c, &p) in self.indptr.iter().enumerate() {
            if (c == 0 && p != 0) || p < prev {
                return Err(format!(
                    "csc_matrix indptr must start at 0 and never decrease (entry {c} is {p})"
                ));
            }
            prev = p;
        }
        if usize::try_from(prev).ok() != Some(nnz) {
            return Err(format!(
                "csc_matrix indptr ends at {prev} but there are {nnz} values"
            ));
        }
        if let Some((k, &r)) = self
            .indices
            .iter()
            .enumerate()
            .find(|&(_, &r)| usize::try_from(r).map_or(true, |r| r >= rows))
        {
            return Err(format!(
                "csc_matrix row index {r} (entry {k}) is outside 0..{rows}"
            ));
        }
        Ok(())
    }

    /// The matrix as a dense row-major `rows * columns` vector (duplicate entries are
    /// summed, as scipy does). Fails when the structure is invalid (see
    /// [`CscMatrix::validate`]) or the dense matrix would exceed [`MAX_DENSE_ELEMENTS`].
    pub fn to_dense_row_major(&self) -> Result<Vec<f64>, String> {
        self.validate()?;
        let (rows, cols) = self.shape;
        let total = rows
            .checked_mul(cols)
            .filter(|&t| t <= MAX_DENSE_ELEMENTS)
            .ok_or_else(|| {
                format!("csc_matrix of shape ({rows}, {cols}) is too large to make dense")
            })?;
        let mut out = vec![0.0; total];
        for (c, w) in self.indptr.windows(2).enumerate() {
            let (Some(&start), Some(&end)) = (w.first(), w.get(1)) else {
                continue;
            };
            let range = usize::try_from(start).unwrap_or(0)..usize::try_from(end).unwrap_or(0);
            let (Some(rs), Some(vs)) = (self.indices.get(range.clone()), self.data.get(range))
            else {
                return Err("csc_matrix indptr is inconsistent".to_string());
            };
            for (&r, &v) in rs.iter().zip(vs) {
                let cell = usize::try_from(r)
                    .ok()
                    .and_then(|r| r.checked_mul(cols))
                    .and_then(|i| i.checked_add(c))
                    .and_then(|i| out.get_mut(i))
                    .ok_or_else(|| format!("csc_matrix row index {r} is out of range"))?;
                *cell += v;
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn get_matches_str_and_latin1_bytes_keys() {
        let d = Value::Dict(vec![
            (Value::Str("a".into()), Value::Int(1)),
            (Value::Bytes(vec![0xe9, b'x']), Value::Int(2)),
            (Value::Int(3), Value::Int(3)),
        ]);
        assert_eq!(d.get("a"), Some(&Value::Int(1)));
        assert_eq!(d.get("éx"), Some(&Value::Int(2)));
        assert_eq!(d.get("ex"), None);
        assert_eq!(d.get("3"), None);
        assert_eq!(Value::Int(1).get("a"), None);
    }

    #[test]
    fn scalar_accessors() {
        assert_eq!(Value::Int(-3).as_f64(), Some(-3.0));
        assert_eq!(Value::Bool(true).as_f64(), Some(1.0));
        assert_eq!(Value::Float(2.0).as_i64(), Some(2));
        assert_eq!(Value::Float(2.5).as_i64(), None);
        assert_eq!(Value::Float(f64::NAN).as_i64(), None);
        assert_eq!(Value::Float(1e300).as_i64(), None);
        let a0 = Value::Array(NdArray {
            shape: vec![],
            data: ArrayData::F32(vec![1.5]),
        });
        assert_eq!(a0.as_f64(), Some(1.5));
        assert_eq!(a0.as_i64(), None);
        let a1 = Value::Array(NdArray {
            shape: vec![1, 1],
            data: ArrayData::U32(vec![7]),
        });
        assert_eq!(a1.as_i64(), Some(7));
        assert_eq!(a1.as_f64(), Some(7.0));
        let a2 = Value::Array(NdArray {
            shape: vec![2],
            data: ArrayData::I64(vec![1, 2]),
        });
        assert_eq!(a2.as_f64(), None);
        assert_eq!(a2.type_name(), "ndarray");
        assert_eq!(Value::Str("x".into()).as_str(), Some("x"));
        assert_eq!(
            Value::Tuple(vec![Value::None]).as_list(),
            Some(&[Value::None][..])
        );
        assert_eq!(Value::Set(vec![]).as_list(), None);
    }

    #[test]
    fn array_conversions() {
        let a = NdArray {
            shape: vec![3],
            data: ArrayData::Bool(vec![true, false, true]),
        };
        assert_eq!(a.dtype(), "b1");
        assert_eq!(a.to_f64(), vec![1.0, 0.0, 1.0]);
        assert_eq!(a.to_i64(), vec![1, 0, 1]);
        let f = NdArray {
            shape: vec![3],
            data: ArrayData::F64(vec![-1.7, f64::NAN, 1e300]),
        };
        assert_eq!(f.to_i64(), vec![-1, 0, i64::MAX]);
        let u = NdArray {
            shape: vec![1],
            data: ArrayData::U32(vec![4_294_967_295]),
        };
        assert_eq!(u.to_i64(), vec![4_294_967_295]);
        assert!(!u.is_empty());
    }

    #[test]
    fn consuming_conversions() {
        let f = NdArray {
            shape: vec![3],
            data: ArrayData::F64(vec![0.1, -2.5, 1e300]),
        };
        assert_eq!(f.clone().into_f64(), vec![0.1, -2.5, 1e300]);
        assert_eq!(f.into_f32(), vec![0.1f32, -2.5, f32::INFINITY]);
        let g = NdArray {
            shape: vec![2],
            data: ArrayData::F32(vec![1.5, -0.25]),
        };
        assert_eq!(g.clone().into_f32(), vec![1.5, -0.25]);
        assert_eq!(g.into_f64(), vec![1.5, -0.25]);
        let i = NdArray {
            shape: vec![2],
            data: ArrayData::I64(vec![-3, 7]),
        };
        assert_eq!(i.clone().into_f32(), vec![-3.0, 7.0]);
        assert_eq!(i.into_f64(), vec![-3.0, 7.0]);
        let b = NdArray {
            shape: vec![2],
            data: ArrayData::Bool(vec![true, false]),
        };
        assert_eq!(b.into_f32(), vec![1.0, 0.0]);
    }

    #[test]
    fn csc_to_dense_and_validation() {
        // [[1, 0, 2], [0, 3, 0]]
        let m = CscMatrix {
            shape: (2, 3),
            data: vec![1.0, 3.0, 2.0],
            indices: vec![0, 1, 0],
            indptr: vec![0, 1, 2, 3],
        };
        assert_eq!(
            m.to_dense_row_major().unwrap(),
            vec![1.0, 0.0, 2.0, 0.0, 3.0, 0.0]
        );
        let mut bad = m.clone();
        bad.indices[1] = 2;
        assert!(bad.to_dense_row_major().unwrap_err().contains("outside"));
        let mut bad = m.clone();
        bad.indptr = vec![0, 1, 3];
        assert!(bad.to_dense_row_major().is_err());
        let mut bad = m.clone();
        bad.indptr = vec![0, 2, 1, 3];
        assert!(bad.to_dense_row_major().is_err());
        let mut bad = m.clone();
        bad.data.push(1.0);
        assert!(bad.to_dense_row_major().is_err());
        let huge = CscMatrix {
            shape: (usize::MAX, 0),
            data: vec![],
            indices: vec![],
            indptr: vec![0],
        };
        assert!(huge.to_dense_row_major().is_ok());
        let huge = CscMatrix {
            shape: (1 << 20, 1 << 20),
            data: vec![],
            indices: vec![],
            indptr: vec![0; (1 << 20) + 1],
        };
        assert!(huge.to_dense_row_major().unwrap_err().contains("too large"));
    }
}
