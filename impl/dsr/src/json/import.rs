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
    /// What a lenient import accepted with a warning: names the dictionary learnt, attribute types kept although
    /// the dictionary declares another, links skipped because an end is missing.
    pub warnings: Vec<JsonWarning>,
}

fn symbol_path(id: NodeId) -> String {
    format!("DSRModel.symbols[\"{id}\"]")
}

fn link_path(key: &EdgeKey) -> String {
    format!("DSRModel.symbols[\"{}\"].links[dst={}, label={:?}]", key.from, key.to, cut(&key.edge_type, 64))
}

impl CortexGraph {
    /// Inserts every symbol and link into `replica` leniently: [`CortexGraph::import_with`] with
    /// [`Strictness::Lenient`].
    ///
    /// # Errors
    /// As [`CortexGraph::import_with`].
    pub fn import_into(&self, replica: &mut Replica, now_ns: u64) -> Result<ImportReport, JsonError> {
        self.import_with(replica, now_ns, Strictness::Lenient)
    }

    /// Inserts every symbol and link into `replica` with their ids, as local operations at `now_ns`.
    ///
    /// Leniently (what the C++ loader accepts), names the replica's dictionary does not know join it, an attribute
    /// whose type differs from the one the dictionary declares keeps the file's type (and that name accepts it
    /// from then on), and a link whose end is neither in the file nor visible in the replica is skipped; each with
    /// a warning in the report. Strictly, each of those is an error.
    ///
    /// All or nothing: everything is checked first (ids already used or deleted in the replica, names taken in
    /// the file or the replica, invalid names, links the replica already has, and what the strictness refuses); on
    /// any error the replica, and its dictionary, are unchanged. Links may end at nodes the replica already holds.
    ///
    /// # Errors
    /// [`JsonError`] naming the symbol or link at fault.
    pub fn import_with(
        &self,
        replica: &mut Replica,
        now_ns: u64,
        strictness: Strictness,
    ) -> Result<ImportReport, JsonError> {
        // Staged on a copy, so that a refusal at any point, even an unforeseen one, leaves the replica unchanged.
        let mut staged = replica.clone();
        let mut warnings = Vec::new();
        if strictness == Strictness::Lenient {
            warnings = self.learn_names(staged.dictionary_mut())?;
        }
        let edges = self.importable_edges(&staged, strictness, &mut warnings)?;
        self.validate_import(&staged, &edges)?;
        let mut deltas = Vec::with_capacity(self.nodes.len() + edges.len());
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
        for (key, attrs) in &edges {
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
        Ok(ImportReport { nodes: self.nodes.len(), edges: edges.len(), attributes, deltas, warnings })
    }

    /// Teaches `dictionary` every name of the file it does not accept yet, with a warning at the first place each
    /// is met: unknown node and edge types and attribute names, and attribute types other than the declared one.
    fn learn_names(&self, dictionary: &mut Dictionary) -> Result<Vec<JsonWarning>, JsonError> {
        let mut warnings = Vec::new();
        let refused = |path: String| move |source| JsonError::Dictionary { path, source };
        let mut learn_attrs = |attrs: &Attributes, owner: String, dictionary: &mut Dictionary| {
            for (name, value) in attrs {
                let path = format!("{owner}{}", key_segment(name));
                let (found, declared) = (value.value_type(), dictionary.attr_type(name));
                if declared == Some(found) || dictionary.learned_types(name).contains(&found) {
                    continue;
                }
                dictionary.learn_attr(name, found).map_err(refused(path.clone()))?;
                let what = match declared {
                    None => format!("unknown attribute name {name:?} joins this graph's dictionary as {found}"),
                    Some(declared) => format!(
                        "attribute {name:?} has type {found} here and {declared} in the dictionary: kept as {found}"
                    ),
                };
                warnings.push(JsonWarning { path, what });
            }
            Ok::<(), JsonError>(())
        };
        let mut types = Vec::new();
        for (id, node) in &self.nodes {
            let path = symbol_path(*id);
            if dictionary.known_node_type(&node.node_type).is_none() {
                dictionary.learn_node_type(&node.node_type).map_err(refused(format!("{path}.type")))?;
                types.push(JsonWarning {
                    path: format!("{path}.type"),
                    what: format!("unknown node type {:?} joins this graph's dictionary", cut(&node.node_type, 64)),
                });
            }
            learn_attrs(&node.attrs, format!("{path}.attribute"), dictionary)?;
        }
        for (key, attrs) in &self.edges {
            let path = link_path(key);
            if dictionary.known_edge_type(&key.edge_type).is_none() {
                dictionary.learn_edge_type(&key.edge_type).map_err(refused(format!("{path}.label")))?;
                types.push(JsonWarning {
                    path: format!("{path}.label"),
                    what: format!("unknown edge type {:?} joins this graph's dictionary", cut(&key.edge_type, 64)),
                });
            }
            learn_attrs(attrs, format!("{path}.linkAttribute"), dictionary)?;
        }
        types.append(&mut warnings);
        Ok(types)
    }

    /// The links to import: every link whose ends are symbols of the file or visible nodes of the replica.
    /// Leniently, a link with a missing end is skipped with a warning (the C++ loader does the same); strictly, it
    /// is an error.
    fn importable_edges(
        &self,
        replica: &Replica,
        strictness: Strictness,
        warnings: &mut Vec<JsonWarning>,
    ) -> Result<Vec<(&EdgeKey, &Attributes)>, JsonError> {
        let mut edges = Vec::with_capacity(self.edges.len());
        'links: for (key, attrs) in &self.edges {
            for (end, id) in [("src", key.from), ("dst", key.to)] {
                if self.nodes.contains_key(&id) || replica.node(id).is_some() {
                    continue;
                }
                let path = format!("{}.{end}", link_path(key));
                if strictness == Strictness::Strict {
                    return Err(JsonError::MissingEndpoint { path, id });
                }
                let what = format!("node {id} does not exist in the file or the replica: the link is skipped");
                warnings.push(JsonWarning { path, what });
                continue 'links;
            }
            edges.push((key, attrs));
        }
        Ok(edges)
    }

    /// Every check of [`CortexGraph::import_with`] on the symbols and on the links to import (`edges`), against a
    /// copy of the replica's dictionary so that an unknown name first seen with one type and later with another is
    /// caught too.
    fn validate_import(&self, replica: &Replica, edges: &[(&EdgeKey, &Attributes)]) -> Result<(), JsonError> {
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
        for (key, attrs) in edges {
            let path = link_path(key);
            if replica.edge(key).is_some() {
                return Err(JsonError::EdgeExists { path, key: (*key).clone() });
            }
            dictionary.check_edge_type(&key.edge_type).map_err(refused(format!("{path}.label")))?;
            for (name, value) in attrs.iter() {
                dictionary
                    .check_attr(name, value.value_type())
                    .map_err(refused(format!("{path}.linkAttribute{}", key_segment(name))))?;
            }
        }
        Ok(())
    }
}
