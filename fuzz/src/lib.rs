//! Helpers and harness bodies of the fuzz targets (see [`core_harness`]).

mod core_harness;
pub use core_harness::*;
