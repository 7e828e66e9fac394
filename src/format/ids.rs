//! Tree-id sidecars (`tiles/<x>_<y>.ids`): the ids of a tile's trees in its
//! instance order, numbers (version 1) and the inventory's text keys where
//! they were text (version 2). Layout: `docs/FORMAT.md`.

use super::error::{at_most, pod_vec, DecodeError, Problem, Reader};
use super::tile::MAX_TILE_INSTANCES;

/// First four bytes of a tree-id sidecar file.
pub const IDS_MAGIC: [u8; 4] = *b"SYID";
/// Tree-id sidecar version of a tile whose ids are all numbers.
pub const IDS_VERSION: u32 = 1;
/// Tree-id sidecar version of a tile with text ids (version 1 and a text section).
pub const IDS_TEXT_VERSION: u32 = 2;
/// Longest text id kept, in bytes (UTF-8).
pub const MAX_TEXT_ID_BYTES: usize = 256;

/// The number of an id cell as a bake keeps it: a whole number below 2^63
/// written as that number writes itself (`"702"`; not `"0702"`, `"+702"` or
/// `"702.0"`, which stay text: an inventory's key, kept as given).
#[must_use]
pub fn numeric_id(cell: &str) -> Option<u64> {
    cell.parse::<u64>().ok().filter(|n| *n < 1 << 63 && n.to_string() == cell)
}

/// A tile's tree ids: a number per instance (as in version 1) and the text id
/// of the instances whose input id was text (their number is their row,
/// `2^63 + row`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TreeIds {
    /// Per instance, in instance order.
    pub numbers: Vec<u64>,
    /// `(instance, text)` of the instances with a text id, by instance.
    pub texts: Vec<(u32, String)>,
}

impl TreeIds {
    /// The text id of `instance`, if it has one.
    #[must_use]
    pub fn text(&self, instance: u32) -> Option<&str> {
        self.texts.binary_search_by_key(&instance, |(i, _)| *i).ok().map(|k| self.texts[k].1.as_str())
    }
}

/// Encodes the tree ids of a tile's instances (same order) into an `.ids` sidecar.
#[must_use]
pub fn encode_ids(ids: &[u64]) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + ids.len() * 8);
    out.extend_from_slice(&IDS_MAGIC);
    out.extend_from_slice(&IDS_VERSION.to_le_bytes());
    out.extend_from_slice(&(ids.len() as u64).to_le_bytes());
    out.extend_from_slice(bytemuck::cast_slice(ids));
    out
}

/// Encodes a tile's ids with the text ids of some instances (`texts` by
/// instance, each 1–[`MAX_TEXT_ID_BYTES`] bytes): version 2, or version 1
/// when there are none (a scene without text ids is as before).
///
/// # Errors
/// Texts that break the format's rules (out of order, past the instances,
/// empty or over 256 bytes, on an instance whose number is no row): what
/// [`decode_tree_ids`] would refuse is never written.
pub fn encode_tree_ids(ids: &TreeIds) -> Result<Vec<u8>, String> {
    if ids.texts.is_empty() {
        return Ok(encode_ids(&ids.numbers));
    }
    let mut out = encode_ids(&ids.numbers);
    out[4..8].copy_from_slice(&IDS_TEXT_VERSION.to_le_bytes());
    out.extend_from_slice(&(ids.texts.len() as u32).to_le_bytes());
    let mut last = None;
    for (i, t) in &ids.texts {
        let number = ids.numbers.get(*i as usize).copied();
        let bad = last.is_some_and(|l| *i <= l)
            || number.is_none_or(|n| n < 1 << 63)
            || t.is_empty()
            || t.len() > MAX_TEXT_ID_BYTES;
        if bad {
            return Err(format!("text id {t:?} of instance {i}: not a text id this format holds"));
        }
        last = Some(*i);
        out.extend_from_slice(&i.to_le_bytes());
    }
    let mut end = 0u32;
    for (_, t) in &ids.texts {
        end = end.checked_add(t.len() as u32).ok_or("over 4 GiB of text ids in one tile")?;
        out.extend_from_slice(&end.to_le_bytes());
    }
    for (_, t) in &ids.texts {
        out.extend_from_slice(t.as_bytes());
    }
    Ok(out)
}

/// Decodes an `.ids` sidecar's numbers (either version).
///
/// # Errors
/// A [`DecodeError`] for a wrong magic or version, or a size that does not match the count.
pub fn decode_ids(file: &str, bytes: &[u8]) -> Result<Vec<u64>, DecodeError> {
    decode_tree_ids(file, bytes).map(|ids| ids.numbers)
}

/// Decodes an `.ids` sidecar: its numbers and, in version 2, its text ids.
///
/// # Errors
/// A [`DecodeError`] for a wrong magic or version, a size that does not
/// match the count, or a text section out of order, out of range or not UTF-8.
pub fn decode_tree_ids(file: &str, bytes: &[u8]) -> Result<TreeIds, DecodeError> {
    let inner = || -> Result<TreeIds, Problem> {
        let r = Reader::new(bytes);
        r.magic("Sylva tree-id", &IDS_MAGIC)?;
        let version = r.u32("header.version", 4)?;
        if version != IDS_VERSION && version != IDS_TEXT_VERSION {
            return Err(Problem::UnsupportedVersion { found: version, supported: IDS_TEXT_VERSION });
        }
        let count = at_most("header.count", r.u64("header.count", 8)?, MAX_TILE_INSTANCES.into())?;
        let body = bytes.len() as u64 - 16;
        if version == IDS_VERSION && body != count * 8 {
            return Err(Problem::Invalid(format!(
                "{count} ids need {} bytes after the header, the file has {body}",
                count * 8
            )));
        }
        let numbers: Vec<u64> = pod_vec(r.slice("ids", 16, count * 8)?);
        if version == IDS_VERSION {
            return Ok(TreeIds { numbers, texts: Vec::new() });
        }
        let at = 16 + count * 8;
        let n = at_most("texts.count", u64::from(r.u32("texts.count", at)?), count)?;
        if n == 0 {
            return Err(Problem::Invalid("version 2 without text ids (written as version 1)".into()));
        }
        let instances: Vec<u32> = pod_vec(r.slice("texts.instances", at + 4, n * 4)?);
        let ends: Vec<u32> = pod_vec(r.slice("texts.ends", at + 4 + n * 4, n * 4)?);
        let blob_at = at + 4 + n * 8;
        let blob = r.slice("texts", blob_at, bytes.len() as u64 - blob_at.min(bytes.len() as u64))?;
        if ends.last().map_or(0, |e| u64::from(*e)) != blob.len() as u64 {
            return Err(Problem::Invalid(format!(
                "the text ids end at byte {} of {} bytes of text",
                ends.last().copied().unwrap_or(0),
                blob.len()
            )));
        }
        let mut texts = Vec::with_capacity(n as usize);
        let mut start = 0usize;
        for (k, (&i, &end)) in instances.iter().zip(&ends).enumerate() {
            let end = end as usize;
            if u64::from(i) >= count || k > 0 && i <= instances[k - 1] {
                return Err(Problem::Invalid(format!("text id {k}: instance {i} (instances rise, below {count})")));
            }
            if numbers[i as usize] < 1 << 63 {
                return Err(Problem::Invalid(format!(
                    "text id {k}: instance {i} has the number {} (a text id's number is 2^63 + its row)",
                    numbers[i as usize]
                )));
            }
            if end <= start || end - start > MAX_TEXT_ID_BYTES || end > blob.len() {
                return Err(Problem::Invalid(format!(
                    "text id {k}: bytes {start}–{end} (1–{MAX_TEXT_ID_BYTES} bytes each, within the text)"
                )));
            }
            let text = std::str::from_utf8(&blob[start..end])
                .map_err(|_| Problem::Invalid(format!("text id {k} is not UTF-8")))?;
            texts.push((i, text.to_string()));
            start = end;
        }
        Ok(TreeIds { numbers, texts })
    };
    inner().map_err(|p| DecodeError::new(file, p))
}
