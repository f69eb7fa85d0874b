//! The one error type of this crate.

/// Everything that can go wrong when configuring or feeding the networks.
#[derive(Debug, thiserror::Error)]
pub enum NetsError {
    /// A preset name that is not `paper`, `quick` or `tiny`.
    #[error("unknown preset `{0}`; expected paper, quick or tiny")]
    UnknownPreset(String),
    /// A configuration or an input that does not fit (sizes, channel counts, shapes).
    #[error("{0}")]
    Invalid(String),
}
