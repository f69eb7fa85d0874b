//! Fuzzes the reader of the project's MANO safetensors (`MANO_{LEFT,RIGHT}.safetensors`
//! written by `bitt convert-mano`): any input gives a valid model or an error naming the
//! file, never a panic. A model that loads must pose, and write back to the same model.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::mano_safetensors(data);
});
