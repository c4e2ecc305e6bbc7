//! `edccif.encode_packet` / `edccif.decode_packet`: the core's wire format
//! (`edccif_core::wire`, docs/formats.md) from Python.

use edccif_core::wire::{self, Header, Kind, WireError};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::convert::{finite_array, to_numpy, Dim};
use crate::errors::{ParameterError, ShapeError, UnknownOptionError, WireFormatError};

fn kind_from_name(name: &str) -> PyResult<Kind> {
    [
        Kind::Measurement,
        Kind::Contribution,
        Kind::Estimate,
        Kind::Information,
    ]
    .into_iter()
    .find(|k| k.name() == name)
    .ok_or_else(|| {
        UnknownOptionError::new_err(format!(
            "kind: expected one of 'measurement', 'contribution', 'estimate', 'information', got {name:?}"
        ))
    })
}

fn wire_err(e: WireError) -> PyErr {
    WireFormatError::new_err(e.to_string())
}

/// A decoded packet (see `edccif.decode_packet`).
#[pyclass(name = "WirePacket", module = "edccif", frozen)]
pub struct PyWirePacket {
    /// "measurement", "contribution", "estimate" or "information".
    #[pyo3(get)]
    kind: &'static str,
    /// Swarm id.
    #[pyo3(get)]
    swarm: u32,
    /// Sender (node or sensor) id.
    #[pyo3(get)]
    sender: u16,
    /// Step the payload belongs to.
    #[pyo3(get)]
    step: u64,
    /// Consensus iteration within the step (0 otherwise).
    #[pyo3(get)]
    round: u8,
    /// Timestamp in nanoseconds.
    #[pyo3(get)]
    stamp_ns: u64,
    /// Packet length in bytes.
    #[pyo3(get)]
    nbytes: usize,
    /// The vector (d,).
    #[pyo3(get)]
    vector: Py<PyArrayDyn<f64>>,
    /// The symmetric matrix (d, d), or None for a measurement.
    #[pyo3(get)]
    matrix: Option<Py<PyArrayDyn<f64>>>,
}

#[pymethods]
impl PyWirePacket {
    fn __repr__(&self) -> String {
        format!(
            "WirePacket(kind={:?}, swarm={}, sender={}, step={}, round={}, stamp_ns={}, nbytes={})",
            self.kind, self.swarm, self.sender, self.step, self.round, self.stamp_ns, self.nbytes
        )
    }
}

/// Encodes one packet of the wire format (docs/formats.md) and returns its bytes.
/// `key` (bytes, at least 16): append the packet's authentication tag
/// (HMAC-SHA256 under `key`, truncated to 16 bytes).
#[pyfunction]
#[pyo3(signature = (kind, vector, matrix = None, *, swarm = 0, sender = 0, step = 0, round = 0, stamp_ns = 0, key = None))]
#[allow(clippy::too_many_arguments)]
pub fn encode_packet<'py>(
    py: Python<'py>,
    kind: &str,
    vector: &Bound<'py, PyAny>,
    matrix: Option<&Bound<'py, PyAny>>,
    swarm: i64,
    sender: i64,
    step: i64,
    round: i64,
    stamp_ns: i64,
    key: Option<&[u8]>,
) -> PyResult<Bound<'py, PyBytes>> {
    let kind = kind_from_name(kind)?;
    let range = |name: &str, v: i64, max: u64| -> PyResult<u64> {
        u64::try_from(v)
            .ok()
            .filter(|u| *u <= max)
            .ok_or_else(|| ParameterError::new_err(format!("{name}: expected 0..={max}, got {v}")))
    };
    let header = Header {
        swarm: range("swarm", swarm, u64::from(u32::MAX))? as u32,
        sender: range("sender", sender, u64::from(u16::MAX))? as u16,
        step: range("step", step, i64::MAX as u64)?,
        round: range("round", round, u64::from(u8::MAX))? as u8,
        stamp_ns: range("stamp_ns", stamp_ns, i64::MAX as u64)?,
    };
    let (v, _) = finite_array(vector, "vector", &[Dim::Any("d")])?;
    let d = v.len();
    if d > wire::MAX_DIM {
        return Err(ShapeError::new_err(format!(
            "vector: expected at most {} values, got {d}",
            wire::MAX_DIM
        )));
    }
    let m = match (kind.has_matrix(), matrix) {
        (true, Some(m)) => Some(finite_array(m, "matrix", &[Dim::Is(d), Dim::Is(d)])?.0),
        (true, None) => {
            return Err(ShapeError::new_err(format!(
                "matrix: a {} packet needs a ({d}, {d}) matrix, got None",
                kind.name()
            )))
        }
        (false, Some(_)) => {
            return Err(ShapeError::new_err(
                "matrix: a measurement packet has no matrix, expected None",
            ))
        }
        (false, None) => None,
    };
    let mut buf = vec![0u8; wire::packet_len(kind, d) + wire::TAG_LEN];
    let mut n = wire::encode(kind, &header, &v, m.as_deref(), &mut buf).map_err(wire_err)?;
    if let Some(key) = key {
        n = wire::sign(key, &mut buf, n).map_err(wire_err)?;
    }
    Ok(PyBytes::new(py, &buf[..n]))
}

/// Decodes and validates one packet of the wire format (docs/formats.md). With
/// `key`, the packet must carry a valid authentication tag under it
/// (`WireFormatError` "without an authentication tag" or "does not verify").
#[pyfunction]
#[pyo3(signature = (data, *, key = None))]
pub fn decode_packet(py: Python<'_>, data: &[u8], key: Option<&[u8]>) -> PyResult<PyWirePacket> {
    let f = match key {
        Some(key) => wire::decode_signed(data, key),
        None => wire::decode(data),
    }
    .map_err(wire_err)?;
    let d = f.dim;
    let vector = to_numpy(py, (0..d).map(|i| f.value(i)).collect(), &[d])?.unbind();
    let matrix = if f.kind.has_matrix() {
        let m = (0..d * d).map(|t| f.matrix_entry(t / d, t % d)).collect();
        Some(to_numpy(py, m, &[d, d])?.unbind())
    } else {
        None
    };
    Ok(PyWirePacket {
        kind: f.kind.name(),
        swarm: f.header.swarm,
        sender: f.header.sender,
        step: f.header.step,
        round: f.header.round,
        stamp_ns: f.header.stamp_ns,
        nbytes: data.len(),
        vector,
        matrix,
    })
}
