//! The bytes a glTF file points at: its buffers and external images.
//!
//! The safety promise (docs/SECURITY.md): a model reads nothing but itself and
//! regular files inside its own folder. A URI is a relative path below the
//! model's folder (after percent-decoding and after following symbolic links),
//! or a base64 `data:` URI; absolute paths, `..`, schemes (`file:`, `http:`)
//! and devices (`/dev/zero`) are refused before anything is opened, and a
//! buffer reads at most its declared `byteLength`.

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use base64::Engine as _;

/// Most bytes all buffers of a tree model may declare together (a
/// 10^6-triangle tree is ~50 MB).
pub const MAX_BUFFER_BYTES: usize = 1 << 30;
/// Largest encoded image file.
pub const MAX_IMAGE_BYTES: u64 = 256 << 20;

/// Loads every buffer of the document: the GLB `BIN` chunk, `data:` URIs and
/// files inside `base`. Each is checked against its declared `byteLength`.
///
/// # Errors
/// A buffer that is missing, too short, larger than [`MAX_BUFFER_BYTES`], or
/// whose URI points outside the model's folder; the message names the buffer.
pub fn load_buffers(
    doc: &gltf::Document,
    blob: Option<&[u8]>,
    base: Option<&Path>,
    fallbacks: &[usize],
) -> Result<Vec<Vec<u8>>> {
    let total = doc.buffers().fold(0usize, |sum, b| sum.saturating_add(b.length()));
    if total > MAX_BUFFER_BYTES {
        bail!("the buffers declare {total} bytes together; a tree model's buffers hold at most {MAX_BUFFER_BYTES}");
    }
    let mut out = Vec::with_capacity(doc.buffers().len());
    for buffer in doc.buffers() {
        let i = buffer.index();
        let declared = buffer.length();
        let mut data = match buffer.source() {
            // A stand-in for meshopt-compressed data (no bytes of its own): its
            // views are filled by the decoder.
            gltf::buffer::Source::Bin if fallbacks.contains(&i) => vec![0; declared],
            // Only the first buffer may be the GLB binary chunk (glTF 2.0 §4.4.3.3).
            gltf::buffer::Source::Bin if i > 0 => {
                bail!("buffer {i} refers to the GLB binary chunk, which only buffer 0 may")
            }
            gltf::buffer::Source::Bin => {
                let blob =
                    blob.ok_or_else(|| anyhow!("buffer {i} refers to the GLB binary chunk, which is missing"))?;
                blob.get(..declared)
                    .ok_or_else(|| {
                        anyhow!("buffer {i} declares {declared} bytes but the GLB binary chunk has {}", blob.len())
                    })?
                    .to_vec()
            }
            gltf::buffer::Source::Uri(uri) => {
                read_uri(uri, base, declared as u64).with_context(|| format!("buffer {i} ({})", short(uri)))?
            }
        };
        if data.len() < declared {
            bail!("buffer {i} declares {declared} bytes but holds {}", data.len());
        }
        data.truncate(declared);
        out.push(data);
    }
    Ok(out)
}

/// Reads a `data:` URI or a file inside `base`, at most `max_bytes` of it.
///
/// # Errors
/// A URI that leaves `base`, names no regular file, or is not base64 data.
pub fn read_uri(uri: &str, base: Option<&Path>, max_bytes: u64) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, b64) = rest.split_once(";base64,").ok_or_else(|| anyhow!("data URI is not base64"))?;
        if b64.len() as u64 / 4 * 3 > max_bytes + 3 {
            bail!("data URI holds more than the {max_bytes} bytes declared");
        }
        return base64::engine::general_purpose::STANDARD.decode(b64.trim()).map_err(|e| anyhow!("data URI: {e}"));
    }
    let base =
        base.ok_or_else(|| anyhow!("external file {uri:?} needs the model's folder (a .glb read from memory)"))?;
    let path = confined_path(base, uri)?;
    let meta = std::fs::metadata(&path).with_context(|| format!("cannot read {}", path.display()))?;
    if !meta.is_file() {
        bail!("{} is not a regular file", path.display());
    }
    let mut bytes = Vec::with_capacity(meta.len().min(max_bytes) as usize);
    std::fs::File::open(&path)
        .and_then(|f| f.take(max_bytes).read_to_end(&mut bytes))
        .with_context(|| format!("cannot read {}", path.display()))?;
    Ok(bytes)
}

/// The file a relative URI names inside `base`, after following links.
///
/// # Errors
/// When the URI is absolute, has a scheme or `..`, or resolves (through a
/// symbolic link) to a place outside `base`.
pub fn confined_path(base: &Path, uri: &str) -> Result<PathBuf> {
    let outside = || anyhow!("{uri:?} points outside the model's folder {}: refused", base.display());
    let decoded = sylva::paths::percent_decode(uri).ok_or_else(|| anyhow!("{uri:?} is not a valid URI"))?;
    // No scheme ("file:", "http:", "C:"), root, `..` or backslash.
    if !sylva::paths::is_plain_relative(&decoded, true) {
        return Err(outside());
    }
    let rel = Path::new(&decoded);
    let base_real =
        std::fs::canonicalize(base).with_context(|| format!("cannot resolve the model's folder {}", base.display()))?;
    let full = base_real.join(rel);
    let real = std::fs::canonicalize(&full).with_context(|| format!("cannot read {}", full.display()))?;
    if !real.starts_with(&base_real) {
        return Err(outside());
    }
    Ok(real)
}

/// A URI shortened for messages (data URIs are long).
fn short(uri: &str) -> String {
    if uri.len() > 60 {
        format!("{}…", &uri[..uri.char_indices().nth(40).map_or(uri.len(), |(i, _)| i)])
    } else {
        uri.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris_stay_inside_the_model_folder() {
        let dir = std::env::temp_dir().join(format!("sylva-uri-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("model/textures")).unwrap();
        std::fs::write(dir.join("model/textures/leaf a.png"), b"png").unwrap();
        std::fs::write(dir.join("secret.txt"), b"secret").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(dir.join("secret.txt"), dir.join("model/link.bin")).unwrap();
        let base = dir.join("model");
        assert_eq!(read_uri("textures/leaf%20a.png", Some(&base), 100).unwrap(), b"png");
        assert_eq!(read_uri("./textures/leaf a.png", Some(&base), 2).unwrap(), b"pn", "bounded by max_bytes");
        for bad in [
            "../secret.txt",
            "textures/../../secret.txt",
            "%2e%2e/secret.txt",
            "/etc/passwd",
            "file:///etc/passwd",
            "/dev/zero",
            "/proc/self/environ",
            "C:\\Windows\\win.ini",
            "link.bin",
        ] {
            let e = format!("{:#}", read_uri(bad, Some(&base), 100).unwrap_err());
            assert!(e.contains("outside the model's folder"), "{bad}: {e}");
        }
        // A folder is no regular file.
        let e = format!("{:#}", read_uri("textures", Some(&base), 100).unwrap_err());
        assert!(e.contains("not a regular file"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
