//! Python bindings of edccif (`edccif._edccif`): conversion in [`convert`], error
//! mapping in [`errors`], thin classes over `edccif-sim` and `edccif-core`.

use pyo3::prelude::*;

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

/// The extension module.
#[pymodule]
fn _edccif(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<scenario::PyScenario>()?;
    m.add_class::<runner::PyRunResult>()?;
    m.add_class::<network::PyNetwork>()?;
    m.add_class::<network::PyModelNetwork>()?;
    m.add_class::<mc::PyMcResult>()?;
    m.add_class::<node::PyNode>()?;
    m.add_class::<node::PySensorTrigger>()?;
    m.add_function(wrap_pyfunction!(runner::run, m)?)?;
    m.add_function(wrap_pyfunction!(mc::monte_carlo, m)?)?;
    m.add_function(wrap_pyfunction!(mc::algorithms, m)?)?;
    m.add_function(wrap_pyfunction!(mc::triggers, m)?)?;
    m.add_function(wrap_pyfunction!(mc::algorithm_name, m)?)?;
    m.add_function(wrap_pyfunction!(mc::trigger_name, m)?)?;
    m.add_function(wrap_pyfunction!(mc::reproduce, m)?)?;
    m.add_function(wrap_pyfunction!(mc::set_worker_threads, m)?)?;
    m.add_function(wrap_pyfunction!(mc::worker_threads, m)?)?;
    m.add_function(wrap_pyfunction!(fuse::ci_fuse, m)?)?;
    m.add_function(wrap_pyfunction!(fuse::fuse, m)?)?;
    m.add_function(wrap_pyfunction!(fuse::fusion_rules, m)?)?;
    m.add_function(wrap_pyfunction!(reliability::reliability_report, m)?)?;
    m.add_function(wrap_pyfunction!(logio::record, m)?)?;
    m.add_function(wrap_pyfunction!(logio::replay, m)?)?;
    m.add_function(wrap_pyfunction!(logio::read_mcap_measurements, m)?)?;
    m.add_function(wrap_pyfunction!(logio::read_ros2, m)?)?;
    m.add_function(wrap_pyfunction!(logio::write_mcap, m)?)?;
    m.add_function(wrap_pyfunction!(logio::read_tum, m)?)?;
    m.add_function(wrap_pyfunction!(logio::write_tum, m)?)?;
    m.add_function(wrap_pyfunction!(logio::preprocess, m)?)?;
    m.add_class::<wire::PyWirePacket>()?;
    m.add_function(wrap_pyfunction!(wire::encode_packet, m)?)?;
    m.add_function(wrap_pyfunction!(wire::decode_packet, m)?)?;
    models::register(m)?;
    filters::register(m)?;
    errors::register(m)?;
    refs::register();
    Ok(())
}
