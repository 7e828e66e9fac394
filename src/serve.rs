//! `sylva serve`: a small static HTTP server for the viewer and a scene (native).
//!
//! `/` is the built viewer (`web/`, with the wasm in `web/pkg/`); `/scene/…` is
//! the scene directory, which the viewer opens by default. Correct MIME types
//! (`application/wasm` for streaming compilation), gzip for text and JSON when the
//! client accepts it, single byte ranges, cache headers and CORS for embedding.
//!
//! What it never serves (docs/SECURITY.md): a path outside the two folders, also
//! not through a symbolic link (paths are resolved, then checked); dotfiles or
//! anything in a dot-folder (`.env`, `.git/`, a bake's working folder); anything
//! but regular files. On a loopback address it answers only requests whose
//! `Host` is a loopback name (`localhost`, `127.0.0.1`, `[::1]`, or one allowed
//! with `--allow-host`), so a web page cannot read the scene through DNS
//! rebinding although responses carry `Access-Control-Allow-Origin: *`.
//!
//! Who may frame the viewer (docs/SECURITY.md, "The viewer in a frame"): HTML
//! carries `Content-Security-Policy: frame-ancestors 'self'` plus the origins
//! given with `--allow-embed`, and `/sylva-embed.json` (the viewer's policy,
//! `web/embed-policy.js`) lists them and the `--allow-source` origins; without
//! either flag a `sylva-embed.json` in the viewer's folder is served as it is,
//! and without that the policy of no other origin.
//!
//! Why hand-written and not hyper + tower-http's `ServeDir`: the rules above are
//! most of the code; the HTTP part is one request per connection, which a
//! viewer's few dozen parallel fetches do not notice (`make bench-serve`).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};

/// What to serve.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// The built viewer (index.html, sylva.js, pkg/).
    pub web_dir: PathBuf,
    /// The scene served under `/scene/`.
    pub scene_dir: PathBuf,
    /// Where to record each request as `"METHOD PATH [RANGE]"` (tests count them).
    pub log: Option<std::sync::Arc<std::sync::Mutex<Vec<String>>>>,
    /// Host names answered on a loopback address besides the loopback ones.
    pub allowed_hosts: Vec<String>,
    /// Origins (see [`parse_origin`]) whose pages may frame the viewer and
    /// drive it by postMessage, besides its own; `*` any.
    pub embed_parents: Vec<String>,
    /// Origins besides the viewer's own that `?scene=`, `?imagery=` and the
    /// `setImagery` message may load from; `*` any.
    pub embed_sources: Vec<String>,
}

impl ServeConfig {
    /// Serves `web_dir` at `/` and `scene_dir` at `/scene/`, without a request log.
    /// The folders are resolved here once (links followed), as [`resolve`] compares
    /// real paths with them.
    #[must_use]
    pub fn new(web_dir: PathBuf, scene_dir: PathBuf) -> Self {
        let real = |p: PathBuf| std::fs::canonicalize(&p).unwrap_or(p);
        Self {
            web_dir: real(web_dir),
            scene_dir: real(scene_dir),
            log: None,
            allowed_hosts: Vec::new(),
            embed_parents: Vec::new(),
            embed_sources: Vec::new(),
        }
    }

    /// The `frame-ancestors` directive for the viewer's pages: `'self'` and the
    /// listed parents, or `*`.
    #[must_use]
    pub fn frame_ancestors(&self) -> String {
        if self.embed_parents.iter().any(|o| o == "*") {
            return "frame-ancestors *".into();
        }
        std::iter::once("frame-ancestors 'self'")
            .chain(self.embed_parents.iter().map(String::as_str))
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// Without `--allow-embed`/`--allow-source`, takes the origins of a
    /// `sylva-embed.json` in the viewer's folder, so the `frame-ancestors`
    /// header and the policy the viewer reads are one (a portal the file lists
    /// is not blocked by the header). Returns whether a file was adopted.
    ///
    /// # Errors
    /// A file that is no policy (not JSON, unknown keys, no origin), named.
    pub fn adopt_policy_file(&mut self) -> Result<bool, String> {
        if !self.embed_parents.is_empty() || !self.embed_sources.is_empty() {
            return Ok(false);
        }
        let Some(path) = resolve(self, "/sylva-embed.json") else { return Ok(false) };
        let name = path.display();
        let text = crate::paths::read_regular(&path, None, 1 << 16).map_err(|e| format!("{name}: {e}"))?;
        let v: serde_json::Value = serde_json::from_slice(&text).map_err(|e| format!("{name}: not JSON ({e})"))?;
        let object =
            v.as_object().ok_or_else(|| format!("{name}: expected {{\"parents\": [...], \"sources\": [...]}}"))?;
        let mut lists = [Vec::new(), Vec::new()];
        for (key, value) in object {
            let k = match key.as_str() {
                "parents" => 0,
                "sources" => 1,
                _ => return Err(format!("{name}: unknown key {key:?} (parents, sources)")),
            };
            for o in value.as_array().ok_or_else(|| format!("{name}: {key:?} must be a list of origins"))? {
                let o = o.as_str().ok_or_else(|| format!("{name}: {o} in {key:?} is no origin"))?;
                lists[k].push(parse_origin(o).map_err(|e| format!("{name}: {e}"))?);
            }
        }
        let [parents, sources] = lists;
        self.embed_parents = parents;
        self.embed_sources = sources;
        Ok(true)
    }

    /// `/sylva-embed.json` from the flags, or None without them (the file in
    /// the viewer's folder is served instead, or [`Self::DEFAULT_EMBED_POLICY`]).
    #[must_use]
    pub fn embed_policy_json(&self) -> Option<String> {
        (!self.embed_parents.is_empty() || !self.embed_sources.is_empty()).then(|| {
            serde_json::json!({"parents": self.embed_parents, "sources": self.embed_sources}).to_string() + "\n"
        })
    }

    /// The policy without flags or a file: the viewer's own origin only (what
    /// the viewer assumes on a 404, answered so a browser logs no failed request).
    pub const DEFAULT_EMBED_POLICY: &'static str = "{\"parents\": [], \"sources\": []}\n";

    /// Whether a request with this `Host` header is answered by a server bound
    /// to `bound` (bound to a non-loopback address, any host is).
    #[must_use]
    pub fn host_allowed(&self, host: Option<&str>, bound: std::net::IpAddr) -> bool {
        if !bound.is_loopback() {
            return true;
        }
        let Some(name) = host.map(host_name) else { return false };
        name == "localhost"
            || name.ends_with(".localhost")
            || name.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.to_canonical().is_loopback())
            || self.allowed_hosts.iter().any(|h| host_name(h) == name)
    }
}

/// The name of a `Host` value, lower case, without port, brackets or a final
/// dot: `[::1]:8080` → `::1`, `Localhost.:8080` → `localhost`.
fn host_name(host: &str) -> String {
    let host = host.trim();
    let name = match host.strip_prefix('[') {
        Some(rest) => rest.split(']').next().unwrap_or(""),
        // A bare IPv6 address has several colons and no port.
        None if host.matches(':').count() > 1 => host,
        None => host.rsplit_once(':').map_or(host, |(h, _)| h),
    };
    name.trim_end_matches('.').to_ascii_lowercase()
}

/// An origin as browsers write it (`location.origin`): `http(s)://host[:port]`,
/// lower case, the scheme's default port dropped, no path (a final `/` is
/// allowed); or `*`. Anything else is refused with what was expected: the
/// value goes into a response header and the viewer's policy.
pub fn parse_origin(s: &str) -> Result<String, String> {
    let s = s.trim();
    if s == "*" {
        return Ok(s.into());
    }
    let expected = || format!("{s:?} is no origin: expected http(s)://host[:port] (no path), or *");
    let lower = s.to_ascii_lowercase();
    let (scheme, rest) = lower.split_once("://").ok_or_else(expected)?;
    let default_port: u16 = match scheme {
        "https" => 443,
        "http" => 80,
        _ => return Err(expected()),
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) if !h.is_empty() && (!h.contains(':') || h.ends_with(']')) => (h, Some(p)),
        _ => (rest, None),
    };
    if host.starts_with('[') {
        return Err(format!(
            "{s:?} is no origin here: an IPv6 address cannot be named in a frame-ancestors header; use a host name"
        ));
    }
    // A host whose last label is a number is an IPv4 address to a browser: a valid one only.
    let numeric = host.rsplit('.').next().is_some_and(|l| !l.is_empty() && l.bytes().all(|b| b.is_ascii_digit()));
    let host_ok = !host.is_empty()
        && host.len() <= 253
        && host
            .split('.')
            .all(|l| !l.is_empty() && l.len() <= 63 && l.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-'))
        && (!numeric || host.parse::<std::net::Ipv4Addr>().is_ok());
    let port = match port {
        None => None,
        Some(p) if !p.is_empty() && p.len() <= 5 && p.bytes().all(|b| b.is_ascii_digit()) => {
            Some(p.parse::<u16>().ok().filter(|&n| n > 0).ok_or_else(expected)?)
        }
        Some(_) => return Err(expected()),
    };
    if !host_ok {
        return Err(expected());
    }
    Ok(match port {
        Some(p) if p != default_port => format!("{scheme}://{host}:{p}"),
        _ => format!("{scheme}://{host}"),
    })
}

/// MIME type by extension.
#[must_use]
pub fn mime_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "html" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "json" => "application/json",
        "wasm" => "application/wasm",
        "png" => "image/png",
        "svg" => "image/svg+xml",
        "geojson" => "application/geo+json",
        _ => "application/octet-stream",
    }
}

/// Maps a request path to a regular file inside its root, refusing anything
/// that leaves it (also through links) and every dotfile (also behind a link).
#[must_use]
pub fn resolve(config: &ServeConfig, url_path: &str) -> Option<PathBuf> {
    let path = url_path.split(['?', '#']).next().unwrap_or("/");
    let path = crate::paths::percent_decode(path)?;
    let (root, rest) = match path.strip_prefix("/scene/") {
        Some(rest) => (&config.scene_dir, rest.to_string()),
        None => (&config.web_dir, path.trim_start_matches('/').to_string()),
    };
    let rest = if rest.is_empty() { "index.html".to_string() } else { rest };
    if !crate::paths::is_plain_relative(&rest, false) {
        return None;
    }
    // Links are followed, then the real path must still be inside the real root
    // (resolved by `ServeConfig::new`) and be no dotfile there.
    let full = std::fs::canonicalize(root.join(&rest)).ok()?;
    let inside = full.strip_prefix(root).ok()?;
    (crate::paths::is_plain_relative(&inside.to_string_lossy(), false) && full.is_file()).then_some(full)
}

/// What a `Range` header asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RangeAsk {
    /// Bytes `a..=b` of the file.
    Bytes(u64, u64),
    /// A single range that starts past the end: 416.
    Unsatisfiable,
    /// Several ranges or an unparsable header: ignored, the whole file (RFC 9110 §14.2).
    Ignore,
}

/// Parses `Range: bytes=a-b`, `bytes=a-` or `bytes=-n` (single ranges only).
fn parse_range(header: &str, len: u64) -> RangeAsk {
    let parsed = (|| {
        let spec = header.trim().strip_prefix("bytes=")?;
        if spec.contains(',') {
            return None;
        }
        let (a, b) = spec.split_once('-')?;
        Some(match (a.trim(), b.trim()) {
            ("", suffix) => {
                let n: u64 = suffix.parse().ok()?;
                if n == 0 || len == 0 {
                    return Some(RangeAsk::Unsatisfiable);
                }
                RangeAsk::Bytes(len.saturating_sub(n), len - 1)
            }
            (a, b) => {
                let start: u64 = a.parse().ok()?;
                let end: Option<u64> = if b.is_empty() { None } else { Some(b.parse().ok()?) };
                if end.is_some_and(|e| e < start) {
                    return None;
                }
                if start >= len {
                    return Some(RangeAsk::Unsatisfiable);
                }
                RangeAsk::Bytes(start, end.unwrap_or(len - 1).min(len - 1))
            }
        })
    })();
    parsed.unwrap_or(RangeAsk::Ignore)
}

fn head_text(status: &str, len: u64, headers: &[(&str, String)]) -> String {
    let mut head = format!("HTTP/1.1 {status}\r\nContent-Length: {len}\r\nConnection: close\r\n");
    head += "Access-Control-Allow-Origin: *\r\nAccess-Control-Expose-Headers: Content-Length, Content-Range\r\n";
    for (k, v) in headers {
        head += &format!("{k}: {v}\r\n");
    }
    head + "\r\n"
}

fn respond(
    stream: &mut TcpStream,
    status: &str,
    headers: &[(&str, String)],
    body: &[u8],
    head_only: bool,
) -> std::io::Result<()> {
    let mut out = head_text(status, body.len() as u64, headers).into_bytes();
    if !head_only {
        out.extend_from_slice(body);
    }
    stream.write_all(&out)
}

/// Most connections served at once (a thread each); more get 503.
const MAX_CONNECTIONS: usize = 512;

/// A place among [`MAX_CONNECTIONS`].
struct Slot(std::sync::Arc<std::sync::atomic::AtomicUsize>);

impl Slot {
    fn take(open: &std::sync::Arc<std::sync::atomic::AtomicUsize>) -> Option<Slot> {
        use std::sync::atomic::Ordering::SeqCst;
        let taken = open.fetch_update(SeqCst, SeqCst, |n| (n < MAX_CONNECTIONS).then_some(n + 1)).is_ok();
        taken.then(|| Slot(open.clone()))
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Answers 503 without a thread: a flood of connections gets answers.
fn busy(stream: &mut TcpStream) {
    let _ = stream.set_write_timeout(Some(std::time::Duration::from_secs(1)));
    let _ = respond(stream, "503 Service Unavailable", &[("Retry-After", "1".into())], b"busy\n", false);
    // Closing with the request unread would reset the connection before the
    // client reads the answer: close our side, then drain what has arrived
    // (without waiting: the accept loop must not stall).
    let _ = stream.shutdown(std::net::Shutdown::Write);
    let _ = stream.set_nonblocking(true);
    let _ = stream.read(&mut [0u8; 16 << 10]);
}

/// Most bytes of a request head (request line and headers) read.
const MAX_HEAD_BYTES: u64 = 16 << 10;

/// How long a client may take to send its request head, and each write to it.
const CLIENT_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

fn handle(mut stream: TcpStream, config: &ServeConfig, bound: std::net::IpAddr) -> std::io::Result<()> {
    stream.set_read_timeout(Some(CLIENT_TIMEOUT))?;
    stream.set_write_timeout(Some(CLIENT_TIMEOUT))?;
    let started = std::time::Instant::now();
    let mut reader = BufReader::new(stream.try_clone()?.take(MAX_HEAD_BYTES));
    let mut request_line = String::new();
    reader.read_line(&mut request_line)?;
    let mut range = None;
    let mut host = None;
    let mut gzip_ok = false;
    loop {
        let mut line = String::new();
        // A byte every few seconds must not hold a connection: the whole head in time.
        if started.elapsed() > CLIENT_TIMEOUT {
            return Err(std::io::ErrorKind::TimedOut.into());
        }
        if reader.read_line(&mut line)? == 0 || line.trim().is_empty() {
            break;
        }
        let lower = line.to_ascii_lowercase();
        if let Some(v) = lower.strip_prefix("range:") {
            range = Some(v.trim().to_string());
        } else if let Some(v) = lower.strip_prefix("host:") {
            host = Some(v.trim().to_string());
        } else if let Some(v) = lower.strip_prefix("accept-encoding:") {
            gzip_ok = v.contains("gzip");
        }
    }
    let mut parts = request_line.split_whitespace();
    let (method, path) = (parts.next().unwrap_or(""), parts.next().unwrap_or("/"));
    if let Some(log) = &config.log {
        if let Ok(mut log) = log.lock() {
            log.push(format!("{method} {path} {}", range.as_deref().unwrap_or("")).trim_end().to_string());
        }
    }
    let head_only = method == "HEAD";
    if !config.host_allowed(host.as_deref(), bound) {
        let text = format!(
            "Host {:?} is not served: on a loopback address sylva serve answers localhost, 127.0.0.1 and [::1] \
             only (sylva serve --allow-host NAME adds a name)\n",
            host.as_deref().unwrap_or("")
        );
        return respond(
            &mut stream,
            "403 Forbidden",
            &[("Content-Type", "text/plain".into())],
            text.as_bytes(),
            head_only,
        );
    }
    if method == "OPTIONS" {
        return respond(&mut stream, "204 No Content", &[("Access-Control-Allow-Headers", "Range".into())], b"", false);
    }
    if method != "GET" && !head_only {
        return respond(&mut stream, "405 Method Not Allowed", &[("Allow", "GET, HEAD".into())], b"", false);
    }
    // The policy by any spelling of its path (`//sylva-embed.json`, `%2D`): the one the flags say.
    let policy_path = path
        .split(['?', '#'])
        .next()
        .and_then(crate::paths::percent_decode)
        .is_some_and(|p| p.split('/').filter(|c| !c.is_empty() && *c != ".").eq(["sylva-embed.json"]));
    if policy_path {
        let json = config
            .embed_policy_json()
            .or_else(|| resolve(config, path).is_none().then(|| ServeConfig::DEFAULT_EMBED_POLICY.to_string()));
        if let Some(json) = json {
            let headers = [("Content-Type", "application/json".to_string()), ("Cache-Control", "no-cache".into())];
            return respond(&mut stream, "200 OK", &headers, json.as_bytes(), head_only);
        }
    }
    let Some(file) = resolve(config, path) else {
        return respond(
            &mut stream,
            "404 Not Found",
            &[("Content-Type", "text/plain".into())],
            b"not found\n",
            head_only,
        );
    };
    let mut f = std::fs::File::open(&file)?;
    let len = f.metadata()?.len();
    let mime = mime_type(&file);
    // The viewer and manifest change when rebuilt; tiles and packs of a scene are immutable.
    let cache =
        if path.starts_with("/scene/") && !path.ends_with(".json") { "public, max-age=3600" } else { "no-cache" };
    let mut headers =
        vec![("Content-Type", mime.to_string()), ("Cache-Control", cache.into()), ("Accept-Ranges", "bytes".into())];
    if mime.starts_with("text/html") {
        headers.push(("Content-Security-Policy", config.frame_ancestors()));
    }
    match range.map_or(RangeAsk::Ignore, |r| parse_range(&r, len)) {
        RangeAsk::Bytes(a, b) => {
            // Read only the range: a viewer fetches parts of large packs.
            use std::io::Seek;
            f.seek(std::io::SeekFrom::Start(a))?;
            headers.push(("Content-Range", format!("bytes {a}-{b}/{len}")));
            return send_file(&mut stream, "206 Partial Content", &headers, f.take(b - a + 1), b - a + 1, head_only);
        }
        RangeAsk::Unsatisfiable => {
            headers.push(("Content-Range", format!("bytes */{len}")));
            return respond(&mut stream, "416 Range Not Satisfiable", &headers, b"", head_only);
        }
        RangeAsk::Ignore => {}
    }
    let compressible = mime.starts_with("text/") || mime == "application/json" || mime == "application/wasm";
    if gzip_ok && compressible && len > 1024 && len <= MAX_GZIP_BYTES {
        let mut body = Vec::new();
        f.read_to_end(&mut body)?;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(&body)?;
        headers.push(("Content-Encoding", "gzip".into()));
        headers.push(("Vary", "Accept-Encoding".into()));
        return respond(&mut stream, "200 OK", &headers, &enc.finish()?, head_only);
    }
    send_file(&mut stream, "200 OK", &headers, f.take(len), len, head_only)
}

/// Sends `len` bytes of `body` after the head: up to [`MAX_BUFFERED_BYTES`]
/// in one write with the head (tiles, index nodes), larger ones streamed, so
/// memory per connection stays small whatever the file.
fn send_file(
    stream: &mut TcpStream,
    status: &str,
    headers: &[(&str, String)],
    mut body: impl Read,
    len: u64,
    head_only: bool,
) -> std::io::Result<()> {
    let mut out = head_text(status, len, headers).into_bytes();
    if head_only {
        return stream.write_all(&out);
    }
    if len <= MAX_BUFFERED_BYTES {
        body.read_to_end(&mut out)?;
        return stream.write_all(&out);
    }
    stream.write_all(&out)?;
    std::io::copy(&mut body, stream)?;
    Ok(())
}

/// Largest file read whole before it is sent.
const MAX_BUFFERED_BYTES: u64 = 1 << 20;

/// Largest file compressed on the fly (the viewer's wasm and JS, manifests).
const MAX_GZIP_BYTES: u64 = 64 << 20;

/// Serves until the process ends; each connection on its own thread.
/// Calls `on_ready` with the bound address first.
///
/// # Errors
/// When the address cannot be bound.
pub fn serve(config: ServeConfig, addr: &str, on_ready: impl FnOnce(std::net::SocketAddr)) -> std::io::Result<()> {
    let listener = TcpListener::bind(addr)?;
    let bound = listener.local_addr()?;
    on_ready(bound);
    let config = std::sync::Arc::new(config);
    let open = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        // A connection's place among MAX_CONNECTIONS, given back when dropped
        // (also when its thread panics or cannot be started).
        let slot = Slot::take(&open);
        let Some(slot) = slot else {
            busy(&mut stream);
            continue;
        };
        let config = config.clone();
        let spawned = std::thread::Builder::new().spawn(move || {
            let _slot = slot;
            let _ = handle(stream, &config, bound.ip());
        });
        if spawned.is_err() {
            continue; // The slot was dropped with the closure; the client sees the socket close.
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_stay_inside_their_roots() {
        let dir = std::env::temp_dir().join(format!("sylva-serve-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("web")).unwrap();
        std::fs::create_dir_all(dir.join("scene/tiles")).unwrap();
        std::fs::write(dir.join("web/index.html"), "x").unwrap();
        std::fs::write(dir.join("scene/tiles/0_0.tile"), "t").unwrap();
        std::fs::write(dir.join("secret"), "s").unwrap();
        let c = ServeConfig::new(dir.join("web"), dir.join("scene"));
        assert_eq!(resolve(&c, "/"), Some(dir.join("web/index.html")));
        assert_eq!(resolve(&c, "/scene/tiles/0_0.tile?x=1"), Some(dir.join("scene/tiles/0_0.tile")));
        for bad in [
            "/../secret",
            "/scene/../secret",
            "/scene/%2e%2e/secret",
            "/%2e%2e/secret",
            "//etc/passwd",
            "/scene/tiles/missing",
        ] {
            assert_eq!(resolve(&c, bad), None, "{bad}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn connection_slots_are_bounded_and_given_back() {
        let open = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let slots: Vec<Slot> = (0..MAX_CONNECTIONS).map_while(|_| Slot::take(&open)).collect();
        assert_eq!(slots.len(), MAX_CONNECTIONS);
        assert!(Slot::take(&open).is_none(), "one more gets 503");
        drop(slots);
        assert_eq!(open.load(std::sync::atomic::Ordering::SeqCst), 0);
        // A thread that panics gives its slot back.
        let slot = Slot::take(&open).unwrap();
        let _ = std::thread::spawn(move || {
            let _slot = slot;
            panic!("a handler bug");
        })
        .join();
        assert_eq!(open.load(std::sync::atomic::Ordering::SeqCst), 0);
    }

    #[test]
    fn ranges_and_mime_types() {
        use RangeAsk::{Bytes, Ignore, Unsatisfiable};
        assert_eq!(parse_range("bytes=0-9", 100), Bytes(0, 9));
        assert_eq!(parse_range("bytes=90-", 100), Bytes(90, 99));
        assert_eq!(parse_range("bytes=-10", 100), Bytes(90, 99));
        assert_eq!(parse_range("bytes=-500", 100), Bytes(0, 99));
        assert_eq!(parse_range("bytes=50-500", 100), Bytes(50, 99));
        assert_eq!(parse_range("bytes=100-", 100), Unsatisfiable);
        assert_eq!(parse_range("bytes=0-", 0), Unsatisfiable);
        // Several ranges, or nonsense: ignored (200 with the whole file).
        for ignored in ["bytes=0-1,5-6", "bytes=x-y", "items=0-9", "bytes=9-2", "bytes=", "bytes=--3"] {
            assert_eq!(parse_range(ignored, 100), Ignore, "{ignored}");
        }
        assert_eq!(mime_type(Path::new("a/sylva_bg.wasm")), "application/wasm");
        assert_eq!(mime_type(Path::new("scene.json")), "application/json");
    }

    #[test]
    fn origins_are_written_as_browsers_write_them_and_nothing_else_passes() {
        for (given, origin) in [
            ("https://Portal.Example.org", "https://portal.example.org"),
            ("https://portal.example.org/", "https://portal.example.org"),
            ("https://portal.example.org:443", "https://portal.example.org"),
            ("http://127.0.0.1:8080", "http://127.0.0.1:8080"),
            ("http://localhost:80", "http://localhost"),
            ("https://a.org:0443", "https://a.org"),
            ("*", "*"),
        ] {
            assert_eq!(parse_origin(given).as_deref(), Ok(origin), "{given}");
        }
        // Paths, other schemes, credentials and anything a header or JSON could be bent by.
        for bad in [
            "portal.example.org",
            "https://portal.example.org/app",
            "ftp://portal.example.org",
            "javascript://x",
            "https://user@portal.example.org",
            "https://a.org\r\nSet-Cookie: x=1",
            "https://a.org; script-src *",
            "https://a.org 'unsafe-inline'",
            "https://a.org:0",
            "https://a.org:99999",
            "https://a.org:",
            "https://",
            "https://a..org",
            "https://[::1",
            "https://a.org?x=1",
            "https://a.org#x",
            "\"https://a.org\"",
            "http://a.org:+80",
            "http://256.1.1.1",
            "http://1.2.3.4.5",
            "http://1.2.3",
        ] {
            let e = parse_origin(bad).unwrap_err();
            assert!(e.contains("is no origin"), "{bad}: {e}");
        }
        // A browser cannot be told an IPv6 host in frame-ancestors: said so.
        assert!(parse_origin("http://[::1]:3000").unwrap_err().contains("IPv6"));
        let mut c = ServeConfig::new("web".into(), "scene".into());
        assert_eq!(c.frame_ancestors(), "frame-ancestors 'self'");
        assert_eq!(c.embed_policy_json(), None);
        c.embed_parents = vec!["https://portal.example.org".into(), "http://127.0.0.1:9000".into()];
        assert_eq!(c.frame_ancestors(), "frame-ancestors 'self' https://portal.example.org http://127.0.0.1:9000");
        let policy: serde_json::Value = serde_json::from_str(&c.embed_policy_json().unwrap()).unwrap();
        assert_eq!(policy["parents"][1], "http://127.0.0.1:9000");
        assert_eq!(policy["sources"].as_array().map(Vec::len), Some(0));
        c.embed_parents.push("*".into());
        assert_eq!(c.frame_ancestors(), "frame-ancestors *");
    }
}

#[cfg(test)]
mod live_tests {
    use super::*;

    #[test]
    fn serves_mime_types_ranges_gzip_cors_and_refuses_escapes() {
        let dir = std::env::temp_dir().join(format!("sylva-serve-live-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("web/pkg")).unwrap();
        std::fs::create_dir_all(dir.join("scene/tiles")).unwrap();
        std::fs::write(dir.join("web/index.html"), "<!doctype html>".repeat(200)).unwrap();
        std::fs::write(dir.join("web/pkg/sylva_bg.wasm"), b"\0asm\x01\0\0\0").unwrap();
        let tile: Vec<u8> = (0..=255u8).collect();
        std::fs::write(dir.join("scene/tiles/0_0.tile"), &tile).unwrap();
        let config = ServeConfig::new(dir.join("web"), dir.join("scene"));
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || serve(config, "127.0.0.1:0", |a| tx.send(a).unwrap()));
        let base = format!("http://{}", rx.recv().unwrap());
        let agent: ureq::Agent = ureq::Agent::config_builder().http_status_as_error(false).build().into();
        let get = |path: &str, headers: &[(&str, &str)]| {
            let mut req = agent.get(&format!("{base}{path}"));
            for (k, v) in headers {
                req = req.header(*k, *v);
            }
            req.call().unwrap()
        };
        let wasm = get("/pkg/sylva_bg.wasm", &[]);
        assert_eq!(wasm.status(), 200);
        assert_eq!(wasm.headers()["content-type"], "application/wasm");
        assert_eq!(wasm.headers()["access-control-allow-origin"], "*");
        let mut part = get("/scene/tiles/0_0.tile", &[("Range", "bytes=10-19")]);
        assert_eq!(part.status(), 206);
        assert_eq!(part.headers()["content-range"], "bytes 10-19/256");
        assert_eq!(part.body_mut().read_to_vec().unwrap(), (10..20u8).collect::<Vec<_>>());
        assert!(part.headers()["cache-control"].to_str().unwrap().contains("max-age"));
        // Raw request: ureq would decode gzip and drop the header.
        let mut raw = TcpStream::connect(base.trim_start_matches("http://")).unwrap();
        raw.write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept-Encoding: gzip, br\r\n\r\n").unwrap();
        let mut reply = Vec::new();
        raw.read_to_end(&mut reply).unwrap();
        let split = reply.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        let head = String::from_utf8_lossy(&reply[..split]).to_ascii_lowercase();
        assert!(head.contains("content-encoding: gzip"), "{head}");
        let mut html = String::new();
        flate2::read::GzDecoder::new(&reply[split + 4..]).read_to_string(&mut html).unwrap();
        assert_eq!(html, "<!doctype html>".repeat(200));
        assert_eq!(get("/scene/../web/index.html", &[]).status(), 404);
        assert_eq!(get("/scene/%2e%2e/web/index.html", &[]).status(), 404);
        assert_eq!(get("/scene/tiles/0_0.tile", &[("Range", "bytes=300-")]).status(), 416);
        // Only pages served here may frame the viewer, and its policy says the same.
        assert_eq!(get("/", &[]).headers()["content-security-policy"], "frame-ancestors 'self'");
        assert!(get("/scene/tiles/0_0.tile", &[]).headers().get("content-security-policy").is_none());
        let mut policy = get("/sylva-embed.json", &[]);
        assert_eq!(policy.status(), 200);
        let policy: serde_json::Value = serde_json::from_str(&policy.body_mut().read_to_string().unwrap()).unwrap();
        assert_eq!(policy, serde_json::json!({"parents": [], "sources": []}));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_embedding_flags_become_the_header_and_the_viewers_policy() {
        let dir = std::env::temp_dir().join(format!("sylva-serve-embed-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("web")).unwrap();
        std::fs::create_dir_all(dir.join("scene")).unwrap();
        std::fs::write(dir.join("web/index.html"), "<!doctype html>").unwrap();
        // A policy file in the viewer's folder is what the flags replace.
        std::fs::write(dir.join("web/sylva-embed.json"), r#"{"parents": ["https://old.example.org"]}"#).unwrap();
        let config = ServeConfig {
            embed_parents: vec!["https://portal.example.org".into()],
            embed_sources: vec!["https://tiles.example.org".into()],
            ..ServeConfig::new(dir.join("web"), dir.join("scene"))
        };
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || serve(config, "127.0.0.1:0", |a| tx.send(a).unwrap()));
        let base = format!("http://{}", rx.recv().unwrap());
        let agent: ureq::Agent = ureq::Agent::config_builder().http_status_as_error(false).build().into();
        let mut page = agent.get(&format!("{base}/index.html")).call().unwrap();
        assert_eq!(page.headers()["content-security-policy"], "frame-ancestors 'self' https://portal.example.org");
        assert_eq!(page.body_mut().read_to_string().unwrap(), "<!doctype html>");
        let mut policy = agent.get(&format!("{base}/sylva-embed.json")).call().unwrap();
        assert_eq!(policy.status(), 200);
        let policy: serde_json::Value = serde_json::from_str(&policy.body_mut().read_to_string().unwrap()).unwrap();
        assert_eq!(
            policy,
            serde_json::json!({"parents": ["https://portal.example.org"], "sources": ["https://tiles.example.org"]})
        );
        // Any spelling of the policy's path is the flags' policy.
        for other in ["//sylva-embed.json", "/sylva%2Dembed.json", "/./sylva-embed.json"] {
            let mut p = agent.get(&format!("{base}{other}")).call().unwrap();
            assert!(p.body_mut().read_to_string().unwrap().contains("portal.example.org"), "{other}");
        }
        // Without flags, the folder's own file: its origins are the header's too.
        let mut config = ServeConfig::new(dir.join("web"), dir.join("scene"));
        assert_eq!(config.adopt_policy_file(), Ok(true));
        assert_eq!(config.frame_ancestors(), "frame-ancestors 'self' https://old.example.org");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || serve(config, "127.0.0.1:0", |a| tx.send(a).unwrap()));
        let base = format!("http://{}", rx.recv().unwrap());
        let mut policy = agent.get(&format!("{base}/sylva-embed.json")).call().unwrap();
        assert!(policy.body_mut().read_to_string().unwrap().contains("old.example.org"));
        let page = agent.get(&format!("{base}/index.html")).call().unwrap();
        assert_eq!(page.headers()["content-security-policy"], "frame-ancestors 'self' https://old.example.org");
        // A broken file stops the server before it starts, saying what is wrong.
        std::fs::write(dir.join("web/sylva-embed.json"), r#"{"parents": ["https://a.org/app"]}"#).unwrap();
        let e = ServeConfig::new(dir.join("web"), dir.join("scene")).adopt_policy_file().unwrap_err();
        assert!(e.contains("sylva-embed.json") && e.contains("is no origin"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
