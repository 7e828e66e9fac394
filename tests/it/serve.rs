//! `sylva serve` against hostile requests (docs/SECURITY.md): links out of the
//! roots, dotfiles, foreign `Host` names (DNS rebinding), traversal encodings,
//! odd `Range` headers. Raw HTTP over 127.0.0.1, so every header is ours.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;

use sylva::serve::{serve, ServeConfig};

struct Server {
    addr: SocketAddr,
    dir: PathBuf,
}

/// A viewer folder, a scene folder and secrets beside them, served on 127.0.0.1.
fn start(name: &str) -> Server {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("serve-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    for d in ["web/pkg", "scene/tiles", "scene/species", "scene/.git", "outside"] {
        std::fs::create_dir_all(dir.join(d)).unwrap();
    }
    std::fs::write(dir.join("web/index.html"), "<!doctype html>viewer").unwrap();
    std::fs::write(dir.join("scene/scene.json"), "{\"scene\":1}").unwrap();
    std::fs::write(dir.join("scene/tiles/0_0.tile"), (0..=255u8).collect::<Vec<_>>()).unwrap();
    // Larger than what is sent in one write: streamed.
    std::fs::write(dir.join("scene/species/big.pack"), (0..3u32 << 20).map(|i| (i % 251) as u8).collect::<Vec<_>>())
        .unwrap();
    std::fs::write(dir.join("scene/.env"), "TOKEN=secret").unwrap();
    std::fs::write(dir.join("scene/.git/config"), "[remote] secret").unwrap();
    std::fs::write(dir.join("scene/.sylva-bake-files.json"), "{}").unwrap();
    std::fs::write(dir.join("outside/passwd"), "root:x:0:0").unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::symlink;
        // Out of the scene: a file, a folder, an absolute system file.
        symlink(dir.join("outside/passwd"), dir.join("scene/passwd_link")).unwrap();
        symlink(dir.join("outside"), dir.join("scene/outside_dir")).unwrap();
        symlink("/etc/passwd", dir.join("scene/etc_passwd")).unwrap();
        symlink("/etc/passwd", dir.join("web/etc_passwd")).unwrap();
        // A plain name inside the scene that leads to a dotfile.
        symlink(dir.join("scene/.git/config"), dir.join("scene/config_link")).unwrap();
        // Inside the scene: allowed.
        symlink(dir.join("scene/tiles/0_0.tile"), dir.join("scene/tiles/alias.tile")).unwrap();
    }
    let mut config = ServeConfig::new(dir.join("web"), dir.join("scene"));
    // Given as a user might type it: case, a port, a final dot.
    config.allowed_hosts = vec!["Forest.Test.:8080".into()];
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || serve(config, "127.0.0.1:0", |a| tx.send(a).unwrap()));
    Server { addr: rx.recv().unwrap(), dir }
}

/// Status, lower-cased head and body of one raw request.
fn request(addr: SocketAddr, raw: &str) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(10))).unwrap();
    s.write_all(raw.as_bytes()).unwrap();
    let mut reply = Vec::new();
    s.read_to_end(&mut reply).unwrap();
    let split = reply.windows(4).position(|w| w == b"\r\n\r\n").expect("a complete response head");
    let head = String::from_utf8_lossy(&reply[..split]).to_ascii_lowercase();
    let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    (status, head, reply[split + 4..].to_vec())
}

fn get(addr: SocketAddr, path: &str, headers: &str) -> (u16, String, Vec<u8>) {
    request(addr, &format!("GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\n{headers}\r\n", addr.port()))
}

#[test]
fn links_out_of_the_roots_dotfiles_and_traversals_get_404() {
    let server = start("paths");
    let addr = server.addr;
    assert_eq!(get(addr, "/", "").0, 200);
    assert_eq!(get(addr, "/scene/scene.json", "").2, b"{\"scene\":1}");
    if cfg!(unix) {
        assert_eq!(get(addr, "/scene/tiles/alias.tile", "").0, 200, "a link inside the scene is served");
    }
    for path in [
        "/scene/passwd_link",
        "/scene/outside_dir/passwd",
        "/scene/etc_passwd",
        "/scene/config_link",
        "/etc_passwd",
        "/scene/.env",
        "/scene/.git/config",
        "/scene/%2egit/config",
        "/scene/.sylva-bake-files.json",
        "/scene/tiles/../.env",
        "/scene/../outside/passwd",
        "/scene/%2e%2e/outside/passwd",
        "/scene/..%2foutside/passwd",
        "/scene/..%5coutside%5cpasswd",
        "/..%2f..%2fetc/passwd",
        "//etc/passwd",
        "/scene/tiles",
        "/scene/tiles/",
    ] {
        let (status, _, body) = get(addr, path, "");
        assert_eq!(status, 404, "{path}: {}", String::from_utf8_lossy(&body));
        assert!(
            !String::from_utf8_lossy(&body).contains("secret") && !String::from_utf8_lossy(&body).contains("root:")
        );
    }
    std::fs::remove_dir_all(&server.dir).unwrap();
}

#[test]
fn a_loopback_server_answers_loopback_and_allowed_host_names_only() {
    let server = start("hosts");
    let addr = server.addr;
    let port = addr.port();
    let with_host = |host: &str| {
        request(addr, &format!("GET /scene/scene.json HTTP/1.1\r\nHost: {host}\r\nOrigin: http://{host}\r\n\r\n")).0
    };
    for ok in [
        format!("127.0.0.1:{port}"),
        "127.0.0.1".into(),
        format!("localhost:{port}"),
        "LOCALHOST".into(),
        format!("[::1]:{port}"),
        "viewer.localhost".into(),
        "localhost.".into(),
        "[::ffff:127.0.0.1]".into(),
        format!("forest.test:{port}"),
    ] {
        assert_eq!(with_host(&ok), 200, "{ok}");
    }
    // A page on evil.example whose name was rebound to 127.0.0.1 sends its own name.
    for refused in [format!("evil.example:{port}"), "evil.example".into(), "127.0.0.1.evil.example".into(), "".into()] {
        assert_eq!(with_host(&refused), 403, "{refused:?}");
    }
    let (status, _, body) = request(addr, "GET /scene/scene.json HTTP/1.0\r\n\r\n");
    assert_eq!(status, 403, "no Host header at all");
    assert!(String::from_utf8_lossy(&body).contains("--allow-host"));
    std::fs::remove_dir_all(&server.dir).unwrap();
}

#[test]
fn odd_range_headers_get_the_whole_file_and_past_the_end_gets_416() {
    let server = start("ranges");
    let addr = server.addr;
    let whole: Vec<u8> = (0..=255u8).collect();
    let (status, head, body) = get(addr, "/scene/tiles/0_0.tile", "Range: bytes=10-19\r\n");
    assert_eq!((status, body), (206, (10..20u8).collect()));
    assert!(head.contains("content-range: bytes 10-19/256"), "{head}");
    for ignored in ["bytes=0-1,5-6", "bytes=x-y", "pages=1-2", "bytes=9-2", "bytes="] {
        let (status, _, body) = get(addr, "/scene/tiles/0_0.tile", &format!("Range: {ignored}\r\n"));
        assert_eq!(status, 200, "{ignored}");
        assert_eq!(body, whole, "{ignored}: the whole file");
    }
    let (status, head, _) = get(addr, "/scene/tiles/0_0.tile", "Range: bytes=300-\r\n");
    assert_eq!(status, 416);
    assert!(head.contains("content-range: bytes */256"), "{head}");
    // A file and a range larger than one write are streamed whole.
    let big: Vec<u8> = (0..3u32 << 20).map(|i| (i % 251) as u8).collect();
    let (status, _, body) = get(addr, "/scene/species/big.pack", "");
    assert_eq!((status, body.len()), (200, big.len()));
    assert!(body == big);
    let (status, head, body) = get(addr, "/scene/species/big.pack", "Range: bytes=1000-2098151\r\n");
    assert_eq!((status, body.len()), (206, 2_097_152));
    assert!(head.contains("content-range: bytes 1000-2098151/3145728"), "{head}");
    assert!(body[..] == big[1000..2_098_152]);
    // HEAD: the head of a GET without its body.
    let (status, head, body) =
        request(addr, &format!("HEAD /scene/tiles/0_0.tile HTTP/1.1\r\nHost: localhost:{}\r\n\r\n", addr.port()));
    assert_eq!((status, body.len()), (200, 0));
    assert!(head.contains("content-length: 256"), "{head}");
    std::fs::remove_dir_all(&server.dir).unwrap();
}

#[test]
fn a_server_on_every_interface_answers_any_host() {
    // Bound beyond loopback the user chose to publish it: no Host filter.
    let config = ServeConfig::new(PathBuf::from("/nonexistent"), PathBuf::from("/nonexistent"));
    let any: std::net::IpAddr = "0.0.0.0".parse().unwrap();
    assert!(config.host_allowed(Some("forest.example.org"), any));
    assert!(!config.host_allowed(Some("forest.example.org"), "127.0.0.1".parse().unwrap()));
    assert!(!config.host_allowed(Some("forest.example.org"), "::1".parse().unwrap()));
}
