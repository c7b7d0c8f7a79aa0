//! Python values as the TOML values an experiment file would hold: a dict given to
//! `Experiment.from_dict` is read as the same file would be, NaN and ±inf included (JSON, the
//! earlier route, has neither), and a value TOML cannot hold is refused by its key.

use crate::error::err;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use toml::Value;

/// `obj` at key path `path` of the dict named `file` as a TOML value; None for Python's None (the
/// key is absent). Lists, tuples and numpy arrays become arrays, numpy scalars Python's numbers.
fn toml_value(obj: &Bound<'_, PyAny>, file: &str, path: &str) -> PyResult<Option<Value>> {
    let refuse = |why: &str| err(format!("{file}: `{path}` = {}: {why}", repr(obj)));
    if obj.is_none() {
        return Ok(None);
    }
    if let Ok(b) = obj.cast::<PyBool>() {
        return Ok(Some(Value::Boolean(b.is_true())));
    }
    if let Ok(s) = obj.cast::<PyString>() {
        return Ok(Some(Value::String(s.to_str()?.to_string())));
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        return table(d, file, path).map(|t| Some(Value::Table(t)));
    }
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        return array(obj, file, path).map(Some);
    }
    // numpy arrays and scalars: their `tolist` gives Python's lists and numbers.
    if obj.hasattr("tolist")? && obj.hasattr("shape")? && !obj.is_instance_of::<PyFloat>() {
        return toml_value(&obj.call_method0("tolist")?, file, path);
    }
    if obj.is_instance_of::<PyInt>() {
        let v: i64 = obj
            .extract()
            .map_err(|_| refuse("an integer beyond TOML's 64 bits"))?;
        return Ok(Some(Value::Integer(v)));
    }
    match obj.extract::<f64>() {
        Ok(v) => Ok(Some(Value::Float(v))),
        Err(_) => Err(refuse(
            "not a value a TOML file holds (a str, bool, int, float, list or dict)",
        )),
    }
}

/// A dict (named `file` in errors) as a TOML table: string keys, None members left out.
pub fn table(d: &Bound<'_, PyDict>, file: &str, path: &str) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    for (k, v) in d.iter() {
        let Ok(key) = k.extract::<String>() else {
            let key = repr(&k);
            let at = if path.is_empty() {
                String::new()
            } else {
                format!(" `{path}`")
            };
            return Err(err(format!("{file}:{at} the key {key} is not a string")));
        };
        let at = if path.is_empty() {
            key.clone()
        } else {
            format!("{path}.{key}")
        };
        if let Some(v) = toml_value(&v, file, &at)? {
            t.insert(key, v);
        }
    }
    Ok(t)
}

/// A list or tuple as a TOML array (a TOML array has no None).
fn array(obj: &Bound<'_, PyAny>, file: &str, path: &str) -> PyResult<Value> {
    let mut items = Vec::new();
    for (i, item) in obj.try_iter()?.enumerate() {
        let at = format!("{path}[{i}]");
        match toml_value(&item?, file, &at)? {
            Some(v) => items.push(v),
            None => {
                return Err(err(format!(
                    "{file}: `{at}` = None: an array cannot hold None"
                )))
            }
        }
    }
    Ok(Value::Array(items))
}

/// `obj` as Python writes it (`repr`), for an error.
fn repr(obj: &Bound<'_, PyAny>) -> String {
    obj.repr()
        .map_or_else(|_| "?".to_string(), |r| r.to_string())
}
