//! Load test of `sylva serve` on 127.0.0.1 (issue 13): bounded and stopping by
//! itself. CLIENTS threads each make REQUESTS requests of what a viewer asks
//! for (the manifest, gzip-compressed; byte ranges of a pack; whole tiles),
//! plus a few slow clients that open a connection and send nothing. Reports
//! requests per second, latency percentiles and errors.
//!
//! Run `make bench-serve`, or `cargo bench --bench serve [-- SCENE_DIR]`.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

const CLIENTS: usize = 16;
const REQUESTS: usize = 250;
const SLOW_CLIENTS: usize = 8;

fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with("--"))
        .map_or_else(|| root.join("tests/fixtures/forest-small"), std::path::PathBuf::from);
    let pack = std::fs::read_dir(scene.join("species")).unwrap().next().unwrap().unwrap().file_name();
    let tiles: Vec<String> = std::fs::read_dir(scene.join("tiles"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".tile"))
        .collect();
    let config = sylva::serve::ServeConfig::new(root.join("web"), scene.clone());
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || sylva::serve::serve(config, "127.0.0.1:0", |a| tx.send(a).unwrap()));
    let addr = rx.recv().unwrap();
    // Slow clients hold connections open without a request for the whole run.
    let slow: Vec<TcpStream> = (0..SLOW_CLIENTS).map(|_| TcpStream::connect(addr).unwrap()).collect();
    let started = Instant::now();
    let workers: Vec<_> = (0..CLIENTS)
        .map(|c| {
            let (pack, tiles) = (pack.to_string_lossy().into_owned(), tiles.clone());
            std::thread::spawn(move || {
                let mut latencies = Vec::with_capacity(REQUESTS);
                let mut errors = 0;
                for r in 0..REQUESTS {
                    let (path, extra) = match r % 3 {
                        0 => ("/scene/scene.json".to_string(), "Accept-Encoding: gzip\r\n".to_string()),
                        1 => {
                            (format!("/scene/species/{pack}"), format!("Range: bytes={}-{}\r\n", r * 16, r * 16 + 4095))
                        }
                        _ => (format!("/scene/tiles/{}", tiles[(c * 7 + r) % tiles.len()]), String::new()),
                    };
                    let t = Instant::now();
                    match get(addr, &path, &extra) {
                        Ok(status) if status == 200 || status == 206 => latencies.push(t.elapsed().as_secs_f64()),
                        _ => errors += 1,
                    }
                }
                (latencies, errors)
            })
        })
        .collect();
    let mut all = Vec::new();
    let mut errors = 0;
    for w in workers {
        let (l, e) = w.join().unwrap();
        all.extend(l);
        errors += e;
    }
    let wall = started.elapsed().as_secs_f64();
    drop(slow);
    all.sort_by(f64::total_cmp);
    let pct =
        |p: f64| all.get(((all.len() as f64 * p) as usize).min(all.len().saturating_sub(1))).map_or(0.0, |v| v * 1e3);
    println!(
        "serve load: {CLIENTS} clients × {REQUESTS} requests (+{SLOW_CLIENTS} idle connections) in {wall:.2} s: \
         {:.0} requests/s, latency p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms, {errors} errors",
        all.len() as f64 / wall,
        pct(0.5),
        pct(0.99),
        pct(1.0)
    );
}

/// One GET on a fresh connection; returns the status after reading the body.
fn get(addr: std::net::SocketAddr, path: &str, extra: &str) -> std::io::Result<u16> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(s, "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n{extra}\r\n")?;
    let mut reply = Vec::new();
    s.read_to_end(&mut reply)?;
    let line = String::from_utf8_lossy(&reply[..reply.len().min(16)]).into_owned();
    Ok(line.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0))
}
