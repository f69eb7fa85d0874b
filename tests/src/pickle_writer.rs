//! A small pickle encoder for tests: it writes the files the project must read with the
//! opcodes, globals, memo use and nesting that the real writers use, so that tests never
//! need Python or licensed files.
//!
//! - [`write_protocol2`] writes like Python 2's `cPickle.dump(obj, f, 2)` (how MANO's
//!   `MANO_RIGHT.pkl` / `MANO_LEFT.pkl` were written): `PROTO 2`, `GLOBAL "module\nname\n"`,
//!   `BINPUT` / `LONG_BINPUT` after every memoized object and `BINGET` for repeats,
//!   Python 2 `str` as `SHORT_BINSTRING` / `BINSTRING`, numpy arrays as
//!   `_reconstruct(ndarray, (0,), 'b')` + `BUILD (1, shape, dtype, is_fortran, raw)`,
//!   dtypes as `dtype('f8', False, True)` + `BUILD (3, '<', None, None, None, -1, -1, 0)`
//!   (one dtype object per type, reused through the memo as numpy does), `csc_matrix` and
//!   chumpy objects through `NEWOBJ` with an empty argument tuple and a `BUILD` of their
//!   `__dict__`, and sets as `__builtin__.set([...])`.
//! - [`write_protocol4`] writes like Python 3's `pickle.dump(obj, f, 4)` with numpy 1.x:
//!   `FRAME`s of about 64 KiB (large byte strings outside frames), `STACK_GLOBAL` with
//!   memoized `SHORT_BINUNICODE` names, `MEMOIZE`, `BINBYTES` array data, `EMPTY_SET` /
//!   `ADDITEMS`, `LONG1` for large ints, and `scipy.sparse._csc`.
//!
//! Like CPython, the writer shares (through the memo) globals, dtypes, one-character strings
//! and identifier-like dict keys, standing in for interned strings; everything else is
//! written afresh. Nothing is validated: a shape that does not match its data is written as
//! given, which lets tests build broken files on purpose.
//!
//! Array data is taken in memory order (see [`PyValue::NdArrayF64`]).

use std::collections::HashMap;

/// A Python value that the writer can emit.
///
/// Array `data` is the raw buffer numpy pickles, in memory order: C (row-major) order, or,
/// with `fortran: true`, Fortran (column-major) order, written with numpy's Fortran flag
/// set (a reader must transpose it back into C order). For `kintree_table` (2, 16), a
/// Fortran `data` lists `parent[0], child[0], parent[1], child[1], ...`.
#[derive(Debug, Clone, PartialEq)]
pub enum PyValue {
    /// `None`.
    None,
    /// `True` / `False`.
    Bool(bool),
    /// An `int` (Python 2 writes those beyond 32 bits as a text `INT`).
    Int(i64),
    /// A `float`.
    Float(f64),
    /// A plain string literal: a Python 2 `str` (byte string) in protocol 2, holding the
    /// latin-1 encoding of the text (UTF-8 if a character is beyond U+00FF); a unicode
    /// `str` in protocol 4.
    Str(String),
    /// A unicode string (`u'...'` in Python 2).
    Unicode(String),
    /// Bytes: a Python 2 `str` with these bytes in protocol 2 (Python 2 has no `bytes`; the
    /// reader gives them back as latin-1 text), `bytes` in protocol 4.
    Bytes(Vec<u8>),
    /// A `list`.
    List(Vec<PyValue>),
    /// A `tuple`.
    Tuple(Vec<PyValue>),
    /// A `set`.
    Set(Vec<PyValue>),
    /// A `dict`, items in this order.
    Dict(Vec<(PyValue, PyValue)>),
    /// numpy `float64` array.
    NdArrayF64 {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in memory order (column-major when `fortran`).
        data: Vec<f64>,
        /// Whether `data` is in Fortran order (numpy's `is_fortran` flag).
        fortran: bool,
    },
    /// numpy `int64` array.
    NdArrayI64 {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in memory order (column-major when `fortran`).
        data: Vec<i64>,
        /// Whether `data` is in Fortran order (numpy's `is_fortran` flag).
        fortran: bool,
    },
    /// numpy `uint32` array (C order).
    NdArrayU32 {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in C order.
        data: Vec<u32>,
    },
    /// numpy `float32` array (C order).
    NdArrayF32 {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in C order.
        data: Vec<f32>,
    },
    /// numpy `int32` array (C order).
    NdArrayI32 {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in C order.
        data: Vec<i32>,
    },
    /// numpy `uint8` array (C order).
    NdArrayU8 {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in C order.
        data: Vec<u8>,
    },
    /// numpy `bool` array (C order).
    NdArrayBool {
        /// Dimensions.
        shape: Vec<usize>,
        /// Elements in C order.
        data: Vec<bool>,
    },
    /// A numpy `float64` scalar (`numpy.core.multiarray.scalar(dtype, raw)`).
    NpScalarF64(f64),
    /// A scipy `csc_matrix` with `f8` data and `i4` index arrays.
    Csc {
        /// `(rows, columns)`.
        shape: (usize, usize),
        /// Stored values.
        data: Vec<f64>,
        /// Row of each value.
        indices: Vec<i32>,
        /// Column starts (`columns + 1` entries).
        indptr: Vec<i32>,
    },
    /// A chumpy `Ch` whose `x` is the given value (an array or a number).
    ChumpyCh(Box<PyValue>),
    /// A chumpy `Select`: `a.r.ravel()[idxs].reshape(preferred_shape)`.
    ChumpySelect {
        /// The selected-from object (usually a [`PyValue::ChumpyCh`]).
        a: Box<PyValue>,
        /// Flat indices into `a` (written as an `i8` array).
        idxs: Vec<i64>,
        /// Shape of the result.
        preferred_shape: Vec<usize>,
    },
}

impl PyValue {
    /// A [`PyValue::Str`].
    pub fn str(s: &str) -> PyValue {
        PyValue::Str(s.to_string())
    }

    /// A dict with [`PyValue::Str`] keys.
    pub fn dict(items: Vec<(&str, PyValue)>) -> PyValue {
        PyValue::Dict(
            items
                .into_iter()
                .map(|(k, v)| (PyValue::str(k), v))
                .collect(),
        )
    }

    /// A C-order `float64` array.
    pub fn f64_array(shape: &[usize], data: Vec<f64>) -> PyValue {
        PyValue::NdArrayF64 {
            shape: shape.to_vec(),
            data,
            fortran: false,
        }
    }
}

/// Writes `value` as Python 2's cPickle does with protocol 2 (how MANO files were written).
pub fn write_protocol2(value: &PyValue) -> Vec<u8> {
    let mut w = Writer::new(2);
    w.save(value);
    w.finish()
}

/// Writes `value` as Python 3 does with protocol 4 and numpy 1.x (how HTML uv files and the
/// InterHand2.6M annotations were written).
pub fn write_protocol4(value: &PyValue) -> Vec<u8> {
    let mut w = Writer::new(4);
    w.save(value);
    w.finish()
}

const BATCH: usize = 1000;
const FRAME_TARGET: usize = 64 * 1024;

struct Writer {
    proto: u8,
    /// Committed output.
    out: Vec<u8>,
    /// Current frame (protocol 4) or everything after PROTO (protocol 2).
    buf: Vec<u8>,
    memo_len: u32,
    /// Memo indices of shared objects (globals, dtypes, "interned" strings).
    shared: HashMap<String, u32>,
}

fn identifier_like(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c == '_' || c.is_ascii_alphabetic())
        && chars.all(|c| c == '_' || c.is_ascii_alphanumeric())
}

fn latin1_or_utf8(s: &str) -> Vec<u8> {
    s.chars()
        .map(|c| u8::try_from(u32::from(c)).ok())
        .collect::<Option<Vec<u8>>>()
        .unwrap_or_else(|| s.as_bytes().to_vec())
}

/// Python's `encode_long`: minimal little-endian two's complement.
fn encode_long(x: i64) -> Vec<u8> {
    if x == 0 {
        return Vec::new();
    }
    let mut b = x.to_le_bytes().to_vec();
    while b.len() > 1 {
        let last = b[b.len() - 1];
        let prev_sign = b[b.len() - 2] & 0x80 != 0;
        if (last == 0 && !prev_sign) || (last == 0xff && prev_sign) {
            b.pop();
        } else {
            break;
        }
    }
    b
}

impl Writer {
    fn new(proto: u8) -> Self {
        Writer {
            proto,
            out: vec![0x80, proto],
            buf: Vec::new(),
            memo_len: 0,
            shared: HashMap::new(),
        }
    }

    fn finish(mut self) -> Vec<u8> {
        self.buf.push(b'.');
        self.commit_frame(true);
        self.out
    }

    fn w(&mut self, b: &[u8]) {
        self.buf.extend_from_slice(b);
    }

    fn op(&mut self, b: u8) {
        self.buf.push(b);
    }

    /// Protocol 4 framing, as `pickle._Framer.commit_frame`.
    fn commit_frame(&mut self, force: bool) {
        if self.proto < 4 {
            if force {
                let buf = std::mem::take(&mut self.buf);
                self.out.extend_from_slice(&buf);
            }
            return;
        }
        if self.buf.len() >= FRAME_TARGET || (force && !self.buf.is_empty()) {
            let buf = std::mem::take(&mut self.buf);
            if buf.len() >= 4 {
                self.out.push(0x95);
                self.out
                    .extend_from_slice(&(buf.len() as u64).to_le_bytes());
            }
            self.out.extend_from_slice(&buf);
        }
    }

    fn memoize(&mut self) -> u32 {
        let idx = self.memo_len;
        self.memo_len += 1;
        if self.proto >= 4 {
            self.op(0x94);
        } else if let Ok(i) = u8::try_from(idx) {
            self.w(&[b'q', i]);
        } else {
            self.op(b'r');
            self.w(&idx.to_le_bytes());
        }
        idx
    }

    fn get(&mut self, idx: u32) {
        if let Ok(i) = u8::try_from(idx) {
            self.w(&[b'h', i]);
        } else {
            self.op(b'j');
            self.w(&idx.to_le_bytes());
        }
    }

    /// Emits a shared object once; later uses fetch it from the memo.
    fn shared_or(&mut self, key: String, emit: impl FnOnce(&mut Self) -> u32) {
        if let Some(&idx) = self.shared.get(&key) {
            self.get(idx);
        } else {
            let idx = emit(self);
            self.shared.insert(key, idx);
        }
    }

    fn save(&mut self, v: &PyValue) {
        self.commit_frame(false);
        match v {
            PyValue::None => self.op(b'N'),
            PyValue::Bool(b) => self.op(if *b { 0x88 } else { 0x89 }),
            PyValue::Int(i) => self.int(*i),
            PyValue::Float(f) => {
                self.op(b'G');
                self.w(&f.to_be_bytes());
            }
            PyValue::Str(s) => self.text(s, false),
            PyValue::Unicode(s) => self.unicode(s, false),
            PyValue::Bytes(b) => {
                if self.proto >= 3 {
                    self.bytes(b);
                } else {
                    self.py2str(b, false);
                }
            }
            PyValue::List(items) => {
                self.op(b']');
                self.memoize();
                self.batch(items, b'a', b'e');
            }
            PyValue::Tuple(items) => self.tuple(items),
            PyValue::Set(items) => self.set(items),
            PyValue::Dict(items) => self.dict(items),
            PyValue::NdArrayF64 {
                shape,
                data,
                fortran,
            } => self.array("f8", shape, *fortran, data, |x| x.to_le_bytes().to_vec()),
            PyValue::NdArrayI64 {
                shape,
                data,
                fortran,
            } => self.array("i8", shape, *fortran, data, |x| x.to_le_bytes().to_vec()),
            PyValue::NdArrayU32 { shape, data } => {
                self.array("u4", shape, false, data, |x| x.to_le_bytes().to_vec())
            }
            PyValue::NdArrayF32 { shape, data } => {
                self.array("f4", shape, false, data, |x| x.to_le_bytes().to_vec())
            }
            PyValue::NdArrayI32 { shape, data } => {
                self.array("i4", shape, false, data, |x| x.to_le_bytes().to_vec())
            }
            PyValue::NdArrayU8 { shape, data } => {
                self.array("u1", shape, false, data, |x| vec![*x])
            }
            PyValue::NdArrayBool { shape, data } => {
                self.array("b1", shape, false, data, |x| vec![u8::from(*x)])
            }
            PyValue::NpScalarF64(x) => {
                self.global("numpy.core.multiarray", "scalar");
                self.dtype("f8");
                self.raw_data(&x.to_le_bytes());
                self.op(0x86);
                self.memoize();
                self.op(b'R');
                self.memoize();
            }
            PyValue::Csc {
                shape,
                data,
                indices,
                indptr,
            } => {
                let module = if self.proto >= 4 {
                    "scipy.sparse._csc"
                } else {
                    "scipy.sparse.csc"
                };
                let state = PyValue::dict(vec![
                    (
                        "_shape",
                        PyValue::Tuple(vec![
                            PyValue::Int(shape.0 as i64),
                            PyValue::Int(shape.1 as i64),
                        ]),
                    ),
                    ("maxprint", PyValue::Int(50)),
                    (
                        "indices",
                        PyValue::NdArrayI32 {
                            shape: vec![indices.len()],
                            data: indices.clone(),
                        },
                    ),
                    (
                        "indptr",
                        PyValue::NdArrayI32 {
                            shape: vec![indptr.len()],
                            data: indptr.clone(),
                        },
                    ),
                    ("format", PyValue::str("csc")),
                    ("data", PyValue::f64_array(&[data.len()], data.clone())),
                ]);
                self.newobj(module, "csc_matrix", &state);
            }
            PyValue::ChumpyCh(x) => {
                let state = PyValue::dict(vec![
                    ("_dirty_vars", PyValue::Set(vec![])),
                    ("_itr", PyValue::None),
                    ("_make_dense", PyValue::Bool(false)),
                    ("_make_sparse", PyValue::Bool(false)),
                    ("_depends_on_deps", PyValue::Dict(vec![])),
                    ("x", (**x).clone()),
                ]);
                self.newobj("chumpy.ch", "Ch", &state);
            }
            PyValue::ChumpySelect {
                a,
                idxs,
                preferred_shape,
            } => {
                let state = PyValue::dict(vec![
                    ("a", (**a).clone()),
                    (
                        "_dirty_vars",
                        PyValue::Set(vec![
                            PyValue::str("a"),
                            PyValue::str("idxs"),
                            PyValue::str("preferred_shape"),
                        ]),
                    ),
                    ("_itr", PyValue::None),
                    (
                        "idxs",
                        PyValue::NdArrayI64 {
                            shape: vec![idxs.len()],
                            data: idxs.clone(),
                            fortran: false,
                        },
                    ),
                    (
                        "preferred_shape",
                        PyValue::Tuple(
                            preferred_shape
                                .iter()
                                .map(|&d| PyValue::Int(d as i64))
                                .collect(),
                        ),
                    ),
                    ("_make_dense", PyValue::Bool(false)),
                    ("_make_sparse", PyValue::Bool(false)),
                    (
                        "_depends_on_deps",
                        PyValue::dict(vec![(
                            "dr_wrt",
                            PyValue::dict(vec![
                                ("deps", PyValue::Set(vec![])),
                                ("value", PyValue::None),
                                ("out_of_date", PyValue::Bool(true)),
                            ]),
                        )]),
                    ),
                ]);
                self.newobj("chumpy.reordering", "Select", &state);
            }
        }
    }

    fn int(&mut self, i: i64) {
        if (0..=0xff).contains(&i) {
            self.w(&[b'K', i as u8]);
        } else if (0..=0xffff).contains(&i) {
            self.op(b'M');
            self.w(&(i as u16).to_le_bytes());
        } else if let Ok(v) = i32::try_from(i) {
            self.op(b'J');
            self.w(&v.to_le_bytes());
        } else if self.proto >= 4 {
            let b = encode_long(i);
            self.w(&[0x8a, b.len() as u8]);
            self.w(&b);
        } else {
            // cPickle: a Python 2 int beyond 32 bits is written as text.
            self.w(format!("I{i}\n").as_bytes());
        }
    }

    /// A plain string literal (`PyValue::Str`); `key` marks dict keys.
    fn text(&mut self, s: &str, key: bool) {
        if self.proto >= 3 {
            self.unicode(s, key);
        } else {
            self.py2str(&latin1_or_utf8(s), key && identifier_like(s));
        }
    }

    fn py2str(&mut self, b: &[u8], interned: bool) {
        let emit = |w: &mut Self| {
            if let Ok(n) = u8::try_from(b.len()) {
                w.w(&[b'U', n]);
            } else {
                w.op(b'T');
                w.w(&(b.len() as i32).to_le_bytes());
            }
            w.w(b);
            w.memoize()
        };
        if interned || b.len() <= 1 {
            let key: String = b.iter().map(|&c| char::from(c)).collect();
            self.shared_or(format!("s:{key}"), emit);
        } else {
            emit(self);
        }
    }

    fn unicode(&mut self, s: &str, key: bool) {
        let emit = |w: &mut Self| {
            let b = s.as_bytes();
            if w.proto >= 4 && b.len() < 256 {
                w.w(&[0x8c, b.len() as u8]);
            } else if let Ok(n) = u32::try_from(b.len()) {
                w.op(b'X');
                w.w(&n.to_le_bytes());
            } else {
                w.op(0x8d);
                w.w(&(b.len() as u64).to_le_bytes());
            }
            w.w(b);
            w.memoize()
        };
        if (key && identifier_like(s)) || s.chars().count() <= 1 {
            self.shared_or(format!("u:{s}"), emit);
        } else {
            emit(self);
        }
    }

    fn bytes(&mut self, b: &[u8]) {
        if let Ok(n) = u8::try_from(b.len()) {
            self.w(&[b'C', n]);
            self.w(b);
        } else {
            let header: Vec<u8> = match u32::try_from(b.len()) {
                Ok(n) => [&[b'B'][..], &n.to_le_bytes()].concat(),
                Err(_) => [&[0x8e][..], &(b.len() as u64).to_le_bytes()].concat(),
            };
            if b.len() >= FRAME_TARGET && self.proto >= 4 {
                // pickle._Pickler._write_large_bytes: outside any frame.
                self.commit_frame(true);
                self.out.extend_from_slice(&header);
                self.out.extend_from_slice(b);
            } else {
                self.w(&header);
                self.w(b);
            }
        }
        self.memoize();
    }

    /// Raw array data: a Python 2 `str` in protocol 2, `bytes` in protocol 3+.
    fn raw_data(&mut self, b: &[u8]) {
        if self.proto >= 3 {
            if b.len() <= 1 {
                let key: String = b.iter().map(|&c| char::from(c)).collect();
                self.shared_or(format!("b:{key}"), |w| {
                    w.bytes(b);
                    w.memo_len - 1
                });
            } else {
                self.bytes(b);
            }
        } else {
            self.py2str(b, false);
        }
    }

    fn batch(&mut self, items: &[PyValue], one: u8, many: u8) {
        for chunk in items.chunks(BATCH) {
            if let [only] = chunk {
                self.save(only);
                self.op(one);
            } else {
                self.op(b'(');
                for x in chunk {
                    self.save(x);
                }
                self.op(many);
            }
        }
    }

    fn tuple(&mut self, items: &[PyValue]) {
        match items.len() {
            0 => self.op(b')'),
            n @ 1..=3 => {
                for x in items {
                    self.save(x);
                }
                self.op(0x84 + n as u8);
                self.memoize();
            }
            _ => {
                self.op(b'(');
                for x in items {
                    self.save(x);
                }
                self.op(b't');
                self.memoize();
            }
        }
    }

    fn set(&mut self, items: &[PyValue]) {
        if self.proto >= 4 {
            self.op(0x8f);
            self.memoize();
            for chunk in items.chunks(BATCH) {
                self.op(b'(');
                for x in chunk {
                    self.save(x);
                }
                self.op(0x90);
            }
        } else {
            // set.__reduce__ = (set, (list(self),), None)
            self.global("__builtin__", "set");
            self.op(b']');
            self.memoize();
            self.batch(items, b'a', b'e');
            self.op(0x85);
            self.memoize();
            self.op(b'R');
            self.memoize();
        }
    }

    fn dict(&mut self, items: &[(PyValue, PyValue)]) {
        self.op(b'}');
        self.memoize();
        for chunk in items.chunks(BATCH) {
            let pair = |w: &mut Self, k: &PyValue, v: &PyValue| {
                match k {
                    PyValue::Str(s) => {
                        w.commit_frame(false);
                        w.text(s, true);
                    }
                    PyValue::Unicode(s) => {
                        w.commit_frame(false);
                        w.unicode(s, true);
                    }
                    _ => w.save(k),
                }
                w.save(v);
            };
            if let [(k, v)] = chunk {
                pair(self, k, v);
                self.op(b's');
            } else {
                self.op(b'(');
                for (k, v) in chunk {
                    pair(self, k, v);
                }
                self.op(b'u');
            }
        }
    }

    fn global(&mut self, module: &str, name: &str) {
        self.shared_or(format!("g:{module}.{name}"), |w| {
            if w.proto >= 4 {
                w.unicode(module, true);
                w.unicode(name, true);
                w.op(0x93);
            } else {
                w.w(format!("c{module}\n{name}\n").as_bytes());
            }
            w.memoize()
        });
    }

    /// One dtype object per type, as numpy's builtin descriptors are singletons.
    fn dtype(&mut self, code: &str) {
        let endian = if matches!(code, "u1" | "b1") {
            "|"
        } else {
            "<"
        };
        self.shared_or(format!("d:{endian}{code}"), |w| {
            w.global("numpy", "dtype");
            // numpy creates the type string afresh (not interned).
            if w.proto >= 3 {
                w.unicode_fresh(code);
            } else {
                w.py2str(code.as_bytes(), false);
            }
            w.op(0x89);
            w.op(0x88);
            w.op(0x87);
            w.memoize();
            w.op(b'R');
            let idx = w.memoize();
            w.op(b'(');
            w.int(3);
            w.text(endian, false);
            w.op(b'N');
            w.op(b'N');
            w.op(b'N');
            w.int(-1);
            w.int(-1);
            w.int(0);
            w.op(b't');
            w.memoize();
            w.op(b'b');
            idx
        });
    }

    fn unicode_fresh(&mut self, s: &str) {
        let b = s.as_bytes();
        if self.proto >= 4 && b.len() < 256 {
            self.w(&[0x8c, b.len() as u8]);
        } else {
            self.op(b'X');
            self.w(&(b.len() as u32).to_le_bytes());
        }
        self.w(b);
        self.memoize();
    }

    /// ndarray.__reduce__: `(_reconstruct, (ndarray, (0,), b'b'), (1, shape, dtype,
    /// is_fortran, raw))`.
    fn array<T>(
        &mut self,
        code: &str,
        shape: &[usize],
        fortran: bool,
        data: &[T],
        to_bytes: impl Fn(&T) -> Vec<u8>,
    ) {
        self.global("numpy.core.multiarray", "_reconstruct");
        self.global("numpy", "ndarray");
        self.int(0);
        self.op(0x85);
        self.memoize();
        self.raw_data(b"b");
        self.op(0x87);
        self.memoize();
        self.op(b'R');
        self.memoize();
        // state
        self.op(b'(');
        self.int(1);
        let dims: Vec<PyValue> = shape.iter().map(|&d| PyValue::Int(d as i64)).collect();
        self.tuple(&dims);
        self.dtype(code);
        self.op(if fortran { 0x88 } else { 0x89 });
        let raw: Vec<u8> = data.iter().flat_map(&to_bytes).collect();
        self.raw_data(&raw);
        self.op(b't');
        self.memoize();
        self.op(b'b');
    }

    /// `copyreg.__newobj__`: `cls`, `()`, NEWOBJ, then BUILD of the instance `__dict__`.
    fn newobj(&mut self, module: &str, name: &str, state: &PyValue) {
        self.global(module, name);
        self.op(b')');
        self.op(0x81);
        self.memoize();
        self.save(state);
        self.op(b'b');
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_long_is_minimal() {
        assert_eq!(encode_long(0), Vec::<u8>::new());
        assert_eq!(encode_long(255), vec![0xff, 0x00]);
        assert_eq!(encode_long(-1), vec![0xff]);
        assert_eq!(encode_long(-128), vec![0x80]);
        assert_eq!(encode_long(1 << 40), vec![0, 0, 0, 0, 0, 1]);
        assert_eq!(encode_long(i64::MIN), i64::MIN.to_le_bytes().to_vec());
    }

    #[test]
    fn protocol2_prefix_and_globals_as_cpickle() {
        let v = PyValue::dict(vec![
            ("a", PyValue::f64_array(&[2], vec![1.0, 2.0])),
            ("b", PyValue::f64_array(&[1], vec![3.0])),
        ]);
        let p = write_protocol2(&v);
        assert_eq!(&p[..4], b"\x80\x02}q");
        let count = |needle: &[u8]| p.windows(needle.len()).filter(|w| *w == needle).count();
        assert_eq!(count(b"cnumpy.core.multiarray\n_reconstruct\n"), 1);
        assert_eq!(count(b"cnumpy\ndtype\n"), 1);
        assert_eq!(p.last(), Some(&b'.'));
    }
}
