//! The keypoint fit's jobs: `bitt fit-hands` (a photo and its keypoints, or the built-in
//! detector's, to both hands and an output folder) and the fit's evaluation on synthetic
//! scenes. The fit itself is `bitt_fit::fit`, re-exported here.

mod eval;
mod jobs;

pub use bitt_fit::fit::*;
pub use eval::{
    FitScores, SceneFitResult, SyntheticFitSettings, SyntheticKeypoints, fit_eval_line,
    fit_eval_summary, fit_synthetic_scene, fit_synthetic_scenes, record_synthetic_fit, score_fit,
    synthetic_keypoints, write_fit_eval,
};
pub use jobs::{
    FIT_JSON, FitOutput, KeypointSource, PhotoFit, PhotoKeypoints, UNMIRRORED_IMAGE, check_fit_out,
    fit_photo, keypoint_overlay, parse_intrinsics, write_fit_outputs,
};
