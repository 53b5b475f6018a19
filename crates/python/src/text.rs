//! The readers' fast path for rows of numbers in text files: `texsense_core::text`.

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;

/// Exactly `expected` numbers separated by `sep` in `line`, as a float32 array (each read as
/// a double and rounded, as numpy does), or None when the line is not that (the reader's own
/// parser then says what is wrong).
#[pyfunction]
#[pyo3(name = "parse_row")]
pub(crate) fn py_parse_row<'py>(
    py: Python<'py>,
    line: &str,
    sep: char,
    expected: usize,
) -> Option<Bound<'py, PyArray1<f32>>> {
    let mut out = Vec::new();
    texsense_core::text::parse_row(line, sep, expected, &mut out).then(|| out.into_pyarray(py))
}

/// The inside of a JSON list of `expected` numbers or `null`s (an MQTT frame's `values`) as a
/// float64 array (null: NaN), or None when it is not exactly that (the station's full JSON
/// parse then says what is wrong).
#[pyfunction]
#[pyo3(name = "parse_json_numbers")]
pub(crate) fn py_parse_json_numbers<'py>(
    py: Python<'py>,
    text: &[u8],
    expected: usize,
) -> Option<Bound<'py, PyArray1<f64>>> {
    let mut out = Vec::new();
    texsense_core::text::parse_json_numbers(text, expected, &mut out).then(|| out.into_pyarray(py))
}

/// A whole MQTT frame payload of the plain form (`texsense_core::text::parse_json_frame`):
/// (seq, t, unit or None, dt or None, values), or None when it is not of that form (the
/// station's JSON parse then reads it or says what is wrong). The payload is read without
/// the interpreter lock (MQTT's thread and the journal's go on meanwhile).
#[pyfunction]
#[pyo3(name = "parse_json_frame")]
#[allow(clippy::type_complexity)]
pub(crate) fn py_parse_json_frame<'py>(
    py: Python<'py>,
    payload: &[u8],
    expected: usize,
) -> Option<(
    u64,
    f64,
    Option<String>,
    Option<f64>,
    Bound<'py, PyArray1<f64>>,
)> {
    let mut out = Vec::new();
    let got = py.detach(|| texsense_core::text::parse_json_frame(payload, expected, &mut out))?;
    // the unit's bytes are printable ASCII (checked by the parse)
    let unit = got
        .unit
        .map(|(a, b)| String::from_utf8_lossy(&payload[a..b]).into_owned());
    Some((got.seq, got.t, unit, got.dt, out.into_pyarray(py)))
}
