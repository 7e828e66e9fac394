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

#[cfg(test)]
mod tests {
    use super::*;

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
