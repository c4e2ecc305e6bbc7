//! Python bindings of edccif (`edccif._edccif`): conversion in [`convert`], error
//! mapping in [`errors`], thin classes over `edccif-sim` and `edccif-core`.

pub mod adapters;
pub mod args;
pub mod class_args;
pub mod convert;
pub mod dims;
pub mod drive;
pub mod errors;
pub mod filters;
pub mod fuse;
pub mod logio;
pub mod mc;
pub mod model_net;
pub mod models;
pub mod network;
pub mod node;
pub mod refs;
pub mod reliability;
pub mod runner;
pub mod scenario;
pub mod wire;

/// The extension module: every name `edccif._edccif` exports, in one list.
///
/// Classes, functions and exception types are exported by `#[pymodule_export]`;
/// the initialiser adds what is built at import time (the version string, the
/// `ArgumentTypeError` type with two bases) and registers the resolver of
/// Python models named by reference.
#[pyo3::pymodule]
mod _edccif {
    use pyo3::prelude::*;

    // Scenarios, runs, networks and Monte Carlo.
    #[pymodule_export]
    use crate::mc::{
        algorithm_name, algorithms, monte_carlo, reproduce, set_worker_threads, trigger_name,
        triggers, worker_threads, PyMcResult,
    };
    #[pymodule_export]
    use crate::network::{PyModelNetwork, PyNetwork};
    #[pymodule_export]
    use crate::reliability::reliability_report;
    #[pymodule_export]
    use crate::runner::{run, PyRunResult};
    #[pymodule_export]
    use crate::scenario::PyScenario;

    // One node, one sensor's trigger, fusion of estimates.
    #[pymodule_export]
    use crate::fuse::{ci_fuse, fuse, fusion_rules};
    #[pymodule_export]
    use crate::node::{PyNode, PySensorTrigger};

    // Recordings and the wire format.
    #[pymodule_export]
    use crate::logio::{
        preprocess, read_mcap_measurements, read_ros2, read_tum, record, replay, write_mcap,
        write_tum,
    };
    #[pymodule_export]
    use crate::wire::{decode_packet, encode_packet, PyWirePacket};

    // Models.
    #[pymodule_export]
    use crate::models::{
        PyBearingOnly, PyConstantAcceleration, PyConstantVelocity, PyCoordinatedTurn,
        PyCoordinatedTurn2D, PyCustomMeasurement, PyCustomMotion, PyLinearMeasurement,
        PyLinearMotion, PyMeasurementModel, PyMotionModel, PyPosition, PyRandomWalk,
        PyRangeBearing, PyRangeOnly, PyRangePitchAzimuth,
    };

    // Single filters.
    #[pymodule_export]
    use crate::filters::{PyCif, PyCkf, PyEkf, PyEtCif, PySingleFilter, PyUkf};

    // Errors.
    #[pymodule_export]
    use crate::errors::{
        EdccifError, GraphError, ModelError, NonFiniteError, NotPositiveDefiniteError,
        ParameterError, ScenarioError, ShapeError, SizeError, UnknownAlgorithmError,
        UnknownOptionError, WireFormatError,
    };

    #[pymodule_init]
    fn init(m: &Bound<'_, PyModule>) -> PyResult<()> {
        m.add("__version__", env!("CARGO_PKG_VERSION"))?;
        m.add(
            "ArgumentTypeError",
            crate::errors::argument_type_error_type(m.py())?,
        )?;
        crate::refs::register();
        Ok(())
    }
}
