//! The names a replica's dictionary learns from its graph: those a received delta brings (found and checked in one
//! pass before the join, learned after it), and those a file or a log defines (`Replica::learn_names`). See the
//! dictionary's module documentation for why the network is never refused for names or types.

use std::sync::Arc;

use super::Replica;
use crate::delta::Delta;
use crate::dictionary::{Dictionary, validate_name};
use crate::error::{DeltaError, DictionaryError};
use crate::ids::Name;
use crate::store::Attrs;
use crate::value::ValueType;

impl Replica {
    /// Teaches the dictionary names that the graph itself defines (a file's, a log's): the attribute names with
    /// their value types and the node types (see [`Dictionary::learn_attr`]). The shared dictionary is copied only
    /// when something is new, so calling this before every write of a log costs lookups only.
    ///
    /// # Errors
    /// [`DictionaryError::InvalidName`] for a name that cannot be held; names before it are learned.
    pub fn learn_names<'n>(
        &mut self,
        attrs: impl IntoIterator<Item = (&'n str, ValueType)>,
        node_types: impl IntoIterator<Item = &'n str>,
    ) -> Result<(), DictionaryError> {
        for (name, value_type) in attrs {
            if !self.dictionary.knows_attr(name, value_type) {
                Arc::make_mut(&mut self.dictionary).learn_attr(name, value_type)?;
            }
        }
        for name in node_types {
            if self.dictionary.known_node_type(name).is_none() {
                Arc::make_mut(&mut self.dictionary).learn_node_type(name)?;
            }
        }
        Ok(())
    }
}

impl Replica {
    /// The names of a delta that the dictionary does not accept yet, each checked to be a name that can be held (see
    /// [`crate::dictionary::validate_name`]); changes nothing. Names and types are not checked against the
    /// dictionary: the network is never refused for them (the dictionary's module documentation says why); they are
    /// learned once the delta has passed ([`learn_names`]). One dictionary lookup per value in the usual case, where
    /// every name is known with its type.
    pub(super) fn new_names<'d>(&self, delta: &'d Delta) -> Result<NewNames<'d>, DeltaError> {
        let dictionary = &*self.dictionary;
        let refused = |place: String| move |source| DeltaError::Dictionary { place, source };
        let mut new = NewNames::default();
        let mut attrs = |attrs: &'d Attrs, owner: &dyn Fn() -> String| -> Result<(), DeltaError> {
            for (name, register) in attrs {
                for value_type in register.values.iter().map(|entry| entry.value.value_type()) {
                    if dictionary.knows_attr(name, value_type) {
                        continue;
                    }
                    validate_name("attribute name", name)
                        .map_err(refused(format!("{} attribute {name:?}", owner())))?;
                    new.attrs.push((name, value_type));
                }
            }
            Ok(())
        };
        for (id, node) in &delta.store.nodes {
            attrs(&node.attrs, &|| format!("node {id}"))?;
        }
        for (key, edge) in &delta.store.edges {
            attrs(&edge.attrs, &|| format!("edge {key}"))?;
        }
        for (id, node) in &delta.store.nodes {
            for node_type in node.core.values.iter().map(|core| &core.value.node_type) {
                if dictionary.known_node_type(node_type).is_none() {
                    validate_name("node type", node_type).map_err(refused(format!("node {id}")))?;
                    new.node_types.push(node_type);
                }
            }
        }
        for (key, edge_type) in delta.store.edges.keys().map(|key| (key, &key.edge_type)) {
            if dictionary.known_edge_type(edge_type).is_none() {
                validate_name("edge type", edge_type).map_err(refused(format!("edge {key}")))?;
                new.edge_types.push(edge_type);
            }
        }
        Ok(new)
    }
}

/// The names of a delta that its replica's dictionary does not accept yet ([`Replica::new_names`]).
#[derive(Default)]
pub(super) struct NewNames<'d> {
    attrs: Vec<(&'d Name, ValueType)>,
    node_types: Vec<&'d Name>,
    edge_types: Vec<&'d Name>,
}

/// Teaches the dictionary the names [`Replica::new_names`] found and checked (so none can fail), copying the shared
/// dictionary only if there is one.
pub(super) fn learn_names(dictionary: &mut Arc<Dictionary>, new: NewNames<'_>) {
    if new.attrs.is_empty() && new.node_types.is_empty() && new.edge_types.is_empty() {
        return;
    }
    let dictionary = Arc::make_mut(dictionary);
    for (name, value_type) in new.attrs {
        dictionary.learn_attr(name, value_type).expect("checked by new_names");
    }
    for name in new.node_types {
        dictionary.learn_node_type(name).expect("checked by new_names");
    }
    for name in new.edge_types {
        dictionary.learn_edge_type(name).expect("checked by new_names");
    }
}
