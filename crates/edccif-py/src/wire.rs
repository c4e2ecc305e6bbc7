//! `edccif.encode_packet` / `edccif.decode_packet`: the core's wire format
//! (`edccif_core::wire`, docs/formats.md) from Python.

use edccif_core::wire::{self, Header, Kind, WireError};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::convert::{finite_array, to_numpy, Dim};
use crate::errors::{ShapeError, UnknownOptionError, WireFormatError};

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

/// The header fields of `encode_packet`, each an integer over its wire range
/// (`ParameterError` naming the field otherwise).
mod header_field {
    use pyo3::prelude::*;

    fn range(v: &Bound<'_, PyAny>, name: &str, max: u64) -> PyResult<u64> {
        crate::args::int_in(
            v,
            name,
            0,
            i128::from(max),
            &format!("an integer in 0..={max}"),
        )
        .map(|x| x as u64)
    }
    pub fn swarm(v: &Bound<'_, PyAny>) -> PyResult<u64> {
        range(v, "swarm", u64::from(u32::MAX))
    }
    pub fn sender(v: &Bound<'_, PyAny>) -> PyResult<u64> {
        range(v, "sender", u64::from(u16::MAX))
    }
    pub fn step(v: &Bound<'_, PyAny>) -> PyResult<u64> {
        range(v, "step", u64::MAX)
    }
    pub fn round(v: &Bound<'_, PyAny>) -> PyResult<u64> {
        range(v, "round", u64::from(u8::MAX))
    }
    pub fn stamp_ns(v: &Bound<'_, PyAny>) -> PyResult<u64> {
        range(v, "stamp_ns", u64::MAX)
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
    #[pyo3(from_py_with = crate::args::text_arg::kind)] kind: String,
    vector: &Bound<'py, PyAny>,
    matrix: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = header_field::swarm)] swarm: u64,
    #[pyo3(from_py_with = header_field::sender)] sender: u64,
    #[pyo3(from_py_with = header_field::step)] step: u64,
    #[pyo3(from_py_with = header_field::round)] round: u64,
    #[pyo3(from_py_with = header_field::stamp_ns)] stamp_ns: u64,
    #[pyo3(from_py_with = opt_key)] key: Option<Vec<u8>>,
) -> PyResult<Bound<'py, PyBytes>> {
    let kind = kind_from_name(&kind)?;
    // Each field was checked over its whole wire range (what decode_packet returns).
    let header = Header {
        swarm: swarm as u32,
        sender: sender as u16,
        step,
        round: round as u8,
        stamp_ns,
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
        (true, Some(m)) => {
            let v = finite_array(m, "matrix", &[Dim::Is(d), Dim::Is(d)])?.0;
            // Only the upper triangle is sent: a non-symmetric matrix would
            // arrive as another one.
            let scale = v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let tol = 1e-12 * scale;
            for i in 0..d {
                for j in (i + 1)..d {
                    let (a, b) = (v[i * d + j], v[j * d + i]);
                    if (a - b).abs() > tol {
                        return Err(crate::errors::NotPositiveDefiniteError::new_err(format!(
                            "matrix: expected a symmetric matrix (the wire format sends its upper triangle), but matrix[{i}, {j}] = {a} and matrix[{j}, {i}] = {b} differ"
                        )));
                    }
                }
            }
            Some(v)
        }
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
    if let Some(key) = key.as_deref() {
        n = wire::sign(key, &mut buf, n).map_err(wire_err)?;
    }
    Ok(PyBytes::new(py, &buf[..n]))
}

/// `data` of `decode_packet`: `bytes` or `bytearray` (`ArgumentTypeError`
/// otherwise).
fn packet_bytes(o: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    if let Ok(b) = o.downcast::<PyBytes>() {
        return Ok(b.as_bytes().to_vec());
    }
    if let Ok(b) = o.downcast::<pyo3::types::PyByteArray>() {
        return Ok(b.to_vec());
    }
    Err(crate::errors::argument_type_error(
        o.py(),
        format!(
            "data: expected the packet's bytes (bytes or bytearray), got {}",
            o.get_type()
                .name()
                .map_or_else(|_| "?".into(), |n| n.to_string())
        ),
    ))
}

/// `key` of `encode_packet`/`decode_packet`: `None`, `bytes` or `bytearray`
/// (`ArgumentTypeError` otherwise; its length is checked by the wire format).
fn opt_key(o: &Bound<'_, PyAny>) -> PyResult<Option<Vec<u8>>> {
    if o.is_none() {
        return Ok(None);
    }
    if let Ok(b) = o.downcast::<PyBytes>() {
        return Ok(Some(b.as_bytes().to_vec()));
    }
    if let Ok(b) = o.downcast::<pyo3::types::PyByteArray>() {
        return Ok(Some(b.to_vec()));
    }
    Err(crate::errors::argument_type_error(
        o.py(),
        format!(
            "key: expected the swarm key's bytes (bytes or bytearray), got {}",
            o.get_type()
                .name()
                .map_or_else(|_| "?".into(), |n| n.to_string())
        ),
    ))
}

/// Decodes and validates one packet of the wire format (docs/formats.md). With
/// `key`, the packet must carry a valid authentication tag under it
/// (`WireFormatError` "without an authentication tag" or "does not verify").
#[pyfunction]
#[pyo3(signature = (data, *, key = None))]
pub fn decode_packet(
    py: Python<'_>,
    #[pyo3(from_py_with = packet_bytes)] data: Vec<u8>,
    #[pyo3(from_py_with = opt_key)] key: Option<Vec<u8>>,
) -> PyResult<PyWirePacket> {
    let data = data.as_slice();
    let f = match key.as_deref() {
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
