//! The networks against the genuine TFLite interpreter on fixed inputs (every backend), and
//! the search on the real demo frames and transformed copies of them.

mod demo_frames;
mod reference;
mod reference_values;
