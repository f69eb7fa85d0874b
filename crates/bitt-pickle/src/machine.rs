//! The pickle virtual machine: interprets opcodes into an arena of objects.
//!
//! Objects live in an arena and the stack and memo hold handles into it, so that an object
//! memoized before it is filled (`EMPTY_DICT`, `BINPUT`, `SETITEMS`) or built (`REDUCE`,
//! `BINPUT`, `BUILD`) is seen complete when fetched again, as in Python. The interpreter is a
//! flat loop: nesting in the input never recurses here.

use std::cell::Cell;
use std::collections::HashMap;
use std::rc::Rc;

use crate::error::PickleErrorKind;
use crate::numpy::{self, Dtype};
use crate::storage::TorchDtype;

type R<T> = Result<T, PickleErrorKind>;

/// Index of an object in the arena.
pub(crate) type H = usize;

/// Most items on the stack at once.
pub(crate) const MAX_STACK: usize = 1 << 22;
/// Most nested marks.
pub(crate) const MAX_MARKS: usize = 1 << 16;
/// Most memo entries.
pub(crate) const MAX_MEMO: usize = 1 << 22;
/// Most objects created.
pub(crate) const MAX_OBJECTS: usize = 1 << 25;
/// Most dimensions of an array (numpy allows 32, or 64 since numpy 2).
pub(crate) const MAX_NDIM: usize = 64;
/// Longest string accepted where a name is expected (globals, dtype codes, encodings).
const MAX_NAME: usize = 1024;

/// Classes whose instances are built from a state dict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Class {
    Csc,
    Ch,
    Select,
}

impl Class {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Class::Csc => "scipy.sparse csc_matrix",
            Class::Ch => "chumpy.ch.Ch",
            Class::Select => "chumpy.reordering.Select",
        }
    }
}

/// The globals this reader understands. Nothing else can be referenced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Global {
    Reconstruct,
    NdArrayType,
    DtypeType,
    Scalar,
    FromBuffer,
    Class(Class),
    SetType,
    ObjectType,
    Reconstructor,
    CodecsEncode,
    BytesType,
    ByteArrayType,
    /// `torch._utils._rebuild_tensor_v2` (torch checkpoints only).
    RebuildTensorV2,
    /// `torch._utils._rebuild_tensor` (torch checkpoints only).
    RebuildTensor,
    /// `torch._utils._rebuild_parameter` (torch checkpoints only).
    RebuildParameter,
    /// `torch.FloatStorage` and the other typed storages (torch checkpoints only).
    Storage(TorchDtype),
    /// `collections.OrderedDict` (torch checkpoints only).
    OrderedDict,
}

impl Global {
    /// The globals of torch checkpoints, understood only by [`Machine::new_torch`].
    fn resolve_torch(module: &str, name: &str) -> Option<Global> {
        Some(match (module, name) {
            ("torch._utils", "_rebuild_tensor_v2") => Global::RebuildTensorV2,
            ("torch._utils", "_rebuild_tensor") => Global::RebuildTensor,
            ("torch._utils", "_rebuild_parameter") => Global::RebuildParameter,
            ("torch", storage) => Global::Storage(TorchDtype::from_storage_name(storage)?),
            ("collections", "OrderedDict") => Global::OrderedDict,
            _ => return None,
        })
    }

    fn resolve(module: &str, name: &str) -> Option<Global> {
        Some(match (module, name) {
            ("numpy.core.multiarray" | "numpy._core.multiarray", "_reconstruct") => {
                Global::Reconstruct
            }
            ("numpy", "ndarray") => Global::NdArrayType,
            ("numpy", "dtype") => Global::DtypeType,
            ("numpy.core.multiarray" | "numpy._core.multiarray", "scalar") => Global::Scalar,
            ("numpy.core.numeric" | "numpy._core.numeric", "_frombuffer") => Global::FromBuffer,
            ("scipy.sparse.csc" | "scipy.sparse._csc", "csc_matrix") => Global::Class(Class::Csc),
            ("chumpy.ch", "Ch") => Global::Class(Class::Ch),
            ("chumpy.reordering", "Select") => Global::Class(Class::Select),
            ("__builtin__" | "builtins", "set" | "frozenset") => Global::SetType,
            ("__builtin__" | "builtins", "object") => Global::ObjectType,
            ("__builtin__" | "builtins", "bytes") => Global::BytesType,
            ("__builtin__" | "builtins", "bytearray") => Global::ByteArrayType,
            ("copy_reg" | "copyreg", "_reconstructor") => Global::Reconstructor,
            ("_codecs", "encode") => Global::CodecsEncode,
            _ => return None,
        })
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Global::Reconstruct => "numpy.core.multiarray._reconstruct",
            Global::NdArrayType => "numpy.ndarray",
            Global::DtypeType => "numpy.dtype",
            Global::Scalar => "numpy.core.multiarray.scalar",
            Global::FromBuffer => "numpy.core.numeric._frombuffer",
            Global::Class(c) => c.name(),
            Global::SetType => "builtins.set",
            Global::ObjectType => "builtins.object",
            Global::Reconstructor => "copyreg._reconstructor",
            Global::CodecsEncode => "_codecs.encode",
            Global::BytesType => "builtins.bytes",
            Global::ByteArrayType => "builtins.bytearray",
            Global::RebuildTensorV2 => "torch._utils._rebuild_tensor_v2",
            Global::RebuildTensor => "torch._utils._rebuild_tensor",
            Global::RebuildParameter => "torch._utils._rebuild_parameter",
            Global::Storage(d) => d.storage_name(),
            Global::OrderedDict => "collections.OrderedDict",
        }
    }
}

/// Bytes: a slice of the input (no copy) or owned.
#[derive(Debug, Clone)]
pub(crate) enum Buf<'a> {
    In(&'a [u8]),
    Own(Rc<[u8]>),
}

impl Buf<'_> {
    pub(crate) fn bytes(&self) -> &[u8] {
        match self {
            Buf::In(b) => b,
            Buf::Own(b) => b,
        }
    }
}

/// A validated numpy array whose elements are decoded when the value is produced.
#[derive(Debug, Clone)]
pub(crate) struct ArraySpec<'a> {
    pub(crate) dtype: Dtype,
    pub(crate) shape: Vec<usize>,
    pub(crate) fortran: bool,
    pub(crate) data: Buf<'a>,
}

/// An object in the arena.
#[derive(Debug)]
pub(crate) enum Obj<'a> {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    /// Unicode `str`.
    Str(String),
    /// Python 2 `str`: bytes, read as latin-1.
    PyStr(Buf<'a>),
    Bytes(Buf<'a>),
    List(Vec<H>),
    Tuple(Vec<H>),
    Set(Vec<H>),
    Dict(Vec<(H, H)>),
    Global(Global),
    Dtype(Dtype),
    /// Made by `_reconstruct`, waiting for its BUILD.
    PendingArray,
    Array(Box<ArraySpec<'a>>),
    /// A csc_matrix or chumpy object; `state` holds the dicts given to BUILD, in order.
    Instance {
        class: Class,
        state: Vec<H>,
    },
    /// A torch storage named by a persistent id (torch checkpoints only): its bytes live
    /// outside the pickle, under `key`.
    Storage {
        dtype: TorchDtype,
        key: String,
        numel: usize,
    },
    /// A torch tensor: a strided view of a [`Obj::Storage`] (torch checkpoints only).
    Tensor(Box<TensorSpec>),
}

/// A validated strided view of a storage (every element lies inside the storage).
#[derive(Debug, Clone)]
pub(crate) struct TensorSpec {
    pub(crate) storage: H,
    pub(crate) offset: usize,
    pub(crate) shape: Vec<usize>,
    pub(crate) stride: Vec<usize>,
}

impl Obj<'_> {
    pub(crate) fn type_name(&self) -> String {
        match self {
            Obj::None => "None".into(),
            Obj::Bool(_) => "bool".into(),
            Obj::Int(_) => "int".into(),
            Obj::Float(_) => "float".into(),
            Obj::Str(_) => "str".into(),
            Obj::PyStr(_) => "str (Python 2)".into(),
            Obj::Bytes(_) => "bytes".into(),
            Obj::List(_) => "list".into(),
            Obj::Tuple(_) => "tuple".into(),
            Obj::Set(_) => "set".into(),
            Obj::Dict(_) => "dict".into(),
            Obj::Global(g) => format!("global {}", g.name()),
            Obj::Dtype(_) => "numpy.dtype".into(),
            Obj::PendingArray => "ndarray (not yet built)".into(),
            Obj::Array(_) => "ndarray".into(),
            Obj::Instance { class, .. } => class.name().into(),
            Obj::Storage { dtype, .. } => dtype.storage_name().into(),
            Obj::Tensor(_) => "torch.Tensor".into(),
        }
    }
}

/// An object and the offset of the opcode that created it (or last built it).
#[derive(Debug)]
pub(crate) struct Slot<'a> {
    pub(crate) obj: Obj<'a>,
    pub(crate) offset: usize,
}

/// The interpreter state.
#[derive(Debug)]
pub(crate) struct Machine<'a> {
    input: &'a [u8],
    pos: usize,
    /// Offset of the opcode being interpreted.
    cur: usize,
    pub(crate) slots: Vec<Slot<'a>>,
    stack: Vec<H>,
    marks: Vec<usize>,
    memo: HashMap<u32, H>,
    /// Items or bytes that calls may still copy (`set(list)`, latin-1 encodings): bounds
    /// the work of a small input that calls them many times on one large argument.
    copy_budget: Cell<usize>,
    /// Torch checkpoint mode: persistent ids name storages, and the torch globals are known.
    torch: bool,
}

fn bad<T>(msg: impl Into<String>) -> R<T> {
    Err(PickleErrorKind::BadArgument(msg.into()))
}

fn internal() -> PickleErrorKind {
    PickleErrorKind::BadArgument("internal error: dangling object handle".to_string())
}

impl<'a> Machine<'a> {
    pub(crate) fn new(input: &'a [u8]) -> Self {
        Machine {
            input,
            pos: 0,
            cur: 0,
            slots: Vec::new(),
            stack: Vec::new(),
            marks: Vec::new(),
            memo: HashMap::new(),
            copy_budget: Cell::new(input.len().saturating_mul(4).saturating_add(1 << 18)),
            torch: false,
        }
    }

    /// A machine for the pickle of a torch checkpoint (`torch.save`): it also understands
    /// persistent ids naming storages (`BINPERSID`), `torch._utils._rebuild_tensor_v2`,
    /// `_rebuild_tensor`, `_rebuild_parameter`, the typed storage classes and
    /// `collections.OrderedDict`.
    pub(crate) fn new_torch(input: &'a [u8]) -> Self {
        Machine {
            torch: true,
            ..Machine::new(input)
        }
    }

    /// Bytes consumed so far (after [`Machine::run`]: the length of the pickle).
    pub(crate) fn position(&self) -> usize {
        self.pos
    }

    fn global(&self, module: &str, name: &str) -> R<Global> {
        let g = Global::resolve(module, name).or_else(|| {
            if self.torch {
                Global::resolve_torch(module, name)
            } else {
                None
            }
        });
        g.ok_or_else(|| PickleErrorKind::UnsupportedGlobal {
            module: module.to_string(),
            name: name.to_string(),
        })
    }

    /// Runs to the STOP opcode; returns the handle of the result, or the offset of the
    /// failing opcode and the error.
    pub(crate) fn run(&mut self) -> Result<H, (usize, PickleErrorKind)> {
        loop {
            self.cur = self.pos;
            let Some(&op) = self.input.get(self.pos) else {
                return Err((self.pos, PickleErrorKind::Truncated));
            };
            self.pos += 1;
            match self.step(op) {
                Ok(Some(h)) => return Ok(h),
                Ok(None) => {}
                Err(k) => return Err((self.cur, k)),
            }
        }
    }

    // ----- input -----

    fn take(&mut self, n: usize) -> R<&'a [u8]> {
        let end = self.pos.checked_add(n).ok_or(PickleErrorKind::Truncated)?;
        let s = self
            .input
            .get(self.pos..end)
            .ok_or(PickleErrorKind::Truncated)?;
        self.pos = end;
        Ok(s)
    }

    fn fixed<const N: usize>(&mut self) -> R<[u8; N]> {
        let s = self.take(N)?;
        s.first_chunk::<N>()
            .copied()
            .ok_or(PickleErrorKind::Truncated)
    }

    fn u8(&mut self) -> R<u8> {
        Ok(self.fixed::<1>()?[0])
    }

    fn u32(&mut self) -> R<u32> {
        Ok(u32::from_le_bytes(self.fixed()?))
    }

    fn u64(&mut self) -> R<u64> {
        Ok(u64::from_le_bytes(self.fixed()?))
    }

    /// Checks a declared length against the input before anything is read or allocated.
    fn length(&self, n: u64) -> R<usize> {
        match usize::try_from(n) {
            Ok(n) if n <= self.input.len() => Ok(n),
            _ => Err(PickleErrorKind::TooLarge(format!(
                "declared length {n} is larger than the whole input ({} bytes)",
                self.input.len()
            ))),
        }
    }

    fn take_len(&mut self, n: u64) -> R<&'a [u8]> {
        let n = self.length(n)?;
        self.take(n)
    }

    /// A line without its `\n`.
    fn line(&mut self) -> R<&'a [u8]> {
        let rest = self
            .input
            .get(self.pos..)
            .ok_or(PickleErrorKind::Truncated)?;
        let n = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or(PickleErrorKind::Truncated)?;
        let s = rest.get(..n).ok_or(PickleErrorKind::Truncated)?;
        self.pos = self.pos.saturating_add(n + 1);
        Ok(s)
    }

    fn line_str(&mut self) -> R<&'a str> {
        let l = self.line()?;
        std::str::from_utf8(l).or_else(|_| bad("line argument is not valid UTF-8"))
    }

    // ----- stack, memo, arena -----

    fn floor(&self) -> usize {
        self.marks.last().copied().unwrap_or(0)
    }

    fn push(&mut self, h: H) -> R<()> {
        if self.stack.len() >= MAX_STACK {
            return Err(PickleErrorKind::TooLarge(format!(
                "more than {MAX_STACK} items on the stack"
            )));
        }
        self.stack.push(h);
        Ok(())
    }

    fn pop(&mut self) -> R<H> {
        if self.stack.len() <= self.floor() {
            return Err(PickleErrorKind::StackUnderflow);
        }
        self.stack.pop().ok_or(PickleErrorKind::StackUnderflow)
    }

    fn top(&self) -> R<H> {
        if self.stack.len() <= self.floor() {
            return Err(PickleErrorKind::StackUnderflow);
        }
        self.stack
            .last()
            .copied()
            .ok_or(PickleErrorKind::StackUnderflow)
    }

    fn pop_n(&mut self, n: usize) -> R<Vec<H>> {
        let start = self
            .stack
            .len()
            .checked_sub(n)
            .filter(|&s| s >= self.floor())
            .ok_or(PickleErrorKind::StackUnderflow)?;
        Ok(self.stack.split_off(start))
    }

    fn pop_mark(&mut self) -> R<Vec<H>> {
        let m = self.marks.pop().ok_or(PickleErrorKind::StackUnderflow)?;
        if m > self.stack.len() {
            return Err(PickleErrorKind::StackUnderflow);
        }
        Ok(self.stack.split_off(m))
    }

    fn alloc(&mut self, obj: Obj<'a>) -> R<H> {
        if self.slots.len() >= MAX_OBJECTS {
            return Err(PickleErrorKind::TooLarge(format!(
                "more than {MAX_OBJECTS} objects"
            )));
        }
        self.slots.push(Slot {
            obj,
            offset: self.cur,
        });
        Ok(self.slots.len() - 1)
    }

    fn new_obj(&mut self, obj: Obj<'a>) -> R<()> {
        let h = self.alloc(obj)?;
        self.push(h)
    }

    pub(crate) fn obj(&self, h: H) -> R<&Obj<'a>> {
        self.slots.get(h).map(|s| &s.obj).ok_or_else(internal)
    }

    fn obj_mut(&mut self, h: H) -> R<&mut Obj<'a>> {
        self.slots
            .get_mut(h)
            .map(|s| &mut s.obj)
            .ok_or_else(internal)
    }

    fn put(&mut self, idx: u32) -> R<()> {
        let h = self.top()?;
        if self.memo.len() >= MAX_MEMO && !self.memo.contains_key(&idx) {
            return Err(PickleErrorKind::TooLarge(format!(
                "more than {MAX_MEMO} memo entries"
            )));
        }
        self.memo.insert(idx, h);
        Ok(())
    }

    fn get(&mut self, idx: u32) -> R<()> {
        let h = *self
            .memo
            .get(&idx)
            .ok_or_else(|| PickleErrorKind::BadArgument(format!("memo key {idx} is not set")))?;
        self.push(h)
    }

    fn line_memo_key(&mut self) -> R<u32> {
        let s = self.line_str()?;
        s.trim()
            .parse::<u32>()
            .or_else(|_| bad(format!("invalid memo key {s:?}")))
    }

    // ----- the interpreter -----

    fn step(&mut self, op: u8) -> R<Option<H>> {
        match op {
            // STOP
            b'.' => return self.pop().map(Some),
            // PROTO
            0x80 => {
                let p = self.u8()?;
                if p > 5 {
                    return Err(PickleErrorKind::UnsupportedProtocol(p));
                }
            }
            // FRAME: only a length prefix; the framed opcodes follow in line.
            0x95 => {
                let n = self.u64()?;
                let n = self.length(n)?;
                if n > self.input.len().saturating_sub(self.pos) {
                    return Err(PickleErrorKind::Truncated);
                }
            }
            // MARK
            b'(' => {
                if self.marks.len() >= MAX_MARKS {
                    return Err(PickleErrorKind::TooLarge(format!(
                        "more than {MAX_MARKS} nested marks"
                    )));
                }
                self.marks.push(self.stack.len());
            }
            // POP: the top item, or the mark when nothing is above it (as CPython does).
            b'0' => {
                if self.stack.len() > self.floor() {
                    self.pop()?;
                } else {
                    self.pop_mark()?;
                }
            }
            // POP_MARK
            b'1' => {
                self.pop_mark()?;
            }
            // DUP
            b'2' => {
                let h = self.top()?;
                self.push(h)?;
            }
            // PUT, BINPUT, LONG_BINPUT, MEMOIZE
            b'p' => {
                let i = self.line_memo_key()?;
                self.put(i)?;
            }
            b'q' => {
                let i = self.u8()?;
                self.put(u32::from(i))?;
            }
            b'r' => {
                let i = self.u32()?;
                self.put(i)?;
            }
            0x94 => {
                let i = u32::try_from(self.memo.len())
                    .map_err(|_| PickleErrorKind::TooLarge("memo too large".into()))?;
                self.put(i)?;
            }
            // GET, BINGET, LONG_BINGET
            b'g' => {
                let i = self.line_memo_key()?;
                self.get(i)?;
            }
            b'h' => {
                let i = self.u8()?;
                self.get(u32::from(i))?;
            }
            b'j' => {
                let i = self.u32()?;
                self.get(i)?;
            }
            // NONE, NEWTRUE, NEWFALSE
            b'N' => self.new_obj(Obj::None)?,
            0x88 => self.new_obj(Obj::Bool(true))?,
            0x89 => self.new_obj(Obj::Bool(false))?,
            // INT (protocol 0; "00"/"01" are the old booleans)
            b'I' => {
                let l = self.line()?;
                let o = match l {
                    b"00" => Obj::Bool(false),
                    b"01" => Obj::Bool(true),
                    _ => Obj::Int(parse_int_text(l, false)?),
                };
                self.new_obj(o)?;
            }
            // BININT, BININT1, BININT2
            b'J' => {
                let v = i32::from_le_bytes(self.fixed()?);
                self.new_obj(Obj::Int(i64::from(v)))?;
            }
            b'K' => {
                let v = self.u8()?;
                self.new_obj(Obj::Int(i64::from(v)))?;
            }
            b'M' => {
                let v = u16::from_le_bytes(self.fixed()?);
                self.new_obj(Obj::Int(i64::from(v)))?;
            }
            // LONG (protocol 0, optional trailing 'L')
            b'L' => {
                let l = self.line()?;
                let v = parse_int_text(l, true)?;
                self.new_obj(Obj::Int(v))?;
            }
            // LONG1, LONG4
            0x8a => {
                let n = self.u8()?;
                let b = self.take(usize::from(n))?;
                let v = decode_long(b)?;
                self.new_obj(Obj::Int(v))?;
            }
            0x8b => {
                let n = i32::from_le_bytes(self.fixed()?);
                let n = u64::try_from(n).or_else(|_| bad("LONG4 with a negative length"))?;
                let b = self.take_len(n)?;
                let v = decode_long(b)?;
                self.new_obj(Obj::Int(v))?;
            }
            // FLOAT, BINFLOAT
            b'F' => {
                let s = self.line_str()?;
                let v = s
                    .trim()
                    .parse::<f64>()
                    .or_else(|_| bad(format!("invalid float literal {s:?}")))?;
                self.new_obj(Obj::Float(v))?;
            }
            b'G' => {
                let v = f64::from_be_bytes(self.fixed()?);
                self.new_obj(Obj::Float(v))?;
            }
            // STRING, BINSTRING, SHORT_BINSTRING (Python 2 str)
            b'S' => {
                let l = self.line()?;
                let b = unescape_string(l)?;
                self.new_obj(Obj::PyStr(Buf::Own(b.into())))?;
            }
            b'T' => {
                let n = i32::from_le_bytes(self.fixed()?);
                let n = u64::try_from(n).or_else(|_| bad("BINSTRING with a negative length"))?;
                let b = self.take_len(n)?;
                self.new_obj(Obj::PyStr(Buf::In(b)))?;
            }
            b'U' => {
                let n = self.u8()?;
                let b = self.take(usize::from(n))?;
                self.new_obj(Obj::PyStr(Buf::In(b)))?;
            }
            // UNICODE, BINUNICODE, SHORT_BINUNICODE, BINUNICODE8
            b'V' => {
                let l = self.line()?;
                let s = raw_unicode_escape(l)?;
                self.new_obj(Obj::Str(s))?;
            }
            b'X' => {
                let n = self.u32()?;
                let b = self.take_len(u64::from(n))?;
                self.new_obj(Obj::Str(utf8(b)?))?;
            }
            0x8c => {
                let n = self.u8()?;
                let b = self.take(usize::from(n))?;
                self.new_obj(Obj::Str(utf8(b)?))?;
            }
            0x8d => {
                let n = self.u64()?;
                let b = self.take_len(n)?;
                self.new_obj(Obj::Str(utf8(b)?))?;
            }
            // BINBYTES, SHORT_BINBYTES, BINBYTES8, BYTEARRAY8
            b'B' => {
                let n = self.u32()?;
                let b = self.take_len(u64::from(n))?;
                self.new_obj(Obj::Bytes(Buf::In(b)))?;
            }
            b'C' => {
                let n = self.u8()?;
                let b = self.take(usize::from(n))?;
                self.new_obj(Obj::Bytes(Buf::In(b)))?;
            }
            0x8e | 0x96 => {
                let n = self.u64()?;
                let b = self.take_len(n)?;
                self.new_obj(Obj::Bytes(Buf::In(b)))?;
            }
            // EMPTY_LIST, APPEND, APPENDS, LIST
            b']' => self.new_obj(Obj::List(Vec::new()))?,
            b'a' => {
                let v = self.pop()?;
                let t = self.top()?;
                match self.obj_mut(t)? {
                    Obj::List(items) => items.push(v),
                    other => return bad(format!("APPEND to a {}", other.type_name())),
                }
            }
            b'e' => {
                let vs = self.pop_mark()?;
                let t = self.top()?;
                match self.obj_mut(t)? {
                    Obj::List(items) => items.extend(vs),
                    other => return bad(format!("APPENDS to a {}", other.type_name())),
                }
            }
            b'l' => {
                let vs = self.pop_mark()?;
                self.new_obj(Obj::List(vs))?;
            }
            // EMPTY_TUPLE, TUPLE, TUPLE1, TUPLE2, TUPLE3
            b')' => self.new_obj(Obj::Tuple(Vec::new()))?,
            b't' => {
                let vs = self.pop_mark()?;
                self.new_obj(Obj::Tuple(vs))?;
            }
            0x85..=0x87 => {
                let vs = self.pop_n(usize::from(op - 0x84))?;
                self.new_obj(Obj::Tuple(vs))?;
            }
            // EMPTY_DICT, DICT, SETITEM, SETITEMS
            b'}' => self.new_obj(Obj::Dict(Vec::new()))?,
            b'd' => {
                let vs = self.pop_mark()?;
                let pairs = pairs(vs)?;
                self.new_obj(Obj::Dict(pairs))?;
            }
            b's' => {
                let v = self.pop()?;
                let k = self.pop()?;
                let t = self.top()?;
                match self.obj_mut(t)? {
                    Obj::Dict(items) => items.push((k, v)),
                    other => return bad(format!("SETITEM on a {}", other.type_name())),
                }
            }
            b'u' => {
                let vs = self.pop_mark()?;
                let t = self.top()?;
                let ps = pairs(vs)?;
                match self.obj_mut(t)? {
                    Obj::Dict(items) => items.extend(ps),
                    other => return bad(format!("SETITEMS on a {}", other.type_name())),
                }
            }
            // EMPTY_SET, ADDITEMS, FROZENSET
            0x8f => self.new_obj(Obj::Set(Vec::new()))?,
            0x90 => {
                let vs = self.pop_mark()?;
                let t = self.top()?;
                match self.obj_mut(t)? {
                    Obj::Set(items) => items.extend(vs),
                    other => return bad(format!("ADDITEMS on a {}", other.type_name())),
                }
            }
            0x91 => {
                let vs = self.pop_mark()?;
                self.new_obj(Obj::Set(vs))?;
            }
            // GLOBAL, STACK_GLOBAL
            b'c' => {
                let module = self.line_str()?;
                let name = self.line_str()?;
                let g = self.global(module, name)?;
                self.new_obj(Obj::Global(g))?;
            }
            0x93 => {
                let name = self.pop()?;
                let module = self.pop()?;
                let name = self.text(name, "STACK_GLOBAL name")?;
                let module = self.text(module, "STACK_GLOBAL module")?;
                let g = self.global(&module, &name)?;
                self.new_obj(Obj::Global(g))?;
            }
            // REDUCE, NEWOBJ, NEWOBJ_EX, BUILD
            b'R' => {
                let args = self.pop()?;
                let func = self.pop()?;
                let o = self.reduce(func, args)?;
                self.new_obj(o)?;
            }
            0x81 => {
                let args = self.pop()?;
                let cls = self.pop()?;
                let o = self.newobj(cls, args, None)?;
                self.new_obj(o)?;
            }
            0x92 => {
                let kwargs = self.pop()?;
                let args = self.pop()?;
                let cls = self.pop()?;
                let o = self.newobj(cls, args, Some(kwargs))?;
                self.new_obj(o)?;
            }
            b'b' => {
                let state = self.pop()?;
                let inst = self.top()?;
                self.build(inst, state)?;
            }
            // BINPERSID: a storage of a torch checkpoint.
            b'Q' if self.torch => {
                let pid = self.pop()?;
                let o = self.persistent_storage(pid)?;
                self.new_obj(o)?;
            }
            other => return Err(PickleErrorKind::UnknownOpcode(other)),
        }
        Ok(None)
    }

    // ----- argument helpers -----

    fn spend(&self, n: usize) -> R<()> {
        let left = self.copy_budget.get().checked_sub(n).ok_or_else(|| {
            PickleErrorKind::TooLarge("the pickle copies too much data (shared references)".into())
        })?;
        self.copy_budget.set(left);
        Ok(())
    }

    /// A unicode or Python 2 (latin-1) string used as a name: at most [`MAX_NAME`] bytes.
    fn text(&self, h: H, what: &str) -> R<String> {
        match self.obj(h)? {
            Obj::Str(s) if s.len() <= MAX_NAME => Ok(s.clone()),
            Obj::PyStr(b) if b.bytes().len() <= MAX_NAME => Ok(latin1(b.bytes())),
            Obj::Str(_) | Obj::PyStr(_) => bad(format!("{what} is longer than {MAX_NAME} bytes")),
            other => bad(format!("{what} must be a str, not a {}", other.type_name())),
        }
    }

    /// The latin-1 encoding of a str, charged to the copy budget.
    fn latin1_of(&self, h: H, what: &str) -> R<Vec<u8>> {
        match self.obj(h)? {
            Obj::Str(s) => {
                self.spend(s.len())?;
                encode_latin1(s).ok_or_else(|| {
                    PickleErrorKind::BadArgument(format!("{what} has characters beyond latin-1"))
                })
            }
            Obj::PyStr(b) => {
                self.spend(b.bytes().len())?;
                Ok(b.bytes().to_vec())
            }
            other => bad(format!("{what} must be a str, not a {}", other.type_name())),
        }
    }

    /// Bytes of a bytes-like argument (bytes, bytearray, Python 2 str, or a str holding
    /// only latin-1 characters, as Python 3 decodes Python 2 strings).
    fn bytes_like(&self, h: H, what: &str) -> R<Buf<'a>> {
        match self.obj(h)? {
            Obj::Bytes(b) | Obj::PyStr(b) => Ok(b.clone()),
            Obj::Str(_) => Ok(Buf::Own(self.latin1_of(h, what)?.into())),
            other => bad(format!("{what} must be bytes, not a {}", other.type_name())),
        }
    }

    fn tuple_items(&self, h: H, what: &str) -> R<&[H]> {
        match self.obj(h)? {
            Obj::Tuple(v) => Ok(v),
            other => bad(format!(
                "{what} must be a tuple, not a {}",
                other.type_name()
            )),
        }
    }

    fn int(&self, h: H, what: &str) -> R<i64> {
        match self.obj(h)? {
            Obj::Int(i) => Ok(*i),
            Obj::Bool(b) => Ok(i64::from(*b)),
            other => bad(format!(
                "{what} must be an int, not a {}",
                other.type_name()
            )),
        }
    }

    fn shape(&self, h: H, what: &str) -> R<Vec<usize>> {
        let items = match self.obj(h)? {
            Obj::Tuple(v) | Obj::List(v) => v,
            Obj::Int(_) => std::slice::from_ref(&h),
            other => {
                return bad(format!(
                    "{what} must be a tuple of ints, not a {}",
                    other.type_name()
                ));
            }
        };
        if items.len() > MAX_NDIM {
            return bad(format!(
                "{what} has {} dimensions (at most {MAX_NDIM})",
                items.len()
            ));
        }
        items
            .iter()
            .map(|&d| {
                let v = self.int(d, what)?;
                usize::try_from(v).or_else(|_| bad(format!("{what} has a negative dimension {v}")))
            })
            .collect()
    }

    fn dtype(&self, h: H, what: &str) -> R<Dtype> {
        match self.obj(h)? {
            Obj::Dtype(d) => Ok(*d),
            other => bad(format!(
                "{what} must be a numpy.dtype, not a {}",
                other.type_name()
            )),
        }
    }

    fn global_of(&self, h: H) -> R<Option<Global>> {
        Ok(match self.obj(h)? {
            Obj::Global(g) => Some(*g),
            _ => None,
        })
    }

    // ----- calls -----

    fn reduce(&self, func: H, args: H) -> R<Obj<'a>> {
        let g = match self.obj(func)? {
            Obj::Global(g) => *g,
            other => {
                return bad(format!(
                    "REDUCE needs a global to call, got a {}",
                    other.type_name()
                ));
            }
        };
        let args = self.tuple_items(args, "REDUCE arguments")?;
        let nargs = |range: std::ops::RangeInclusive<usize>| -> R<()> {
            if range.contains(&args.len()) {
                Ok(())
            } else {
                bad(format!(
                    "{} called with {} arguments (expected {}..={})",
                    g.name(),
                    args.len(),
                    range.start(),
                    range.end()
                ))
            }
        };
        let arg = |i: usize| -> R<H> { args.get(i).copied().ok_or_else(internal) };
        match g {
            Global::Reconstruct => {
                nargs(3..=3)?;
                if self.global_of(arg(0)?)? != Some(Global::NdArrayType) {
                    return bad("_reconstruct may only make a numpy.ndarray");
                }
                Ok(Obj::PendingArray)
            }
            Global::DtypeType => {
                nargs(1..=3)?;
                let s = self.text(arg(0)?, "numpy.dtype argument")?;
                Ok(Obj::Dtype(Dtype::parse(&s)?))
            }
            Global::Scalar => {
                nargs(2..=2)?;
                let dtype = self.dtype(arg(0)?, "numpy scalar dtype")?;
                let data = self.bytes_like(arg(1)?, "numpy scalar data")?;
                numpy::check_size(&[], dtype, data.bytes().len())?;
                Ok(Obj::Array(Box::new(ArraySpec {
                    dtype,
                    shape: Vec::new(),
                    fortran: false,
                    data,
                })))
            }
            Global::FromBuffer => {
                nargs(4..=4)?;
                let data = self.bytes_like(arg(0)?, "_frombuffer buffer")?;
                let dtype = self.dtype(arg(1)?, "_frombuffer dtype")?;
                let shape = self.shape(arg(2)?, "_frombuffer shape")?;
                let order = self.text(arg(3)?, "_frombuffer order")?;
                let fortran = match order.as_str() {
                    "C" | "A" | "K" => false,
                    "F" => true,
                    _ => return bad(format!("_frombuffer order {order:?} is not C or F")),
                };
                numpy::check_size(&shape, dtype, data.bytes().len())?;
                Ok(Obj::Array(Box::new(ArraySpec {
                    dtype,
                    shape,
                    fortran,
                    data,
                })))
            }
            Global::SetType => {
                nargs(0..=1)?;
                let items = match args.first() {
                    None => Vec::new(),
                    Some(&h) => match self.obj(h)? {
                        Obj::List(v) | Obj::Tuple(v) | Obj::Set(v) => {
                            self.spend(v.len())?;
                            v.clone()
                        }
                        other => {
                            return bad(format!("set() of a {}", other.type_name()));
                        }
                    },
                };
                Ok(Obj::Set(items))
            }
            Global::Reconstructor => {
                nargs(3..=3)?;
                let Some(Global::Class(class)) = self.global_of(arg(0)?)? else {
                    return bad("copyreg._reconstructor of an unsupported class");
                };
                if self.global_of(arg(1)?)? != Some(Global::ObjectType) {
                    return bad("copyreg._reconstructor with a base other than object");
                }
                if !matches!(self.obj(arg(2)?)?, Obj::None) {
                    return bad("copyreg._reconstructor with a base state");
                }
                Ok(Obj::Instance {
                    class,
                    state: Vec::new(),
                })
            }
            Global::CodecsEncode => {
                nargs(2..=2)?;
                let b = self.encode_text(arg(0)?, arg(1)?, g)?;
                Ok(Obj::Bytes(Buf::Own(b.into())))
            }
            Global::BytesType => {
                nargs(0..=0)?;
                Ok(Obj::Bytes(Buf::Own(Rc::from(Vec::new()))))
            }
            // bytearray(), bytearray(b'...'), or bytearray(u'...', 'latin-1') (protocol < 3).
            Global::ByteArrayType => match args {
                [] => Ok(Obj::Bytes(Buf::Own(Rc::from(Vec::new())))),
                [b] => Ok(Obj::Bytes(self.bytes_like(*b, "bytearray argument")?)),
                [text, enc] => Ok(Obj::Bytes(Buf::Own(
                    self.encode_text(*text, *enc, g)?.into(),
                ))),
                _ => {
                    nargs(0..=2)?;
                    Err(internal())
                }
            },
            Global::Class(class) => {
                nargs(0..=0)?;
                Ok(Obj::Instance {
                    class,
                    state: Vec::new(),
                })
            }
            Global::RebuildTensorV2 => {
                // (storage, offset, size, stride, requires_grad, backward_hooks[, metadata])
                nargs(6..=7)?;
                Ok(Obj::Tensor(Box::new(self.tensor_spec(args)?)))
            }
            Global::RebuildTensor => {
                nargs(4..=4)?;
                Ok(Obj::Tensor(Box::new(self.tensor_spec(args)?)))
            }
            Global::RebuildParameter => {
                // (data, requires_grad, backward_hooks): the parameter is its data.
                nargs(3..=3)?;
                match self.obj(arg(0)?)? {
                    Obj::Tensor(t) => Ok(Obj::Tensor(t.clone())),
                    other => bad(format!(
                        "_rebuild_parameter of a {}, expected a tensor",
                        other.type_name()
                    )),
                }
            }
            Global::OrderedDict => {
                nargs(0..=1)?;
                let Some(&items) = args.first() else {
                    return Ok(Obj::Dict(Vec::new()));
                };
                let items = match self.obj(items)? {
                    Obj::List(v) | Obj::Tuple(v) => v,
                    other => return bad(format!("OrderedDict() of a {}", other.type_name())),
                };
                self.spend(items.len())?;
                let mut pairs = Vec::with_capacity(items.len());
                for &item in items {
                    match self.obj(item)? {
                        Obj::List(kv) | Obj::Tuple(kv) if kv.len() == 2 => {
                            pairs.push((kv[0], kv[1]));
                        }
                        other => {
                            return bad(format!(
                                "OrderedDict() item is a {}, expected a pair",
                                other.type_name()
                            ));
                        }
                    }
                }
                Ok(Obj::Dict(pairs))
            }
            Global::NdArrayType | Global::ObjectType | Global::Storage(_) => {
                bad(format!("{} cannot be called by this reader", g.name()))
            }
        }
    }

    /// `text.encode(encoding)` for latin-1 encodings only (how Python 3 writes bytes in
    /// protocols below 3).
    fn encode_text(&self, text: H, encoding: H, g: Global) -> R<Vec<u8>> {
        let enc = self
            .text(encoding, "encoding")?
            .to_ascii_lowercase()
            .replace('_', "-");
        if !matches!(
            enc.as_str(),
            "latin1" | "latin-1" | "iso-8859-1" | "iso8859-1" | "l1"
        ) {
            return bad(format!("{} with encoding {enc:?} (only latin1)", g.name()));
        }
        self.latin1_of(text, "text to encode")
    }

    fn newobj(&self, cls: H, args: H, kwargs: Option<H>) -> R<Obj<'a>> {
        let Some(Global::Class(class)) = self.global_of(cls)? else {
            return bad(format!(
                "NEWOBJ of a {} (only csc_matrix and chumpy classes)",
                self.obj(cls)?.type_name()
            ));
        };
        if !self.tuple_items(args, "NEWOBJ arguments")?.is_empty() {
            return bad(format!("NEWOBJ of {} with arguments", class.name()));
        }
        if let Some(k) = kwargs {
            match self.obj(k)? {
                Obj::Dict(d) if d.is_empty() => {}
                _ => {
                    return bad(format!(
                        "NEWOBJ_EX of {} with keyword arguments",
                        class.name()
                    ));
                }
            }
        }
        Ok(Obj::Instance {
            class,
            state: Vec::new(),
        })
    }

    fn build(&mut self, inst: H, state: H) -> R<()> {
        let new = match self.obj(inst)? {
            Obj::PendingArray | Obj::Array(_) => Obj::Array(Box::new(self.array_state(state)?)),
            Obj::Dtype(d) => Obj::Dtype(self.dtype_state(*d, state)?),
            Obj::Instance { class, .. } => {
                let mut dicts = Vec::new();
                let class = *class;
                match self.obj(state)? {
                    Obj::Dict(_) => dicts.push(state),
                    Obj::None => {}
                    Obj::Tuple(t) if t.len() == 2 => {
                        for &h in t {
                            match self.obj(h)? {
                                Obj::Dict(_) => dicts.push(h),
                                Obj::None => {}
                                other => {
                                    return bad(format!(
                                        "{} state holds a {}",
                                        class.name(),
                                        other.type_name()
                                    ));
                                }
                            }
                        }
                    }
                    other => {
                        return bad(format!(
                            "{} state must be a dict, not a {}",
                            class.name(),
                            other.type_name()
                        ));
                    }
                }
                let cur = self.cur;
                let slot = self.slots.get_mut(inst).ok_or_else(internal)?;
                if let Obj::Instance { state, .. } = &mut slot.obj {
                    state.extend(dicts);
                }
                slot.offset = cur;
                return Ok(());
            }
            // Attributes of a torch state dict (an OrderedDict with `_metadata`): dropped.
            Obj::Dict(_) if self.torch => {
                return match self.obj(state)? {
                    Obj::Dict(_) | Obj::None => Ok(()),
                    other => bad(format!(
                        "OrderedDict state must be a dict, not a {}",
                        other.type_name()
                    )),
                };
            }
            other => return bad(format!("BUILD on a {}", other.type_name())),
        };
        let cur = self.cur;
        let slot = self.slots.get_mut(inst).ok_or_else(internal)?;
        slot.obj = new;
        slot.offset = cur;
        Ok(())
    }

    /// The persistent id of a torch storage: `('storage', <typed storage class>, key,
    /// location, numel)` (zip checkpoints) or the same with a sixth `view_metadata` entry,
    /// which must be `None` (legacy checkpoints; storage views are not supported).
    fn persistent_storage(&self, pid: H) -> R<Obj<'a>> {
        let t = self.tuple_items(pid, "persistent id")?;
        if !(5..=6).contains(&t.len()) {
            return bad(format!(
                "persistent id with {} items (expected a 5- or 6-item storage id)",
                t.len()
            ));
        }
        let kind = self.text(t[0], "persistent id kind")?;
        if kind != "storage" {
            return bad(format!("persistent id of kind {kind:?} (only 'storage')"));
        }
        let dtype = match self.obj(t[1])? {
            Obj::Global(Global::Storage(d)) => *d,
            Obj::Global(g) => {
                return bad(format!(
                    "storage of type {} (only typed storages such as torch.FloatStorage)",
                    g.name()
                ));
            }
            other => {
                return bad(format!(
                    "storage type is a {}, expected a storage class",
                    other.type_name()
                ));
            }
        };
        let key = self.text(t[2], "storage key")?;
        self.text(t[3], "storage location")?;
        let numel = self.int(t[4], "storage size")?;
        let numel =
            usize::try_from(numel).or_else(|_| bad(format!("negative storage size {numel}")))?;
        if let Some(&view) = t.get(5)
            && !matches!(self.obj(view)?, Obj::None)
        {
            return bad("storage views (legacy view_metadata) are not supported");
        }
        Ok(Obj::Storage { dtype, key, numel })
    }

    /// `_rebuild_tensor(_v2)` arguments `(storage, offset, size, stride, ...)`, checked so
    /// that every element lies inside the storage.
    fn tensor_spec(&self, args: &[H]) -> R<TensorSpec> {
        let [storage, offset, size, stride, ..] = args else {
            return Err(internal());
        };
        let numel = match self.obj(*storage)? {
            Obj::Storage { numel, .. } => *numel,
            other => {
                return bad(format!(
                    "tensor storage is a {}, expected a persistent storage",
                    other.type_name()
                ));
            }
        };
        let offset = self.int(*offset, "tensor storage offset")?;
        let offset = usize::try_from(offset)
            .or_else(|_| bad(format!("negative tensor storage offset {offset}")))?;
        let shape = self.shape(*size, "tensor size")?;
        let stride = self.shape(*stride, "tensor stride")?;
        if shape.len() != stride.len() {
            return bad(format!(
                "tensor size has {} dimensions but its stride {}",
                shape.len(),
                stride.len()
            ));
        }
        if !shape.contains(&0) {
            let mut last = offset;
            for (&n, &s) in shape.iter().zip(&stride) {
                last = (n - 1)
                    .checked_mul(s)
                    .and_then(|v| v.checked_add(last))
                    .ok_or_else(|| PickleErrorKind::TooLarge("tensor extent overflows".into()))?;
            }
            if last >= numel {
                return Err(PickleErrorKind::SizeMismatch(format!(
                    "tensor of size {} (stride {}, offset {offset}) reaches element {last} of a \
                     storage of {numel}",
                    numpy::shape_str(&shape),
                    numpy::shape_str(&stride)
                )));
            }
        }
        Ok(TensorSpec {
            storage: *storage,
            offset,
            shape,
            stride,
        })
    }

    /// ndarray state: `(version, shape, dtype, is_fortran, rawdata)` or the old 4-tuple
    /// without the version.
    fn array_state(&self, state: H) -> R<ArraySpec<'a>> {
        let t = self.tuple_items(state, "ndarray state")?;
        let rest = match t {
            [v, rest @ ..] if rest.len() == 4 => {
                self.int(*v, "ndarray state version")?;
                rest
            }
            _ if t.len() == 4 => t,
            _ => {
                return bad(format!(
                    "ndarray state must have 4 or 5 items, found {}",
                    t.len()
                ));
            }
        };
        let [shape, dtype, fortran, data] = rest else {
            return Err(internal());
        };
        let shape = self.shape(*shape, "ndarray shape")?;
        let dtype = self.dtype(*dtype, "ndarray dtype")?;
        let fortran = self.int(*fortran, "ndarray is_fortran flag")? != 0;
        if let Obj::List(_) = self.obj(*data)? {
            return bad("object arrays (dtype 'O') are not supported");
        }
        let data = self.bytes_like(*data, "ndarray data")?;
        numpy::check_size(&shape, dtype, data.bytes().len())?;
        Ok(ArraySpec {
            dtype,
            shape,
            fortran,
            data,
        })
    }

    /// dtype state: `(version, endian, subarray, names, fields, elsize, alignment, flags[,
    /// metadata])`; only the byte order matters for the plain types supported here.
    fn dtype_state(&self, mut d: Dtype, state: H) -> R<Dtype> {
        let t = self.tuple_items(state, "numpy.dtype state")?;
        let endian_at = match t.first() {
            Some(&h) if matches!(self.obj(h)?, Obj::Int(_)) => 1,
            _ => 0,
        };
        let endian = t
            .get(endian_at)
            .ok_or_else(|| PickleErrorKind::BadArgument("numpy.dtype state too short".into()))?;
        let endian = self.text(*endian, "numpy.dtype byte order")?;
        d.big_endian = match endian.as_str() {
            "<" | "=" | "|" => false,
            ">" => true,
            _ => return bad(format!("numpy.dtype byte order {endian:?}")),
        };
        for (i, &h) in t.iter().enumerate().skip(endian_at + 1).take(3) {
            if !matches!(self.obj(h)?, Obj::None) {
                let what = ["subarray", "names", "fields"]
                    .get(i - endian_at - 1)
                    .copied()
                    .unwrap_or("field");
                return bad(format!(
                    "structured or subarray dtypes are not supported (the {what} entry is set)"
                ));
            }
        }
        Ok(d)
    }
}

fn pairs(vs: Vec<H>) -> R<Vec<(H, H)>> {
    if !vs.len().is_multiple_of(2) {
        return bad("odd number of items for a dict");
    }
    let mut out = Vec::with_capacity(vs.len() / 2);
    let mut it = vs.into_iter();
    while let (Some(k), Some(v)) = (it.next(), it.next()) {
        out.push((k, v));
    }
    Ok(out)
}

pub(crate) fn latin1(b: &[u8]) -> String {
    b.iter().map(|&c| char::from(c)).collect()
}

fn encode_latin1(s: &str) -> Option<Vec<u8>> {
    s.chars().map(|c| u8::try_from(u32::from(c)).ok()).collect()
}

fn utf8(b: &[u8]) -> R<String> {
    String::from_utf8(b.to_vec()).or_else(|_| bad("str is not valid UTF-8"))
}

/// Text integer of INT / LONG (`123`, `-5`, `123L`).
fn parse_int_text(l: &[u8], long: bool) -> R<i64> {
    let s = std::str::from_utf8(l)
        .or_else(|_| bad("integer literal is not ASCII"))?
        .trim();
    let s = if long {
        s.strip_suffix('L').unwrap_or(s)
    } else {
        s
    };
    s.parse::<i64>().or_else(|_| {
        let digits = s.strip_prefix(['-', '+']).unwrap_or(s);
        if !digits.is_empty() && digits.bytes().all(|c| c.is_ascii_digit()) {
            bad(format!("integer {s} does not fit in 64 bits"))
        } else {
            bad(format!("invalid integer literal {s:?}"))
        }
    })
}

/// Little-endian two's complement integer of LONG1 / LONG4.
fn decode_long(b: &[u8]) -> R<i64> {
    let Some(&last) = b.last() else {
        return Ok(0);
    };
    let neg = last & 0x80 != 0;
    let ext = if neg { 0xff } else { 0 };
    let (low, high) = b.split_at(b.len().min(8));
    let mut buf = [ext; 8];
    for (d, s) in buf.iter_mut().zip(low) {
        *d = *s;
    }
    let v = i64::from_le_bytes(buf);
    if high.iter().any(|&x| x != ext) || (v < 0) != neg {
        return bad(format!(
            "integer of {} bytes does not fit in 64 bits",
            b.len()
        ));
    }
    Ok(v)
}

/// The argument of STRING: a quoted Python 2 string literal with backslash escapes.
fn unescape_string(l: &[u8]) -> R<Vec<u8>> {
    let inner = match l {
        [q @ (b'\'' | b'"'), inner @ .., e] if q == e => inner,
        _ => return bad("the STRING opcode argument must be quoted"),
    };
    let mut out = Vec::with_capacity(inner.len());
    let mut i = 0;
    while let Some(&c) = inner.get(i) {
        i += 1;
        if c != b'\\' {
            out.push(c);
            continue;
        }
        let Some(&e) = inner.get(i) else {
            return bad("trailing backslash in STRING");
        };
        i += 1;
        match e {
            b'\n' => {}
            b'\\' | b'\'' | b'"' => out.push(e),
            b'a' => out.push(7),
            b'b' => out.push(8),
            b't' => out.push(9),
            b'n' => out.push(10),
            b'v' => out.push(11),
            b'f' => out.push(12),
            b'r' => out.push(13),
            b'0'..=b'7' => {
                let mut v = u32::from(e - b'0');
                for _ in 0..2 {
                    match inner.get(i) {
                        Some(&d @ b'0'..=b'7') => {
                            v = v * 8 + u32::from(d - b'0');
                            i += 1;
                        }
                        _ => break,
                    }
                }
                out.push((v & 0xff) as u8);
            }
            b'x' => {
                let h = inner
                    .get(i..i + 2)
                    .and_then(|h| std::str::from_utf8(h).ok())
                    .filter(|h| h.bytes().all(|c| c.is_ascii_hexdigit()))
                    .and_then(|h| u8::from_str_radix(h, 16).ok())
                    .ok_or_else(|| PickleErrorKind::BadArgument("invalid \\x escape".into()))?;
                out.push(h);
                i += 2;
            }
            other => {
                out.push(b'\\');
                out.push(other);
            }
        }
    }
    Ok(out)
}

/// The argument of UNICODE: latin-1 text with `\uXXXX` / `\UXXXXXXXX` escapes (Python's
/// raw-unicode-escape codec).
fn raw_unicode_escape(l: &[u8]) -> R<String> {
    let mut out = String::with_capacity(l.len());
    let mut i = 0;
    while let Some(&c) = l.get(i) {
        if c != b'\\' {
            out.push(char::from(c));
            i += 1;
            continue;
        }
        let start = i;
        while l.get(i) == Some(&b'\\') {
            i += 1;
        }
        let run = i - start;
        let digits = match l.get(i) {
            Some(b'u') if run % 2 == 1 => 4,
            Some(b'U') if run % 2 == 1 => 8,
            _ => {
                out.extend(std::iter::repeat_n('\\', run));
                continue;
            }
        };
        out.extend(std::iter::repeat_n('\\', run - 1));
        i += 1;
        let ch = l
            .get(i..i + digits)
            .and_then(|h| std::str::from_utf8(h).ok())
            .filter(|h| h.bytes().all(|c| c.is_ascii_hexdigit()))
            .and_then(|h| u32::from_str_radix(h, 16).ok())
            .and_then(char::from_u32)
            .ok_or_else(|| {
                PickleErrorKind::BadArgument(
                    "invalid \\u escape in UNICODE (truncated, a surrogate or out of range)".into(),
                )
            })?;
        out.push(ch);
        i += digits;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_decoding() {
        assert_eq!(decode_long(&[]).unwrap(), 0);
        assert_eq!(decode_long(&[0xff]).unwrap(), -1);
        assert_eq!(decode_long(&[0x00, 0x80]).unwrap(), -32768);
        assert_eq!(decode_long(&[0xff, 0x00]).unwrap(), 255);
        assert_eq!(
            decode_long(&[0xff, 0xff, 0xff, 0xff, 0, 0, 0, 0]).unwrap(),
            4_294_967_295
        );
        assert_eq!(
            decode_long(&[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f]).unwrap(),
            i64::MAX
        );
        assert_eq!(decode_long(&[0, 0, 0, 0, 0, 0, 0, 0x80]).unwrap(), i64::MIN);
        // 2^63 needs 9 bytes and does not fit.
        assert!(decode_long(&[0, 0, 0, 0, 0, 0, 0, 0x80, 0]).is_err());
        // Non-minimal but in range.
        assert_eq!(decode_long(&[5, 0, 0, 0, 0, 0, 0, 0, 0, 0]).unwrap(), 5);
        assert_eq!(
            decode_long(&[0xfb, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff]).unwrap(),
            -5
        );
        assert!(decode_long(&[0, 0, 0, 0, 0, 0, 0, 0, 1]).is_err());
    }

    #[test]
    fn text_ints() {
        assert_eq!(parse_int_text(b"42", false).unwrap(), 42);
        assert_eq!(parse_int_text(b"-7L", true).unwrap(), -7);
        assert!(
            parse_int_text(b"99999999999999999999", false)
                .unwrap_err()
                .to_string()
                .contains("does not fit")
        );
        assert!(parse_int_text(b"abc", false).is_err());
    }

    #[test]
    fn string_escapes() {
        assert_eq!(
            unescape_string(br"'a\n\x41\\\'\101\0'").unwrap(),
            b"a\nA\\'A\0".to_vec()
        );
        assert_eq!(unescape_string(br#""\q""#).unwrap(), b"\\q".to_vec());
        assert!(unescape_string(b"'abc").is_err());
        assert!(unescape_string(b"'").is_err());
        assert!(unescape_string(br"'\x4'").is_err());
        assert!(unescape_string(br"'\'").is_err());
    }

    #[test]
    fn raw_unicode() {
        assert_eq!(raw_unicode_escape(br"caf\u00e9").unwrap(), "café");
        assert_eq!(raw_unicode_escape(br"\U0001F600").unwrap(), "\u{1F600}");
        assert_eq!(raw_unicode_escape(br"a\\u0041").unwrap(), "a\\\\u0041");
        assert_eq!(raw_unicode_escape(br"a\\\u0041").unwrap(), "a\\\\A");
        assert_eq!(raw_unicode_escape(b"\xe9").unwrap(), "é");
        assert!(raw_unicode_escape(br"\u12").is_err());
        assert!(raw_unicode_escape(br"\ud800").is_err());
    }
}
