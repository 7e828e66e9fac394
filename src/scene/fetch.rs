//! One fetch abstraction for everything a scene loads: manifest, tiles, packs.
//!
//! A [`Fetcher`] starts requests and hands back finished ones when polled; it
//! never blocks the caller, so a frame never waits for the network. Natively,
//! [`ThreadFetcher`] serves local paths and `http(s)://` URLs from worker
//! threads; the browser build uses `fetch` (the browser viewer issue).

/// Identifies a request.
pub type RequestId = u64;

/// Why a fetch failed. `retryable` says whether trying again may help.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FetchError {
    /// 404 or a missing file: retrying will not help.
    #[error("{url}: not found")]
    NotFound {
        /// What was fetched.
        url: String,
    },
    /// Another HTTP error status.
    #[error("{url}: HTTP status {status}")]
    Status {
        /// What was fetched.
        url: String,
        /// The status code.
        status: u16,
    },
    /// A local path that is no regular file (a folder, FIFO, device, a link
    /// loop) or a file over the size limit: retrying will not help.
    #[error("{url}: {message}")]
    Refused {
        /// What was fetched.
        url: String,
        /// Why.
        message: String,
    },
    /// Connection, I/O or protocol trouble.
    #[error("{url}: {message}")]
    Transport {
        /// What was fetched.
        url: String,
        /// What went wrong.
        message: String,
    },
}

impl FetchError {
    /// Whether a retry may succeed (server errors, timeouts, broken connections).
    #[must_use]
    pub fn retryable(&self) -> bool {
        match self {
            FetchError::NotFound { .. } | FetchError::Refused { .. } => false,
            FetchError::Status { status, .. } => *status >= 500 || *status == 408 || *status == 429,
            FetchError::Transport { .. } => true,
        }
    }
}

/// A byte range of a file: `start..end` (end exclusive).
pub type ByteRange = (u64, u64);

/// Starts requests and returns finished ones, without blocking.
pub trait Fetcher {
    /// Starts fetching `url` (an absolute URL or a local path).
    fn start(&mut self, url: &str) -> RequestId {
        self.start_range(url, None)
    }
    /// Starts fetching bytes `range` of `url` (all of it for `None`). A server
    /// that ignores ranges may answer with the whole file: callers check the length.
    fn start_range(&mut self, url: &str, range: Option<ByteRange>) -> RequestId;
    /// Starts inflating `deflated` (raw deflate: a stored pack's part, fetched
    /// from `url`) to exactly `bytes` bytes, off the caller's thread; the result
    /// comes back from `poll` as a fetch's does (an error when the stream is
    /// corrupt or does not inflate to exactly that). No request goes out.
    fn start_inflate(&mut self, url: &str, deflated: Vec<u8>, bytes: u64) -> RequestId;
    /// Finished requests since the last poll.
    fn poll(&mut self) -> Vec<(RequestId, Result<Vec<u8>, FetchError>)>;
    /// Requests started and not yet returned by `poll`.
    fn in_flight(&self) -> usize;
}

/// Joins a relative path (from a manifest) onto the manifest's base (a URL or a
/// directory path ending in `/`).
#[must_use]
pub fn join(base: &str, relative: &str) -> String {
    if base.is_empty() {
        relative.to_string()
    } else if base.ends_with('/') {
        format!("{base}{relative}")
    } else {
        format!("{base}/{relative}")
    }
}

/// The base (directory) and manifest location of a scene given as a directory,
/// a `scene.json` path, or a URL of either.
#[must_use]
pub fn scene_locations(scene: &str) -> (String, String) {
    let trimmed = scene.trim_end_matches('/');
    if trimmed.ends_with(".json") {
        let base = trimmed.rsplit_once('/').map_or(String::new(), |(b, _)| format!("{b}/"));
        (base, trimmed.to_string())
    } else {
        (format!("{trimmed}/"), format!("{trimmed}/scene.json"))
    }
}

#[cfg(not(target_arch = "wasm32"))]
mod native {
    use super::{FetchError, Fetcher, RequestId};
    use std::collections::HashMap;
    use std::sync::mpsc;

    /// A fetch of a range (or the whole file), or an inflation of fetched bytes.
    enum Work {
        Fetch(Option<super::ByteRange>),
        Inflate(Vec<u8>, u64),
    }
    type Job = (RequestId, String, Work);
    type Done = (RequestId, Result<Vec<u8>, FetchError>);

    /// Worker threads serving local files and HTTP(S).
    pub struct ThreadFetcher {
        jobs: Option<mpsc::Sender<Job>>,
        done: mpsc::Receiver<Done>,
        next: RequestId,
        pending: HashMap<RequestId, String>,
        workers: Vec<std::thread::JoinHandle<()>>,
    }

    impl ThreadFetcher {
        /// `workers` threads (the number of requests actually in flight at once).
        #[must_use]
        pub fn new(workers: usize) -> Self {
            let (job_tx, job_rx) = mpsc::channel::<Job>();
            let (done_tx, done_rx) = mpsc::channel::<Done>();
            let job_rx = std::sync::Arc::new(std::sync::Mutex::new(job_rx));
            let agent: ureq::Agent =
                ureq::Agent::config_builder().timeout_global(Some(std::time::Duration::from_secs(60))).build().into();
            let workers = (0..workers.max(1))
                .map(|_| {
                    let rx = job_rx.clone();
                    let tx = done_tx.clone();
                    let agent = agent.clone();
                    std::thread::spawn(move || loop {
                        let job = rx.lock().map(|r| r.recv());
                        let Ok(Ok((id, url, work))) = job else { return };
                        let result = match work {
                            Work::Fetch(range) => fetch_blocking(&agent, &url, range),
                            Work::Inflate(bytes, len) => inflate(&url, &bytes, len),
                        };
                        if tx.send((id, result)).is_err() {
                            return;
                        }
                    })
                })
                .collect();
            Self { jobs: Some(job_tx), done: done_rx, next: 0, pending: HashMap::new(), workers }
        }
    }

    impl Drop for ThreadFetcher {
        fn drop(&mut self) {
            self.jobs = None; // workers see the closed channel and exit
            for w in self.workers.drain(..) {
                let _ = w.join();
            }
        }
    }

    /// Fetches one whole file or URL, blocking (a one-off: a pick's tile and sidecars).
    ///
    /// # Errors
    /// As a streamed request would fail.
    pub fn fetch_once(url: &str) -> Result<Vec<u8>, FetchError> {
        let agent: ureq::Agent =
            ureq::Agent::config_builder().timeout_global(Some(std::time::Duration::from_secs(60))).build().into();
        fetch_blocking(&agent, url, None)
    }

    /// Most bytes one response may have, as one local file.
    const MAX_RESPONSE_BYTES: u64 = crate::paths::MAX_SCENE_FILE_BYTES;

    fn fetch_blocking(agent: &ureq::Agent, url: &str, range: Option<super::ByteRange>) -> Result<Vec<u8>, FetchError> {
        if let Some((a, b)) = range {
            if b <= a {
                return Ok(Vec::new());
            }
        }
        if url.starts_with("http://") || url.starts_with("https://") {
            let mut req = agent.get(url);
            if let Some((a, b)) = range {
                req = req.header("Range", &format!("bytes={a}-{}", b - 1));
            }
            match req.call() {
                Ok(mut resp) => resp
                    .body_mut()
                    .with_config()
                    .limit(MAX_RESPONSE_BYTES)
                    .read_to_vec()
                    .map_err(|e| FetchError::Transport { url: url.into(), message: e.to_string() }),
                Err(ureq::Error::StatusCode(404)) => Err(FetchError::NotFound { url: url.into() }),
                Err(ureq::Error::StatusCode(status)) => Err(FetchError::Status { url: url.into(), status }),
                Err(e) => Err(FetchError::Transport { url: url.into(), message: e.to_string() }),
            }
        } else {
            let path = url.strip_prefix("file://").unwrap_or(url);
            // Regular files only, bounded as over HTTP (docs/SECURITY.md).
            crate::paths::read_regular(std::path::Path::new(path), range, MAX_RESPONSE_BYTES).map_err(|e| {
                match e.kind() {
                    std::io::ErrorKind::NotFound => FetchError::NotFound { url: url.into() },
                    // Not a regular file, too large, a folder, a link loop: a retry reads the same.
                    // (io::ErrorKind::FilesystemLoop is not stable yet.)
                    std::io::ErrorKind::InvalidInput => FetchError::Refused { url: url.into(), message: e.to_string() },
                    _ if is_link_loop(&e) => FetchError::Refused { url: url.into(), message: e.to_string() },
                    _ => FetchError::Transport { url: url.into(), message: e.to_string() },
                }
            })
        }
    }

    /// A stored pack's part inflated, or why not (corrupt: worth a fresh fetch).
    pub(crate) fn inflate(url: &str, bytes: &[u8], len: u64) -> Result<Vec<u8>, FetchError> {
        crate::format::stored::inflate_exact(bytes, len)
            .map_err(|m| FetchError::Transport { url: url.into(), message: format!("the stored part {m}") })
    }

    /// Whether `e` says a path's links loop (ELOOP).
    fn is_link_loop(e: &std::io::Error) -> bool {
        #[cfg(unix)]
        return e.raw_os_error() == Some(libc::ELOOP);
        #[cfg(not(unix))]
        return false;
    }

    impl Fetcher for ThreadFetcher {
        fn start_range(&mut self, url: &str, range: Option<super::ByteRange>) -> RequestId {
            let id = self.next;
            self.next += 1;
            self.pending.insert(id, url.to_string());
            if let Some(jobs) = &self.jobs {
                let _ = jobs.send((id, url.to_string(), Work::Fetch(range)));
            }
            id
        }

        fn start_inflate(&mut self, url: &str, deflated: Vec<u8>, bytes: u64) -> RequestId {
            let id = self.next;
            self.next += 1;
            self.pending.insert(id, url.to_string());
            if let Some(jobs) = &self.jobs {
                let _ = jobs.send((id, url.to_string(), Work::Inflate(deflated, bytes)));
            }
            id
        }

        fn poll(&mut self) -> Vec<(RequestId, Result<Vec<u8>, FetchError>)> {
            let mut out = Vec::new();
            while let Ok((id, r)) = self.done.try_recv() {
                self.pending.remove(&id);
                out.push((id, r));
            }
            out
        }

        fn in_flight(&self) -> usize {
            self.pending.len()
        }
    }
}

#[cfg(not(target_arch = "wasm32"))]
pub use native::{fetch_once, ThreadFetcher};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_and_joins() {
        assert_eq!(scene_locations("demo"), ("demo/".into(), "demo/scene.json".into()));
        assert_eq!(scene_locations("demo/"), ("demo/".into(), "demo/scene.json".into()));
        assert_eq!(
            scene_locations("http://h:1/s/scene.json"),
            ("http://h:1/s/".into(), "http://h:1/s/scene.json".into())
        );
        assert_eq!(join("http://h/s/", "tiles/0_0.tile"), "http://h/s/tiles/0_0.tile");
        assert!(!FetchError::NotFound { url: "x".into() }.retryable());
        assert!(FetchError::Status { url: "x".into(), status: 503 }.retryable());
        assert!(!FetchError::Status { url: "x".into(), status: 403 }.retryable());
    }

    #[test]
    fn local_files_that_are_no_regular_files_are_refused_for_good() {
        // A FIFO waited for a writer; a folder or a link loop was
        // retried as if the network had failed. Refused, named, not retried.
        let dir = std::env::temp_dir().join(format!("sylva-fetch-refused-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("folder.jpg")).unwrap();
        let fifo = dir.join("a.cnpy");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()), "mkfifo");
        let looped = dir.join("a.terr");
        std::os::unix::fs::symlink("a.terr", &looped).unwrap();
        for (name, says) in [("a.cnpy", "a FIFO"), ("folder.jpg", "a folder"), ("a.terr", "")] {
            let url = dir.join(name).display().to_string();
            let e = fetch_once(&url).unwrap_err();
            assert!(matches!(e, FetchError::Refused { .. }) && !e.retryable(), "{name}: {e:?}");
            assert!(e.to_string().starts_with(&url) && e.to_string().contains(says), "{e}");
        }
        assert!(matches!(fetch_once(&dir.join("none.tile").display().to_string()), Err(FetchError::NotFound { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
