//! Fuzzes the torch checkpoint reader (`bitt convert-lpips` feeds it the user's `.pth`
//! files): zip archives and the legacy format must give a value or an error, never a panic,
//! a hang or a huge allocation; every tensor must be self-consistent.

#![no_main]

use bitt_pickle::{Value, torch_from_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match torch_from_bytes(data, "fuzz.pth") {
        Ok(v) => exercise(&v),
        Err(e) => {
            // Errors point inside the input (or just past its end) and name it.
            assert!(e.offset <= data.len(), "{e}");
            assert!(e.to_string().contains("fuzz.pth"), "{e}");
        }
    }
});

fn exercise(v: &Value) {
    let _ = (v.type_name(), v.as_f64(), v.as_i64(), v.as_str());
    match v {
        Value::Array(a) => {
            let n = a
                .shape
                .iter()
                .try_fold(1usize, |acc, &d| acc.checked_mul(d));
            assert_eq!(n, Some(a.len()), "shape {:?} vs {}", a.shape, a.len());
            assert_eq!(a.to_f64().len(), a.len());
            let _ = a.dtype();
        }
        Value::List(items) | Value::Tuple(items) | Value::Set(items) => {
            items.iter().for_each(exercise);
        }
        Value::Dict(items) => {
            for (k, x) in items {
                exercise(k);
                exercise(x);
            }
        }
        _ => {}
    }
}
