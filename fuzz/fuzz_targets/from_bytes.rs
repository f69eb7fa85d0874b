//! Fuzzes the pickle reader: any input must give a value or an error, never a panic, an
//! overflow, a hang or a huge allocation; and every value must be self-consistent.

#![no_main]

use bitt_pickle::{Value, from_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match from_bytes(data, "fuzz") {
        Ok(v) => exercise(&v),
        Err(e) => {
            // Errors point inside the input (or just past its end).
            assert!(e.offset <= data.len(), "{e}");
            let _ = e.to_string();
        }
    }
});

fn exercise(v: &Value) {
    let _ = (
        v.type_name(),
        v.as_f64(),
        v.as_i64(),
        v.as_str(),
        v.as_list(),
    );
    for key in ["v_template", "x", "", "\u{e9}"] {
        let _ = v.get(key);
    }
    match v {
        Value::Array(a) => {
            let n = a
                .shape
                .iter()
                .try_fold(1usize, |acc, &d| acc.checked_mul(d));
            assert_eq!(
                n,
                Some(a.len()),
                "shape {:?} vs {} elements",
                a.shape,
                a.len()
            );
            assert_eq!(a.to_f64().len(), a.len());
            assert_eq!(a.to_i64().len(), a.len());
            let _ = a.dtype();
        }
        // The reader validated the structure, so a small matrix must densify.
        Value::Sparse(m) if m.shape.0.saturating_mul(m.shape.1) <= 1 << 16 => {
            let dense = m.to_dense_row_major();
            assert!(dense.is_ok(), "{dense:?}");
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
