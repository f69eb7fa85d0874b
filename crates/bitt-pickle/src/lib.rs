//! A safe reader for the Python pickles of MANO, HTML and BiTT annotation files.
//!
//! A pickle is a program for a small stack machine. This crate interprets a fixed set of
//! opcodes (protocols 0 to 5, without persistent ids, extension codes or out-of-band
//! buffers) and a fixed set of globals, and never executes anything:
//!
//! - numpy arrays (`numpy.core.multiarray._reconstruct` / `numpy._core...`, `numpy.ndarray`,
//!   `numpy.dtype`, the protocol-5 `numpy.core.numeric._frombuffer`) and numpy scalars
//!   (`numpy.core.multiarray.scalar`), with dtypes `f4 f8 i4 i8 u4 u1 b1`, either byte
//!   order, C or Fortran order;
//! - scipy `csc_matrix` (`scipy.sparse.csc` or `scipy.sparse._csc`);
//! - chumpy `Ch` and `Select` (`chumpy.ch.Ch`, `chumpy.reordering.Select`), resolved to the
//!   arrays they evaluate to;
//! - `set` / `frozenset`, `object` and `copyreg._reconstructor` (Python 2 and 3 names) to
//!   build the above, and `_codecs.encode(str, 'latin1')`, `bytes()` and `bytearray(...)`,
//!   which is how Python 3 writes bytes in protocols below 3 (latin-1 only).
//!
//! Torch checkpoints (`torch.save` files, zip or legacy format) are read by [`load_torch`],
//! which adds persistent storage ids and the few torch globals that rebuild tensors (see
//! its module docs); [`from_bytes`] and [`from_path`] refuse those.
//!
//! Any other global is refused with [`PickleErrorKind::UnsupportedGlobal`]. Sizes read from
//! the input are checked against the input length before anything is allocated, the
//! stack, memo and object count are capped, nesting is limited to [`MAX_DEPTH`] levels,
//! and shared references may expand the input only by a bounded factor. Every error names
//! the source and the byte offset of the opcode at fault.
//!
//! Modules, lowest first: `error`, `value`, `numpy`, `storage` (torch typed storages),
//! `machine` (the opcode interpreter), `convert` (the machine's objects to [`Value`]s),
//! `torch` (checkpoints); each imports only modules before it. The readers are fuzzed
//! (`fuzz/`, `cargo xtask fuzz`): no input may make them panic.
//!
//! Values come out as plain data ([`Value`]): Python 2 `str` is decoded as latin-1, numpy
//! arrays are always in C order (Fortran-ordered data is transposed on reading), numpy
//! scalars are 0-d arrays, and chumpy objects are evaluated (`Ch` to its `x`, `Select` to
//! `a.flat[idxs].reshape(preferred_shape)`).
//!
//! ```
//! // {'a': 1} in protocol 2
//! let v = bitt_pickle::from_bytes(b"\x80\x02}q\x00U\x01aK\x01s.", "example").unwrap();
//! assert_eq!(v.get("a").and_then(|x| x.as_i64()), Some(1));
//! ```

#![warn(missing_docs)]

mod convert;
mod error;
mod machine;
mod numpy;
mod storage;
mod torch;
mod value;

#[cfg(test)]
mod tests;

pub use convert::MAX_DEPTH;
pub use error::{PickleError, PickleErrorKind};
pub use torch::{load_torch, torch_from_bytes};
pub use value::{ArrayData, CscMatrix, MAX_DENSE_ELEMENTS, NdArray, Value};

/// Reads a pickle from memory. `source` names it in error messages (usually a path).
pub fn from_bytes(bytes: &[u8], source: &str) -> Result<Value, PickleError> {
    let mut m = machine::Machine::new(bytes);
    let root = m
        .run()
        .map_err(|(offset, kind)| PickleError::new(source, offset, kind))?;
    // Each value or array element produced costs one unit: a well-formed pickle needs at
    // most about one per input byte; sharing may multiply that by a small factor.
    let budget = bytes.len().saturating_mul(4).saturating_add(1 << 18);
    convert::Converter::new(&m, budget)
        .value(root, 0)
        .map_err(|(offset, kind)| PickleError::new(source, offset, kind))
}

/// Reads a pickle file. Errors name the path; an unreadable file gives
/// [`PickleErrorKind::Io`] at offset 0.
pub fn from_path(path: &std::path::Path) -> Result<Value, PickleError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path)
        .map_err(|e| PickleError::new(name.clone(), 0, PickleErrorKind::Io(e)))?;
    from_bytes(&bytes, &name)
}
