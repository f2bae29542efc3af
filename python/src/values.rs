//! Python values ⇄ `dsr::Value`: the type a Python value takes when it becomes an attribute, the conversions an
//! attribute name of a known type allows, and the numpy arrays that vectors and images come back as.
//!
//! The rules follow pydsr's (its pybind11 variant tries the value types in a fixed order): `str` → string, `bool` →
//! bool, a non-negative `int` → u64 and a negative one → i32, `float` → f64, a numpy array of `uint8` / `float32` /
//! `uint64` → `vec<u8>` / `vec<f32>` / `vec<u64>`, a list of ints 0..=255 → `vec<u8>`, of larger ints → `vec<u64>`, of
//! floats → `vec<f32>`. A name whose type is known then narrows the value as pydsr's attribute map does: u64 → u32 or
//! i32, f64 → f32, `vec<f32>` → [f32; N], `vec<u8>` → `vec<u64>`. Unknown names keep the type they are first seen with
//! in this process, as in pydsr.
//!
//! Copies: a C-contiguous numpy array of the attribute's own element type, or `bytes`, becomes an attribute in one
//! `memcpy` into the attribute's own buffer (`bytes::Bytes`, `dsr::Numbers<f32>`, `dsr::Numbers<u64>`); an
//! attribute comes back as a new numpy array in one `memcpy` out of it. No per-element conversion in either direction on that path (a
//! non-contiguous view is gathered element by element, a float64 array narrowed element by element, and a Python
//! list, as in pydsr, is converted per element).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use bytes::Bytes;
use dsr::{Dictionary, Numbers, Value, ValueType};
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyByteArray, PyBytes, PyFloat, PyInt, PyList, PyString, PyTuple};

/// The pydsr name of a value type, for error messages (`FLOAT`, `VEC3`, ...).
pub fn type_name(value_type: ValueType) -> &'static str {
    match value_type {
        ValueType::String => "STRING",
        ValueType::I32 => "INT",
        ValueType::F32 => "FLOAT",
        ValueType::VecF32 => "FLOAT_VEC",
        ValueType::Bool => "BOOL",
        ValueType::Bytes => "BYTE_VEC",
        ValueType::U32 => "UINT",
        ValueType::U64 => "UINT64",
        ValueType::F64 => "DOUBLE",
        ValueType::VecU64 => "UINT64_VEC",
        ValueType::F32x2 => "FLOAT_VEC2",
        ValueType::F32x3 => "FLOAT_VEC3",
        ValueType::F32x4 => "FLOAT_VEC4",
        ValueType::F32x6 => "FLOAT_VEC6",
    }
}

/// The value a Python object becomes, by pydsr's inference rules (see the module docs).
///
/// # Errors
/// `TypeError` for a Python type no attribute can hold (`None`, a dict, an int above u64, a numpy array of another
/// dtype than uint8, float32, float64 or uint64).
pub fn infer(object: &Bound<'_, PyAny>) -> PyResult<Value> {
    if let Ok(text) = object.cast::<PyString>() {
        return Ok(Value::String(Arc::from(text.to_str()?)));
    }
    if let Ok(flag) = object.cast::<PyBool>() {
        return Ok(Value::Bool(flag.is_true()));
    }
    if let Ok(array) = object.cast::<PyUntypedArray>() {
        return from_array(array);
    }
    if let Ok(bytes) = object.cast::<PyBytes>() {
        return Ok(Value::Bytes(Bytes::copy_from_slice(bytes.as_bytes())));
    }
    if let Ok(bytes) = object.cast::<PyByteArray>() {
        return Ok(Value::Bytes(Bytes::from(bytes.to_vec())));
    }
    if object.is_instance_of::<PyList>() || object.is_instance_of::<PyTuple>() {
        return from_sequence(object);
    }
    if object.is_instance_of::<PyInt>() {
        if let Ok(value) = object.extract::<u64>() {
            return Ok(Value::U64(value));
        }
        if let Ok(value) = object.extract::<i32>() {
            return Ok(Value::I32(value));
        }
        return Err(PyTypeError::new_err(format!("the integer {object} fits neither u64 nor i32")));
    }
    if let Ok(value) = object.cast::<PyFloat>() {
        return Ok(Value::F64(value.value()));
    }
    Err(PyTypeError::new_err(format!(
        "an attribute cannot hold a {}: use str, bool, int, float, bytes, a list or a numpy array",
        object.get_type().name()?
    )))
}

/// A numpy array of uint8, float32 or uint64 (any shape, flattened in C order), in one copy; float64 is narrowed
/// to float32.
fn from_array(array: &Bound<'_, PyUntypedArray>) -> PyResult<Value> {
    if let Ok(array) = array.cast::<PyArrayDyn<u8>>() {
        let array = array.readonly();
        return Ok(Value::Bytes(match array.as_slice() {
            Ok(slice) => Bytes::copy_from_slice(slice),
            Err(_) => Bytes::from(array.as_array().iter().copied().collect::<Vec<u8>>()),
        }));
    }
    if let Ok(array) = array.cast::<PyArrayDyn<f32>>() {
        let array = array.readonly();
        return Ok(Value::VecF32(match array.as_slice() {
            Ok(slice) => Numbers::from(slice),
            Err(_) => array.as_array().iter().copied().collect(),
        }));
    }
    if let Ok(array) = array.cast::<PyArrayDyn<u64>>() {
        let array = array.readonly();
        return Ok(Value::VecU64(match array.as_slice() {
            Ok(slice) => Numbers::from(slice),
            Err(_) => array.as_array().iter().copied().collect(),
        }));
    }
    if let Ok(array) = array.cast::<PyArrayDyn<f64>>() {
        let array = array.readonly();
        return Ok(Value::VecF32(array.as_array().iter().map(|&x| x as f32).collect()));
    }
    Err(PyTypeError::new_err(format!(
        "a numpy array of dtype {} cannot be an attribute: use uint8 (images, bytes), float32 or uint64",
        array.dtype()
    )))
}

/// A list or tuple: all ints 0..=255 → vec<u8> (also when empty), all non-negative ints → vec<u64>, otherwise
/// numbers → vec<f32>.
fn from_sequence(sequence: &Bound<'_, PyAny>) -> PyResult<Value> {
    let items: Vec<Bound<'_, PyAny>> = sequence.try_iter()?.collect::<PyResult<_>>()?;
    let all_ints = items.iter().all(|item| item.is_instance_of::<PyInt>() && !item.is_instance_of::<PyBool>());
    if all_ints {
        let values: Option<Vec<u64>> = items.iter().map(|item| item.extract::<u64>().ok()).collect();
        if let Some(values) = values {
            if values.iter().all(|&v| v <= u64::from(u8::MAX)) {
                return Ok(Value::Bytes(values.iter().map(|&v| v as u8).collect()));
            }
            return Ok(Value::VecU64(values.into()));
        }
    }
    Ok(Value::VecF32(floats(&items)?.into()))
}

fn floats(items: &[Bound<'_, PyAny>]) -> PyResult<Vec<f32>> {
    items
        .iter()
        .map(|item| {
            if item.is_instance_of::<PyBool>() {
                return Err(PyTypeError::new_err("a vector of floats cannot hold a bool"));
            }
            item.extract::<f64>()
                .map(|x| x as f32)
                .map_err(|_| PyTypeError::new_err(format!("a vector attribute holds numbers, not {}", item.get_type())))
        })
        .collect()
}

/// Types first given to names outside the built-in dictionary, as pydsr registers a name with the type it is
/// first used with.
static FIRST_SEEN: Mutex<Option<HashMap<String, ValueType>>> = Mutex::new(None);

/// The type an attribute name has: built-in, or first seen in this process (then recorded).
fn known_type(name: &str, value_type: ValueType) -> ValueType {
    thread_local! {
        static BUILTIN: Dictionary = Dictionary::builtin();
    }
    if let Some(known) = BUILTIN.with(|dictionary| dictionary.attr_type(name)) {
        return known;
    }
    let mut seen = FIRST_SEEN.lock().unwrap_or_else(|p| p.into_inner());
    *seen.get_or_insert_with(HashMap::new).entry(name.to_owned()).or_insert(value_type)
}

/// `value` made fit for attribute `name` by the narrowing conversions pydsr's attribute map does (see the module
/// docs): to the type the element already holds under that name (`held`: a graph's file may store a name with
/// another type than the built-in one, and the graph accepts that type), else to the name's known type; `None` when
/// `value` cannot take it.
pub fn fit_to_name(name: &str, value: &Value, held: Option<ValueType>) -> Option<Value> {
    let wanted = held.unwrap_or_else(|| known_type(name, value.value_type()));
    convert(value, wanted)
}

/// `value` as a value of type `wanted`, by a lossless or pydsr-sanctioned conversion.
pub fn convert(value: &Value, wanted: ValueType) -> Option<Value> {
    if value.value_type() == wanted {
        return Some(value.clone());
    }
    let fixed = |values: &[f32]| -> Option<Value> {
        Some(match wanted {
            ValueType::F32x2 => Value::F32x2(values.try_into().ok()?),
            ValueType::F32x3 => Value::F32x3(values.try_into().ok()?),
            ValueType::F32x4 => Value::F32x4(values.try_into().ok()?),
            ValueType::F32x6 => Value::F32x6(values.try_into().ok()?),
            ValueType::VecF32 => Value::VecF32(Numbers::from(values)),
            _ => return None,
        })
    };
    match (value, wanted) {
        (Value::U64(v), ValueType::U32) => u32::try_from(*v).ok().map(Value::U32),
        (Value::U64(v), ValueType::I32) => i32::try_from(*v).ok().map(Value::I32),
        (Value::I32(v), ValueType::U32) => u32::try_from(*v).ok().map(Value::U32),
        (Value::I32(v), ValueType::U64) => u64::try_from(*v).ok().map(Value::U64),
        (Value::U64(v), ValueType::F32) => Some(Value::F32(*v as f32)),
        (Value::I32(v), ValueType::F32) => Some(Value::F32(*v as f32)),
        (Value::U64(v), ValueType::F64) => Some(Value::F64(*v as f64)),
        (Value::I32(v), ValueType::F64) => Some(Value::F64(f64::from(*v))),
        (Value::F64(v), ValueType::F32) => Some(Value::F32(*v as f32)),
        (Value::F32(v), ValueType::F64) => Some(Value::F64(f64::from(*v))),
        (Value::VecF32(values), _) => fixed(values),
        (Value::F32x2(values), _) => fixed(values),
        (Value::F32x3(values), _) => fixed(values),
        (Value::F32x4(values), _) => fixed(values),
        (Value::F32x6(values), _) => fixed(values),
        (Value::Bytes(bytes), ValueType::VecU64) => Some(Value::VecU64(bytes.iter().map(|&b| u64::from(b)).collect())),
        (Value::Bytes(bytes), ValueType::VecF32) => Some(Value::VecF32(bytes.iter().map(|&b| f32::from(b)).collect())),
        (Value::VecU64(values), ValueType::VecF32) => Some(Value::VecF32(values.iter().map(|&v| v as f32).collect())),
        (Value::VecU64(values), ValueType::Bytes) => {
            values.iter().map(|&v| u8::try_from(v).ok()).collect::<Option<Vec<u8>>>().map(|v| Value::Bytes(v.into()))
        }
        _ => None,
    }
}

/// The Python object of a value: `str`, `int`, `float`, `bool`, or a new numpy array (float32, uint8, uint64)
/// filled in one copy.
pub fn to_python<'py>(py: Python<'py>, value: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        Value::String(text) => PyString::new(py, text).into_any(),
        Value::I32(v) => v.into_pyobject(py)?.into_any(),
        Value::F32(v) => PyFloat::new(py, f64::from(*v)).into_any(),
        Value::VecF32(values) => PyArray1::from_slice(py, values).into_any(),
        Value::Bool(v) => PyBool::new(py, *v).to_owned().into_any(),
        Value::Bytes(bytes) => PyArray1::from_slice(py, bytes).into_any(),
        Value::U32(v) => v.into_pyobject(py)?.into_any(),
        Value::U64(v) => v.into_pyobject(py)?.into_any(),
        Value::F64(v) => PyFloat::new(py, *v).into_any(),
        Value::VecU64(values) => PyArray1::from_slice(py, values).into_any(),
        Value::F32x2(values) => PyArray1::from_slice(py, values).into_any(),
        Value::F32x3(values) => PyArray1::from_slice(py, values).into_any(),
        Value::F32x4(values) => PyArray1::from_slice(py, values).into_any(),
        Value::F32x6(values) => PyArray1::from_slice(py, values).into_any(),
    })
}

/// Python `object` as a new value for an attribute of type `wanted` (`Attribute.value = ...`), or the pydsr
/// `TypeError` ("Attributes cannot change type").
pub fn assign(object: &Bound<'_, PyAny>, wanted: ValueType) -> PyResult<Value> {
    let refuse = |found: &str| {
        PyTypeError::new_err(format!(
            "Attributes cannot change type. Selected type is {} and used type is {found}",
            type_name(wanted)
        ))
    };
    let inferred = infer(object).map_err(|_| refuse("unsupported"))?;
    // A bool is never a number here (Python's `True` is an int, pydsr refuses it).
    if matches!(inferred, Value::Bool(_)) != (wanted == ValueType::Bool) {
        return Err(refuse(type_name(inferred.value_type())));
    }
    convert(&inferred, wanted).ok_or_else(|| refuse(type_name(inferred.value_type())))
}
