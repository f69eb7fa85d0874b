//! What a run is given, read and checked: the hand models and texture prior it names
//! (`prior.rs`: MANO or procedural hands, HTML or the procedural PCA), the photos and their
//! hands as prepared views (`view.rs`). Bringing an image of any size to the preset's square
//! size (crop around both hands, resize, camera adjusted) is `bitt_fit::photo`'s, re-exported
//! here.
//!
//! Architecture invariant: nothing here trains, refines or writes a run; the jobs above
//! (`real`, `fit`, `refine`) read their inputs through it.

mod prior;
mod view;

pub use prior::{
    HandSource, PriorSource, adapt_config_to_prior, attach_html_uvs, check_sources,
    left_uv_from_right, load_html_prior, load_models, sources, texture_model,
};
pub(crate) use view::check_photo_under_hands;
pub use view::{
    FittedView, HAND_DEPTH_RANGE_M, MIN_HAND_INSIDE, RealScene, RealView, annotation_view,
    check_hand_placement, fit_synthetic_view, interhand_views, prepare_view, read_image,
};

/// `p` made absolute (as given when that fails).
pub(crate) fn absolute(p: &std::path::Path) -> std::path::PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

pub use bitt_fit::photo::*;
