//! Fuzzes the reader of the project's MANO safetensors (`MANO_{LEFT,RIGHT}.safetensors`
//! written by `bitt convert-mano`): any input gives a valid model or an error naming the
//! file, never a panic. A model that loads must pose, and write back to the same model.

#![no_main]

use std::path::Path;

use bitt_mesh::HandParams;
use bitt_mesh::mano::{from_safetensors, to_safetensors};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.safetensors");
    match from_safetensors(data, path) {
        Ok(model) => {
            model.validate().expect("a loaded model is valid");
            let posed = model.forward(&HandParams::mean_pose());
            assert!(posed.is_ok(), "{posed:?}");
            let bytes = to_safetensors(&model).expect("a loaded model writes");
            let back = from_safetensors(&bytes, path).expect("a written model reads");
            assert_eq!(back, model);
        }
        Err(e) => assert!(e.to_string().contains("fuzz.safetensors"), "{e}"),
    }
});
