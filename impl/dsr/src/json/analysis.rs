//! The analysis behind `cortex graph info`: counts, RT depth, dangling links, several parents, RT cycles, and
//! the names outside the built-in dictionary.

use super::*;

/// A summary of a graph's contents and RT structure, for `cortex graph info`. Node ids serialize as decimal
/// strings, like in CORTEX JSON.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct GraphAnalysis {
    /// Number of symbols.
    pub nodes: usize,
    /// Number of links.
    pub edges: usize,
    /// Number of attributes on symbols and links.
    pub attributes: usize,
    /// Symbols by node type.
    pub node_types: BTreeMap<String, usize>,
    /// Links by label.
    pub edge_labels: BTreeMap<String, usize>,
    /// Attributes by value type, in type-code order (types that do not occur are left out).
    pub attribute_types: Vec<TypeCount>,
    /// Attributes by (name, value type), in that order.
    pub attribute_names: Vec<AttributeCount>,
    /// RT links on the longest path from an RT root (a node without an RT parent) down to a leaf; nodes on or
    /// below an RT cycle are not counted.
    pub rt_depth: usize,
    /// Symbols that have RT children but no RT parent.
    #[serde(serialize_with = "ids_as_text")]
    pub rt_roots: Vec<NodeId>,
    /// Links whose src or dst is not a symbol of the graph.
    pub dangling_links: Vec<DanglingLink>,
    /// Groups of symbols that reach each other along RT links (each group holds at least one cycle), each sorted.
    #[serde(serialize_with = "id_groups_as_text")]
    pub rt_cycles: Vec<Vec<NodeId>>,
    /// Symbols with more than one RT parent.
    pub several_rt_parents: Vec<SeveralParents>,
    /// Names the built-in dictionary does not know, or knows with another type: a lenient import teaches them
    /// to the graph's dictionary, a strict one refuses them.
    pub outside_dictionary: OutsideDictionary,
}

/// The names of a graph that the built-in dictionary does not know, or knows with another type.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct OutsideDictionary {
    /// Unknown node types.
    pub node_types: Vec<String>,
    /// Unknown edge labels.
    pub edge_labels: Vec<String>,
    /// Unknown attribute names.
    pub attributes: Vec<String>,
    /// Attribute names stored with a type other than the built-in one: `name: file type (dictionary type)`.
    pub other_types: Vec<String>,
}

/// How many attributes have one value type.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct TypeCount {
    /// The value type, e.g. `f32`.
    #[serde(serialize_with = "type_as_text")]
    pub value_type: ValueType,
    /// Its CORTEX type code.
    pub code: u8,
    /// Attributes of this type.
    pub count: usize,
}

/// How often an attribute name occurs with one value type.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct AttributeCount {
    /// The attribute name.
    pub name: String,
    /// Its value type.
    #[serde(serialize_with = "type_as_text")]
    pub value_type: ValueType,
    /// Occurrences on symbols.
    pub on_nodes: usize,
    /// Occurrences on links.
    pub on_edges: usize,
}

/// A link with an end that is not a symbol.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct DanglingLink {
    /// Source.
    #[serde(serialize_with = "id_as_text")]
    pub src: NodeId,
    /// Destination.
    #[serde(serialize_with = "id_as_text")]
    pub dst: NodeId,
    /// Label.
    pub label: String,
    /// Which ends are missing: `src`, `dst` or both.
    pub missing: Vec<&'static str>,
}

/// A symbol with several RT parents.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct SeveralParents {
    /// The symbol.
    #[serde(serialize_with = "id_as_text")]
    pub node: NodeId,
    /// Its RT parents, in id order.
    #[serde(serialize_with = "ids_as_text")]
    pub parents: Vec<NodeId>,
}

fn id_as_text<S: Serializer>(id: &NodeId, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_str(id)
}

fn ids_as_text<S: Serializer>(ids: &[NodeId], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(ids.iter().map(NodeId::to_string))
}

fn id_groups_as_text<S: Serializer>(groups: &[Vec<NodeId>], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(groups.iter().map(|group| group.iter().map(NodeId::to_string).collect::<Vec<_>>()))
}

fn type_as_text<S: Serializer>(value_type: &ValueType, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(value_type.name())
}

/// The names among these counts that the built-in dictionary does not know, or knows with another type.
fn outside_dictionary(
    node_types: &BTreeMap<String, usize>,
    edge_labels: &BTreeMap<String, usize>,
    by_name: &BTreeMap<(String, ValueType), (usize, usize)>,
) -> OutsideDictionary {
    let builtin = Dictionary::builtin();
    let unknown = |names: &BTreeMap<String, usize>, known: &dyn Fn(&str) -> bool| -> Vec<String> {
        names.keys().filter(|name| !known(name)).cloned().collect()
    };
    let mut outside = OutsideDictionary {
        node_types: unknown(node_types, &|name| builtin.known_node_type(name).is_some()),
        edge_labels: unknown(edge_labels, &|name| builtin.known_edge_type(name).is_some()),
        ..OutsideDictionary::default()
    };
    for (name, value_type) in by_name.keys() {
        match builtin.attr_type(name) {
            None if outside.attributes.last() != Some(name) => outside.attributes.push(name.clone()),
            Some(declared) if declared != *value_type => {
                outside.other_types.push(format!("{name}: {value_type} (dictionary: {declared})"));
            }
            _ => {}
        }
    }
    outside
}

impl CortexGraph {
    /// RT links between two symbols of the graph, as parent → children lists (children in id order).
    fn rt_children(&self) -> BTreeMap<NodeId, Vec<NodeId>> {
        let mut children: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
        for key in self.edges.keys() {
            if &*key.edge_type == RT && self.nodes.contains_key(&key.from) && self.nodes.contains_key(&key.to) {
                children.entry(key.from).or_default().push(key.to);
            }
        }
        children
    }

    /// Counts and RT structure of the graph. Runs in time linear in the graph's size, cycles included.
    pub fn analyze(&self) -> GraphAnalysis {
        let mut node_types: BTreeMap<String, usize> = BTreeMap::new();
        let mut edge_labels: BTreeMap<String, usize> = BTreeMap::new();
        let mut by_name: BTreeMap<(String, ValueType), (usize, usize)> = BTreeMap::new();
        for node in self.nodes.values() {
            *node_types.entry(node.node_type.clone()).or_default() += 1;
            for (name, value) in &node.attrs {
                by_name.entry((name.clone(), value.value_type())).or_default().0 += 1;
            }
        }
        let mut dangling_links = Vec::new();
        for (key, attrs) in &self.edges {
            *edge_labels.entry(key.edge_type.to_string()).or_default() += 1;
            for (name, value) in attrs {
                by_name.entry((name.clone(), value.value_type())).or_default().1 += 1;
            }
            let missing: Vec<&'static str> = [("src", key.from), ("dst", key.to)]
                .into_iter()
                .filter(|(_, id)| !self.nodes.contains_key(id))
                .map(|(end, _)| end)
                .collect();
            if !missing.is_empty() {
                dangling_links.push(DanglingLink {
                    src: key.from,
                    dst: key.to,
                    label: key.edge_type.to_string(),
                    missing,
                });
            }
        }
        let mut by_type: BTreeMap<ValueType, usize> = BTreeMap::new();
        for ((_, value_type), (on_nodes, on_edges)) in &by_name {
            *by_type.entry(*value_type).or_default() += on_nodes + on_edges;
        }
        let children = self.rt_children();
        let mut parents: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
        for (parent, kids) in &children {
            for kid in kids {
                parents.entry(*kid).or_default().push(*parent);
            }
        }
        let rt_roots = children.keys().filter(|id| !parents.contains_key(id)).copied().collect();
        let outside_dictionary = outside_dictionary(&node_types, &edge_labels, &by_name);
        GraphAnalysis {
            nodes: self.nodes.len(),
            edges: self.edges.len(),
            attributes: by_type.values().sum(),
            node_types,
            edge_labels,
            attribute_types: by_type
                .into_iter()
                .map(|(value_type, count)| TypeCount { value_type, code: value_type.code(), count })
                .collect(),
            attribute_names: by_name
                .into_iter()
                .map(|((name, value_type), (on_nodes, on_edges))| AttributeCount {
                    name,
                    value_type,
                    on_nodes,
                    on_edges,
                })
                .collect(),
            rt_depth: self.rt_depth(&children, &parents),
            rt_roots,
            dangling_links,
            rt_cycles: rt_cycles(&children),
            several_rt_parents: parents
                .into_iter()
                .filter(|(_, parents)| parents.len() > 1)
                .map(|(node, parents)| SeveralParents { node, parents })
                .collect(),
            outside_dictionary,
        }
    }

    /// The longest root-to-leaf RT path, in links, by visiting nodes in topological order (Kahn's algorithm):
    /// nodes on or below a cycle are never reached, so a cycle cannot make it loop.
    fn rt_depth(&self, children: &BTreeMap<NodeId, Vec<NodeId>>, parents: &BTreeMap<NodeId, Vec<NodeId>>) -> usize {
        let mut waiting: BTreeMap<NodeId, usize> =
            parents.iter().map(|(node, parents)| (*node, parents.len())).collect();
        let mut depth: BTreeMap<NodeId, usize> = BTreeMap::new();
        let mut ready: Vec<NodeId> = self.nodes.keys().filter(|id| !parents.contains_key(id)).copied().collect();
        for root in &ready {
            depth.insert(*root, 0);
        }
        let mut deepest = 0;
        while let Some(node) = ready.pop() {
            let here = depth.get(&node).copied().unwrap_or(0);
            deepest = deepest.max(here);
            for child in children.get(&node).into_iter().flatten() {
                let below = depth.entry(*child).or_insert(0);
                *below = (*below).max(here + 1);
                if let Some(count) = waiting.get_mut(child) {
                    *count -= 1;
                    if *count == 0 {
                        ready.push(*child);
                    }
                }
            }
        }
        deepest
    }
}

/// The strongly connected groups of the RT graph that contain a cycle (more than one node, or a self-link),
/// found with Kosaraju's two passes, both iterative so that no graph can overflow the stack.
fn rt_cycles(children: &BTreeMap<NodeId, Vec<NodeId>>) -> Vec<Vec<NodeId>> {
    let mut reverse: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
    let mut all: BTreeSet<NodeId> = BTreeSet::new();
    for (parent, kids) in children {
        all.insert(*parent);
        for kid in kids {
            all.insert(*kid);
            reverse.entry(*kid).or_default().push(*parent);
        }
    }
    let empty: Vec<NodeId> = Vec::new();
    // Pass 1: nodes in order of finishing a depth-first search.
    let mut finished: Vec<NodeId> = Vec::with_capacity(all.len());
    let mut visited: BTreeSet<NodeId> = BTreeSet::new();
    for start in &all {
        if !visited.insert(*start) {
            continue;
        }
        let mut stack: Vec<(NodeId, usize)> = vec![(*start, 0)];
        while let Some((node, next)) = stack.last_mut() {
            let kids = children.get(node).unwrap_or(&empty);
            if let Some(kid) = kids.get(*next) {
                *next += 1;
                if visited.insert(*kid) {
                    stack.push((*kid, 0));
                }
            } else {
                finished.push(*node);
                stack.pop();
            }
        }
    }
    // Pass 2: on the reversed graph, in reverse finishing order; each search collects one group.
    let mut assigned: BTreeSet<NodeId> = BTreeSet::new();
    let mut cycles = Vec::new();
    for start in finished.iter().rev() {
        if !assigned.insert(*start) {
            continue;
        }
        let mut group = vec![*start];
        let mut stack = vec![*start];
        while let Some(node) = stack.pop() {
            for parent in reverse.get(&node).unwrap_or(&empty) {
                if assigned.insert(*parent) {
                    group.push(*parent);
                    stack.push(*parent);
                }
            }
        }
        let self_link = children.get(start).is_some_and(|kids| kids.contains(start));
        if group.len() > 1 || self_link {
            group.sort_unstable();
            cycles.push(group);
        }
    }
    cycles.sort();
    cycles
}
