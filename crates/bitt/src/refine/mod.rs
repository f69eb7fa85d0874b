//! The refinement's jobs: a scene's or a photo's hands refined and the output folder of
//! `bitt refine-hands`. The refinement itself is `bitt_fit::refine`, re-exported here.

mod jobs;

pub use bitt_fit::refine::*;
pub use jobs::{
    HANDS_JSON, PhotoRefinement, SceneRefinement, check_refine_out, read_mask, refine_photo,
    refine_photo_hands, refine_scene, write_refine_outputs,
};
