//! The crate's integration tests, one module per subject, in one test binary
//! (one link and one copy of the generic code instead of one per file).

mod clocks;
mod logio;
mod mcap;
mod ros2;
