//! The view model: what the page receives, as JSON. A snapshot holds every visible node and edge with their
//! attributes **summarised** (long vectors as length, min, max and a head; byte buffers as their length and, for
//! camera images, their size; long strings cut), plus the top-view world geometry: each node's pose in its RT
//! root's frame, laser scans as points and detections' covariance ellipses. A patch holds the same for the
//! elements that changed since the last message to that client, so a patch's size is bounded by the graph's
//! size, never by the update rate. Node ids travel as strings (minted ids exceed JavaScript's 2^53).

use std::collections::{BTreeMap, BTreeSet};

use dsr::kinematics::{RT, translation_mm};
use dsr::{EdgeKey, Element, NodeId, NodeRef, Replica, Value};
use nalgebra::{Point3, Vector3};
use serde_json::{Map, Value as Json, json};

/// Vectors up to this length are sent whole; longer ones as a summary.
pub const INLINE_VECTOR: usize = 16;
/// Elements of a vector's head sent with its summary.
pub const SUMMARY_HEAD: usize = 8;
/// Characters of a string sent inline.
pub const INLINE_STRING: usize = 2000;
/// Most elements of a vector sent when the page asks for all of it.
pub const MAX_EXPANDED: usize = 65_536;
/// Most points of one laser scan drawn in the world view.
pub const MAX_SCAN_POINTS: usize = 1000;

/// The page's key of an element: `n:ID` or `e:FROM:TO:TYPE`.
pub fn element_key(element: &Element) -> String {
    match element {
        Element::Node(id) => format!("n:{}", id.0),
        Element::Edge(key) => edge_key(key),
    }
}

/// The page's key of an edge.
pub fn edge_key(key: &EdgeKey) -> String {
    format!("e:{}:{}:{}", key.from.0, key.to.0, key.edge_type)
}

/// Parses a key made by [`element_key`].
///
/// # Errors
/// A message saying what is wrong with the key.
pub fn parse_element(text: &str) -> Result<Element, String> {
    let id = |s: &str| s.parse::<u64>().map(NodeId).map_err(|_| format!("`{s}` in element `{text}` is not a node id"));
    if let Some(rest) = text.strip_prefix("n:") {
        return Ok(Element::Node(id(rest)?));
    }
    if let Some(rest) = text.strip_prefix("e:") {
        let mut parts = rest.splitn(3, ':');
        if let (Some(from), Some(to), Some(edge_type)) = (parts.next(), parts.next(), parts.next()) {
            return Ok(Element::Edge(EdgeKey::new(id(from)?, id(to)?, edge_type)));
        }
    }
    Err(format!("element `{text}` is neither `n:ID` nor `e:FROM:TO:TYPE`"))
}

fn float(x: f64) -> Json {
    serde_json::Number::from_f64(x).map_or(Json::Null, Json::Number)
}

fn big(x: u64) -> Json {
    if x < (1 << 53) { json!(x) } else { json!(x.to_string()) }
}

fn vector_summary<T: Copy>(t: &str, values: &[T], as_f64: impl Fn(T) -> f64, one: impl Fn(T) -> Json) -> Json {
    if values.len() <= INLINE_VECTOR {
        return json!({"t": t, "v": values.iter().map(|&x| one(x)).collect::<Vec<_>>()});
    }
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    for &x in values {
        let x = as_f64(x);
        if x < min {
            min = x;
        }
        if x > max {
            max = x;
        }
    }
    json!({
        "t": t,
        "len": values.len(),
        "min": float(min),
        "max": float(max),
        "head": values[..SUMMARY_HEAD].iter().map(|&x| one(x)).collect::<Vec<_>>(),
    })
}

/// A value as the page shows it: `{"t": type, "v": value}`, or a summary without `v` for long vectors, byte
/// buffers and long strings. `image` is `[width, height]` when the buffer is a camera image.
pub fn value_json(value: &Value, image: Option<(usize, usize)>) -> Json {
    let t = value.value_type().name();
    match value {
        Value::String(s) if s.chars().count() > INLINE_STRING => {
            json!({"t": t, "v": s.chars().take(INLINE_STRING).collect::<String>(), "cut": s.chars().count()})
        }
        Value::String(s) => json!({"t": t, "v": &**s}),
        Value::I32(x) => json!({"t": t, "v": x}),
        Value::U32(x) => json!({"t": t, "v": x}),
        Value::U64(x) => json!({"t": t, "v": big(*x)}),
        Value::F32(x) => json!({"t": t, "v": float(f64::from(*x))}),
        Value::F64(x) => json!({"t": t, "v": float(*x)}),
        Value::Bool(x) => json!({"t": t, "v": x}),
        Value::VecF32(v) => vector_summary(t, v, f64::from, |x| float(f64::from(x))),
        Value::VecU64(v) => vector_summary(t, v, |x| x as f64, big),
        Value::F32x2(v) => vector_summary(t, v, f64::from, |x| float(f64::from(x))),
        Value::F32x3(v) => vector_summary(t, v, f64::from, |x| float(f64::from(x))),
        Value::F32x4(v) => vector_summary(t, v, f64::from, |x| float(f64::from(x))),
        Value::F32x6(v) => vector_summary(t, v, f64::from, |x| float(f64::from(x))),
        Value::Bytes(b) => match image {
            Some((w, h)) => json!({"t": t, "len": b.len(), "image": [w, h]}),
            None => json!({"t": t, "len": b.len()}),
        },
    }
}

/// A value whole (the page's "expand"), up to [`MAX_EXPANDED`] elements.
///
/// # Errors
/// When the value is too long to send, or is a byte buffer (images are served as pictures).
pub fn full_value_json(value: &Value) -> Result<Json, String> {
    let t = value.value_type().name();
    let len = match value {
        Value::VecF32(v) => v.len(),
        Value::VecU64(v) => v.len(),
        Value::Bytes(b) => return Err(format!("a byte buffer ({} bytes) is not shown as numbers", b.len())),
        _ => 0,
    };
    if len > MAX_EXPANDED {
        return Err(format!("{len} elements are more than the {MAX_EXPANDED} the page shows"));
    }
    Ok(match value {
        Value::VecF32(v) => json!({"t": t, "v": v.iter().map(|&x| float(f64::from(x))).collect::<Vec<_>>()}),
        Value::VecU64(v) => json!({"t": t, "v": v.iter().map(|&x| big(x)).collect::<Vec<_>>()}),
        Value::String(s) => json!({"t": t, "v": &**s}),
        other => value_json(other, None),
    })
}

/// Width, height and channels of byte attribute `name` of `node` if it is a picture: the node has integer
/// attributes `<name>_width`, `<name>_height` (and optionally `<name>_depth`, default 1 or 3 by size) whose
/// product is the buffer's length.
pub fn image_shape(node: &NodeRef<'_>, name: &str) -> Option<(usize, usize, usize)> {
    let Value::Bytes(bytes) = node.attr(name)? else { return None };
    let int = |suffix: &str| match node.attr(&format!("{name}_{suffix}")) {
        Some(Value::I32(x)) => usize::try_from(*x).ok(),
        Some(Value::U32(x)) => usize::try_from(*x).ok(),
        _ => None,
    };
    let (w, h) = (int("width")?, int("height")?);
    let pixels = w.checked_mul(h)?;
    if pixels == 0 {
        return None;
    }
    let depth = int("depth").unwrap_or(bytes.len() / pixels);
    (matches!(depth, 1 | 3) && pixels.checked_mul(depth) == Some(bytes.len())).then_some((w, h, depth))
}

/// An uncompressed 24-bit BMP (which every browser shows) of `rgb` pixels (`depth` 1: grey, 3: RGB, or BGR when
/// `bgr`), row-major from the top.
///
/// # Errors
/// When the buffer does not match the size or the picture is larger than 8192 x 8192.
pub fn bmp(width: usize, height: usize, depth: usize, bgr: bool, pixels: &[u8]) -> Result<Vec<u8>, String> {
    if width == 0 || height == 0 || width > 8192 || height > 8192 || !matches!(depth, 1 | 3) {
        return Err(format!("cannot draw a {width}x{height} picture with {depth} channels"));
    }
    if pixels.len() != width * height * depth {
        return Err(format!(
            "a {width}x{height}x{depth} picture needs {} bytes, got {}",
            width * height * depth,
            pixels.len()
        ));
    }
    let row = (width * 3).div_ceil(4) * 4;
    let size = 54 + row * height;
    let mut out = Vec::with_capacity(size);
    let u32le = |out: &mut Vec<u8>, x: usize| out.extend_from_slice(&(x as u32).to_le_bytes());
    out.extend_from_slice(b"BM");
    u32le(&mut out, size);
    u32le(&mut out, 0);
    u32le(&mut out, 54);
    u32le(&mut out, 40);
    u32le(&mut out, width);
    u32le(&mut out, height);
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&24u16.to_le_bytes());
    for x in [0, row * height, 2835, 2835, 0, 0] {
        u32le(&mut out, x);
    }
    for y in (0..height).rev() {
        let line = &pixels[y * width * depth..(y + 1) * width * depth];
        for px in line.chunks_exact(depth) {
            match (depth, bgr) {
                (1, _) => out.extend_from_slice(&[px[0], px[0], px[0]]),
                (_, true) => out.extend_from_slice(&[px[0], px[1], px[2]]),
                _ => out.extend_from_slice(&[px[2], px[1], px[0]]),
            }
        }
        out.resize(out.len() + row - width * 3, 0);
    }
    Ok(out)
}

/// The picture in byte attribute `name` of node `id`, as a BMP.
///
/// # Errors
/// When the node or attribute is missing or is not a picture.
pub fn node_image(replica: &Replica, id: NodeId, name: &str) -> Result<Vec<u8>, String> {
    let node = replica.node(id).ok_or_else(|| format!("node {id} is not visible"))?;
    let (w, h, depth) =
        image_shape(&node, name).ok_or_else(|| format!("attribute `{name}` of node {id} is not a picture"))?;
    let Some(Value::Bytes(bytes)) = node.attr(name) else { return Err(format!("node {id} has no `{name}`")) };
    let bgr = matches!(node.attr(&format!("{name}_encoding")), Some(Value::String(e)) if &**e == "bgr8");
    bmp(w, h, depth, bgr, bytes)
}

/// A node for the page: id, type, name and summarised attributes.
pub fn node_json(node: &NodeRef<'_>) -> Json {
    let mut attrs = Map::new();
    for (name, value) in node.attrs() {
        let image = image_shape(node, name).map(|(w, h, _)| (w, h));
        attrs.insert(name.to_string(), value_json(value, image));
    }
    json!({"id": node.id().0.to_string(), "type": node.node_type(), "name": node.name(), "attrs": attrs})
}

/// An edge for the page.
pub fn edge_json(edge: &dsr::EdgeRef<'_>) -> Json {
    let attrs: Map<String, Json> =
        edge.attrs().map(|(name, value)| (name.to_string(), value_json(value, None))).collect();
    json!({
        "key": edge_key(edge.key()),
        "from": edge.from().0.to_string(),
        "to": edge.to().0.to_string(),
        "type": edge.edge_type(),
        "attrs": attrs,
    })
}

/// The top view of the geometric nodes: per node `[x, y, z, yaw]` (mm, rad) in its RT root's frame and the root,
/// laser scans as `[x, y, z]` points and detections' covariance ellipses (`[xx, xy, yy]`, mm², in the x-y plane)
/// in the same frame. The page draws the plane of the two axes along which the poses spread most (CORTEX
/// world graphs are y-up, newer ones z-up).
pub fn world_json(replica: &Replica) -> Json {
    let mut poses = Map::new();
    let mut scans = Map::new();
    let mut ellipses = Map::new();
    let mut yaw_of = BTreeMap::new();
    for node in replica.nodes() {
        let id = node.id();
        let Some(root) = rt_root(replica, id) else { continue };
        let Ok(pose) = replica.transform(id, root) else { continue };
        let t = translation_mm(&pose);
        let x_axis = pose.rotation * Vector3::new(1.0, 0.0, 0.0);
        let yaw = x_axis[1].atan2(x_axis[0]);
        yaw_of.insert(id, yaw);
        poses.insert(id.0.to_string(), json!([float(t[0]), float(t[1]), float(t[2]), float(yaw), root.0.to_string()]));
        if let (Some(Value::VecF32(dists)), Some(Value::VecF32(angles))) =
            (node.attr("laser_dists"), node.attr("laser_angles"))
        {
            let n = dists.len().min(angles.len());
            let stride = n.div_ceil(MAX_SCAN_POINTS).max(1);
            let points: Vec<Json> = (0..n)
                .step_by(stride)
                .filter(|&i| dists[i].is_finite() && dists[i] > 0.0)
                .map(|i| {
                    let (d, a) = (f64::from(dists[i]), f64::from(angles[i]));
                    let p = pose * point(d * a.cos(), d * a.sin());
                    json!([float(p[0].round()), float(p[1].round()), float(p[2].round())])
                })
                .collect();
            scans.insert(id.0.to_string(), Json::Array(points));
        }
    }
    for node in replica.nodes() {
        let Some(Value::F32x4(c)) = node.attr("track_covariance_mm2") else { continue };
        let parent_yaw = replica
            .rt_parent_edge(node.id())
            .ok()
            .flatten()
            .and_then(|e| yaw_of.get(&e.from()).copied())
            .unwrap_or(0.0);
        let (s, k) = parent_yaw.sin_cos();
        let (a, b, d) = (f64::from(c[0]), f64::from(c[1]), f64::from(c[3]));
        // R C Rᵀ for a rotation by the sensor's yaw.
        let xx = k * k * a - 2.0 * k * s * b + s * s * d;
        let xy = k * s * (a - d) + (k * k - s * s) * b;
        let yy = s * s * a + 2.0 * k * s * b + k * k * d;
        ellipses.insert(node.id().0.to_string(), json!([float(xx), float(xy), float(yy)]));
    }
    json!({"poses": poses, "scans": scans, "ellipses": ellipses})
}

fn point(x: f64, y: f64) -> Point3<f64> {
    Point3::new(x, y, 0.0)
}

/// The root of `id`'s RT tree (a node without an RT parent), or `None` for a node that is in no RT edge at all or
/// whose ancestry is broken (cycle, several parents).
pub fn rt_root(replica: &Replica, id: NodeId) -> Option<NodeId> {
    let mut current = id;
    let mut steps = 0usize;
    let mut has_rt = replica.out_edges(id).any(|e| e.edge_type() == RT);
    while let Some(edge) = replica.rt_parent_edge(current).ok()? {
        has_rt = true;
        current = edge.from();
        steps += 1;
        if steps > replica.node_count() {
            return None;
        }
    }
    has_rt.then_some(current)
}

/// What changed since the last message to one client: elements to re-read (the latest value of each).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Dirty {
    /// Nodes touched.
    pub nodes: BTreeSet<NodeId>,
    /// Edges touched.
    pub edges: BTreeSet<EdgeKey>,
}

impl Dirty {
    /// Elements held.
    pub fn len(&self) -> usize {
        self.nodes.len() + self.edges.len()
    }

    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty() && self.edges.is_empty()
    }

    /// Records a change.
    pub fn add(&mut self, change: &dsr::Change) {
        use dsr::Change::*;
        match change {
            NodeInserted { id } | NodeDeleted { id } | NodeRenamed { id } => {
                self.nodes.insert(*id);
            }
            EdgeInserted { key } | EdgeDeleted { key } => {
                self.edges.insert(key.clone());
            }
            AttrUpdated { element, .. } | AttrRemoved { element, .. } => match element {
                Element::Node(id) => {
                    self.nodes.insert(*id);
                }
                Element::Edge(key) => {
                    self.edges.insert(key.clone());
                }
            },
        }
    }
}

/// The whole graph for the page.
pub fn snapshot_json(replica: &Replica, seq: u64) -> Json {
    let nodes: Vec<Json> = replica.nodes().map(|n| node_json(&n)).collect();
    let edges: Vec<Json> = replica.edges().map(|e| edge_json(&e)).collect();
    json!({"seq": seq, "nodes": nodes, "edges": edges, "world": world_json(replica)})
}

/// The current state of the elements in `dirty`: upserts for visible ones, deletions for the others, and the
/// world geometry again when something geometric changed.
pub fn patch_json(replica: &Replica, dirty: &Dirty, seq: u64) -> Json {
    let mut nodes = Vec::new();
    let mut deleted_nodes = Vec::new();
    let mut edges = Vec::new();
    let mut deleted_edges = Vec::new();
    let mut geometric = false;
    for &id in &dirty.nodes {
        match replica.node(id) {
            Some(node) => {
                geometric |= node.attr("laser_dists").is_some()
                    || node.attr("track_covariance_mm2").is_some()
                    || node.node_type() == "gaze_target";
                nodes.push(node_json(&node));
            }
            None => {
                geometric = true;
                deleted_nodes.push(json!(id.0.to_string()));
            }
        }
    }
    for key in &dirty.edges {
        geometric |= key.edge_type.as_str() == RT;
        match replica.edge(key) {
            Some(edge) => edges.push(edge_json(&edge)),
            None => deleted_edges.push(json!(edge_key(key))),
        }
    }
    let mut patch = json!({
        "seq": seq,
        "nodes": nodes,
        "deleted_nodes": deleted_nodes,
        "edges": edges,
        "deleted_edges": deleted_edges,
    });
    if geometric {
        patch["world"] = world_json(replica);
    }
    patch
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsr::{NewNode, ReplicaId};

    #[test]
    fn long_vectors_are_summarised_and_short_ones_sent_whole() {
        let short = value_json(&Value::VecF32(vec![1.0f32, 2.0, 3.0].into()), None);
        assert_eq!(short["v"], json!([1.0, 2.0, 3.0]));
        let long: Vec<f32> = (0..100).map(|i| i as f32 - 10.0).collect();
        let summary = value_json(&Value::VecF32(long.into()), None);
        assert_eq!(
            (summary["len"].as_u64(), summary["min"].as_f64(), summary["max"].as_f64()),
            (Some(100), Some(-10.0), Some(89.0))
        );
        assert!(summary.get("v").is_none());
        assert_eq!(summary["head"].as_array().map(Vec::len), Some(SUMMARY_HEAD));
        assert_eq!(value_json(&Value::U64(u64::MAX), None)["v"], json!(u64::MAX.to_string()));
    }

    #[test]
    fn element_keys_round_trip_and_bad_keys_say_why() {
        let edge = Element::Edge(EdgeKey::new(NodeId(5), NodeId(1 << 50), "RT"));
        assert_eq!(parse_element(&element_key(&edge)), Ok(edge));
        assert_eq!(parse_element("n:7"), Ok(Element::Node(NodeId(7))));
        assert!(parse_element("n:x").unwrap_err().contains("`x`"));
        assert!(parse_element("q:1").is_err());
        assert!(parse_element("e:1:2").is_err());
    }

    #[test]
    fn bmp_has_the_right_size_and_refuses_mismatched_buffers() {
        let grey = bmp(3, 2, 1, false, &[0, 1, 2, 3, 4, 5]).unwrap();
        assert_eq!(grey.len(), 54 + 12 * 2);
        assert_eq!(&grey[..2], b"BM");
        // Bottom row first: pixel (0, 1) = 3 as grey.
        assert_eq!(&grey[54..57], &[3, 3, 3]);
        assert!(bmp(3, 2, 3, false, &[0; 5]).is_err());
    }

    #[test]
    fn world_view_places_nodes_by_their_rt_transforms_and_scans_as_points() {
        let mut r = Replica::new(ReplicaId(1));
        let (world, _) = r.insert_node(1, NewNode::new("world", "world")).unwrap();
        let (laser, _) = r
            .insert_node(
                2,
                NewNode::new("laser", "laser")
                    .with_attr("laser_dists", Value::VecF32(vec![1000.0f32].into()))
                    .with_attr("laser_angles", Value::VecF32(vec![0.0f32].into())),
            )
            .unwrap();
        r.insert_edge(
            3,
            world,
            laser,
            "RT",
            vec![
                ("rt_translation".into(), vec![500.0f32, 0.0, 0.0].into()),
                ("rt_rotation_euler_xyz".into(), vec![0.0f32, 0.0, std::f32::consts::FRAC_PI_2].into()),
            ],
        )
        .unwrap();
        let w = world_json(&r);
        let pose = &w["poses"][laser.0.to_string()];
        assert_eq!(pose[0].as_f64(), Some(500.0));
        assert!((pose[3].as_f64().unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        // A beam straight ahead of a laser turned 90° lands 1 m to the world's +y.
        assert_eq!(w["scans"][laser.0.to_string()], json!([[500.0, 1000.0, 0.0]]));
    }
}
