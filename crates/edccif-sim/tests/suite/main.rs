//! The crate's integration tests, one module per subject, in one test binary
//! (one link and one copy of the generic code instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod clocks;
mod closed_form;
mod control;
mod default_path;
mod fast_trig;
mod fault_mask;
mod faults;
mod flights;
mod fusion_rules;
mod layout;
mod mixed;
mod neighbour_lists;
mod parallel;
mod recording;
mod replay;
mod runner;
mod runner_parallel;
mod scenario_files;
mod thresholds;
mod time;
mod triggers;
