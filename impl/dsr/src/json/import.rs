//! Importing a [`CortexGraph`] into a replica, all or nothing.

use super::*;

/// What an import did.
#[derive(Clone, Debug)]
pub struct ImportReport {
    /// Nodes inserted.
    pub nodes: usize,
    /// Edges inserted.
    pub edges: usize,
    /// Attributes written (on nodes and edges).
    pub attributes: usize,
    /// The deltas produced, in order: one per node, then one per edge. An agent publishes them.
    pub deltas: Vec<Arc<Delta>>,
}

fn symbol_path(id: NodeId) -> String {
    format!("DSRModel.symbols[\"{id}\"]")
}

fn link_path(key: &EdgeKey) -> String {
    format!("DSRModel.symbols[\"{}\"].links[dst={}, label={:?}]", key.from, key.to, cut(&key.edge_type, 64))
}

impl CortexGraph {
    /// Inserts every symbol and link into `replica` with their ids, as local operations at `now_ns`.
    ///
    /// All or nothing: everything is checked first (ids already used or deleted in the replica, names taken in
    /// the file or the replica, invalid names, names and types the replica's dictionary refuses, links whose ends
    /// are neither in the file nor visible in the replica, links the replica already has); on any error the
    /// replica is unchanged. Links may end at nodes the replica already holds.
    ///
    /// # Errors
    /// [`JsonError`] naming the symbol or link at fault.
    pub fn import_into(&self, replica: &mut Replica, now_ns: u64) -> Result<ImportReport, JsonError> {
        self.validate_import(replica)?;
        // Validation passed; apply to a copy so that even an unforeseen refusal leaves the replica unchanged.
        let mut staged = replica.clone();
        let mut deltas = Vec::with_capacity(self.nodes.len() + self.edges.len());
        let mut attributes = 0;
        for (id, node) in &self.nodes {
            let (_, delta) = staged
                .insert_node(
                    now_ns,
                    NewNode {
                        id: Some(*id),
                        node_type: node.node_type.clone(),
                        name: node.name.clone(),
                        attrs: node.attrs.iter().map(|(name, value)| (name.clone(), value.clone())).collect(),
                    },
                )
                .map_err(|source| JsonError::Refused { path: symbol_path(*id), source })?;
            attributes += node.attrs.len();
            deltas.push(delta);
        }
        for (key, attrs) in &self.edges {
            let (_, delta) = staged
                .insert_edge(
                    now_ns,
                    key.from,
                    key.to,
                    &key.edge_type,
                    attrs.iter().map(|(name, value)| (name.clone(), value.clone())).collect(),
                )
                .map_err(|source| JsonError::Refused { path: link_path(key), source })?;
            attributes += attrs.len();
            deltas.push(delta);
        }
        *replica = staged;
        Ok(ImportReport { nodes: self.nodes.len(), edges: self.edges.len(), attributes, deltas })
    }

    /// Every check of [`CortexGraph::import_into`], against a copy of the replica's dictionary so that an unknown
    /// name first seen with one type and later with another is caught too.
    fn validate_import(&self, replica: &Replica) -> Result<(), JsonError> {
        let mut dictionary = replica.dictionary().clone();
        let mut names: BTreeMap<&str, NodeId> = BTreeMap::new();
        let refused = |path: String| move |source| JsonError::Dictionary { path, source };
        for (id, node) in &self.nodes {
            let path = symbol_path(*id);
            if replica.is_deleted(*id) || replica.store().nodes.contains_key(id) {
                return Err(JsonError::IdInUse { path: format!("{path}.id"), id: *id });
            }
            if !valid_node_name(&node.name) {
                return Err(JsonError::InvalidNodeName { path: format!("{path}.name"), name: cut(&node.name, 64) });
            }
            let holder = match names.insert(&node.name, *id) {
                Some(other) => Some(format!("symbol {other} of the file")),
                None => replica.node_by_name(&node.name).map(|holder| format!("node {} of the replica", holder.id())),
            };
            if let Some(holder) = holder {
                return Err(JsonError::NameTaken { path: format!("{path}.name"), name: node.name.clone(), holder });
            }
            dictionary.check_node_type(&node.node_type).map_err(refused(format!("{path}.type")))?;
            for (name, value) in &node.attrs {
                dictionary
                    .check_attr(name, value.value_type())
                    .map_err(refused(format!("{path}.attribute{}", key_segment(name))))?;
            }
        }
        for (key, attrs) in &self.edges {
            let path = link_path(key);
            for (end, id) in [("src", key.from), ("dst", key.to)] {
                if !self.nodes.contains_key(&id) && replica.node(id).is_none() {
                    return Err(JsonError::MissingEndpoint { path: format!("{path}.{end}"), id });
                }
            }
            if replica.edge(key).is_some() {
                return Err(JsonError::EdgeExists { path, key: key.clone() });
            }
            dictionary.check_edge_type(&key.edge_type).map_err(refused(format!("{path}.label")))?;
            for (name, value) in attrs {
                dictionary
                    .check_attr(name, value.value_type())
                    .map_err(refused(format!("{path}.linkAttribute{}", key_segment(name))))?;
            }
        }
        Ok(())
    }
}
