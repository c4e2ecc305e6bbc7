//! Scalar arguments checked before conversion: an integer out of range or of
//! the wrong type raises an `EdccifError` naming the argument and what was
//! expected (`ParameterError`, or `ArgumentTypeError` for a wrong type)
//! instead of PyO3's `OverflowError`/`TypeError`.

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyComplex, PyFloat, PyString};

use crate::errors::{argument_type_error, ParameterError};

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
}

/// An integer argument (a Python `int` or anything with `__index__`, not a
/// `bool`) in `lo..=hi`; `expected` describes the range for the message
/// (e.g. `"an integer >= 1"`).
pub fn int_in(
    obj: &Bound<'_, PyAny>,
    name: &str,
    lo: i128,
    hi: i128,
    expected: &str,
) -> PyResult<i128> {
    let py = obj.py();
    let wrong_type = || {
        argument_type_error(
            py,
            format!("{name}: expected {expected}, got {}", type_name(obj)),
        )
    };
    if obj.is_instance_of::<PyBool>()
        || obj.is_instance_of::<PyFloat>()
        || obj.is_instance_of::<PyString>()
        || obj.is_instance_of::<PyComplex>()
    {
        return Err(wrong_type());
    }
    let index = obj.call_method0("__index__").map_err(|_| wrong_type())?;
    let out_of_range = || {
        let shown = index
            .repr()
            .map(|r| r.to_string())
            .unwrap_or_else(|_| "?".into());
        let shown = if shown.len() > 40 {
            format!("an integer of {} digits", shown.len())
        } else {
            shown
        };
        ParameterError::new_err(format!("{name}: expected {expected}, got {shown}"))
    };
    match index.extract::<i128>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        _ => Err(out_of_range()),
    }
}

/// A count `>= min` that fits in `usize`.
pub fn count(obj: &Bound<'_, PyAny>, name: &str, min: usize) -> PyResult<usize> {
    let expected = format!("an integer >= {min}");
    int_in(obj, name, min as i128, usize::MAX as i128, &expected).map(|v| v as usize)
}

/// A `u64` (seeds, steps, stamps): `0..=2**64 - 1`.
pub fn u64_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<u64> {
    int_in(
        obj,
        name,
        0,
        u64::MAX as i128,
        "an integer in 0..=18446744073709551615 (an unsigned 64-bit integer)",
    )
    .map(|v| v as u64)
}

/// An index into `0..len`.
pub fn index(obj: &Bound<'_, PyAny>, name: &str, len: usize) -> PyResult<usize> {
    let expected = format!("a node index in 0..{len}");
    let v = int_in(obj, name, i128::MIN, i128::MAX, &expected)?;
    if (0..len as i128).contains(&v) {
        Ok(v as usize)
    } else {
        Err(ParameterError::new_err(format!(
            "{name}: node index {v} is out of range; expected {expected}"
        )))
    }
}

/// A real number (an `int`, a `float` or anything with `__float__`; not a
/// `bool`, a `str` or a `complex`), not yet checked for finiteness.
pub fn real(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    let py = obj.py();
    let wrong = || {
        argument_type_error(
            py,
            format!("{name}: expected a real number, got {}", type_name(obj)),
        )
    };
    if obj.is_instance_of::<PyBool>()
        || obj.is_instance_of::<PyString>()
        || obj.is_instance_of::<PyComplex>()
    {
        return Err(wrong());
    }
    obj.extract::<f64>().map_err(|_| wrong())
}

/// A finite real number `> 0` (thresholds, rates, time steps).
pub fn positive(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    let v = real(obj, name)?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(ParameterError::new_err(format!(
            "{name}: expected a finite number > 0, got {v}"
        )))
    }
}

/// A string argument (`ArgumentTypeError` otherwise).
pub fn string(obj: &Bound<'_, PyAny>, name: &str, expected: &str) -> PyResult<String> {
    obj.extract::<String>().map_err(|_| {
        argument_type_error(
            obj.py(),
            format!("{name}: expected {expected}, got {}", type_name(obj)),
        )
    })
}

/// `True` or `False` (`ArgumentTypeError` otherwise).
pub fn boolean(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<bool> {
    if obj.is_instance_of::<PyBool>() {
        obj.extract()
    } else {
        Err(argument_type_error(
            obj.py(),
            format!("{name}: expected True or False, got {}", type_name(obj)),
        ))
    }
}

/// A list of integers `>= min` (e.g. node counts).
pub fn counts(obj: &Bound<'_, PyAny>, name: &str, min: usize) -> PyResult<Vec<usize>> {
    if obj.is_instance_of::<PyString>() {
        return Err(argument_type_error(
            obj.py(),
            format!("{name}: expected a list of integers >= {min}, got str"),
        ));
    }
    let items = obj.try_iter().map_err(|_| {
        argument_type_error(
            obj.py(),
            format!(
                "{name}: expected a list of integers >= {min}, got {}",
                type_name(obj)
            ),
        )
    })?;
    items
        .enumerate()
        .map(|(i, it)| count(&it?, &format!("{name}[{i}]"), min))
        .collect()
}

/// A list of finite real numbers `> 0` (e.g. thresholds).
pub fn positives(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let items = obj.try_iter().map_err(|_| {
        argument_type_error(
            obj.py(),
            format!(
                "{name}: expected a list of finite numbers > 0, got {}",
                type_name(obj)
            ),
        )
    })?;
    items
        .enumerate()
        .map(|(i, it)| positive(&it?, &format!("{name}[{i}]")))
        .collect()
}

/// `from_py_with` converters of the common arguments: each names its argument.
pub mod named {
    use super::*;

    /// `runs`: an integer >= 1.
    pub fn runs(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "runs", 1)
    }
    /// `seed`: an unsigned 64-bit integer.
    pub fn seed(o: &Bound<'_, PyAny>) -> PyResult<u64> {
        u64_arg(o, "seed")
    }
    /// `nodes`: an integer >= 1.
    pub fn nodes(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "nodes", 1)
    }
    /// `nodes`: a list of integers >= 1.
    pub fn node_list(o: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
        counts(o, "nodes", 1)
    }
    /// `steps`: an integer >= 1.
    pub fn steps(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "steps", 1)
    }
    /// `n`: a state dimension (an integer >= 0; the model names the
    /// supported sizes).
    pub fn n(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "n", 0)
    }
    /// `m`: a measurement dimension (an integer >= 0; the model names the
    /// supported sizes).
    pub fn m(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "m", 0)
    }
    /// `dim`: a spatial dimension >= 1 (the model checks 1, 2 or 3).
    pub fn dim(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "dim", 1)
    }
    /// `angles`: a list of component indices >= 0.
    pub fn angles(o: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
        counts(o, "angles", 0)
    }
    /// `node`: an index >= 0 (the scenario checks it is one of its nodes).
    pub fn node(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "node", 0)
    }
    /// `t`: a step index >= 0.
    pub fn step(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "t", 0)
    }
    /// `i`: a node index >= 0 (the network checks it is one of its nodes).
    pub fn i(o: &Bound<'_, PyAny>) -> PyResult<usize> {
        count(o, "i", 0)
    }
}

/// `None` or a real number (see [`real`]).
pub fn opt_real(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<f64>> {
    if obj.is_none() {
        Ok(None)
    } else {
        real(obj, name).map(Some)
    }
}

/// A string (see [`string`]), named in its message.
pub fn text(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<String> {
    string(obj, name, "a string")
}

/// `None` or a string.
pub fn opt_text(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<String>> {
    if obj.is_none() {
        Ok(None)
    } else {
        text(obj, name).map(Some)
    }
}

/// An instance of the class `T` (e.g. a `Scenario` or a model), borrowed;
/// `ArgumentTypeError` naming `name` and the class otherwise.
pub fn instance<'py, T: pyo3::PyClass>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyRef<'py, T>> {
    obj.extract::<PyRef<'py, T>>().map_err(|_| {
        argument_type_error(
            obj.py(),
            format!(
                "{name}: expected an instance of {}.{}, got {}",
                <T as pyo3::type_object::PyTypeInfo>::MODULE.unwrap_or("edccif"),
                T::NAME,
                type_name(obj)
            ),
        )
    })
}

/// `from_py_with` converters, one per argument name, so that the message
/// names the argument (PyO3 names only its own `TypeError`s).
macro_rules! converters {
    ($module:ident, $ty:ty, $conv:path, $doc:literal; $($name:ident),* $(,)?) => {
        #[doc = $doc]
        pub mod $module {
            use pyo3::prelude::*;
            $(
                #[doc = concat!("`", stringify!($name), "`.")]
                pub fn $name(o: &Bound<'_, PyAny>) -> PyResult<$ty> {
                    $conv(o, stringify!($name))
                }
            )*
        }
    };
}

converters!(real_arg, f64, super::real, "Real-number arguments.";
    dt, t0, q, q1, q2, sigma_r, sigma_a, sigma_b, alpha, beta, kappa, sigma1, sigma2,
    offset_window, residual_factor);
converters!(opt_real_arg, Option<f64>, super::opt_real, "Optional real-number arguments.";
    dt, t, delta, gate, rate_hz, max_gap_s);
converters!(text_arg, String, super::text, "String arguments.";
    algorithm, trigger, kind, call, text, duplicates, noise, align, rule);
converters!(opt_text_arg, Option<String>, super::opt_text, "Optional string arguments.";
    et_policy, truth, json, frame);
converters!(flag_arg, bool, super::boolean, "True/False arguments.";
    fast_trig, record_covariances, untriggered_closed_form, robustness, progress, ros2, spatial,
    normalised,
    with_scale, scenario_sensors);

/// Name arguments with a fixed set of values, returned as the canonical
/// static name (so that a literal default works): an unknown name is the
/// parser's error (`UnknownAlgorithmError`, `UnknownOptionError`).
pub mod name_arg {
    use pyo3::prelude::*;

    use crate::errors::IntoPyResult;

    /// `algorithm`: one of the rows (`edccif.ALGORITHMS`).
    pub fn algorithm(o: &Bound<'_, PyAny>) -> PyResult<&'static str> {
        let s = super::string(o, "algorithm", "an algorithm name (edccif.ALGORITHMS)")?;
        Ok(s.parse::<edccif_sim::Algorithm>().py()?.name())
    }
    /// `algorithm`: `None` or one of the rows.
    pub fn opt_algorithm(o: &Bound<'_, PyAny>) -> PyResult<Option<&'static str>> {
        if o.is_none() {
            Ok(None)
        } else {
            algorithm(o).map(Some)
        }
    }
    /// `trigger`: one of the triggers (`edccif.TRIGGERS`).
    pub fn trigger(o: &Bound<'_, PyAny>) -> PyResult<&'static str> {
        let s = super::string(o, "trigger", "a trigger name (edccif.TRIGGERS)")?;
        Ok(s.parse::<edccif_sim::TriggerKind>().py()?.name())
    }
}

/// A filesystem path (`str`, `bytes` or `os.PathLike`); `ArgumentTypeError`
/// naming `name` otherwise.
pub fn path(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<std::path::PathBuf> {
    let py = obj.py();
    let wrong = || {
        argument_type_error(
            py,
            format!(
                "{name}: expected a path (str or os.PathLike), got {}",
                type_name(obj)
            ),
        )
    };
    let fs = py
        .import("os")?
        .getattr("fspath")?
        .call1((obj,))
        .map_err(|_| wrong())?;
    fs.extract::<std::path::PathBuf>().map_err(|_| wrong())
}

/// `None` or a path.
pub fn opt_path(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<std::path::PathBuf>> {
    if obj.is_none() {
        Ok(None)
    } else {
        path(obj, name).map(Some)
    }
}

/// A list of paths.
pub fn paths(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<std::path::PathBuf>> {
    let py = obj.py();
    if obj.is_instance_of::<PyString>() {
        return Err(argument_type_error(
            py,
            format!("{name}: expected a list of paths, got one str"),
        ));
    }
    let items = obj.try_iter().map_err(|_| {
        argument_type_error(
            py,
            format!("{name}: expected a list of paths, got {}", type_name(obj)),
        )
    })?;
    items
        .enumerate()
        .map(|(i, it)| path(&it?, &format!("{name}[{i}]")))
        .collect()
}

/// A list of strings.
pub fn texts(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<String>> {
    let py = obj.py();
    if obj.is_instance_of::<PyString>() {
        return Err(argument_type_error(
            py,
            format!("{name}: expected a list of strings, got one str"),
        ));
    }
    let items = obj.try_iter().map_err(|_| {
        argument_type_error(
            py,
            format!("{name}: expected a list of strings, got {}", type_name(obj)),
        )
    })?;
    items
        .enumerate()
        .map(|(i, it)| text(&it?, &format!("{name}[{i}]")))
        .collect()
}

/// `None` or a list of paths.
pub fn opt_paths(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<Vec<std::path::PathBuf>>> {
    if obj.is_none() {
        Ok(None)
    } else {
        paths(obj, name).map(Some)
    }
}

/// `None` or a list of strings.
pub fn opt_texts(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<Vec<String>>> {
    if obj.is_none() {
        Ok(None)
    } else {
        texts(obj, name).map(Some)
    }
}

/// `None` or a list of integers >= 0.
pub fn opt_counts(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<Vec<usize>>> {
    if obj.is_none() {
        Ok(None)
    } else {
        counts(obj, name, 0).map(Some)
    }
}

converters!(path_arg, std::path::PathBuf, super::path, "Path arguments.";
    path, truth, out);
converters!(opt_path_arg, Option<std::path::PathBuf>, super::opt_path, "Optional path arguments.";
    mcap, tum_dir, flight_data_dir);
converters!(paths_arg, Vec<std::path::PathBuf>, super::paths, "Lists of paths.";
    observers);
converters!(opt_paths_arg, Option<Vec<std::path::PathBuf>>, super::opt_paths, "Optional lists of paths.";
    flight_files);
converters!(texts_arg, Vec<String>, super::texts, "Lists of strings.";
    measurements);
converters!(opt_texts_arg, Option<Vec<String>>, super::opt_texts, "Optional lists of strings.";
    measurements, same_frames);
converters!(opt_counts_arg, Option<Vec<usize>>, super::opt_counts, "Optional lists of integers >= 0.";
    nodes);

/// More `from_py_with` converters of single names.
pub mod more {
    use pyo3::prelude::*;

    /// `override`: True or False.
    pub fn override_flag(o: &Bound<'_, PyAny>) -> PyResult<bool> {
        super::boolean(o, "override")
    }
    /// `t0_ns`: an unsigned 64-bit integer.
    pub fn t0_ns(o: &Bound<'_, PyAny>) -> PyResult<u64> {
        super::u64_arg(o, "t0_ns")
    }
    /// `compression`: `"zstd"` or `"none"`, returned as a static name (a
    /// literal default works); another string is refused by the caller.
    pub fn compression(o: &Bound<'_, PyAny>) -> PyResult<&'static str> {
        let s = super::string(o, "compression", "\"zstd\" or \"none\"")?;
        match s.as_str() {
            "zstd" => Ok("zstd"),
            "none" => Ok("none"),
            other => Err(crate::errors::ParameterError::new_err(format!(
                "compression: {other:?}; expected \"zstd\" or \"none\""
            ))),
        }
    }
}
