//! The one error type of this crate.

use std::path::PathBuf;

use bitt_stdx::FileError;

/// Everything that can go wrong when loading the detector or detecting hands.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    /// A weights or model file that cannot be read or does not hold what it should.
    #[error(transparent)]
    File(#[from] FileError),
    /// A TFLite model that uses something this crate does not implement, or is malformed.
    #[error("{path}: {detail}")]
    Model {
        /// The model file (or the name of the built-in weights).
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// An image the detector cannot work on (empty, too small, not finite).
    #[error("{image}: {detail}")]
    Image {
        /// The photo.
        image: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// No hand in the photo.
    #[error(
        "{image}: no hand found (the best candidate's hand presence was {best_presence:.2}); use a photo in which both hands are visible and not cut by the border, or give their keypoints with --keypoints"
    )]
    NoHand {
        /// The photo.
        image: PathBuf,
        /// The highest hand presence any candidate reached.
        best_presence: f64,
    },
    /// Only one of the two hands was found.
    #[error(
        "{image}: only the {found} hand was found (presence {presence:.2}), not the {missing} hand; BiTT needs both hands: give both hands' keypoints with --keypoints, or use a photo in which both hands are visible"
    )]
    OneHand {
        /// The photo.
        image: PathBuf,
        /// `left` or `right`: the hand that was found.
        found: &'static str,
        /// The other one.
        missing: &'static str,
        /// The found hand's presence score.
        presence: f64,
    },
    /// A tensor that could not be read back from the device.
    #[error(transparent)]
    Readback(#[from] bitt_stdx::ReadBackError),
}

impl DetectError {
    /// A [`DetectError::Model`] for `path`.
    pub(crate) fn model(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        DetectError::Model {
            path: path.into(),
            detail: detail.into(),
        }
    }
}
