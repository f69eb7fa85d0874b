//! Turns the finished object graph of the [`Machine`] into [`Value`]s, decoding arrays and
//! resolving scipy and chumpy objects.
//!
//! This walk recurses, so it is depth-limited ([`MAX_DEPTH`], which also stops reference
//! cycles), and it is charged against a budget so that shared references cannot expand a
//! small input into an enormous value.

use std::collections::HashMap;

use crate::error::PickleErrorKind;
use crate::machine::{Class, H, Machine, Obj, TensorSpec, latin1};
use crate::numpy::{self, shape_str};
use crate::value::{ArrayData, CscMatrix, NdArray, Value};

/// Deepest nesting of containers (and chumpy / scipy objects) accepted.
pub const MAX_DEPTH: usize = 200;

type R<T> = Result<T, (usize, PickleErrorKind)>;

pub(crate) struct Converter<'m, 'a> {
    m: &'m Machine<'a>,
    /// Values and array elements that may still be produced.
    budget: usize,
    /// The storages of a torch checkpoint, by key (empty for other pickles).
    storages: Option<&'m HashMap<String, &'m [u8]>>,
}

#[derive(Hash, PartialEq, Eq)]
enum DictKey {
    Str(String),
    Bytes(Vec<u8>),
    Int(i64),
}

fn dict_key(v: &Value) -> Option<DictKey> {
    match v {
        Value::Str(s) => Some(DictKey::Str(s.clone())),
        Value::Bytes(b) => Some(DictKey::Bytes(b.clone())),
        Value::Int(i) => Some(DictKey::Int(*i)),
        Value::Bool(b) => Some(DictKey::Int(i64::from(*b))),
        _ => None,
    }
}

impl<'m, 'a> Converter<'m, 'a> {
    pub(crate) fn new(m: &'m Machine<'a>, budget: usize) -> Self {
        Converter {
            m,
            budget,
            storages: None,
        }
    }

    /// A converter for a torch checkpoint's object pickle, with its storages by key.
    pub(crate) fn with_storages(
        m: &'m Machine<'a>,
        budget: usize,
        storages: &'m HashMap<String, &'m [u8]>,
    ) -> Self {
        Converter {
            m,
            budget,
            storages: Some(storages),
        }
    }

    fn offset(&self, h: H) -> usize {
        self.m.slots.get(h).map_or(0, |s| s.offset)
    }

    fn obj(&self, h: H) -> R<&'m Obj<'a>> {
        self.m.obj(h).map_err(|k| (self.offset(h), k))
    }

    fn charge(&mut self, h: H, n: usize) -> R<()> {
        match self.budget.checked_sub(n) {
            Some(b) => {
                self.budget = b;
                Ok(())
            }
            None => Err((
                self.offset(h),
                PickleErrorKind::TooLarge(
                    "the pickle expands to too many values (heavily shared references)".into(),
                ),
            )),
        }
    }

    fn fail<T>(&self, h: H, kind: PickleErrorKind) -> R<T> {
        Err((self.offset(h), kind))
    }

    fn bad<T>(&self, h: H, msg: impl Into<String>) -> R<T> {
        self.fail(h, PickleErrorKind::BadArgument(msg.into()))
    }

    /// The value of object `h`, `depth` levels below the root.
    pub(crate) fn value(&mut self, h: H, depth: usize) -> R<Value> {
        if depth > MAX_DEPTH {
            return self.fail(
                h,
                PickleErrorKind::TooLarge(format!(
                    "nesting deeper than {MAX_DEPTH} levels (or a reference cycle)"
                )),
            );
        }
        self.charge(h, 1)?;
        Ok(match self.obj(h)? {
            Obj::None => Value::None,
            Obj::Bool(b) => Value::Bool(*b),
            Obj::Int(i) => Value::Int(*i),
            Obj::Float(f) => Value::Float(*f),
            Obj::Str(s) => {
                self.charge(h, s.len() / 8)?;
                Value::Str(s.clone())
            }
            Obj::PyStr(b) => {
                self.charge(h, b.bytes().len() / 8)?;
                Value::Str(latin1(b.bytes()))
            }
            Obj::Bytes(b) => {
                self.charge(h, b.bytes().len() / 8)?;
                Value::Bytes(b.bytes().to_vec())
            }
            Obj::List(items) => Value::List(self.values(items, depth)?),
            Obj::Tuple(items) => Value::Tuple(self.values(items, depth)?),
            Obj::Set(items) => Value::Set(self.values(items, depth)?),
            Obj::Dict(pairs) => self.dict(pairs, depth)?,
            Obj::Global(g) => {
                return self.bad(
                    h,
                    format!(
                        "a bare global ({}) cannot be represented as a value",
                        g.name()
                    ),
                );
            }
            Obj::Dtype(d) => {
                return self.bad(
                    h,
                    format!(
                        "a numpy.dtype object ({}) cannot be represented as a value",
                        d.describe()
                    ),
                );
            }
            Obj::PendingArray => {
                return self.bad(h, "an ndarray that was never built (no BUILD opcode)");
            }
            Obj::Array(spec) => {
                let count = numpy::element_count(&spec.shape).map_err(|k| (self.offset(h), k))?;
                self.charge(h, count)?;
                Value::Array(
                    numpy::to_ndarray(spec.data.bytes(), spec.dtype, &spec.shape, spec.fortran)
                        .map_err(|k| (self.offset(h), k))?,
                )
            }
            Obj::Instance { class, state } => match class {
                Class::Csc => Value::Sparse(self.csc(h, state, depth)?),
                Class::Ch => Value::Array(self.ch(h, state, depth)?),
                Class::Select => Value::Array(self.select(h, state, depth)?),
            },
            Obj::Storage { dtype, .. } => {
                return self.bad(
                    h,
                    format!(
                        "a bare {} (not inside a tensor) cannot be represented as a value",
                        dtype.storage_name()
                    ),
                );
            }
            Obj::Tensor(spec) => Value::Array(self.tensor(h, spec)?),
        })
    }

    #[inline(never)]
    fn tensor(&mut self, h: H, spec: &TensorSpec) -> R<NdArray> {
        let Obj::Storage { dtype, key, numel } = self.obj(spec.storage)? else {
            return self.bad(h, "tensor storage is not a storage");
        };
        let bytes = self
            .storages
            .and_then(|s| s.get(key))
            .copied()
            .ok_or_else(|| {
                (
                    self.offset(h),
                    PickleErrorKind::BadArgument(format!(
                        "the checkpoint holds no data for storage {key:?}"
                    )),
                )
            })?;
        let count = numpy::element_count(&spec.shape).map_err(|k| (self.offset(h), k))?;
        self.charge(h, count)?;
        crate::storage::tensor_data(
            *dtype,
            bytes,
            *numel,
            spec.offset,
            &spec.shape,
            &spec.stride,
        )
        .map_err(|k| (self.offset(h), k))
    }

    fn values(&mut self, items: &[H], depth: usize) -> R<Vec<Value>> {
        let mut out = Vec::with_capacity(items.len());
        for &i in items {
            out.push(self.value(i, depth + 1)?);
        }
        Ok(out)
    }

    #[inline(never)]
    fn dict(&mut self, pairs: &[(H, H)], depth: usize) -> R<Value> {
        let mut out: Vec<(Value, Value)> = Vec::with_capacity(pairs.len());
        let mut seen: HashMap<DictKey, usize> = HashMap::new();
        for &(k, v) in pairs {
            let k = self.value(k, depth + 1)?;
            let v = self.value(v, depth + 1)?;
            match dict_key(&k) {
                Some(key) => match seen.get(&key).and_then(|&i| out.get_mut(i)) {
                    Some(slot) => slot.1 = v,
                    None => {
                        seen.insert(key, out.len());
                        out.push((k, v));
                    }
                },
                None => out.push((k, v)),
            }
        }
        Ok(Value::Dict(out))
    }

    /// The value handle stored under `key` in an instance's state dicts (last one wins).
    /// Each entry looked at is charged, so that many objects sharing one huge state dict
    /// cannot make the lookups quadratic.
    fn state_get(&mut self, state: &[H], key: &str) -> R<Option<H>> {
        for &d in state.iter().rev() {
            self.charge(d, 1)?;
            let Obj::Dict(pairs) = self.obj(d)? else {
                continue;
            };
            for &(k, v) in pairs.iter().rev() {
                self.charge(d, 1)?;
                let matches = match self.obj(k)? {
                    Obj::Str(s) => s == key,
                    Obj::PyStr(b) => b.bytes() == key.as_bytes(),
                    _ => false,
                };
                if matches {
                    return Ok(Some(v));
                }
            }
        }
        Ok(None)
    }

    fn required(&mut self, h: H, state: &[H], class: Class, key: &str) -> R<H> {
        match self.state_get(state, key)? {
            Some(v) => Ok(v),
            None => self.bad(h, format!("{} state has no {key:?}", class.name())),
        }
    }

    /// The chumpy value of `h` as an array: arrays as they are, numbers as 0-d arrays,
    /// chumpy objects resolved.
    fn array_of(&mut self, h: H, depth: usize, what: &str) -> R<NdArray> {
        match self.value(h, depth)? {
            Value::Array(a) => Ok(a),
            Value::Float(f) => Ok(NdArray {
                shape: Vec::new(),
                data: ArrayData::F64(vec![f]),
            }),
            Value::Int(i) => Ok(NdArray {
                shape: Vec::new(),
                data: ArrayData::I64(vec![i]),
            }),
            Value::Bool(b) => Ok(NdArray {
                shape: Vec::new(),
                data: ArrayData::Bool(vec![b]),
            }),
            other => self.bad(
                h,
                format!("{what} is a {}, expected an array", other.type_name()),
            ),
        }
    }

    /// Integers of an integer array or a list / tuple of ints, with their shape.
    fn ints_of(&mut self, h: H, depth: usize, what: &str) -> R<(Vec<i64>, Vec<usize>)> {
        match self.value(h, depth)? {
            Value::Array(a) => match a.data {
                ArrayData::F32(_) | ArrayData::F64(_) => self.bad(
                    h,
                    format!("{what} must be integers, found dtype {}", a.dtype()),
                ),
                _ => Ok((a.to_i64(), a.shape)),
            },
            Value::List(items) | Value::Tuple(items) => {
                let n = items.len();
                let v: Option<Vec<i64>> = items.iter().map(Value::as_i64).collect();
                match v {
                    Some(v) => Ok((v, vec![n])),
                    None => self.bad(h, format!("{what} must hold integers")),
                }
            }
            Value::Int(i) => Ok((vec![i], vec![])),
            other => self.bad(
                h,
                format!("{what} is a {}, expected integers", other.type_name()),
            ),
        }
    }

    fn dims_of(&mut self, h: H, depth: usize, what: &str) -> R<Vec<usize>> {
        let (v, _) = self.ints_of(h, depth, what)?;
        v.iter()
            .map(|&d| usize::try_from(d).ok())
            .collect::<Option<Vec<usize>>>()
            .map_or_else(|| self.bad(h, format!("{what} has a negative entry")), Ok)
    }

    #[inline(never)]
    fn csc(&mut self, h: H, state: &[H], depth: usize) -> R<CscMatrix> {
        let class = Class::Csc;
        let shape_h = match self.state_get(state, "_shape")? {
            Some(s) => s,
            None => self.required(h, state, class, "shape")?,
        };
        let shape = self.dims_of(shape_h, depth + 1, "csc_matrix shape")?;
        let &[rows, cols] = shape.as_slice() else {
            return self.bad(
                h,
                format!("csc_matrix shape {} is not 2-d", shape_str(&shape)),
            );
        };
        let data_h = self.required(h, state, class, "data")?;
        let data = self
            .array_of(data_h, depth + 1, "csc_matrix data")?
            .to_f64();
        let indices_h = self.required(h, state, class, "indices")?;
        let (indices, _) = self.ints_of(indices_h, depth + 1, "csc_matrix indices")?;
        let indptr_h = self.required(h, state, class, "indptr")?;
        let (indptr, _) = self.ints_of(indptr_h, depth + 1, "csc_matrix indptr")?;
        let m = CscMatrix {
            shape: (rows, cols),
            data,
            indices,
            indptr,
        };
        m.validate()
            .map_err(|e| (self.offset(h), PickleErrorKind::SizeMismatch(e)))?;
        Ok(m)
    }

    #[inline(never)]
    fn ch(&mut self, h: H, state: &[H], depth: usize) -> R<NdArray> {
        let x = self.required(h, state, Class::Ch, "x")?;
        self.array_of(x, depth + 1, "chumpy Ch 'x'")
    }

    #[inline(never)]
    fn select(&mut self, h: H, state: &[H], depth: usize) -> R<NdArray> {
        let class = Class::Select;
        let a_h = self.required(h, state, class, "a")?;
        let a = self.array_of(a_h, depth + 1, "chumpy Select 'a'")?;
        let idxs_h = self.required(h, state, class, "idxs")?;
        let (idxs, idx_shape) = self.ints_of(idxs_h, depth + 1, "chumpy Select 'idxs'")?;
        let shape = match self.state_get(state, "preferred_shape")? {
            Some(p) => self.dims_of(p, depth + 1, "chumpy Select 'preferred_shape'")?,
            None => idx_shape,
        };
        let n = numpy::element_count(&shape).map_err(|k| (self.offset(h), k))?;
        if n != idxs.len() {
            return self.fail(
                h,
                PickleErrorKind::SizeMismatch(format!(
                    "chumpy Select has {} indices but preferred_shape {} holds {n}",
                    idxs.len(),
                    shape_str(&shape)
                )),
            );
        }
        self.charge(h, n)?;
        let len = a.len();
        let mut flat = Vec::with_capacity(idxs.len());
        for &i in &idxs {
            match usize::try_from(i) {
                Ok(u) if u < len => flat.push(u),
                _ => {
                    return self.fail(
                        h,
                        PickleErrorKind::SizeMismatch(format!(
                            "chumpy Select index {i} is outside its array of {len} elements"
                        )),
                    );
                }
            }
        }
        let data = numpy::gather(&a.data, &flat).ok_or_else(|| {
            (
                self.offset(h),
                PickleErrorKind::BadArgument("bad index".into()),
            )
        })?;
        Ok(NdArray { shape, data })
    }
}
