//! pydsr's `rt_api(g)` and `inner_api(g)`: RT edges and transforms between node frames, answered by
//! `dsr::kinematics` on the agent's current graph, returned as numpy float64 arrays (4×4 and 3×3 matrices,
//! 3- and 6-vectors), or `None` where pydsr returns `None` (a missing node or edge, frames not connected).
//!
//! The `timestamp` arguments are accepted and ignored: DSR_d keeps no history of RT edges, so every answer is
//! about the current graph (pydsr's `0`).

use dsr::kinematics::{euler_xyz, rt_isometry, translation_mm};
use dsr::{EdgeKey, NodeId, Replica, Value, attrs};
use nalgebra::Isometry3;
use numpy::PyArray1;
use numpy::PyArrayMethods;
use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyString;

use crate::graph::{DsrGraph, agent_of, edge_copy, edge_object};
use crate::objects::{Edge, Node};

/// A 4×4 homogeneous matrix of an isometry.
fn matrix4<'py>(py: Python<'py>, pose: &Isometry3<f64>) -> PyResult<Bound<'py, PyAny>> {
    let m = pose.to_homogeneous();
    let rows: Vec<f64> = (0..4).flat_map(|r| (0..4).map(move |c| m[(r, c)])).collect();
    Ok(PyArray1::from_vec(py, rows).reshape([4, 4])?.into_any())
}

/// A 3×3 rotation matrix of an isometry.
fn matrix3<'py>(py: Python<'py>, pose: &Isometry3<f64>) -> PyResult<Bound<'py, PyAny>> {
    let m = pose.rotation.to_rotation_matrix();
    let rows: Vec<f64> = (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect();
    Ok(PyArray1::from_vec(py, rows).reshape([3, 3])?.into_any())
}

fn vector<'py>(py: Python<'py>, values: &[f64]) -> Bound<'py, PyAny> {
    PyArray1::from_slice(py, values).into_any()
}

/// Three floats from a Python sequence or array.
fn three(name: &str, values: Vec<f64>) -> PyResult<[f64; 3]> {
    values.try_into().map_err(|v: Vec<f64>| PyTypeError::new_err(format!("{name} needs 3 values, not {}", v.len())))
}

/// The first three floats of an RT attribute value.
fn first_three(value: Option<&Value>) -> Option<[f64; 3]> {
    let floats: &[f32] = match value? {
        Value::VecF32(values) => values,
        Value::F32x3(values) => values,
        _ => return None,
    };
    match floats {
        [x, y, z, ..] => Some([f64::from(*x), f64::from(*y), f64::from(*z)]),
        _ => None,
    }
}

/// `rt_api(g)`: RT edges (parent → child, translation in mm, Euler x y z in rad).
#[pyclass(module = "cortex_dsr", name = "rt_api")]
pub struct RtApi {
    graph: Py<DsrGraph>,
}

impl RtApi {
    fn read<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&Replica) -> R + Send) -> PyResult<R> {
        self.graph.bind(py).get().read(py, f)
    }
}

#[pymethods]
impl RtApi {
    #[new]
    fn py_new(graph: Py<DsrGraph>) -> Self {
        RtApi { graph }
    }

    /// Places node `to` under `node` with an RT edge (inserted or moved), and sets its `parent` and `level`.
    #[pyo3(signature = (node, to, trans, rot_euler))]
    #[pyo3(name = "insert_or_assign_edge_RT")]
    fn insert_or_assign_edge_rt(
        &self,
        py: Python<'_>,
        node: PyRef<'_, Node>,
        to: u64,
        trans: Vec<f64>,
        rot_euler: Vec<f64>,
    ) -> PyResult<()> {
        let parent = NodeId(node.id);
        drop(node);
        let [tx, ty, tz] = three("trans", trans)?;
        let [rx, ry, rz] = three("rot_euler", rot_euler)?;
        let agent = agent_of(self.graph.bind(py))?;
        py.detach(|| {
            agent.set_rt(parent, NodeId(to), [tx as f32, ty as f32, tz as f32], [rx as f32, ry as f32, rz as f32])
        })
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))
    }

    /// The RT edge from `node` to `to`, or `None`.
    #[pyo3(name = "get_edge_RT")]
    fn get_edge_rt(&self, py: Python<'_>, node: PyRef<'_, Node>, to: u64) -> PyResult<Option<Py<Edge>>> {
        let key = EdgeKey::new(NodeId(node.id), NodeId(to), "RT");
        drop(node);
        let copy = self.read(py, move |r| r.edge(&key).map(|e| edge_copy(&e)))?;
        copy.map(|c| edge_object(py, c)).transpose()
    }

    /// The node's pose in its RT parent's frame (4×4), or `None` for a root or a node that does not exist.
    #[pyo3(name = "get_RT_pose_from_parent")]
    fn get_rt_pose_from_parent<'py>(
        &self,
        py: Python<'py>,
        node: PyRef<'_, Node>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let id = NodeId(node.id);
        drop(node);
        let pose = self
            .read(py, move |r| r.rt_parent_edge(id).ok().flatten().and_then(|e| dsr::kinematics::edge_pose(&e).ok()))?;
        pose.map(|p| matrix4(py, &p)).transpose()
    }

    /// The 4×4 matrix of an RT edge object's translation and rotation, or `None` if it lacks them.
    #[pyo3(signature = (edge, timestamp = 0))]
    #[pyo3(name = "get_edge_RT_as_rtmat")]
    fn get_edge_rt_as_rtmat<'py>(
        &self,
        py: Python<'py>,
        edge: PyRef<'_, Edge>,
        timestamp: u64,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let _ = timestamp;
        let attrs = edge.attrs.borrow(py);
        let value = |names: [&str; 2]| -> Option<Value> {
            names.iter().find_map(|name| attrs.entries.get(*name).map(|a| a.borrow(py).value.clone()))
        };
        let translation = first_three(value([attrs::RT_TRANSLATION.name(), attrs::TRANSLATION.name()]).as_ref());
        let rotation =
            first_three(value([attrs::RT_ROTATION_EULER_XYZ.name(), attrs::ROTATION_EULER_XYZ.name()]).as_ref());
        match (translation, rotation) {
            (Some(t), Some(r)) => matrix4(py, &rt_isometry(t, r)).map(Some),
            _ => Ok(None),
        }
    }

    /// The translation of the RT edge from `node_id` to `to` (mm), or `None`.
    #[pyo3(signature = (node_id, to, timestamp = 0))]
    fn get_translation<'py>(
        &self,
        py: Python<'py>,
        node_id: u64,
        to: u64,
        timestamp: u64,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let _ = timestamp;
        let key = EdgeKey::new(NodeId(node_id), NodeId(to), "RT");
        let translation = self.read(py, move |r| {
            let edge = r.edge(&key)?;
            first_three(edge.attr(attrs::RT_TRANSLATION.name()).or_else(|| edge.attr(attrs::TRANSLATION.name())))
        })?;
        Ok(translation.map(|t| vector(py, &t)))
    }
}

/// `inner_api(g)`: transforms between the frames of two nodes named by name, through their common RT ancestor.
#[pyclass(module = "cortex_dsr", name = "inner_api")]
pub struct InnerApi {
    graph: Py<DsrGraph>,
}

/// pydsr's two forms: `(dest, orig, timestamp=0)` and `(dest, vector, orig, timestamp=0)`.
struct TransformArgs {
    dest: String,
    orig: String,
    vector: Option<Vec<f64>>,
}

impl TransformArgs {
    fn parse(dest: String, second: &Bound<'_, PyAny>, third: Option<&Bound<'_, PyAny>>) -> PyResult<TransformArgs> {
        if let Ok(orig) = second.cast::<PyString>() {
            return Ok(TransformArgs { dest, orig: orig.to_str()?.to_owned(), vector: None });
        }
        let vector: Vec<f64> = second.extract()?;
        let orig = third
            .ok_or_else(|| PyTypeError::new_err("transform(dest, vector, orig): the origin node's name is missing"))?
            .extract()?;
        Ok(TransformArgs { dest, orig, vector: Some(vector) })
    }
}

/// A numpy answer, or `None` where pydsr answers `None`.
type Answer<'py> = PyResult<Option<Bound<'py, PyAny>>>;

/// What `inner_api`'s matrix getters return of a transform.
#[derive(Clone, Copy)]
enum Wanted {
    Matrix,
    Rotation,
    Translation,
    Euler,
}

impl InnerApi {
    /// The transform from `orig`'s frame to `dest`'s as `wanted` (`timestamp` is ignored: no RT history).
    fn answer<'py>(&self, py: Python<'py>, dest: String, orig: String, timestamp: u64, wanted: Wanted) -> Answer<'py> {
        let _ = timestamp;
        let Some(pose) = self.pose(py, dest, orig)? else { return Ok(None) };
        Ok(Some(match wanted {
            Wanted::Matrix => matrix4(py, &pose)?,
            Wanted::Rotation => matrix3(py, &pose)?,
            Wanted::Translation => vector(py, &translation_mm(&pose)),
            Wanted::Euler => vector(py, &euler_xyz(&pose.rotation)),
        }))
    }

    /// pydsr's `(dest, orig[, timestamp])` or `(dest, vector, orig[, timestamp])`: the transform and the vector
    /// (`len` zeros in the first form), or `None` when the transform cannot be computed.
    fn pose_and_vector(
        &self,
        py: Python<'_>,
        dest: String,
        second: &Bound<'_, PyAny>,
        third: Option<&Bound<'_, PyAny>>,
        len: usize,
    ) -> PyResult<Option<(Isometry3<f64>, Vec<f64>)>> {
        // A third positional int is the first form's timestamp.
        let args = TransformArgs::parse(dest, second, third.filter(|t| !t.is_instance_of::<pyo3::types::PyInt>()))?;
        let vector = args.vector.unwrap_or_else(|| vec![0.0; len]);
        if vector.len() != len {
            return Err(PyTypeError::new_err(format!("the vector needs {len} values, not {}", vector.len())));
        }
        Ok(self.pose(py, args.dest, args.orig)?.map(|pose| (pose, vector)))
    }

    /// The isometry from `orig`'s frame to `dest`'s, or `None` when it cannot be computed.
    fn pose(&self, py: Python<'_>, dest: String, orig: String) -> PyResult<Option<Isometry3<f64>>> {
        self.graph.bind(py).get().read(py, move |r| {
            let dest = r.node_by_name(&dest)?.id();
            let orig = r.node_by_name(&orig)?.id();
            r.transform(orig, dest).ok()
        })
    }
}

#[pymethods]
impl InnerApi {
    #[new]
    fn py_new(graph: Py<DsrGraph>) -> Self {
        InnerApi { graph }
    }

    /// A point (default the origin) of `orig`'s frame in `dest`'s frame, mm.
    #[pyo3(signature = (dest, second, third = None, timestamp = None))]
    fn transform<'py>(
        &self,
        py: Python<'py>,
        dest: String,
        second: &Bound<'py, PyAny>,
        third: Option<&Bound<'py, PyAny>>,
        timestamp: Option<u64>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let _ = timestamp;
        let Some((pose, point)) = self.pose_and_vector(py, dest, second, third, 3)? else { return Ok(None) };
        let p = pose * nalgebra::Point3::new(point[0], point[1], point[2]);
        Ok(Some(vector(py, &[p.x, p.y, p.z])))
    }

    /// A pose `[x, y, z, rx, ry, rz]` (default zero) of `orig`'s frame in `dest`'s frame.
    #[pyo3(signature = (dest, second, third = None, timestamp = None))]
    fn transform_axis<'py>(
        &self,
        py: Python<'py>,
        dest: String,
        second: &Bound<'py, PyAny>,
        third: Option<&Bound<'py, PyAny>>,
        timestamp: Option<u64>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let _ = timestamp;
        let Some((pose, axis)) = self.pose_and_vector(py, dest, second, third, 6)? else { return Ok(None) };
        let moved = pose * rt_isometry([axis[0], axis[1], axis[2]], [axis[3], axis[4], axis[5]]);
        let [x, y, z] = translation_mm(&moved);
        let [a, b, c] = euler_xyz(&moved.rotation);
        Ok(Some(vector(py, &[x, y, z, a, b, c])))
    }

    /// The 4×4 matrix from `orig`'s frame to `dest`'s.
    #[pyo3(signature = (dest, orig, timestamp = 0))]
    fn get_transformation_matrix<'py>(
        &self,
        py: Python<'py>,
        dest: String,
        orig: String,
        timestamp: u64,
    ) -> Answer<'py> {
        self.answer(py, dest, orig, timestamp, Wanted::Matrix)
    }

    /// The 3×3 rotation from `orig`'s frame to `dest`'s.
    #[pyo3(signature = (dest, orig, timestamp = 0))]
    fn get_rotation_matrix<'py>(&self, py: Python<'py>, dest: String, orig: String, timestamp: u64) -> Answer<'py> {
        self.answer(py, dest, orig, timestamp, Wanted::Rotation)
    }

    /// The translation from `orig`'s frame to `dest`'s (mm).
    #[pyo3(signature = (dest, orig, timestamp = 0))]
    fn get_translation_vector<'py>(&self, py: Python<'py>, dest: String, orig: String, timestamp: u64) -> Answer<'py> {
        self.answer(py, dest, orig, timestamp, Wanted::Translation)
    }

    /// The Euler angles x, y, z (rad) of the rotation from `orig`'s frame to `dest`'s.
    #[pyo3(signature = (dest, orig, timestamp = 0))]
    fn get_euler_xyz_angles<'py>(&self, py: Python<'py>, dest: String, orig: String, timestamp: u64) -> Answer<'py> {
        self.answer(py, dest, orig, timestamp, Wanted::Euler)
    }
}
