//! # A web inspector for a DSR_d agent and BICA's debug primitives
//!
//! [`Inspector::start`] serves a page (embedded in the binary: plain HTML, JS and CSS, no CDN, no build step) with
//! four live views of the graph an agent holds — a graph drawing, the RT tree, a 2-D top view of the geometric
//! nodes, and the Debug view of a BICA runtime's components and their debug primitives — and, when allowed,
//! edits through the normal agent API.
//!
//! - [`feed`]: the only contact with the agent API ([`feed::GraphFeed`], implemented for `agent::Agent`).
//! - [`view`]: the JSON the page receives: snapshots and patches with summarised values, world geometry.
//! - [`stream`]: the bounded, coalescing, rate-limited server-sent event stream.
//! - [`http`]: a small HTTP/1.1 server with size limits and time-outs.
//! - [`edit`]: edit requests from the page, parsed by the dictionary's types.
//! - [`debug`]: [`debug::DebugSource`] and its implementations for an in-process `bica` runtime and for the
//!   runtime of another agent, called over the network.
//! - [`demo`]: a camera-detector role on the bundled EuRoC frames, for `cortex inspect --demo`.

pub mod debug;
pub mod demo;
pub mod edit;
pub mod feed;
pub mod http;
pub mod stream;
pub mod view;

use std::io::Write;
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bica::debug::DebugFrame;
use serde_json::{Value as Json, json};

use crate::debug::{ComponentInfo, DebugSource};
use crate::edit::EditRequest;
use crate::feed::{EditOutcome, GraphFeed};
use crate::http::{Handled, Request, Response, Server};
use crate::stream::{Client, Hub, MIN_INTERVAL};

/// How often the Debug view's data is refreshed (at most).
pub const DEBUG_INTERVAL: Duration = Duration::from_millis(500);
/// A comment line is sent on an idle stream this often, so dead connections are noticed.
pub const KEEPALIVE: Duration = Duration::from_secs(10);

const INDEX_HTML: &str = include_str!("../assets/index.html");
const APP_JS: &str = include_str!("../assets/app.js");
const STYLE_CSS: &str = include_str!("../assets/style.css");

/// Settings of an inspector.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InspectorConfig {
    /// Where to listen (loopback by default).
    pub listen: SocketAddr,
    /// Whether the page may edit the graph.
    pub allow_edit: bool,
    /// A title for the page header.
    pub title: String,
}

impl Default for InspectorConfig {
    fn default() -> Self {
        InspectorConfig {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            allow_edit: false,
            title: "cortex inspect".into(),
        }
    }
}

/// Why the inspector could not start.
#[derive(Debug, thiserror::Error)]
pub enum InspectorError {
    /// The address could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// A thread could not be started.
    #[error("cannot start the inspector's update thread: {0}")]
    Thread(std::io::Error),
}

struct DebugCache {
    refreshed: Option<Instant>,
    components: Result<Vec<ComponentInfo>, String>,
    frame: Option<Arc<DebugFrame>>,
    frame_error: Option<String>,
}

struct Shared {
    feed: Arc<dyn GraphFeed>,
    debug: Option<Arc<dyn DebugSource>>,
    config: InspectorConfig,
    hub: Hub,
    seq: AtomicU64,
    debug_cache: Mutex<DebugCache>,
}

/// A running inspector: the HTTP server and the update thread. Dropping it stops both.
pub struct Inspector {
    shared: Arc<Shared>,
    server: Server,
    hub_thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Inspector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Inspector").field("addr", &self.server.addr()).finish_non_exhaustive()
    }
}

impl Inspector {
    /// Serves the page for `feed` (and `debug`, if given) on `config.listen`.
    ///
    /// # Errors
    /// [`InspectorError`] if the address cannot be bound or a thread cannot start.
    pub fn start(
        feed: Arc<dyn GraphFeed>,
        debug: Option<Arc<dyn DebugSource>>,
        config: InspectorConfig,
    ) -> Result<Inspector, InspectorError> {
        let listen = config.listen;
        let shared = Arc::new(Shared {
            feed,
            debug,
            config,
            hub: Hub::default(),
            seq: AtomicU64::new(0),
            debug_cache: Mutex::new(DebugCache {
                refreshed: None,
                components: Ok(Vec::new()),
                frame: None,
                frame_error: None,
            }),
        });
        let hub_shared = Arc::clone(&shared);
        let hub_thread = std::thread::Builder::new()
            .name("inspector-hub".into())
            .spawn(move || hub_shared.hub.run(&*hub_shared.feed))
            .map_err(InspectorError::Thread)?;
        let handler_shared = Arc::clone(&shared);
        let server = Server::start(listen, Arc::new(move |request| route(&handler_shared, request)))
            .map_err(|source| InspectorError::Listen { addr: listen, source })?;
        Ok(Inspector { shared, server, hub_thread: Some(hub_thread) })
    }

    /// The address the page is served on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr()
    }

    /// Streaming clients connected.
    pub fn clients(&self) -> usize {
        self.shared.hub.client_count()
    }
}

impl Drop for Inspector {
    fn drop(&mut self) {
        self.shared.hub.stop();
        self.server.stop();
        if let Some(thread) = self.hub_thread.take() {
            let _ = thread.join();
        }
    }
}

fn read_json(shared: &Shared, f: impl FnOnce(&dsr::Replica) -> Result<Json, Response>) -> Response {
    let mut f = Some(f);
    let mut out = None;
    let ready = shared.feed.read(&mut |replica| {
        if let Some(f) = f.take() {
            out = Some(f(replica));
        }
    });
    match out {
        Some(Ok(json)) => Response::json(200, &json),
        Some(Err(response)) => response,
        None if !ready => Response::error(503, "the agent has not joined a graph yet"),
        None => Response::error(500, "the graph could not be read"),
    }
}

fn route(shared: &Arc<Shared>, request: Request) -> Handled {
    let response = match (request.method.as_str(), request.path.as_str()) {
        ("GET", "/") | ("GET", "/index.html") => Response::new(200, "text/html; charset=utf-8", INDEX_HTML),
        ("GET", "/app.js") => Response::new(200, "text/javascript; charset=utf-8", APP_JS),
        ("GET", "/style.css") => Response::new(200, "text/css; charset=utf-8", STYLE_CSS),
        ("GET", "/api/config") => Response::json(
            200,
            &json!({"allow_edit": shared.config.allow_edit, "title": shared.config.title, "debug": shared.debug.is_some()}),
        ),
        ("GET", "/api/snapshot") => {
            let seq = shared.seq.fetch_add(1, Ordering::Relaxed);
            read_json(shared, |r| Ok(view::snapshot_json(r, seq)))
        }
        ("GET", "/api/status") => Response::json(200, &status_json(shared, None)),
        ("GET", "/api/attr") => attr(shared, &request),
        ("GET", "/api/image") => image(shared, &request),
        ("POST", "/api/edit") => edit(shared, &request),
        ("GET", "/api/debug") => Response::json(200, &debug_json(shared, true)),
        ("GET", "/api/debug/image") => debug_image(shared, &request),
        ("POST", "/api/debug/mark") => debug_mark(shared, &request),
        ("GET", "/api/events") => return events(shared),
        (_, "/" | "/app.js" | "/style.css" | "/api/snapshot" | "/api/edit" | "/api/events" | "/api/debug/mark") => {
            Response::error(405, format!("{} is not allowed on {}", request.method, request.path))
        }
        _ => Response::error(404, format!("nothing at {}", request.path)),
    };
    Handled::Respond(response)
}

fn attr(shared: &Shared, request: &Request) -> Response {
    let (Some(element), Some(name)) = (request.param("el"), request.param("name")) else {
        return Response::error(400, "/api/attr needs `el` and `name`");
    };
    let element = match view::parse_element(element) {
        Ok(element) => element,
        Err(e) => return Response::error(400, e),
    };
    let name = name.to_owned();
    read_json(shared, move |r| {
        let value = match &element {
            dsr::Element::Node(id) => r.node(*id).and_then(|n| n.attr(&name).cloned()),
            dsr::Element::Edge(key) => r.edge(key).and_then(|e| e.attr(&name).cloned()),
        };
        let value = value.ok_or_else(|| Response::error(404, format!("no attribute `{name}` on {element:?}")))?;
        view::full_value_json(&value).map_err(|e| Response::error(422, e))
    })
}

fn image(shared: &Shared, request: &Request) -> Response {
    let (Some(node), Some(name)) = (request.param("node"), request.param("attr")) else {
        return Response::error(400, "/api/image needs `node` and `attr`");
    };
    let Ok(id) = node.parse::<u64>() else { return Response::error(400, format!("`{node}` is not a node id")) };
    let mut out = None;
    let ready = shared.feed.read(&mut |r| out = Some(view::node_image(r, dsr::NodeId(id), name)));
    match out {
        Some(Ok(bytes)) => Response::new(200, "image/bmp", bytes),
        Some(Err(e)) => Response::error(404, e),
        None => Response::error(503, format!("the agent has no graph yet (ready: {ready})")),
    }
}

fn edit(shared: &Shared, request: &Request) -> Response {
    if !shared.config.allow_edit {
        return Response::error(403, "this inspector is read-only (start it with --allow-edit)");
    }
    let parsed: EditRequest = match serde_json::from_slice(&request.body) {
        Ok(parsed) => parsed,
        Err(e) => return Response::error(400, format!("edit request: {e}")),
    };
    let mut types = std::collections::BTreeMap::new();
    shared.feed.read(&mut |r| {
        if let EditRequest::SetAttr { name, .. } = &parsed {
            types.insert(name.clone(), r.dictionary().attr_type(name));
        }
    });
    let edit = match parsed.into_edit(|name| types.get(name).copied().flatten()) {
        Ok(edit) => edit,
        Err(e) => return Response::error(400, e),
    };
    match shared.feed.edit(edit) {
        Ok(EditOutcome::Done) => Response::json(200, &json!({"ok": true})),
        Ok(EditOutcome::Node(id)) => Response::json(200, &json!({"ok": true, "id": id.0.to_string()})),
        Err(e) => Response::error(422, e),
    }
}

fn refresh_debug(shared: &Shared) -> std::sync::MutexGuard<'_, DebugCache> {
    let mut cache = shared.debug_cache.lock().unwrap_or_else(|p| p.into_inner());
    let Some(source) = &shared.debug else { return cache };
    if cache.refreshed.is_some_and(|at| at.elapsed() < DEBUG_INTERVAL) {
        return cache;
    }
    cache.refreshed = Some(Instant::now());
    cache.components = source.components();
    match source.latest_frame() {
        Ok(frame) => {
            cache.frame = Some(Arc::new(frame));
            cache.frame_error = None;
        }
        Err(e) => cache.frame_error = Some(e),
    }
    cache
}

fn debug_json(shared: &Shared, with_frame: bool) -> Json {
    if shared.debug.is_none() {
        return json!({"available": false});
    }
    let cache = refresh_debug(shared);
    let components = match &cache.components {
        Ok(list) => json!(list),
        Err(e) => json!({"error": e}),
    };
    let frame = match (&cache.frame, with_frame) {
        (Some(frame), true) => debug::frame_json(frame),
        _ => Json::Null,
    };
    json!({"available": true, "components": components, "frame": frame, "error": cache.frame_error})
}

fn debug_image(shared: &Shared, request: &Request) -> Response {
    let Some(index) = request.param("i").and_then(|i| i.parse::<usize>().ok()) else {
        return Response::error(400, "/api/debug/image needs a numeric `i`");
    };
    let frame = shared.debug_cache.lock().unwrap_or_else(|p| p.into_inner()).frame.clone();
    match frame {
        Some(frame) => match debug::frame_image(&frame, index) {
            Ok(bytes) => Response::new(200, "image/bmp", bytes),
            Err(e) => Response::error(404, e),
        },
        None => Response::error(404, "no debug frame yet"),
    }
}

fn debug_mark(shared: &Shared, request: &Request) -> Response {
    #[derive(serde::Deserialize)]
    struct Mark {
        component: String,
        on: bool,
    }
    let Some(source) = &shared.debug else { return Response::error(404, "no debug source is connected") };
    let mark: Mark = match serde_json::from_slice(&request.body) {
        Ok(mark) => mark,
        Err(e) => return Response::error(400, format!("mark request: {e}")),
    };
    match source.set_debug(&mark.component, mark.on) {
        Ok(()) => {
            // The next refresh shows the change.
            shared.debug_cache.lock().unwrap_or_else(|p| p.into_inner()).refreshed = None;
            Response::json(200, &json!({"ok": true}))
        }
        Err(e) => Response::error(422, e),
    }
}

fn status_json(shared: &Shared, client: Option<&Client>) -> Json {
    json!({
        "agent": shared.feed.status(),
        "clients": shared.hub.client_count(),
        "signals": shared.hub.signals(),
        "stream": client.map(Client::counters),
        "min_interval_ms": MIN_INTERVAL.as_millis() as u64,
        "max_pending": stream::MAX_PENDING,
    })
}

fn events(shared: &Arc<Shared>) -> Handled {
    let Some(client) = shared.hub.join() else {
        return Handled::Respond(Response::error(503, "too many pages are streaming from this inspector"));
    };
    let shared = Arc::clone(shared);
    Handled::Stream(Box::new(move |mut stream: TcpStream| {
        let _ = stream_events(&shared, &client, &mut stream);
        shared.hub.leave(&client);
    }))
}

fn send(stream: &mut TcpStream, event: &str, data: &Json) -> std::io::Result<()> {
    let text = data.to_string();
    write!(stream, "event: {event}\ndata: {text}\n\n")?;
    stream.flush()
}

fn snapshot(shared: &Shared) -> Option<Json> {
    let seq = shared.seq.fetch_add(1, Ordering::Relaxed);
    let mut out = None;
    shared.feed.read(&mut |r| out = Some(view::snapshot_json(r, seq)));
    out
}

fn stream_events(shared: &Shared, client: &Client, stream: &mut TcpStream) -> std::io::Result<()> {
    write!(
        stream,
        "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n"
    )?;
    let mut need_snapshot = true;
    let mut last_sent = Instant::now() - MIN_INTERVAL;
    let mut last_debug: Option<Instant> = None;
    let mut last_status = Instant::now() - Duration::from_secs(1);
    let mut last_frame_at = None;
    loop {
        let wait = if need_snapshot { Duration::from_millis(200) } else { DEBUG_INTERVAL.min(KEEPALIVE) };
        let since = last_sent.elapsed();
        if since < MIN_INTERVAL {
            std::thread::sleep(MIN_INTERVAL - since);
        }
        let pending = client.wait_take(wait);
        let mut wrote = false;
        if need_snapshot || pending.resync {
            match snapshot(shared) {
                Some(data) => {
                    send(stream, "snapshot", &data)?;
                    need_snapshot = false;
                    wrote = true;
                }
                None => need_snapshot = true,
            }
        } else if !pending.dirty.is_empty() {
            let seq = shared.seq.fetch_add(1, Ordering::Relaxed);
            let mut out = None;
            shared.feed.read(&mut |r| out = Some(view::patch_json(r, &pending.dirty, seq)));
            if let Some(data) = out {
                send(stream, "patch", &data)?;
                wrote = true;
            }
        }
        if shared.debug.is_some() && last_debug.is_none_or(|at| at.elapsed() >= DEBUG_INTERVAL) {
            last_debug = Some(Instant::now());
            let data = debug_json(shared, false);
            let frame_at = shared.debug_cache.lock().unwrap_or_else(|p| p.into_inner()).frame.as_ref().map(|f| f.at_ns);
            let mut data = data;
            if frame_at != last_frame_at {
                last_frame_at = frame_at;
                let frame = shared.debug_cache.lock().unwrap_or_else(|p| p.into_inner()).frame.clone();
                data["frame"] = frame.map_or(Json::Null, |f| debug::frame_json(&f));
            }
            send(stream, "debug", &data)?;
            wrote = true;
        }
        if last_status.elapsed() >= Duration::from_secs(1) {
            last_status = Instant::now();
            send(stream, "status", &status_json(shared, Some(client)))?;
            wrote = true;
        }
        if wrote {
            client.sent();
            last_sent = Instant::now();
        } else if last_sent.elapsed() >= KEEPALIVE {
            stream.write_all(b": keepalive\n\n")?;
            stream.flush()?;
            last_sent = Instant::now();
        }
    }
}
