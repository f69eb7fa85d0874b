//! The error type of the reader.

/// Why a pickle could not be read, with the file and the byte offset where it happened.
///
/// Displays as `"<source>: byte <offset>: <message>"`. The offset is the position of the
/// opcode being interpreted when the problem was found (for problems found while turning
/// the finished object graph into [`Value`](crate::Value)s, the opcode that created or last
/// built the object concerned); it is 0 for IO errors.
#[derive(Debug, thiserror::Error)]
#[error("{source_name}: byte {offset}: {kind}")]
pub struct PickleError {
    /// What was being read: a path, or the name passed to [`from_bytes`](crate::from_bytes).
    pub source_name: String,
    /// Byte offset of the opcode at fault (0 for IO errors).
    pub offset: usize,
    /// What went wrong.
    pub kind: PickleErrorKind,
}

impl PickleError {
    /// Builds an error.
    pub fn new(source_name: impl Into<String>, offset: usize, kind: PickleErrorKind) -> Self {
        Self {
            source_name: source_name.into(),
            offset,
            kind,
        }
    }
}

/// The kinds of [`PickleError`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PickleErrorKind {
    /// The file could not be read.
    #[error("could not be read: {0}")]
    Io(std::io::Error),
    /// The input ended before the pickle was complete (no STOP opcode, or an opcode's
    /// argument runs past the end).
    #[error("pickle data is truncated")]
    Truncated,
    /// An opcode this reader does not interpret (or that does not exist).
    #[error("unknown or unsupported opcode 0x{0:02x}")]
    UnknownOpcode(u8),
    /// A global (class or function) outside the fixed set this reader knows.
    #[error(
        "global '{module}.{name}' is not allowed (only numpy arrays, scipy csc_matrix and \
         chumpy Ch/Select objects are understood; nothing is ever executed)"
    )]
    UnsupportedGlobal {
        /// Module part of the global.
        module: String,
        /// Name part of the global.
        name: String,
    },
    /// An opcode needed more stack items (or a mark) than there were.
    #[error("stack underflow (malformed pickle)")]
    StackUnderflow,
    /// An opcode or a known global got an argument of the wrong type or value.
    #[error("{0}")]
    BadArgument(String),
    /// Sizes that must agree do not (array shape vs. raw data, sparse matrix arrays, ...).
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
    /// A declared size, a nesting depth or a resource limit of the reader is exceeded.
    #[error("too large: {0}")]
    TooLarge(String),
    /// A PROTO opcode names a protocol newer than 5.
    #[error("unsupported pickle protocol {0} (this reader knows protocols 0 to 5)")]
    UnsupportedProtocol(u8),
}
