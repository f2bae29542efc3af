//! A small HTTP/1.1 server on `std::net`: one thread per connection, at most [`MAX_CONNECTIONS`] at once (more get
//! `503`), one request per connection (`Connection: close`), request heads up to [`MAX_HEAD`] bytes and bodies up to
//! [`MAX_BODY`] bytes, read and write time-outs so a stalled peer cannot hold a thread. A handler either answers
//! with a [`Response`] or keeps the stream (server-sent events).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Largest request line plus headers.
pub const MAX_HEAD: usize = 16 << 10;
/// Largest request body.
pub const MAX_BODY: usize = 1 << 20;
/// Most connections served at once.
pub const MAX_CONNECTIONS: usize = 64;
/// Read and write time-out of a connection.
pub const IO_TIMEOUT: Duration = Duration::from_secs(10);

/// A parsed request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    /// `GET`, `POST`, ...
    pub method: String,
    /// The path without the query.
    pub path: String,
    /// Query parameters, percent-decoded.
    pub query: Vec<(String, String)>,
    /// The body.
    pub body: Vec<u8>,
}

impl Request {
    /// The first query parameter called `name`.
    pub fn param(&self, name: &str) -> Option<&str> {
        self.query.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }
}

/// An answer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Response {
    /// Status code.
    pub status: u16,
    /// `Content-Type`.
    pub content_type: &'static str,
    /// The body.
    pub body: Vec<u8>,
}

impl Response {
    /// A response.
    pub fn new(status: u16, content_type: &'static str, body: impl Into<Vec<u8>>) -> Self {
        Response { status, content_type, body: body.into() }
    }

    /// A JSON response.
    pub fn json(status: u16, value: &serde_json::Value) -> Self {
        Response::new(status, "application/json", value.to_string())
    }

    /// A JSON error `{"error": message}`.
    pub fn error(status: u16, message: impl std::fmt::Display) -> Self {
        Response::json(status, &serde_json::json!({ "error": message.to_string() }))
    }
}

/// What a handler does with a request.
pub enum Handled {
    /// Send this response and close.
    Respond(Response),
    /// Hand the stream over (the handler has written what it wanted and keeps it).
    Stream(Box<dyn FnOnce(TcpStream) + Send>),
}

/// Why a request could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// The socket failed or timed out.
    #[error("reading the request: {0}")]
    Io(#[from] std::io::Error),
    /// The request is malformed or too large.
    #[error("bad request: {0}")]
    Bad(String),
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        413 => "Payload Too Large",
        422 => "Unprocessable Entity",
        503 => "Service Unavailable",
        _ => "Error",
    }
}

/// Writes a whole response.
///
/// # Errors
/// The socket's error.
pub fn write_response(stream: &mut impl Write, response: &Response) -> std::io::Result<()> {
    write!(
        stream,
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        response.status,
        reason(response.status),
        response.content_type,
        response.body.len()
    )?;
    stream.write_all(&response.body)?;
    stream.flush()
}

fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => out.push(b' '),
            b'%' if i + 2 < bytes.len() => {
                let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok().and_then(|h| u8::from_str_radix(h, 16).ok());
                match hex {
                    Some(b) => {
                        out.push(b);
                        i += 2;
                    }
                    None => out.push(b'%'),
                }
            }
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Reads one request (head and body) with the size limits.
///
/// # Errors
/// [`RequestError`] saying what is wrong.
pub fn read_request(reader: &mut impl BufRead) -> Result<Request, RequestError> {
    let mut head = Vec::new();
    loop {
        let before = head.len();
        let n = reader.take((MAX_HEAD - head.len()) as u64 + 1).read_until(b'\n', &mut head)?;
        if n == 0 {
            return Err(RequestError::Bad("connection closed before the request head ended".into()));
        }
        if head.len() > MAX_HEAD {
            return Err(RequestError::Bad(format!("request head longer than {MAX_HEAD} bytes")));
        }
        let line = &head[before..];
        if line == b"\r\n" || line == b"\n" {
            break;
        }
    }
    let head = String::from_utf8(head).map_err(|_| RequestError::Bad("request head is not UTF-8".into()))?;
    let mut lines = head.lines();
    let request_line = lines.next().unwrap_or_default();
    let mut parts = request_line.split(' ');
    let (Some(method), Some(target), Some(version)) = (parts.next(), parts.next(), parts.next()) else {
        return Err(RequestError::Bad(format!("request line `{request_line}` is not `METHOD TARGET VERSION`")));
    };
    if !version.starts_with("HTTP/1.") {
        return Err(RequestError::Bad(format!("unsupported protocol `{version}`")));
    }
    let mut length = 0usize;
    for line in lines {
        if let Some((name, value)) = line.split_once(':')
            && name.trim().eq_ignore_ascii_case("content-length")
        {
            length =
                value.trim().parse().map_err(|_| RequestError::Bad(format!("content-length `{}`", value.trim())))?;
        }
    }
    if length > MAX_BODY {
        return Err(RequestError::Bad(format!("body of {length} bytes is longer than {MAX_BODY}")));
    }
    let mut body = vec![0; length];
    reader.read_exact(&mut body)?;
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let query = query
        .split('&')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap_or((p, ""));
            (percent_decode(k), percent_decode(v))
        })
        .collect();
    Ok(Request { method: method.to_owned(), path: percent_decode(path), query, body })
}

/// A running server.
#[derive(Debug)]
pub struct Server {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Server {
    /// Listens on `addr` and serves every request with `handler` on its own thread.
    ///
    /// # Errors
    /// When the address cannot be bound.
    pub fn start(addr: SocketAddr, handler: Arc<dyn Fn(Request) -> Handled + Send + Sync>) -> std::io::Result<Server> {
        let listener = TcpListener::bind(addr)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let open = Arc::new(AtomicUsize::new(0));
        let stop_flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new().name("inspector-http".into()).spawn(move || {
            for stream in listener.incoming() {
                if stop_flag.load(Ordering::SeqCst) {
                    break;
                }
                let Ok(mut stream) = stream else { continue };
                if open.load(Ordering::SeqCst) >= MAX_CONNECTIONS {
                    let _ = write_response(&mut stream, &Response::error(503, "too many connections"));
                    continue;
                }
                open.fetch_add(1, Ordering::SeqCst);
                let handler = Arc::clone(&handler);
                let open_here = Arc::clone(&open);
                let spawned = std::thread::Builder::new().name("inspector-conn".into()).spawn(move || {
                    serve(stream, &*handler);
                    open_here.fetch_sub(1, Ordering::SeqCst);
                });
                if spawned.is_err() {
                    open.fetch_sub(1, Ordering::SeqCst);
                }
            }
        })?;
        Ok(Server { addr, stop, thread: Some(thread) })
    }

    /// The bound address (with the real port when 0 was asked for).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops accepting connections and waits for the accepting thread.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        // Wake the blocking accept.
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop();
    }
}

fn serve(stream: TcpStream, handler: &(dyn Fn(Request) -> Handled + Send + Sync)) {
    let _ = stream.set_read_timeout(Some(IO_TIMEOUT));
    let _ = stream.set_write_timeout(Some(IO_TIMEOUT));
    let Ok(read_half) = stream.try_clone() else { return };
    let mut reader = BufReader::new(read_half);
    let mut stream = stream;
    match read_request(&mut reader) {
        Ok(request) => match handler(request) {
            Handled::Respond(response) => {
                let _ = write_response(&mut stream, &response);
            }
            Handled::Stream(keep) => keep(stream),
        },
        Err(RequestError::Io(_)) => {}
        Err(error @ RequestError::Bad(_)) => {
            let _ = write_response(&mut stream, &Response::error(400, error));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_parse_with_query_and_body_and_limits_hold() {
        let raw = b"POST /api/edit?el=n%3A5&x=a+b HTTP/1.1\r\nHost: x\r\nContent-Length: 4\r\n\r\nbody";
        let request = read_request(&mut &raw[..]).unwrap();
        assert_eq!(request.method, "POST");
        assert_eq!(request.path, "/api/edit");
        assert_eq!(request.param("el"), Some("n:5"));
        assert_eq!(request.param("x"), Some("a b"));
        assert_eq!(request.body, b"body");
        let huge = format!("POST / HTTP/1.1\r\nContent-Length: {}\r\n\r\n", MAX_BODY + 1);
        assert!(matches!(read_request(&mut huge.as_bytes()), Err(RequestError::Bad(_))));
        let long_head = format!("GET /{} HTTP/1.1\r\n\r\n", "a".repeat(MAX_HEAD));
        assert!(matches!(read_request(&mut long_head.as_bytes()), Err(RequestError::Bad(_))));
        assert!(matches!(read_request(&mut &b"GARBAGE\r\n\r\n"[..]), Err(RequestError::Bad(_))));
        assert!(matches!(read_request(&mut &b"GET / HTTP/1.1\r\n"[..]), Err(RequestError::Bad(_))));
        assert_eq!(percent_decode("%zz%4"), "%zz%4");
    }
}
