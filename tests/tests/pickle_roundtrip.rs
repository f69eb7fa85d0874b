//! Pickles written by the test pickle writer (protocol 2 as Python 2's cPickle, protocol 4
//! as Python 3) are read back by `bitt-pickle` into exactly the values they encode.

use bitt_pickle::{ArrayData, CscMatrix, NdArray, Value, from_bytes};
use bitt_tests::pickle_writer::{PyValue, write_protocol2, write_protocol4};

/// C-order elements of an array whose `data` is listed in Fortran order when `fortran`
/// (else already in C order).
fn c_order<T: Copy>(shape: &[usize], data: &[T], fortran: bool) -> Vec<T> {
    if !fortran {
        return data.to_vec();
    }
    let n: usize = shape.iter().product();
    assert_eq!(n, data.len());
    let mut f_strides = vec![1usize; shape.len()];
    for k in 1..shape.len() {
        f_strides[k] = f_strides[k - 1] * shape[k - 1];
    }
    let mut out = Vec::with_capacity(n);
    let mut idx = vec![0usize; shape.len()];
    for _ in 0..n {
        let f: usize = idx.iter().zip(&f_strides).map(|(i, s)| i * s).sum();
        out.push(data[f]);
        for k in (0..shape.len()).rev() {
            idx[k] += 1;
            if idx[k] < shape[k] {
                break;
            }
            idx[k] = 0;
        }
    }
    out
}

fn arr(shape: &[usize], data: ArrayData) -> Value {
    Value::Array(NdArray {
        shape: shape.to_vec(),
        data,
    })
}

/// What the reader must return for `v` written with protocol `proto`.
fn expected(v: &PyValue, proto: u8) -> Value {
    let all = |items: &[PyValue]| items.iter().map(|x| expected(x, proto)).collect();
    match v {
        PyValue::None => Value::None,
        PyValue::Bool(b) => Value::Bool(*b),
        PyValue::Int(i) => Value::Int(*i),
        PyValue::Float(f) => Value::Float(*f),
        PyValue::Str(s) | PyValue::Unicode(s) => Value::Str(s.clone()),
        PyValue::Bytes(b) if proto < 3 => Value::Str(b.iter().map(|&c| char::from(c)).collect()),
        PyValue::Bytes(b) => Value::Bytes(b.clone()),
        PyValue::List(items) => Value::List(all(items)),
        PyValue::Tuple(items) => Value::Tuple(all(items)),
        PyValue::Set(items) => Value::Set(all(items)),
        PyValue::Dict(items) => Value::Dict(
            items
                .iter()
                .map(|(k, v)| (expected(k, proto), expected(v, proto)))
                .collect(),
        ),
        PyValue::NdArrayF64 {
            shape,
            data,
            fortran,
        } => arr(shape, ArrayData::F64(c_order(shape, data, *fortran))),
        PyValue::NdArrayI64 {
            shape,
            data,
            fortran,
        } => arr(shape, ArrayData::I64(c_order(shape, data, *fortran))),
        PyValue::NdArrayU32 { shape, data } => arr(shape, ArrayData::U32(data.clone())),
        PyValue::NdArrayF32 { shape, data } => arr(shape, ArrayData::F32(data.clone())),
        PyValue::NdArrayI32 { shape, data } => arr(shape, ArrayData::I32(data.clone())),
        PyValue::NdArrayU8 { shape, data } => arr(shape, ArrayData::U8(data.clone())),
        PyValue::NdArrayBool { shape, data } => arr(shape, ArrayData::Bool(data.clone())),
        PyValue::NpScalarF64(x) => arr(&[], ArrayData::F64(vec![*x])),
        PyValue::Csc {
            shape,
            data,
            indices,
            indptr,
        } => Value::Sparse(CscMatrix {
            shape: *shape,
            data: data.clone(),
            indices: indices.iter().map(|&i| i64::from(i)).collect(),
            indptr: indptr.iter().map(|&i| i64::from(i)).collect(),
        }),
        PyValue::ChumpyCh(x) => match expected(x, proto) {
            Value::Float(f) => arr(&[], ArrayData::F64(vec![f])),
            Value::Int(i) => arr(&[], ArrayData::I64(vec![i])),
            other => other,
        },
        PyValue::ChumpySelect {
            a,
            idxs,
            preferred_shape,
        } => {
            let Value::Array(a) = expected(a, proto) else {
                panic!("Select over a non-array");
            };
            let data = match &a.data {
                ArrayData::F64(v) => ArrayData::F64(idxs.iter().map(|&i| v[i as usize]).collect()),
                ArrayData::F32(v) => ArrayData::F32(idxs.iter().map(|&i| v[i as usize]).collect()),
                other => panic!("unexpected dtype {}", other.dtype()),
            };
            arr(preferred_shape, data)
        }
    }
}

/// A small file with the structure of MANO_RIGHT.pkl (same keys, globals and nesting).
fn mano_like() -> PyValue {
    let nv = 6;
    let x: Vec<f64> = (0..nv * 3 * 4).map(|i| i as f64 * 0.5 - 3.0).collect();
    let idxs: Vec<i64> = (0..nv * 3)
        .flat_map(|row| (0..2).map(move |b| (row * 4 + b) as i64))
        .collect();
    let parents = [4_294_967_295i64, 0, 1, 0];
    let mut kintree = Vec::new();
    for (j, p) in parents.iter().enumerate() {
        kintree.push(*p);
        kintree.push(j as i64);
    }
    PyValue::dict(vec![
        (
            "J_regressor",
            PyValue::Csc {
                shape: (4, nv),
                data: vec![0.5, 0.5, 1.0, 0.25, 0.75, 1.0],
                indices: vec![0, 1, 0, 2, 3, 1],
                indptr: vec![0, 2, 3, 4, 5, 6, 6],
            },
        ),
        (
            "f",
            PyValue::NdArrayU32 {
                shape: vec![2, 3],
                data: vec![0, 1, 2, 2, 3, 5],
            },
        ),
        (
            "kintree_table",
            PyValue::NdArrayI64 {
                shape: vec![2, 4],
                data: kintree,
                fortran: true,
            },
        ),
        (
            "weights",
            PyValue::f64_array(
                &[nv, 4],
                (0..nv * 4).map(|i| f64::from(i as u32) / 24.0).collect(),
            ),
        ),
        (
            "posedirs",
            PyValue::NdArrayF64 {
                shape: vec![nv, 3, 2],
                data: (0..nv * 6).map(|i| -f64::from(i as u32)).collect(),
                fortran: false,
            },
        ),
        ("bs_style", PyValue::str("lbs")),
        (
            "v_template",
            PyValue::f64_array(
                &[nv, 3],
                (0..nv * 3).map(|i| f64::from(i as u32) * 1e-3).collect(),
            ),
        ),
        (
            "shapedirs",
            PyValue::ChumpySelect {
                a: Box::new(PyValue::ChumpyCh(Box::new(PyValue::NdArrayF64 {
                    shape: vec![nv, 3, 4],
                    data: x,
                    fortran: false,
                }))),
                idxs,
                preferred_shape: vec![nv, 3, 2],
            },
        ),
        ("hands_mean", PyValue::f64_array(&[3], vec![0.1, -0.2, 0.3])),
        ("bs_type", PyValue::str("lrotmin")),
        (
            "J_regressor_prior",
            PyValue::Csc {
                shape: (1, 1),
                data: vec![1.0],
                indices: vec![0],
                indptr: vec![0, 1],
            },
        ),
    ])
}

/// Everything else the writer can express, including sizes that force LONG_BINPUT /
/// LONG_BINGET, several APPENDS batches, frames and out-of-frame data.
fn assorted() -> PyValue {
    let many_strings: Vec<PyValue> = (0..300)
        .map(|i| PyValue::str(&format!("item {i}")))
        .collect();
    PyValue::dict(vec![
        ("none", PyValue::None),
        (
            "bools",
            PyValue::List(vec![PyValue::Bool(true), PyValue::Bool(false)]),
        ),
        (
            "ints",
            PyValue::List(
                [
                    0i64,
                    255,
                    256,
                    65535,
                    65536,
                    -1,
                    -129,
                    1 << 31,
                    -(1 << 31) - 1,
                    1 << 40,
                    i64::MIN,
                    i64::MAX,
                ]
                .into_iter()
                .map(PyValue::Int)
                .collect(),
            ),
        ),
        (
            "floats",
            PyValue::Tuple(vec![PyValue::Float(1.5), PyValue::Float(-1e300)]),
        ),
        ("latin", PyValue::str("café")),
        ("unicode", PyValue::Unicode("ünï €".to_string())),
        ("bytes", PyValue::Bytes(vec![0, 1, 2, 200, 255])),
        (
            "tuples",
            PyValue::List(vec![
                PyValue::Tuple(vec![]),
                PyValue::Tuple(vec![PyValue::Int(1)]),
                PyValue::Tuple(vec![
                    PyValue::Int(1),
                    PyValue::Int(2),
                    PyValue::Int(3),
                    PyValue::Int(4),
                ]),
            ]),
        ),
        (
            "set",
            PyValue::Set(vec![PyValue::Int(3), PyValue::str("x")]),
        ),
        ("many_strings", PyValue::List(many_strings)),
        // First used after 300 memo entries: its dtype is fetched with LONG_BINGET later.
        (
            "late_i4",
            PyValue::NdArrayI32 {
                shape: vec![3],
                data: vec![-1, 0, 1],
            },
        ),
        (
            "late_i4_again",
            PyValue::NdArrayI32 {
                shape: vec![1, 1],
                data: vec![7],
            },
        ),
        (
            "long_list",
            PyValue::List((0..2500).map(PyValue::Int).collect()),
        ),
        (
            "big",
            PyValue::f64_array(
                &[100, 100],
                (0..10_000).map(|i| f64::from(i) * 0.25).collect(),
            ),
        ),
        (
            "f32",
            PyValue::NdArrayF32 {
                shape: vec![2, 2],
                data: vec![1.0, -2.0, 0.5, 8.0],
            },
        ),
        (
            "u8",
            PyValue::NdArrayU8 {
                shape: vec![4],
                data: vec![0, 7, 128, 255],
            },
        ),
        (
            "mask",
            PyValue::NdArrayBool {
                shape: vec![3],
                data: vec![true, false, true],
            },
        ),
        (
            "fortran3d",
            PyValue::NdArrayF64 {
                shape: vec![2, 3, 2],
                data: (0..12).map(f64::from).collect(),
                fortran: true,
            },
        ),
        ("scalar", PyValue::NpScalarF64(0.125)),
        (
            "ch_scalar",
            PyValue::ChumpyCh(Box::new(PyValue::Float(2.0))),
        ),
        (
            "nested",
            PyValue::Dict(vec![
                (PyValue::Int(1), PyValue::List(vec![PyValue::Dict(vec![])])),
                (
                    PyValue::Unicode("k".into()),
                    PyValue::Tuple(vec![PyValue::None]),
                ),
            ]),
        ),
    ])
}

fn read(bytes: &[u8]) -> Value {
    from_bytes(bytes, "roundtrip.pkl").unwrap_or_else(|e| panic!("{e}"))
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

#[test]
fn mano_like_protocol2_round_trip() {
    let v = mano_like();
    let p = write_protocol2(&v);
    assert_eq!(&p[..2], b"\x80\x02");
    for g in [
        &b"cnumpy.core.multiarray\n_reconstruct\n"[..],
        b"cnumpy\nndarray\n",
        b"cnumpy\ndtype\n",
        b"cscipy.sparse.csc\ncsc_matrix\n",
        b"cchumpy.ch\nCh\n",
        b"cchumpy.reordering\nSelect\n",
        b"c__builtin__\nset\n",
    ] {
        assert!(contains(&p, g), "{}", String::from_utf8_lossy(g));
    }
    assert_eq!(
        &p[2..4],
        b"}q",
        "no FRAME in protocol 2: EMPTY_DICT, BINPUT"
    );
    let got = read(&p);
    assert_eq!(got, expected(&v, 2));
    // The facts a MANO loader relies on.
    let kt = got.get("kintree_table").and_then(Value::as_array).unwrap();
    assert_eq!(kt.to_i64(), vec![4_294_967_295, 0, 1, 0, 0, 1, 2, 3]);
    let sd = got.get("shapedirs").and_then(Value::as_array).unwrap();
    assert_eq!(sd.shape, vec![6, 3, 2]);
    assert_eq!(sd.to_f64()[..4], [-3.0, -2.5, -1.0, -0.5]);
    assert_eq!(got.get("bs_style").and_then(Value::as_str), Some("lbs"));
    let jr = got.get("J_regressor").and_then(Value::as_sparse).unwrap();
    let dense = jr.to_dense_row_major().unwrap();
    assert_eq!(dense.len(), 4 * 6);
    assert_eq!(dense[0], 0.5);
}

#[test]
fn mano_like_protocol4_round_trip() {
    let v = mano_like();
    let p = write_protocol4(&v);
    assert_eq!(&p[..3], b"\x80\x04\x95");
    assert!(contains(&p, b"\x8c\x11scipy.sparse._csc\x94"));
    assert_eq!(read(&p), expected(&v, 4));
}

#[test]
fn assorted_values_round_trip_in_both_protocols() {
    let v = assorted();
    for (proto, p) in [(2u8, write_protocol2(&v)), (4, write_protocol4(&v))] {
        assert_eq!(read(&p), expected(&v, proto), "protocol {proto}");
    }
    let p2 = write_protocol2(&v);
    assert!(
        contains(&p2, b"I1099511627776\n"),
        "cPickle writes big ints as text"
    );
    assert!(
        p2.contains(&b'r') && p2.contains(&b'j'),
        "LONG_BINPUT / LONG_BINGET"
    );
    let p4 = write_protocol4(&v);
    // The 80 KB array is written outside any frame; a new frame follows it.
    let header = [b'B', 0x80, 0x38, 0x01, 0x00]; // BINBYTES of 80000 bytes
    let at = p4
        .windows(5)
        .position(|w| w == header)
        .expect("BINBYTES header");
    assert_eq!(p4[at + 5 + 80_000], 0x95);
}

#[test]
fn every_truncation_of_a_written_file_is_an_error() {
    let v = PyValue::dict(vec![
        (
            "a",
            PyValue::ChumpySelect {
                a: Box::new(PyValue::ChumpyCh(Box::new(PyValue::f64_array(
                    &[4],
                    vec![1.0, 2.0, 3.0, 4.0],
                )))),
                idxs: vec![3, 0],
                preferred_shape: vec![2],
            },
        ),
        (
            "b",
            PyValue::Csc {
                shape: (1, 2),
                data: vec![1.0],
                indices: vec![0],
                indptr: vec![0, 1, 1],
            },
        ),
    ]);
    for p in [write_protocol2(&v), write_protocol4(&v)] {
        assert!(from_bytes(&p, "full").is_ok());
        for n in 0..p.len() {
            assert!(from_bytes(&p[..n], "cut").is_err(), "prefix of {n} bytes");
        }
    }
}
