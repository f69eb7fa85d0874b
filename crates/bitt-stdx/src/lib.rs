//! What every BiTT crate shares, and nothing else (rust-analyzer's `stdx` is the model):
//!
//! - [`FileError`]: the file error every crate's error wraps (`File(#[from] FileError)`), so a
//!   path and its problem read the same whichever crate reports them; [`FileErrorExt`] gives
//!   its constructors to those errors; [`Context`] ([`WithContext::context_with`]) says what
//!   was being done when an error happened.
//! - [`write`]: atomic writes of a file, of several files together and of a whole folder, and
//!   the refusal to replace what is not ours.
//! - [`st`]: the one checked safetensors reader and writer (shapes, finite values,
//!   checksums).
//! - `host` (feature `burn`): a tensor's values back on the host, `to_host`.
//!
//! Architecture invariant: this crate knows nothing of hands, images, networks or runs. It
//! depends on no crate of the workspace, and on burn only with its `burn` feature (so
//! `bitt-mesh` and the fuzz targets build without burn); every crate may depend on it.
//!
//! Architecture invariant: every file a library crate writes goes through [`write`], and
//! every safetensors file it writes or reads back through [`st`], so no file is left
//! half-written or trusted after it was altered.

mod error;
#[cfg(feature = "burn")]
pub mod host;
pub mod st;
pub mod write;

pub use error::{Context, FileError, FileErrorExt, WithContext};
#[cfg(feature = "burn")]
pub use host::{ReadBackError, to_host};
pub use write::{
    check_replaceable, remove_stale_temporaries, write_all_or_none, write_atomically,
    write_folder_atomically,
};
