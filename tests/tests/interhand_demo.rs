//! The two real InterHand2.6M demo frames (when `../shared` is beside the checkout): the pickle
//! reader must give the same tree Python's `pickle` gives, and the annotation reader the same
//! parameters. Skipped, saying so, where the frames, Python or numpy are missing.

use std::path::PathBuf;
use std::process::Command;

use bitt_mesh::annotation::BITT_CROP_SIZE;
use bitt_mesh::lbs::HandPose;
use bitt_pickle::Value;

fn demo_dir() -> Option<PathBuf> {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/interhand_demo");
    d.join("01.pkl").is_file().then_some(d)
}

/// Python's view of a pickle as JSON: arrays as `{"ndarray": dtype, "shape", "data"}`, and
/// every float as its shortest round-trip `repr` string (parsed exactly on the Rust side).
const DUMP: &str = r#"
import json, pickle, sys
import numpy as np
def conv(x):
    if isinstance(x, dict): return {"dict": [[conv(k), conv(v)] for k, v in x.items()]}
    if isinstance(x, (list, tuple)): return [conv(v) for v in x]
    if isinstance(x, np.ndarray): return {"ndarray": x.dtype.str[1:], "shape": list(x.shape), "data": [conv(v) for v in x.ravel().tolist()]}
    if isinstance(x, np.generic): return conv(x.item())
    if isinstance(x, float): return {"float": repr(x)}
    return x
print(json.dumps(conv(pickle.load(open(sys.argv[1], "rb")))))
"#;

fn python_view(path: &std::path::Path) -> Option<serde_json::Value> {
    let out = Command::new("python3")
        .arg("-c")
        .arg(DUMP)
        .arg(path)
        .output()
        .ok()?;
    if !out.status.success() {
        eprintln!(
            "python3 could not read it: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
        return None;
    }
    serde_json::from_slice(&out.stdout).ok()
}

/// A number from the dump: an int, a bool, or `{"float": repr}`.
fn py_number(v: &serde_json::Value) -> f64 {
    match v {
        serde_json::Value::Object(o) => o["float"].as_str().unwrap().parse().unwrap(),
        serde_json::Value::Bool(b) => f64::from(u8::from(*b)),
        n => n.as_f64().unwrap(),
    }
}

fn same(rust: &Value, py: &serde_json::Value, at: &str) {
    match (rust, py) {
        (Value::Dict(items), serde_json::Value::Object(o)) if o.contains_key("dict") => {
            let pairs = o["dict"].as_array().unwrap();
            assert_eq!(items.len(), pairs.len(), "{at}: dict sizes");
            for ((k, v), pair) in items.iter().zip(pairs) {
                same(k, &pair[0], at);
                same(v, &pair[1], &format!("{at}.{}", pair[0]));
            }
        }
        (Value::Array(a), serde_json::Value::Object(o)) if o.contains_key("ndarray") => {
            assert_eq!(a.dtype(), o["ndarray"].as_str().unwrap(), "{at}: dtype");
            let shape: Vec<usize> = o["shape"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_u64().unwrap() as usize)
                .collect();
            assert_eq!(a.shape, shape, "{at}: shape");
            let want: Vec<f64> = o["data"]
                .as_array()
                .unwrap()
                .iter()
                .map(py_number)
                .collect();
            assert_eq!(a.to_f64(), want, "{at}: values");
        }
        (Value::List(items) | Value::Tuple(items), serde_json::Value::Array(py)) => {
            assert_eq!(items.len(), py.len(), "{at}: lengths");
            for (i, (r, p)) in items.iter().zip(py).enumerate() {
                same(r, p, &format!("{at}[{i}]"));
            }
        }
        (Value::Str(s), serde_json::Value::String(p)) => assert_eq!(s, p, "{at}"),
        (Value::Int(i), serde_json::Value::Number(n)) => assert_eq!(Some(*i), n.as_i64(), "{at}"),
        (Value::Float(f), p @ serde_json::Value::Object(o)) if o.contains_key("float") => {
            assert_eq!(*f, py_number(p), "{at}")
        }
        (Value::Bool(b), serde_json::Value::Bool(p)) => assert_eq!(b, p, "{at}"),
        (Value::None, serde_json::Value::Null) => {}
        (r, p) => panic!("{at}: Rust read a {} where Python has {p}", r.type_name()),
    }
}

#[test]
fn demo_pickles_read_as_python_reads_them() {
    let Some(dir) = demo_dir() else {
        eprintln!(
            "SKIPPED demo_pickles_read_as_python_reads_them: ../shared/data/interhand_demo is not beside this checkout"
        );
        return;
    };
    for name in ["01.pkl", "02.pkl"] {
        let path = dir.join(name);
        let rust = bitt_pickle::from_path(&path).unwrap();
        let Some(py) = python_view(&path) else {
            eprintln!(
                "SKIPPED the Python comparison of {name}: python3 with numpy is not available"
            );
            continue;
        };
        same(&rust, &py, name);
        eprintln!("{name}: the Rust reader matches Python's pickle");
    }
}

#[test]
fn demo_annotation_gives_the_pickled_parameters() {
    let Some(dir) = demo_dir() else {
        eprintln!(
            "SKIPPED demo_annotation_gives_the_pickled_parameters: ../shared/data/interhand_demo is not beside this checkout"
        );
        return;
    };
    let path = dir.join("01.pkl");
    let raw = bitt_pickle::from_path(&path).unwrap();
    let scene = bitt_mesh::load_bitt_annotation(&path, (BITT_CROP_SIZE, BITT_CROP_SIZE)).unwrap();
    let arr = |keys: &[&str]| {
        let mut v = &raw;
        for k in keys {
            v = v.get(k).unwrap();
        }
        v.as_array().unwrap().to_f64()
    };
    let right = scene.right.as_ref().unwrap();
    let r = arr(&["mano_params", "right", "R"]);
    for i in 0..3 {
        for j in 0..3 {
            assert_eq!(right.root_rotation.col(j)[i], r[i * 3 + j]);
        }
    }
    assert_eq!(
        right.pose,
        HandPose::Pca(arr(&["mano_params", "right", "pose"]))
    );
    assert_eq!(right.betas, arr(&["mano_params", "right", "shape"]));
    assert_eq!(
        right.trans.to_array().to_vec(),
        arr(&["mano_params", "right", "trans"])
    );
    let k = arr(&["camera", "camera"]);
    assert_eq!(scene.camera.focal().x, k[0]);
    assert_eq!(scene.camera.principal_point().y, k[5]);
    assert_eq!(
        scene.camera.translation.to_array().to_vec(),
        arr(&["camera", "t"])
    );
    assert_eq!(scene.frame.camera.as_deref(), Some("400028"));
    // The procedural hands (no MANO here) posed with it land in front of the camera, inside
    // the crop's neighbourhood.
    let posed = scene.pose_in_camera(&bitt_mesh::procedural_pair()).unwrap();
    for hand in [posed.left.unwrap(), posed.right.unwrap()] {
        let b = scene.pixel_box(&hand.vertices).unwrap();
        let c = (b.min + b.max) / 2.0;
        assert!(
            c.x > -64.0 && c.x < 320.0 && c.y > -64.0 && c.y < 320.0,
            "hand centre {c} far outside the 256x256 crop"
        );
    }
}
