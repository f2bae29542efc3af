//! # `cortex_dsr`: pydsr's Python API over a live DSR_d agent
//!
//! CORTEX researchers script the graph from Python with `pydsr`, the pybind11 wrapper of the C++ DSR API. This
//! module offers the same API over this project's agent, so a pydsr script runs with its import changed to
//! `from cortex_dsr import *`:
//!
//! - `DSRGraph(root, name, id, dsr_input_file="", all_same_host=True)` starts an `agent::Agent` on RTPS as
//!   `cortex agent` does (same domain and topic prefix by default), joins the running agents' graph, or starts
//!   from the JSON file when none answers ([`graph`]);
//! - `Node`, `Edge`, `Attribute` and their mutable mappings `attrs` and `edges` are detached copies, as in pydsr
//!   ([`objects`]), with pydsr's value-type rules ([`values`]);
//! - `rt_api(g)` and `inner_api(g)` answer with numpy arrays ([`kinematics`]);
//! - `signals.connect(g, signals.UPDATE_NODE, callback)` calls Python from a dispatcher thread that holds no
//!   agent lock while Python runs ([`signals`]).
//!
//! The GIL is released whenever a call waits on the agent; nothing panics across the FFI boundary (every error is
//! a Python exception: `TypeError`, `AttributeError`, `KeyError` or `RuntimeError`, as pydsr raises them).

use pyo3::prelude::*;

pub mod graph;
pub mod kinematics;
pub mod objects;
pub mod signals;
pub mod values;

/// The `cortex_dsr` module.
#[pymodule]
fn cortex_dsr(py: Python<'_>, module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add_class::<objects::Attribute>()?;
    module.add_class::<objects::AttrMap>()?;
    module.add_class::<objects::EdgeMap>()?;
    module.add_class::<objects::Node>()?;
    module.add_class::<objects::Edge>()?;
    module.add_class::<graph::DsrGraph>()?;
    module.add_class::<kinematics::RtApi>()?;
    module.add_class::<kinematics::InnerApi>()?;

    let signals = PyModule::new(py, "signals")?;
    signals.add_class::<signals::SignalType>()?;
    for (kind, name) in signals::SignalType::ALL {
        signals.add(name, kind)?;
    }
    signals.add_function(wrap_pyfunction!(graph::connect_signal, &signals)?)?;
    signals.add_function(wrap_pyfunction!(signals::_shutdown, &signals)?)?;
    module.add_submodule(&signals)?;
    // `import cortex_dsr.signals` and `from cortex_dsr.signals import ...` find the submodule too.
    py.import("sys")?.getattr("modules")?.set_item("cortex_dsr.signals", &signals)?;
    py.import("atexit")?.call_method1("register", (signals.getattr("_shutdown")?,))?;

    // The attribute and edge maps are mutable mappings, as pydsr's bound `std::map`s behave.
    let mutable_mapping = py.import("collections.abc")?.getattr("MutableMapping")?;
    mutable_mapping.call_method1("register", (module.getattr("MapStringAttribute")?,))?;
    mutable_mapping.call_method1("register", (module.getattr("MapStringEdge")?,))?;
    module.add(
        "__all__",
        [
            "Attribute",
            "Node",
            "Edge",
            "DSRGraph",
            "rt_api",
            "inner_api",
            "signals",
            "MapStringAttribute",
            "MapStringEdge",
        ],
    )?;
    Ok(())
}
