//! Relative paths from untrusted text (glTF URIs, HTTP request paths, the
//! bake's list of its files), shared by `sylva serve` and the bake so the
//! rules are one: percent-decoding that refuses malformed escapes, and plain
//! relative paths only — no `..`, no root, no drive or scheme, no backslash.

use std::path::{Component, Path};

/// Decodes `%XX` escapes; `None` for a malformed escape or bytes that are no UTF-8.
#[must_use]
pub fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Whether `text` is a plain relative path: names (and `.`) only, no `..`,
/// no root or drive, no scheme (`:`), no backslash; with `dotfiles` false, no
/// name may start with a dot either.
#[must_use]
pub fn is_plain_relative(text: &str, dotfiles: bool) -> bool {
    if text.is_empty() || text.contains([':', '\\', '\0']) || text.starts_with('/') {
        return false;
    }
    Path::new(text).components().all(|c| match c {
        Component::Normal(n) => dotfiles || !n.to_string_lossy().starts_with('.'),
        Component::CurDir => true,
        _ => false,
    })
}

/// Most bytes one scene file may have, read from a local folder as over HTTP
/// (a pack with 8k² textures stays below it).
pub const MAX_SCENE_FILE_BYTES: u64 = 1 << 30;

/// Reads a scene file from a local path — all of it, or the bytes `range`
/// (start, end exclusive) — at most `cap` bytes: a regular file only, also at
/// the end of a link. A FIFO, device, socket or folder is refused before it is
/// opened, so a read neither waits for a writer nor runs on for ever
/// (`/dev/zero`); a file over `cap` is refused before it is read. The error
/// says what the path is, not the path: the caller names it.
///
/// # Errors
/// `NotFound` for a missing file; `InvalidInput` for what is no regular file or
/// too large; other I/O errors as they come.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_regular(path: &Path, range: Option<(u64, u64)>, cap: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Error, ErrorKind, Read, Seek};
    let refuse = |what: &str| Error::new(ErrorKind::InvalidInput, format!("it is {what}, not a regular file"));
    let kind = |m: &std::fs::Metadata| -> Option<&'static str> {
        let t = m.file_type();
        if t.is_file() {
            return None;
        }
        if t.is_dir() {
            return Some("a folder");
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if t.is_fifo() {
                return Some("a FIFO");
            }
            if t.is_char_device() || t.is_block_device() {
                return Some("a device");
            }
            if t.is_socket() {
                return Some("a socket");
            }
        }
        Some("something else")
    };
    if let Some(what) = kind(&std::fs::metadata(path)?) {
        return Err(refuse(what));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    // Opened without waiting: a FIFO swapped in between the look and the open
    // does not block the open (it is then refused below); a regular file reads
    // as ever.
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY);
    }
    let mut f = options.open(path)?;
    // The path may have been swapped between the look and the open.
    let meta = f.metadata()?;
    if let Some(what) = kind(&meta) {
        return Err(refuse(what));
    }
    let (start, want) = match range {
        Some((a, b)) => (a, b.saturating_sub(a)),
        None => (0, meta.len()),
    };
    if want > cap {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!("{want} bytes asked, over the limit of {cap} for one scene file"),
        ));
    }
    if start > 0 {
        f.seek(std::io::SeekFrom::Start(start))?;
    }
    let mut out = Vec::with_capacity(usize::try_from(want.min(meta.len().saturating_sub(start))).unwrap_or(0));
    // A file that grows while it is read stops at what was asked.
    f.take(want).read_to_end(&mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_files_are_read_only_when_regular_and_within_the_cap() {
        let dir = std::env::temp_dir().join(format!("sylva-read-regular-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a.tile");
        std::fs::write(&file, (0..100u8).collect::<Vec<_>>()).unwrap();
        assert_eq!(read_regular(&file, None, 100).unwrap().len(), 100);
        assert_eq!(read_regular(&file, Some((10, 20)), 100).unwrap(), (10..20u8).collect::<Vec<_>>());
        assert_eq!(read_regular(&file, Some((90, 200)), 1000).unwrap().len(), 10, "a range past the end stops at it");
        let e = read_regular(&file, None, 99).unwrap_err();
        assert!(e.to_string().contains("over the limit of 99"), "{e}");
        assert_eq!(read_regular(&dir.join("missing"), None, 100).unwrap_err().kind(), std::io::ErrorKind::NotFound);
        // A link to a regular file is read; to a device, a FIFO or a folder, refused at once.
        let link = dir.join("link.tile");
        std::os::unix::fs::symlink(&file, &link).unwrap();
        assert_eq!(read_regular(&link, None, 100).unwrap().len(), 100);
        let zero = dir.join("zero.attr");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        let e = read_regular(&zero, None, MAX_SCENE_FILE_BYTES).unwrap_err();
        assert!(e.to_string().contains("is a device, not a regular file"), "{e}");
        assert!(read_regular(&dir, None, 100).unwrap_err().to_string().contains("a folder"));
        let fifo = dir.join("fifo.cnpy");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()), "mkfifo");
        let e = read_regular(&fifo, None, 100).unwrap_err();
        assert!(e.to_string().contains("is a FIFO"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn plain_relative_paths_only() {
        for ok in ["a", "tiles/0_0.tile", "./x/y.bin", "leaf image.png"] {
            assert!(is_plain_relative(ok, false), "{ok}");
        }
        for bad in ["", "/etc/passwd", "../x", "a/../../x", "C:\\x", "c:x", "file:///x", "a\\..\\x", "x\0y"] {
            assert!(!is_plain_relative(bad, true), "{bad}");
        }
        assert!(!is_plain_relative(".env", false) && is_plain_relative(".env", true));
        assert!(!is_plain_relative("a/.git/config", false));
        assert_eq!(percent_decode("leaf%20a.png").as_deref(), Some("leaf a.png"));
        assert_eq!(percent_decode("%2e%2e/x").as_deref(), Some("../x"));
        assert_eq!(percent_decode("%zz"), None);
        assert_eq!(percent_decode("%4"), None);
        assert_eq!(percent_decode("%ff"), None, "not UTF-8");
    }
}
