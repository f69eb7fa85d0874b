//! Pickles assembled byte by byte, read back, and checked value by value.

use crate::{ArrayData, CscMatrix, NdArray, PickleError, PickleErrorKind, Value, from_bytes};

/// A tiny byte assembler: every method appends one opcode (with its argument).
#[derive(Clone, Default)]
struct B(Vec<u8>);

impl B {
    fn new() -> Self {
        B(Vec::new())
    }
    fn proto(self, p: u8) -> Self {
        self.op(0x80).op(p)
    }
    fn op(mut self, b: u8) -> Self {
        self.0.push(b);
        self
    }
    fn raw(mut self, b: &[u8]) -> Self {
        self.0.extend_from_slice(b);
        self
    }
    /// GLOBAL `module\nname\n`.
    fn global(self, module: &str, name: &str) -> Self {
        self.op(b'c')
            .raw(module.as_bytes())
            .op(b'\n')
            .raw(name.as_bytes())
            .op(b'\n')
    }
    /// SHORT_BINSTRING (Python 2 str).
    fn sbs(self, s: &[u8]) -> Self {
        let n = u8::try_from(s.len()).unwrap();
        self.op(b'U').op(n).raw(s)
    }
    /// BINSTRING (Python 2 str).
    fn binstring(self, s: &[u8]) -> Self {
        let n = i32::try_from(s.len()).unwrap();
        self.op(b'T').raw(&n.to_le_bytes()).raw(s)
    }
    /// SHORT_BINUNICODE.
    fn sbu(self, s: &str) -> Self {
        let n = u8::try_from(s.len()).unwrap();
        self.op(0x8c).op(n).raw(s.as_bytes())
    }
    /// BINBYTES.
    fn binbytes(self, s: &[u8]) -> Self {
        let n = u32::try_from(s.len()).unwrap();
        self.op(b'B').raw(&n.to_le_bytes()).raw(s)
    }
    /// BININT1.
    fn k(self, v: u8) -> Self {
        self.op(b'K').op(v)
    }
    /// BININT2.
    fn m(self, v: u16) -> Self {
        self.op(b'M').raw(&v.to_le_bytes())
    }
    /// BININT.
    fn j(self, v: i32) -> Self {
        self.op(b'J').raw(&v.to_le_bytes())
    }
    /// BINFLOAT.
    fn g(self, v: f64) -> Self {
        self.op(b'G').raw(&v.to_be_bytes())
    }
    /// BINPUT.
    fn put(self, i: u8) -> Self {
        self.op(b'q').op(i)
    }
    /// BINGET.
    fn get(self, i: u8) -> Self {
        self.op(b'h').op(i)
    }
    /// MEMOIZE.
    fn memoize(self) -> Self {
        self.op(0x94)
    }
    fn stop(self) -> Vec<u8> {
        self.op(b'.').0
    }
    fn len(&self) -> usize {
        self.0.len()
    }

    /// A numpy dtype the way Python 2 numpy writes it (no memo):
    /// `numpy.dtype(code, False, True)` then BUILD `(3, endian, None, None, None, -1, -1, 0)`.
    fn dtype2(self, code: &str, endian: &str) -> Self {
        self.global("numpy", "dtype")
            .sbs(code.as_bytes())
            .op(0x89)
            .op(0x88)
            .op(0x87)
            .op(b'R')
            .op(b'(')
            .k(3)
            .sbs(endian.as_bytes())
            .op(b'N')
            .op(b'N')
            .op(b'N')
            .j(-1)
            .j(-1)
            .k(0)
            .op(b't')
            .op(b'b')
    }

    /// `_reconstruct(ndarray, (0,), 'b')` called (REDUCE), without memo: an empty ndarray
    /// waiting for its BUILD state.
    fn reconstruct_ndarray(self) -> Self {
        self.global("numpy.core.multiarray", "_reconstruct")
            .global("numpy", "ndarray")
            .k(0)
            .op(0x85)
            .sbs(b"b")
            .op(0x87)
            .op(b'R')
    }

    /// A Python-2 style ndarray (no memo): `_reconstruct(ndarray, (0,), 'b')`, BUILD
    /// `(1, shape, dtype, fortran, raw)`.
    fn array2(self, shape: &[u16], code: &str, endian: &str, fortran: bool, raw: &[u8]) -> Self {
        let mut b = self.reconstruct_ndarray().op(b'(').k(1).op(b'(');
        for &d in shape {
            b = b.m(d);
        }
        b = b
            .op(b't')
            .dtype2(code, endian)
            .op(if fortran { 0x88 } else { 0x89 });
        b = if raw.len() < 256 {
            b.sbs(raw)
        } else {
            b.binstring(raw)
        };
        b.op(b't').op(b'b')
    }
}

fn read(p: &[u8]) -> Value {
    match from_bytes(p, "test.pkl") {
        Ok(v) => v,
        Err(e) => panic!("unexpected error: {e}"),
    }
}

fn read_err(p: &[u8]) -> PickleError {
    match from_bytes(p, "test.pkl") {
        Ok(v) => panic!("expected an error, got {v:?}"),
        Err(e) => e,
    }
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn i64_bytes(v: &[i64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn i32_bytes(v: &[i32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn s(x: &str) -> Value {
    Value::Str(x.to_string())
}

// ---------------------------------------------------------------- opcode families

#[test]
fn integers_and_constants() {
    let p = B::new()
        .proto(2)
        .op(b'(')
        .op(b'N')
        .op(0x88)
        .op(0x89)
        .raw(b"I-12\n")
        .raw(b"I01\n")
        .raw(b"I00\n")
        .raw(b"I123456789012\n")
        .j(-5)
        .k(200)
        .m(65535)
        .raw(b"L-77L\n")
        .op(0x8a)
        .op(2)
        .raw(&[0x00, 0x80]) // LONG1 -32768
        .op(0x8a)
        .op(0) // LONG1 0
        .op(0x8b)
        .raw(&5i32.to_le_bytes())
        .raw(&[0xff, 0xff, 0xff, 0xff, 0x00]) // LONG4 4294967295
        .raw(b"F2.5\n")
        .g(-0.125)
        .op(b'l')
        .stop();
    assert_eq!(
        read(&p),
        Value::List(vec![
            Value::None,
            Value::Bool(true),
            Value::Bool(false),
            Value::Int(-12),
            Value::Bool(true),
            Value::Bool(false),
            Value::Int(123_456_789_012),
            Value::Int(-5),
            Value::Int(200),
            Value::Int(65535),
            Value::Int(-77),
            Value::Int(-32768),
            Value::Int(0),
            Value::Int(4_294_967_295),
            Value::Float(2.5),
            Value::Float(-0.125),
        ])
    );
}

#[test]
fn longs_beyond_64_bits_are_errors() {
    let p = B::new()
        .proto(2)
        .op(0x8a)
        .op(9)
        .raw(&[0, 0, 0, 0, 0, 0, 0, 0x80, 0])
        .stop();
    let e = read_err(&p);
    assert_eq!(e.offset, 2);
    assert!(matches!(e.kind, PickleErrorKind::BadArgument(_)));
    assert!(e.to_string().contains("does not fit in 64 bits"));
    let e = read_err(b"L123456789012345678901234567890L\n.");
    assert_eq!(e.offset, 0);
    assert!(e.to_string().contains("does not fit in 64 bits"));
}

fn strings_pickle() -> Vec<u8> {
    B::new()
        .proto(4)
        .op(b'(')
        .raw(b"S'a\\n\\x41\\'b'\n") // STRING
        .binstring(b"caf\xe9") // BINSTRING, latin-1
        .sbs(b"xy") // SHORT_BINSTRING
        .raw(b"Vcaf\\u00e9 \\U0001f600\n") // UNICODE
        .op(b'X')
        .raw(&4u32.to_le_bytes())
        .raw("dé!".as_bytes()) // BINUNICODE
        .sbu("short") // SHORT_BINUNICODE
        .op(0x8d)
        .raw(&2u64.to_le_bytes())
        .raw(b"u8") // BINUNICODE8
        .binbytes(&[0, 1, 255]) // BINBYTES
        .op(b'C')
        .op(1)
        .op(7) // SHORT_BINBYTES
        .op(0x8e)
        .raw(&2u64.to_le_bytes())
        .raw(&[9, 8]) // BINBYTES8
        .op(0x96)
        .raw(&1u64.to_le_bytes())
        .raw(&[42]) // BYTEARRAY8
        .op(b'l')
        .stop()
}

#[test]
fn strings_of_every_kind() {
    let p = strings_pickle();
    assert_eq!(
        read(&p),
        Value::List(vec![
            s("a\nA'b"),
            s("café"),
            s("xy"),
            s("café \u{1f600}"),
            s("dé!"),
            s("short"),
            s("u8"),
            Value::Bytes(vec![0, 1, 255]),
            Value::Bytes(vec![7]),
            Value::Bytes(vec![9, 8]),
            Value::Bytes(vec![42]),
        ])
    );
}

#[test]
fn invalid_utf8_is_an_error() {
    let p = B::new().proto(4).op(0x8c).op(1).op(0xff).stop();
    let e = read_err(&p);
    assert_eq!(e.offset, 2);
    assert!(e.to_string().contains("UTF-8"));
}

#[test]
fn lists_tuples_dicts_sets() {
    let p = B::new()
        .proto(4)
        .op(b'}') // EMPTY_DICT
        .op(b'(')
        // "list": EMPTY_LIST, APPEND, APPENDS
        .sbu("list")
        .op(b']')
        .k(1)
        .op(b'a')
        .op(b'(')
        .k(2)
        .k(3)
        .op(b'e')
        // "mlist": MARK ... LIST
        .sbu("mlist")
        .op(b'(')
        .k(4)
        .op(b'l')
        // "tuples": (), (1,), (1, 2), (1, 2, 3), MARK ... TUPLE
        .sbu("tuples")
        .op(b'(')
        .op(b')')
        .k(1)
        .op(0x85)
        .k(1)
        .k(2)
        .op(0x86)
        .k(1)
        .k(2)
        .k(3)
        .op(0x87)
        .op(b'(')
        .k(1)
        .k(2)
        .k(3)
        .k(4)
        .op(b't')
        .op(b'l')
        // "dict": MARK ... DICT, then SETITEM
        .sbu("dict")
        .op(b'(')
        .sbu("x")
        .k(1)
        .op(b'd')
        .sbu("y")
        .k(2)
        .op(b's')
        // "set": EMPTY_SET, ADDITEMS
        .sbu("set")
        .op(0x8f)
        .op(b'(')
        .k(5)
        .k(6)
        .op(0x90)
        // "frozen": FROZENSET
        .sbu("frozen")
        .op(b'(')
        .k(7)
        .op(0x91)
        // "pyset": builtins.set([8]) as Python 2 writes it
        .sbu("pyset")
        .global("__builtin__", "set")
        .op(b']')
        .k(8)
        .op(b'a')
        .op(0x85)
        .op(b'R')
        .op(b'u') // SETITEMS
        .stop();
    let v = read(&p);
    let list = |xs: &[i64]| Value::List(xs.iter().map(|&x| Value::Int(x)).collect());
    let tuple = |xs: &[i64]| Value::Tuple(xs.iter().map(|&x| Value::Int(x)).collect());
    assert_eq!(v.get("list"), Some(&list(&[1, 2, 3])));
    assert_eq!(v.get("mlist"), Some(&list(&[4])));
    assert_eq!(
        v.get("tuples"),
        Some(&Value::List(vec![
            tuple(&[]),
            tuple(&[1]),
            tuple(&[1, 2]),
            tuple(&[1, 2, 3]),
            tuple(&[1, 2, 3, 4]),
        ]))
    );
    assert_eq!(
        v.get("dict"),
        Some(&Value::Dict(vec![
            (s("x"), Value::Int(1)),
            (s("y"), Value::Int(2)),
        ]))
    );
    assert_eq!(
        v.get("set"),
        Some(&Value::Set(vec![Value::Int(5), Value::Int(6)]))
    );
    assert_eq!(v.get("frozen"), Some(&Value::Set(vec![Value::Int(7)])));
    assert_eq!(v.get("pyset"), Some(&Value::Set(vec![Value::Int(8)])));
    assert_eq!(v.as_dict().map(<[_]>::len), Some(7));
}

#[test]
fn duplicate_dict_keys_keep_first_position_and_last_value() {
    let p = B::new()
        .proto(2)
        .op(b'(')
        .sbs(b"a")
        .k(1)
        .sbs(b"b")
        .k(2)
        .sbu("a") // unicode 'a' equals Python-2 'a' once decoded
        .k(3)
        .op(b'd')
        .stop();
    assert_eq!(
        read(&p),
        Value::Dict(vec![(s("a"), Value::Int(3)), (s("b"), Value::Int(2))])
    );
}

#[test]
fn stack_ops_and_memo() {
    let p = B::new()
        .proto(2)
        .op(b']') // the result list
        .op(b'(')
        .k(1)
        .op(b'0') // POP: drops 1
        .op(b'(') // a mark with junk above it
        .k(9)
        .k(9)
        .op(b'1') // POP_MARK drops both 9s and the mark
        .k(2)
        .op(b'2') // DUP
        .op(b'r')
        .raw(&300u32.to_le_bytes()) // LONG_BINPUT 300
        .op(b'p')
        .raw(b"7\n") // PUT 7
        .op(b'e') // APPENDS 2, 2
        .op(b'j')
        .raw(&300u32.to_le_bytes()) // LONG_BINGET 300
        .op(b'a')
        .op(b'g')
        .raw(b"7\n") // GET 7
        .op(b'a')
        .op(b'(')
        .op(b'0') // POP with nothing above the mark pops the mark
        .stop();
    assert_eq!(read(&p), Value::List(vec![Value::Int(2); 4]));
}

#[test]
fn memoized_containers_are_shared_and_see_later_mutation() {
    // d = {}; memo it; fill it afterwards; then a list refers to d through the memo twice.
    let p = B::new()
        .proto(4)
        .op(b']')
        .memoize() // 0: the outer list
        .op(b'}')
        .memoize() // 1: d, still empty
        .op(b'(')
        .sbu("k")
        .memoize() // 2
        .k(1)
        .op(b'u')
        .op(b'a') // outer.append(d)
        .get(1)
        .op(b'a') // outer.append(d) again
        .stop();
    let d = Value::Dict(vec![(s("k"), Value::Int(1))]);
    assert_eq!(read(&p), Value::List(vec![d.clone(), d]));
}

#[test]
fn protocol0_as_python2_writes_it() {
    // pickle.dumps({'a': [1, 2.5, 'x', u'caf\xe9', None, True], 'b': <same list>}, 0)
    let p =
        b"(dp0\nS'a'\np1\n(lp2\nI1\naF2.5\naS'x'\np3\naVcaf\\u00e9\np4\naNaI01\nasS'b'\np5\ng2\ns.";
    let list = Value::List(vec![
        Value::Int(1),
        Value::Float(2.5),
        s("x"),
        s("café"),
        Value::None,
        Value::Bool(true),
    ]);
    assert_eq!(
        read(p),
        Value::Dict(vec![(s("a"), list.clone()), (s("b"), list)])
    );
}

#[test]
fn frames_and_protocol_checks() {
    let body = B::new().op(b']').memoize().k(1).op(b'a').stop();
    let mut p = B::new()
        .proto(4)
        .op(0x95)
        .raw(&(body.len() as u64).to_le_bytes());
    p = p.raw(&body);
    assert_eq!(read(&p.0), Value::List(vec![Value::Int(1)]));
    // A frame longer than what is left.
    let p = B::new()
        .proto(4)
        .op(0x95)
        .raw(&100u64.to_le_bytes())
        .op(b'N')
        .stop();
    let e = read_err(&p);
    assert!(matches!(e.kind, PickleErrorKind::TooLarge(_)));
    let p = B::new()
        .proto(4)
        .op(0x95)
        .raw(&10u64.to_le_bytes())
        .op(b'N')
        .stop();
    assert!(matches!(read_err(&p).kind, PickleErrorKind::Truncated));
    let e = read_err(&B::new().proto(6).op(b'N').stop());
    assert!(matches!(e.kind, PickleErrorKind::UnsupportedProtocol(6)));
    assert_eq!(e.offset, 0);
    // Protocol 5 is fine; trailing bytes after STOP are ignored (as Python does).
    let mut p = B::new().proto(5).op(b'N').stop();
    p.extend_from_slice(b"garbage");
    assert_eq!(read(&p), Value::None);
}

#[test]
fn bytes_as_python3_protocol2_writes_them() {
    let p = B::new()
        .proto(2)
        .op(b'(')
        .global("_codecs", "encode")
        .op(b'X')
        .raw(&2u32.to_le_bytes())
        .raw("é".as_bytes())
        .op(b'X')
        .raw(&6u32.to_le_bytes())
        .raw(b"latin1")
        .op(0x86)
        .op(b'R')
        .global("__builtin__", "bytes")
        .op(b')')
        .op(b'R')
        .op(b'l')
        .stop();
    assert_eq!(
        read(&p),
        Value::List(vec![Value::Bytes(vec![0xe9]), Value::Bytes(vec![])])
    );
    // bytearray and frozenset as Python 3 writes them below protocol 5 / 4.
    let p = B::new()
        .proto(2)
        .op(b'(')
        .global("__builtin__", "bytearray")
        .sbu("\u{e9}a")
        .sbu("latin-1")
        .op(0x86)
        .op(b'R')
        .global("builtins", "bytearray")
        .op(b'C')
        .op(1)
        .op(5)
        .op(0x85)
        .op(b'R')
        .global("builtins", "bytearray")
        .op(b')')
        .op(b'R')
        .global("__builtin__", "frozenset")
        .op(b']')
        .k(4)
        .op(b'a')
        .op(0x85)
        .op(b'R')
        .op(b'l')
        .stop();
    assert_eq!(
        read(&p),
        Value::List(vec![
            Value::Bytes(vec![0xe9, b'a']),
            Value::Bytes(vec![5]),
            Value::Bytes(vec![]),
            Value::Set(vec![Value::Int(4)]),
        ])
    );
    let p = B::new()
        .proto(2)
        .global("_codecs", "encode")
        .sbu("x")
        .sbu("utf-8")
        .op(0x86)
        .op(b'R')
        .stop();
    assert!(read_err(&p).to_string().contains("only latin1"));
}

// ---------------------------------------------------------------- numpy

#[test]
fn python2_numpy_f8_c_order_and_i8_fortran_with_shared_memo() {
    let v_template = [0.5, -1.0, 2.25, 3.0, 1e-3, -7.5];
    let parents: [i64; 16] = [
        4_294_967_295,
        0,
        1,
        2,
        0,
        4,
        5,
        0,
        7,
        8,
        0,
        10,
        11,
        0,
        13,
        14,
    ];
    let children: [i64; 16] = std::array::from_fn(|i| i as i64);
    // Fortran order: column by column.
    let mut fortran = Vec::new();
    for c in 0..16 {
        fortran.extend_from_slice(&parents[c].to_le_bytes());
        fortran.extend_from_slice(&children[c].to_le_bytes());
    }
    let p = B::new()
        .proto(2)
        .op(b'}')
        .put(0)
        .op(b'(')
        .sbs(b"v_template")
        .put(1)
        // _reconstruct(ndarray, (0,), 'b')
        .global("numpy.core.multiarray", "_reconstruct")
        .put(2)
        .global("numpy", "ndarray")
        .put(3)
        .k(0)
        .op(0x85)
        .put(4)
        .sbs(b"b")
        .put(5)
        .op(0x87)
        .put(6)
        .op(b'R')
        .put(7)
        // state (1, (2, 3), dtype('f8'), False, raw)
        .op(b'(')
        .k(1)
        .k(2)
        .k(3)
        .op(0x86)
        .put(8)
        .global("numpy", "dtype")
        .put(9)
        .sbs(b"f8")
        .put(10)
        .op(0x89)
        .op(0x88)
        .op(0x87)
        .put(11)
        .op(b'R')
        .put(12) // the dtype, memoized before its BUILD
        .op(b'(')
        .k(3)
        .sbs(b"<")
        .put(13)
        .op(b'N')
        .op(b'N')
        .op(b'N')
        .j(-1)
        .j(-1)
        .k(0)
        .op(b't')
        .put(14)
        .op(b'b')
        .op(0x89)
        .sbs(&f64_bytes(&v_template))
        .put(15)
        .op(b't')
        .put(16)
        .op(b'b')
        // "kintree_table": i8 (2, 16), Fortran order, 256 bytes as BINSTRING
        .sbs(b"kintree_table")
        .put(17)
        .get(2)
        .get(3)
        .k(0)
        .op(0x85)
        .put(18)
        .get(5)
        .op(0x87)
        .put(19)
        .op(b'R')
        .put(20)
        .op(b'(')
        .k(1)
        .k(2)
        .k(16)
        .op(0x86)
        .put(21)
        .get(9)
        .sbs(b"i8")
        .put(22)
        .op(0x89)
        .op(0x88)
        .op(0x87)
        .put(23)
        .op(b'R')
        .put(24)
        .op(b'(')
        .k(3)
        .get(13)
        .op(b'N')
        .op(b'N')
        .op(b'N')
        .j(-1)
        .j(-1)
        .k(0)
        .op(b't')
        .put(25)
        .op(b'b')
        .op(0x88) // is_fortran
        .binstring(&fortran)
        .put(26)
        .op(b't')
        .put(27)
        .op(b'b')
        // "J": a second f8 array reusing the memoized (built) dtype
        .sbs(b"J")
        .put(28)
        .get(2)
        .get(3)
        .k(0)
        .op(0x85)
        .get(5)
        .op(0x87)
        .op(b'R')
        .op(b'(')
        .k(1)
        .k(2)
        .op(0x85)
        .get(12)
        .op(0x89)
        .sbs(&f64_bytes(&[1.0, 2.0]))
        .op(b't')
        .op(b'b')
        .op(b'u')
        .stop();
    let v = read(&p);
    let vt = v.get("v_template").and_then(Value::as_array).unwrap();
    assert_eq!(vt.shape, vec![2, 3]);
    assert_eq!(vt.dtype(), "f8");
    assert_eq!(vt.data, ArrayData::F64(v_template.to_vec()));
    let kt = v.get("kintree_table").and_then(Value::as_array).unwrap();
    assert_eq!(kt.shape, vec![2, 16]);
    let mut expected = parents.to_vec();
    expected.extend_from_slice(&children);
    assert_eq!(kt.data, ArrayData::I64(expected));
    let j = v.get("J").and_then(Value::as_array).unwrap();
    assert_eq!(
        j,
        &NdArray {
            shape: vec![2],
            data: ArrayData::F64(vec![1.0, 2.0])
        }
    );
}

fn protocol4_f32_pickle() -> Vec<u8> {
    let values = [0.5f32, -1.25, 3.0, 1e-7];
    let raw: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
    let body = B::new()
        .op(b'}')
        .memoize() // 0
        .sbu("R")
        .memoize() // 1
        .sbu("numpy.core.multiarray")
        .memoize() // 2
        .sbu("_reconstruct")
        .memoize() // 3
        .op(0x93)
        .memoize() // 4
        .sbu("numpy")
        .memoize() // 5
        .sbu("ndarray")
        .memoize() // 6
        .op(0x93)
        .memoize() // 7
        .k(0)
        .op(0x85)
        .memoize() // 8
        .op(b'C')
        .op(1)
        .op(b'b')
        .memoize() // 9
        .op(0x87)
        .memoize() // 10
        .op(b'R')
        .memoize() // 11
        .op(b'(')
        .k(1)
        .k(2)
        .k(2)
        .op(0x86)
        .memoize() // 12
        .get(5)
        .sbu("dtype")
        .memoize() // 13
        .op(0x93)
        .memoize() // 14
        .sbu("f4")
        .memoize() // 15
        .op(0x89)
        .op(0x88)
        .op(0x87)
        .memoize() // 16
        .op(b'R')
        .memoize() // 17
        .op(b'(')
        .k(3)
        .sbu("<")
        .memoize() // 18
        .op(b'N')
        .op(b'N')
        .op(b'N')
        .j(-1)
        .j(-1)
        .k(0)
        .op(b't')
        .memoize() // 19
        .op(b'b')
        .op(0x89)
        .op(b'C')
        .op(16)
        .raw(&raw)
        .memoize() // 20
        .op(b't')
        .memoize() // 21
        .op(b'b')
        .op(b's')
        .stop();
    let p = B::new()
        .proto(4)
        .op(0x95)
        .raw(&(body.len() as u64).to_le_bytes())
        .raw(&body);
    p.0
}

#[test]
fn protocol4_f32_array_with_stack_global_memoize_and_frame() {
    let values = [0.5f32, -1.25, 3.0, 1e-7];
    let v = read(&protocol4_f32_pickle());
    let r = v.get("R").and_then(Value::as_array).unwrap();
    assert_eq!(r.shape, vec![2, 2]);
    assert_eq!(r.dtype(), "f4");
    assert_eq!(r.data, ArrayData::F32(values.to_vec()));
    assert_eq!(r.to_f64()[1], -1.25);
}

#[test]
fn dtypes_and_byte_orders() {
    let p = B::new()
        .proto(2)
        .op(b'(')
        .array2(
            &[2],
            "f4",
            ">",
            false,
            &[0x3f, 0x80, 0, 0, 0xc0, 0x20, 0, 0],
        )
        .array2(&[3], "u1", "|", false, &[1, 2, 255])
        .array2(&[3], "b1", "|", false, &[0, 1, 2])
        .array2(&[1], "u4", "<", false, &[0xff, 0xff, 0xff, 0xff])
        .array2(&[2], "i4", "<", false, &i32_bytes(&[-3, 7]))
        .array2(
            &[2],
            "i8",
            ">",
            false,
            &[
                0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xfe, 0, 0, 0, 0, 0, 0, 1, 0,
            ],
        )
        .array2(&[0, 3], "f8", "<", true, &[])
        .op(b'l')
        .stop();
    let v = read(&p);
    let arrays: Vec<&NdArray> = v
        .as_list()
        .unwrap()
        .iter()
        .map(|x| x.as_array().unwrap())
        .collect();
    assert_eq!(arrays[0].data, ArrayData::F32(vec![1.0, -2.5]));
    assert_eq!(arrays[1].data, ArrayData::U8(vec![1, 2, 255]));
    assert_eq!(arrays[2].data, ArrayData::Bool(vec![false, true, true]));
    assert_eq!(arrays[3].data, ArrayData::U32(vec![4_294_967_295]));
    assert_eq!(arrays[4].data, ArrayData::I32(vec![-3, 7]));
    assert_eq!(arrays[5].data, ArrayData::I64(vec![-2, 256]));
    assert_eq!(arrays[6].shape, vec![0, 3]);
    assert!(arrays[6].is_empty());
    let dtypes: Vec<&str> = arrays.iter().map(|a| a.dtype()).collect();
    assert_eq!(dtypes, ["f4", "u1", "b1", "u4", "i4", "i8", "f8"]);
}

#[test]
fn unsupported_dtype_is_an_error() {
    let p = B::new()
        .proto(2)
        .array2(&[1], "c16", "<", false, &[0; 16])
        .stop();
    let e = read_err(&p);
    assert!(e.to_string().contains("unsupported numpy dtype"), "{e}");
}

#[test]
fn numpy_scalar_is_a_0d_array() {
    let p = B::new()
        .proto(2)
        .global("numpy.core.multiarray", "scalar")
        .dtype2("f8", "<")
        .sbs(&2.75f64.to_le_bytes())
        .op(0x86)
        .op(b'R')
        .stop();
    let v = read(&p);
    let a = v.as_array().unwrap();
    assert!(a.shape.is_empty());
    assert_eq!(a.data, ArrayData::F64(vec![2.75]));
    assert_eq!(v.as_f64(), Some(2.75));
    // Wrong number of bytes for the dtype.
    let p = B::new()
        .proto(2)
        .global("numpy._core.multiarray", "scalar")
        .dtype2("i8", "<")
        .sbs(&[1, 2, 3])
        .op(0x86)
        .op(b'R')
        .stop();
    assert!(matches!(
        read_err(&p).kind,
        PickleErrorKind::SizeMismatch(_)
    ));
}

#[test]
fn protocol5_frombuffer_in_band() {
    // numpy >= 1.16 with protocol 5: _frombuffer(bytearray(raw), dtype, shape, order)
    let raw = f64_bytes(&[1.0, 4.0, 2.0, 5.0, 3.0, 6.0]); // (2, 3) in Fortran order
    let p = B::new()
        .proto(5)
        .sbu("numpy._core.numeric")
        .sbu("_frombuffer")
        .op(0x93)
        .op(b'(')
        .op(0x96)
        .raw(&(raw.len() as u64).to_le_bytes())
        .raw(&raw)
        .sbu("numpy")
        .sbu("dtype")
        .op(0x93)
        .sbu("f8")
        .op(0x89)
        .op(0x88)
        .op(0x87)
        .op(b'R')
        .op(b'(')
        .k(3)
        .sbu("<")
        .op(b'N')
        .op(b'N')
        .op(b'N')
        .j(-1)
        .j(-1)
        .k(0)
        .op(b't')
        .op(b'b')
        .k(2)
        .k(3)
        .op(0x86)
        .sbu("F")
        .op(b't')
        .op(b'R')
        .stop();
    let a = read(&p);
    let a = a.as_array().unwrap();
    assert_eq!(a.shape, vec![2, 3]);
    assert_eq!(a.data, ArrayData::F64(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
}

#[test]
fn array_size_mismatch_names_shape_dtype_and_offset() {
    let b = B::new()
        .proto(2)
        .reconstruct_ndarray()
        .op(b'(')
        .k(1)
        .k(2)
        .k(3)
        .op(0x86)
        .dtype2("f8", "<")
        .op(0x89)
        .sbs(&[0u8; 40])
        .op(b't');
    let build_at = b.len();
    let p = b.op(b'b').stop();
    let e = read_err(&p);
    assert_eq!(e.offset, build_at);
    assert!(matches!(e.kind, PickleErrorKind::SizeMismatch(_)));
    assert_eq!(
        e.to_string(),
        format!(
            "test.pkl: byte {build_at}: size mismatch: array of shape (2, 3) and dtype <f8 needs 48 bytes but the pickle holds 40"
        )
    );
    // An absurd shape overflows instead of allocating.
    let p = B::new()
        .proto(2)
        .reconstruct_ndarray()
        .op(b'(')
        .k(1)
        .op(0x8a)
        .op(8)
        .raw(&(1u64 << 62).to_le_bytes())
        .op(0x8a)
        .op(8)
        .raw(&(1u64 << 62).to_le_bytes())
        .op(0x86)
        .dtype2("f8", "<")
        .op(0x89)
        .sbs(&[0u8; 8])
        .op(b't')
        .op(b'b')
        .stop();
    assert!(matches!(read_err(&p).kind, PickleErrorKind::TooLarge(_)));
}

// ---------------------------------------------------------------- scipy

fn csc_py2(shape: (u16, u16), data: &[f64], indices: &[i32], indptr: &[i32]) -> B {
    B::new()
        .proto(2)
        .global("scipy.sparse.csc", "csc_matrix")
        .put(0)
        .op(b')')
        .op(0x81) // NEWOBJ
        .put(1)
        .op(b'}')
        .put(2)
        .op(b'(')
        .sbs(b"_shape")
        .m(shape.0)
        .m(shape.1)
        .op(0x86)
        .sbs(b"indices")
        .array2(
            &[indices.len() as u16],
            "i4",
            "<",
            false,
            &i32_bytes(indices),
        )
        .sbs(b"indptr")
        .array2(&[indptr.len() as u16], "i4", "<", false, &i32_bytes(indptr))
        .sbs(b"maxprint")
        .k(50)
        .sbs(b"format")
        .sbs(b"csc")
        .sbs(b"data")
        .array2(&[data.len() as u16], "f8", "<", false, &f64_bytes(data))
        .op(b'u')
        .op(b'b')
}

#[test]
fn csc_matrix_via_newobj() {
    // [[1, 0, 2], [0, 3, 0]]
    let p = csc_py2((2, 3), &[1.0, 3.0, 2.0], &[0, 1, 0], &[0, 1, 2, 3]).stop();
    let v = read(&p);
    let m = match &v {
        Value::Sparse(m) => m,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        m,
        &CscMatrix {
            shape: (2, 3),
            data: vec![1.0, 3.0, 2.0],
            indices: vec![0, 1, 0],
            indptr: vec![0, 1, 2, 3],
        }
    );
    assert_eq!(
        m.to_dense_row_major().unwrap(),
        vec![1.0, 0.0, 2.0, 0.0, 3.0, 0.0]
    );
    assert_eq!(v.type_name(), "csc_matrix");
}

#[test]
fn csc_matrix_via_copyreg_reconstructor() {
    let p = B::new()
        .proto(1)
        .global("copy_reg", "_reconstructor")
        .op(b'(')
        .global("scipy.sparse._csc", "csc_matrix")
        .global("__builtin__", "object")
        .op(b'N')
        .op(b't')
        .op(b'R')
        .op(b'(')
        .sbu("_shape")
        .k(1)
        .k(1)
        .op(0x86)
        .sbu("data")
        .array2(&[1], "f8", "<", false, &f64_bytes(&[9.0]))
        .sbu("indices")
        .array2(&[1], "i4", "<", false, &i32_bytes(&[0]))
        .sbu("indptr")
        .array2(&[2], "i4", "<", false, &i32_bytes(&[0, 1]))
        .op(b'd')
        .op(b'b')
        .stop();
    let v = read(&p);
    assert_eq!(
        v.as_sparse().unwrap().to_dense_row_major().unwrap(),
        vec![9.0]
    );
}

#[test]
fn invalid_csc_matrices_are_errors() {
    // Row index out of range.
    let e = read_err(&csc_py2((2, 3), &[1.0, 3.0, 2.0], &[0, 2, 0], &[0, 1, 2, 3]).stop());
    assert!(matches!(e.kind, PickleErrorKind::SizeMismatch(_)), "{e}");
    // indptr of the wrong length.
    let e = read_err(&csc_py2((2, 3), &[1.0, 3.0, 2.0], &[0, 1, 0], &[0, 1, 3]).stop());
    assert!(e.to_string().contains("indptr"), "{e}");
    // Fewer indices than values.
    let e = read_err(&csc_py2((2, 3), &[1.0, 3.0, 2.0], &[0, 1], &[0, 1, 2, 3]).stop());
    assert!(e.to_string().contains("indices"), "{e}");
    // The offset is the BUILD of the matrix (the last opcode before STOP).
    let p = csc_py2((2, 3), &[1.0], &[5], &[0, 1, 1, 1]).stop();
    assert_eq!(read_err(&p).offset, p.len() - 2);
}

// ---------------------------------------------------------------- chumpy

/// A chumpy Ch as Python 2 writes it: NEWOBJ with no arguments, then BUILD of its
/// `__dict__` (minus `_parents` and `_cache`).
fn ch_py2(b: B, shape: &[u16], x: &[f64]) -> B {
    b.global("chumpy.ch", "Ch")
        .op(b')')
        .op(0x81)
        .op(b'}')
        .op(b'(')
        .sbs(b"_dirty_vars")
        .global("__builtin__", "set")
        .op(b']')
        .op(0x85)
        .op(b'R')
        .sbs(b"_itr")
        .op(b'N')
        .sbs(b"_depends_on_deps")
        .op(b'}')
        .sbs(b"_make_dense")
        .op(0x89)
        .sbs(b"x")
        .array2(shape, "f8", "<", false, &f64_bytes(x))
        .sbs(b"_make_sparse")
        .op(0x89)
        .op(b'u')
        .op(b'b')
}

fn select_py2(x_shape: &[u16], x: &[f64], idxs: &[i64], preferred: &[u16]) -> Vec<u8> {
    let mut b = B::new()
        .proto(2)
        .global("chumpy.reordering", "Select")
        .op(b')')
        .op(0x81)
        .op(b'}')
        .op(b'(')
        .sbs(b"a");
    b = ch_py2(b, x_shape, x);
    b = b
        .sbs(b"idxs")
        .array2(&[idxs.len() as u16], "i8", "<", false, &i64_bytes(idxs))
        .sbs(b"_dirty_vars")
        .global("__builtin__", "set")
        .op(b']')
        .op(b'(')
        .sbs(b"a")
        .sbs(b"idxs")
        .op(b'e')
        .op(0x85)
        .op(b'R')
        .sbs(b"preferred_shape")
        .op(b'(');
    for &d in preferred {
        b = b.m(d);
    }
    b.op(b't').sbs(b"_itr").op(b'N').op(b'u').op(b'b').stop()
}

#[test]
fn chumpy_select_over_ch_equals_slice() {
    // x: (2, 3, 4) with x[i, j, k] = 100 i + 10 j + k; Select picks x[:, :, :2] as MANO's
    // shapedirs does with x[:, :, :10].
    let mut x = Vec::new();
    let mut idxs = Vec::new();
    for i in 0..2 {
        for j in 0..3 {
            for k in 0..4 {
                x.push(f64::from(100 * i + 10 * j + k));
                if k < 2 {
                    idxs.push(i64::from(i * 12 + j * 4 + k));
                }
            }
        }
    }
    let v = read(&select_py2(&[2, 3, 4], &x, &idxs, &[2, 3, 2]));
    let a = v.as_array().unwrap();
    assert_eq!(a.shape, vec![2, 3, 2]);
    let mut expected = Vec::new();
    for i in 0..2 {
        for j in 0..3 {
            for k in 0..2 {
                expected.push(f64::from(100 * i + 10 * j + k));
            }
        }
    }
    assert_eq!(a.data, ArrayData::F64(expected));
}

#[test]
fn chumpy_errors() {
    let x = [1.0, 2.0, 3.0];
    let e = read_err(&select_py2(&[3], &x, &[0, 3], &[2]));
    assert!(e.to_string().contains("index 3 is outside"), "{e}");
    let e = read_err(&select_py2(&[3], &x, &[0, 1], &[3]));
    assert!(matches!(e.kind, PickleErrorKind::SizeMismatch(_)), "{e}");
    // A Ch without 'x'.
    let p = B::new()
        .proto(2)
        .global("chumpy.ch", "Ch")
        .op(b')')
        .op(0x81)
        .op(b'}')
        .op(b'b')
        .stop();
    assert!(read_err(&p).to_string().contains("no \"x\""));
}

#[test]
fn chumpy_ch_alone_and_via_newobj_ex() {
    let p = ch_py2(B::new().proto(2), &[2], &[1.5, 2.5]).stop();
    assert_eq!(
        read(&p).as_array().unwrap().data,
        ArrayData::F64(vec![1.5, 2.5])
    );
    // NEWOBJ_EX with empty kwargs, and a scalar x.
    let p = B::new()
        .proto(4)
        .sbu("chumpy.ch")
        .sbu("Ch")
        .op(0x93)
        .op(b')')
        .op(b'}')
        .op(0x92)
        .op(b'}')
        .sbu("x")
        .g(0.25)
        .op(b's')
        .op(b'b')
        .stop();
    let v = read(&p);
    assert_eq!(v.as_f64(), Some(0.25));
    assert!(v.as_array().unwrap().shape.is_empty());
}

// ---------------------------------------------------------------- errors and safety

fn valid_pickles() -> Vec<Vec<u8>> {
    let mut x = Vec::new();
    for i in 0..24 {
        x.push(f64::from(i));
    }
    let idxs: Vec<i64> = (0..12).map(|i| i * 2).collect();
    vec![
        select_py2(&[2, 3, 4], &x, &idxs, &[2, 3, 2]),
        csc_py2((2, 3), &[1.0, 3.0, 2.0], &[0, 1, 0], &[0, 1, 2, 3]).stop(),
        b"(dp0\nS'a'\np1\n(lp2\nI1\naF2.5\naS'x'\np3\naVcaf\\u00e9\np4\naNaI01\nasS'b'\np5\ng2\ns."
            .to_vec(),
        B::new()
            .proto(4)
            .op(0x95)
            .raw(&12u64.to_le_bytes())
            .op(0x8d)
            .raw(&2u64.to_le_bytes())
            .raw(b"ab")
            .stop(),
        B::new()
            .proto(2)
            .array2(&[2, 2], "i8", "<", true, &i64_bytes(&[1, 2, 3, 4]))
            .stop(),
    ]
}

#[test]
fn every_truncation_is_an_error() {
    for p in valid_pickles() {
        assert!(from_bytes(&p, "full").is_ok());
        for n in 0..p.len() {
            let e = match from_bytes(&p[..n], "cut") {
                Ok(v) => panic!("prefix of {n} bytes read as {v:?}"),
                Err(e) => e,
            };
            assert!(
                matches!(
                    e.kind,
                    PickleErrorKind::Truncated | PickleErrorKind::TooLarge(_)
                ),
                "prefix {n}: {e}"
            );
            assert!(e.offset <= n);
        }
    }
}

#[test]
fn unknown_globals_are_refused_with_name_and_offset() {
    let e = read_err(b"\x80\x02cos\nsystem\nq\x00(U\x02lstq\x01tR.");
    assert_eq!(e.offset, 2);
    match &e.kind {
        PickleErrorKind::UnsupportedGlobal { module, name } => {
            assert_eq!((module.as_str(), name.as_str()), ("os", "system"));
        }
        other => panic!("{other:?}"),
    }
    assert!(
        e.to_string()
            .starts_with("test.pkl: byte 2: global 'os.system' is not allowed"),
        "{e}"
    );
    let p = B::new()
        .proto(4)
        .sbu("builtins")
        .sbu("eval")
        .op(0x93)
        .stop();
    let e = read_err(&p);
    assert_eq!(e.offset, 2 + 10 + 6);
    assert!(matches!(e.kind, PickleErrorKind::UnsupportedGlobal { .. }));
}

#[test]
fn unknown_opcodes_are_refused_with_offset() {
    for op in [0xffu8, b'P', b'Q', b'i', b'o', 0x82, 0x97, 0x98, b'x'] {
        let e = read_err(&B::new().proto(2).op(b'N').op(op).stop());
        assert_eq!(e.offset, 3, "opcode {op:#x}");
        assert!(
            matches!(e.kind, PickleErrorKind::UnknownOpcode(o) if o == op),
            "{e}"
        );
    }
    let e = read_err(b"\x80\x02\xff");
    assert_eq!(
        e.to_string(),
        "test.pkl: byte 2: unknown or unsupported opcode 0xff"
    );
}

#[test]
fn huge_declared_lengths_do_not_allocate() {
    let cases: Vec<Vec<u8>> = vec![
        B::new()
            .proto(4)
            .op(0x8d)
            .raw(&u64::MAX.to_le_bytes())
            .stop(),
        B::new()
            .proto(4)
            .op(0x8e)
            .raw(&(1u64 << 62).to_le_bytes())
            .stop(),
        B::new()
            .proto(5)
            .op(0x96)
            .raw(&(1u64 << 40).to_le_bytes())
            .stop(),
        B::new()
            .proto(4)
            .op(0x95)
            .raw(&u64::MAX.to_le_bytes())
            .stop(),
        B::new()
            .proto(2)
            .op(b'X')
            .raw(&u32::MAX.to_le_bytes())
            .stop(),
        B::new()
            .proto(3)
            .op(b'B')
            .raw(&u32::MAX.to_le_bytes())
            .stop(),
        B::new()
            .proto(2)
            .op(b'T')
            .raw(&i32::MAX.to_le_bytes())
            .stop(),
        B::new()
            .proto(2)
            .op(0x8b)
            .raw(&i32::MAX.to_le_bytes())
            .stop(),
    ];
    for p in cases {
        let e = read_err(&p);
        assert_eq!(e.offset, 2);
        assert!(matches!(e.kind, PickleErrorKind::TooLarge(_)), "{e}");
    }
    // Negative lengths.
    let e = read_err(
        &B::new()
            .proto(2)
            .op(b'T')
            .raw(&(-1i32).to_le_bytes())
            .stop(),
    );
    assert!(e.to_string().contains("negative"));
    let e = read_err(
        &B::new()
            .proto(2)
            .op(0x8b)
            .raw(&(-1i32).to_le_bytes())
            .stop(),
    );
    assert!(e.to_string().contains("negative"));
    // A length that fits the input but not what is left of it.
    let e = read_err(
        &B::new()
            .proto(3)
            .op(b'B')
            .raw(&5u32.to_le_bytes())
            .raw(b"ab")
            .stop(),
    );
    assert!(matches!(e.kind, PickleErrorKind::Truncated));
}

#[test]
fn stack_underflows() {
    for p in [
        &b"."[..],
        b"\x80\x02a.",
        b"\x80\x02N(.",
        b"\x80\x020.",
        b"\x80\x021.",
        b"\x80\x02e.",
        b"\x80\x02K\x01\x86.",
        b"\x80\x02(K\x01\x86.",
        b"\x80\x02Nb.",
        b"\x80\x02q\x00.",
        b"\x80\x02(2.",
    ] {
        let e = read_err(p);
        assert!(
            matches!(e.kind, PickleErrorKind::StackUnderflow),
            "{p:?}: {e}"
        );
    }
}

#[test]
fn bad_arguments() {
    for (p, msg) in [
        (&b"\x80\x02h\x05."[..], "memo key 5"),
        (b"\x80\x02]NK\x01s.", "SETITEM on a list"),
        (b"\x80\x02}K\x01a.", "APPEND to a dict"),
        (b"\x80\x02}(K\x01u.", "odd number"),
        (b"\x80\x02K\x01)R.", "REDUCE needs a global"),
        (b"\x80\x02cnumpy\nndarray\n)R.", "cannot be called"),
        (b"\x80\x02cchumpy.ch\nCh\nK\x01\x85\x81.", "with arguments"),
        (b"\x80\x02}}b.", "BUILD on a dict"),
        (
            b"\x80\x02cchumpy.ch\nCh\n)\x81K\x01b.",
            "state must be a dict",
        ),
        (b"\x80\x02cnumpy\ndtype\n.", "bare global"),
        (b"\x80\x02S'abc\n.", "must be quoted"),
        (b"\x80\x02Fabc\n.", "invalid float"),
    ] {
        let e = read_err(p);
        assert!(e.to_string().contains(msg), "{p:?}: {e}");
    }
    // An ndarray reconstructed but never built.
    let p = B::new().proto(2).reconstruct_ndarray().stop();
    assert!(read_err(&p).to_string().contains("never built"));
}

#[test]
fn deep_nesting_is_limited_without_overflowing_the_stack() {
    fn nested(depth: usize) -> Vec<u8> {
        let mut p = vec![0x80, 2];
        p.extend(std::iter::repeat_n(b']', depth + 1));
        p.extend(std::iter::repeat_n(b'a', depth));
        p.push(b'.');
        p
    }
    let mut v = read(&nested(crate::MAX_DEPTH));
    for _ in 0..crate::MAX_DEPTH {
        v = match v {
            Value::List(mut items) if items.len() == 1 => items.pop().unwrap(),
            other => panic!("{other:?}"),
        };
    }
    assert_eq!(v, Value::List(vec![]));
    let e = read_err(&nested(crate::MAX_DEPTH + 1));
    assert!(matches!(e.kind, PickleErrorKind::TooLarge(_)), "{e}");
    let e = read_err(&nested(200_000));
    assert!(e.to_string().contains("nesting deeper"), "{e}");
    // 70,000 nested marks.
    let mut p = vec![0x80, 2];
    p.extend(std::iter::repeat_n(b'(', 70_000));
    p.push(b'.');
    assert!(matches!(read_err(&p).kind, PickleErrorKind::TooLarge(_)));
}

#[test]
fn cycles_and_exponential_sharing_are_refused() {
    // l = []; l.append(l)
    let e = read_err(b"\x80\x02]q\x00h\x00a.");
    assert!(e.to_string().contains("cycle"), "{e}");
    // t = ((((x, x), (x, x)), ...)) 64 levels deep: 2^64 leaves from 140 bytes.
    let mut p = vec![0x80, 2, b'N'];
    for _ in 0..64 {
        p.extend_from_slice(&[b'2', 0x86]);
    }
    p.push(b'.');
    let e = read_err(&p);
    assert!(e.to_string().contains("too many values"), "{e}");
}

#[test]
fn repeated_calls_on_one_large_argument_are_bounded() {
    // l = [0] * 100_000; then set(l) 100_000 times through the memo.
    let mut p = B::new().proto(2).op(b']').put(0).op(b'(');
    for _ in 0..100_000 {
        p = p.k(0);
    }
    p = p.op(b'e').global("__builtin__", "set").put(1).op(b'(');
    for _ in 0..100_000 {
        p = p.get(1).get(0).op(0x85).op(b'R');
    }
    let e = read_err(&p.op(b'l').stop());
    assert!(e.to_string().contains("copies too much"), "{e}");
    // The same with _codecs.encode of a 100 KB str.
    let text = "x".repeat(100_000);
    let mut p = B::new()
        .proto(2)
        .op(b'X')
        .raw(&(text.len() as u32).to_le_bytes())
        .raw(text.as_bytes())
        .put(0)
        .global("_codecs", "encode")
        .put(1)
        .sbu("latin1")
        .put(2)
        .op(b'(');
    for _ in 0..10_000 {
        p = p.get(1).get(0).get(2).op(0x86).op(b'R');
    }
    let e = read_err(&p.op(b'l').stop());
    assert!(e.to_string().contains("copies too much"), "{e}");
    // 200,000 BUILDs on one chumpy object stay linear.
    let mut p = B::new()
        .proto(2)
        .global("chumpy.ch", "Ch")
        .op(b')')
        .op(0x81);
    for _ in 0..200_000 {
        p = p.op(b'}').op(b'b');
    }
    let e = read_err(&p.stop());
    assert!(e.to_string().contains("no \"x\""), "{e}");
}

#[test]
fn names_and_dimensions_are_capped() {
    let long = "m".repeat(2000);
    let p = B::new()
        .proto(4)
        .op(b'X')
        .raw(&(long.len() as u32).to_le_bytes())
        .raw(long.as_bytes())
        .sbu("x")
        .op(0x93)
        .stop();
    assert!(read_err(&p).to_string().contains("longer than 1024"));
    let mut b = B::new()
        .proto(2)
        .reconstruct_ndarray()
        .op(b'(')
        .k(1)
        .op(b'(');
    for _ in 0..65 {
        b = b.k(1);
    }
    let p = b
        .op(b't')
        .dtype2("u1", "|")
        .op(0x89)
        .sbs(b"a")
        .op(b't')
        .op(b'b')
        .stop();
    assert!(read_err(&p).to_string().contains("65 dimensions"));
}

#[test]
fn io_errors_name_the_path() {
    let path = std::path::Path::new("/nonexistent/dir/MANO_RIGHT.pkl");
    let e = crate::from_path(path).unwrap_err();
    assert_eq!(e.offset, 0);
    assert!(matches!(e.kind, PickleErrorKind::Io(_)));
    let msg = e.to_string();
    assert!(
        msg.starts_with("/nonexistent/dir/MANO_RIGHT.pkl: byte 0: could not be read"),
        "{msg}"
    );
}

#[test]
fn from_path_reads_a_file() {
    let dir = std::env::temp_dir().join(format!("bitt-pickle-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("x.pkl");
    std::fs::write(&path, b"\x80\x02K\x07.").unwrap();
    let v = crate::from_path(&path);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(v.unwrap(), Value::Int(7));
}

/// Reads the InterHand2.6M demo annotation when the shared data folder is present
/// (it is test data outside the project; a fresh clone skips this test).
#[test]
fn interhand_demo_annotation_if_present() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/interhand_demo/01.pkl");
    if !path.exists() {
        eprintln!(
            "SKIPPED interhand_demo_annotation_if_present: {} not found",
            path.display()
        );
        return;
    }
    let v = crate::from_path(&path).unwrap();
    assert_eq!(v.get("inter_idx").and_then(Value::as_i64), Some(12));
    assert_eq!(
        v.get("annotation")
            .and_then(|a| a.get("hand_type"))
            .and_then(Value::as_str),
        Some("interacting")
    );
    let left = v.get("mano_params").and_then(|m| m.get("left")).unwrap();
    let r = left.get("R").and_then(Value::as_array).unwrap();
    assert_eq!((r.shape.as_slice(), r.dtype()), (&[1, 3, 3][..], "f4"));
    assert_eq!(
        r.to_f64()[0],
        f64::from(f32::from_le_bytes([0x50, 0xae, 0x03, 0x3d]))
    );
    let pose = left.get("pose").and_then(Value::as_array).unwrap();
    assert_eq!(pose.shape, vec![1, 45]);
    let cam = v.get("camera").unwrap();
    let k = cam.get("camera").and_then(Value::as_array).unwrap();
    assert_eq!((k.shape.as_slice(), k.dtype()), (&[3, 3][..], "f8"));
    let t = cam.get("t").and_then(Value::as_array).unwrap();
    assert_eq!(t.shape, vec![3]);
}
