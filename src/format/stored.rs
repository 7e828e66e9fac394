//! Stored packs: a pack's parts deflated, each as one block, behind the same
//! head (`docs/FORMAT.md`, "Stored packs").
//!
//! The far tiers are texture arrays whose texels are mostly empty (around a
//! crown) or smooth; deflated they take a tenth of their bytes. A viewer
//! fetches a part's block by byte range as before and inflates it to exactly
//! the bytes the section table places (the browser with its own
//! `DecompressionStream`, natively [`inflate_exact`]), so everything after the
//! fetch reads a stored pack as a pack. Whole-file readers (the bake, `sylva
//! render --pack`, the export) call [`unstore`] first.

use super::error::{DecodeError, Problem};
use super::pack::PackHead;
#[cfg(not(target_arch = "wasm32"))]
use super::pack::{
    decode_pack, encode_pack, kind, part_range_in, read_table, PackPart, Section, PACK_VERSION_STORED,
    STORED_BLOCK_BYTES,
};

/// A pack (as [`encode_pack`] writes it, or a stored one) stored: its sections
/// in part order, a `STOR` table after `META`, each part deflated (level 9)
/// after the head.
///
/// # Errors
/// A [`DecodeError`] when `pack` does not decode, or holds a section of no
/// part (an unknown kind: a stored pack places every byte in a part).
#[cfg(not(target_arch = "wasm32"))]
pub fn store_pack(name: &str, pack: &[u8]) -> Result<Vec<u8>, DecodeError> {
    let logical;
    let pack = if PackHead::decode(name, pack)?.stored.is_empty() {
        pack
    } else {
        logical = unstore(name, pack.to_vec())?;
        &logical
    };
    let decoded = decode_pack(name, pack)?;
    let mut by_part: Vec<(usize, Section)> = Vec::new();
    for (e, bytes) in decoded.sections.iter().skip(1) {
        if e.kind == kind::STORED {
            continue;
        }
        let Some(part) = PackPart::of(e.kind, e.index) else {
            let what = format!("section {} belongs to no part: a stored pack cannot hold it", kind_name(e.kind));
            return Err(DecodeError::new(name, Problem::Invalid(what)));
        };
        let section = Section { kind: e.kind, index: e.index, count: e.count, stride: e.stride, data: bytes.to_vec() };
        by_part.push((part.index(), section));
    }
    // (Stable: each part's sections keep their order.)
    by_part.sort_by_key(|(p, _)| *p);
    let mut parts: Vec<usize> = by_part.iter().map(|(p, _)| *p).collect();
    parts.dedup();
    let table = Section {
        kind: kind::STORED,
        index: 0,
        count: parts.len() as u32,
        stride: STORED_BLOCK_BYTES as u32,
        data: vec![0; parts.len() * STORED_BLOCK_BYTES as usize],
    };
    let sections: Vec<Section> = std::iter::once(table).chain(by_part.into_iter().map(|(_, s)| s)).collect();
    let mut out = encode_pack(&decoded.meta, &sections);
    out[4..6].copy_from_slice(&PACK_VERSION_STORED.to_le_bytes());
    // The layout as encoded: STOR's place (its table still zeros), each part's range.
    let (entries, _) = read_table(&out, false).map_err(|p| DecodeError::new(name, p))?;
    let stor = entries[1];
    let (stor_at, head_end) = (stor.offset, (stor.offset + stor.bytes) as usize);
    let ranges: Vec<(u64, u64)> = parts.iter().filter_map(|p| part_range_in(&entries, PackPart::ALL[*p])).collect();
    let mut blocks = Vec::with_capacity(ranges.len());
    let mut table = Vec::with_capacity(ranges.len() * STORED_BLOCK_BYTES as usize);
    let mut at = head_end as u64;
    for (lo, hi) in &ranges {
        let deflated = deflate(&out[*lo as usize..*hi as usize]);
        for w in [*lo, hi - lo, at, deflated.len() as u64] {
            table.extend_from_slice(&w.to_le_bytes());
        }
        at += deflated.len() as u64;
        blocks.push(deflated);
    }
    out[stor_at as usize..head_end].copy_from_slice(&table);
    out.truncate(head_end);
    for b in blocks {
        out.extend_from_slice(&b);
    }
    // What a viewer will read, read back.
    PackHead::decode(name, &out)?;
    Ok(out)
}

/// The pack in `file` with its parts inflated in place: the bytes the section
/// table describes ([`decode_pack`] reads them). A version 1 pack comes back
/// as it is.
///
/// # Errors
/// A [`DecodeError`] for a head that does not decode, a block outside the file
/// or one that does not inflate to exactly its part's size.
pub fn unstore(name: &str, file: Vec<u8>) -> Result<Vec<u8>, DecodeError> {
    unstore_with(name, file, &mut |deflated, len| inflate(deflated, len))
}

/// Inflates a stored block to its part's bytes (`deflated`, the part's size).
pub type Inflater<'a> = dyn FnMut(&[u8], u64) -> Result<Vec<u8>, String> + 'a;

/// [`unstore`] with another inflater: `inflate(deflated, len)` gives a
/// block's `len` bytes or says why not (the browser inflates each block
/// first, with its own `DecompressionStream`, then hands them over).
///
/// # Errors
/// As [`unstore`].
pub fn unstore_with(name: &str, file: Vec<u8>, inflate: &mut Inflater) -> Result<Vec<u8>, DecodeError> {
    let head = PackHead::decode(name, &file)?;
    if head.stored.is_empty() {
        return Ok(file);
    }
    let len = file.len() as u64;
    if let Some(b) = head.stored.iter().find(|b| b.stored.1 > len) {
        let what = format!("stored part at bytes {}..{}", b.stored.0, b.stored.1);
        return Err(DecodeError::new(name, Problem::Truncated { what, start: b.stored.0, end: b.stored.1, len }));
    }
    // (Grown as the blocks inflate, in order, each after at most the alignment's
    // padding: no more than what they truly hold, `read_blocks` checked.)
    let mut out = head.bytes.clone();
    for b in &head.stored {
        out.resize(b.logical.0 as usize, 0);
        let part =
            inflate(&file[b.stored.0 as usize..b.stored.1 as usize], b.logical.1 - b.logical.0).map_err(|e| {
                DecodeError::new(name, Problem::Invalid(format!("stored part at bytes {}: {e}", b.stored.0)))
            })?;
        if part.len() as u64 != b.logical.1 - b.logical.0 {
            let what = format!(
                "stored part at bytes {} inflates to {} bytes, not {}",
                b.stored.0,
                part.len(),
                b.logical.1 - b.logical.0
            );
            return Err(DecodeError::new(name, Problem::Invalid(what)));
        }
        out.extend_from_slice(&part);
    }
    out.resize(head.file_bytes as usize, 0);
    Ok(out)
}

/// Inflates raw deflate `bytes` to exactly `len` bytes: an error for a stream
/// that is corrupt, ends early or holds more (never inflating past `len` + 1).
///
/// # Errors
/// What is wrong, in words.
#[cfg(not(target_arch = "wasm32"))]
pub fn inflate_exact(bytes: &[u8], len: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut out = Vec::with_capacity(len.min(bytes.len() as u64 * 64) as usize);
    flate2::read::DeflateDecoder::new(bytes)
        .take(len + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("does not inflate ({e})"))?;
    if out.len() as u64 != len {
        let more = if out.len() as u64 > len { "more than" } else { "only" };
        return Err(format!("inflates to {more} {} bytes, expected {len}", out.len().min(len as usize + 1)));
    }
    Ok(out)
}

#[cfg(not(target_arch = "wasm32"))]
fn inflate(bytes: &[u8], len: u64) -> Result<Vec<u8>, String> {
    inflate_exact(bytes, len)
}

/// In the browser whole stored packs are not read: a part comes by range and
/// the browser inflates it (`crate::web::fetch`).
#[cfg(target_arch = "wasm32")]
fn inflate(_bytes: &[u8], _len: u64) -> Result<Vec<u8>, String> {
    Err("a stored pack is read by parts here: the server must answer byte-range requests".into())
}

#[cfg(not(target_arch = "wasm32"))]
fn deflate(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
    enc.write_all(bytes).expect("writing to a Vec");
    enc.finish().expect("writing to a Vec")
}

#[cfg(not(target_arch = "wasm32"))]
fn kind_name(k: [u8; 4]) -> String {
    String::from_utf8_lossy(&k).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::pack::PackPart;

    fn fixture_pack() -> Vec<u8> {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small/species");
        let first = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|x| x == "pack"));
        std::fs::read(first.expect("a fixture pack")).unwrap()
    }

    #[test]
    fn a_stored_pack_reads_back_as_its_pack() {
        let raw = fixture_pack();
        let stored = store_pack("p", &raw).unwrap();
        assert!(stored.len() * 3 < raw.len(), "{} bytes stored of {}", stored.len(), raw.len());
        let head = PackHead::decode("p", &stored).unwrap();
        assert!(!head.stored.is_empty());
        let back = unstore("p", stored.clone()).unwrap();
        let (a, b) = (decode_pack("raw", &raw).unwrap(), decode_pack("back", &back).unwrap());
        assert_eq!(a.meta, b.meta);
        for (e, bytes) in a.sections.iter().skip(1) {
            assert_eq!(b.section(e.kind, e.index), Some(*bytes), "{}{}", kind_name(e.kind), e.index);
        }
        // Every part fetched by its block and inflated assembles the same pack.
        let mut held = Vec::new();
        for p in PackPart::ALL {
            let Some(f) = head.fetch_of(p) else { continue };
            let part = inflate_exact(&stored[f.range.0 as usize..f.range.1 as usize], f.inflated.unwrap()).unwrap();
            held.push((head.part_range(p).unwrap().0, part));
        }
        let assembled = head.assemble("p", &held).unwrap();
        assert_eq!(assembled.sections.len(), a.sections.len());
        // Storing again changes nothing.
        assert_eq!(store_pack("p", &stored).unwrap(), stored);
        // A whole stored file is not a pack to decode_pack.
        let e = decode_pack("p", &stored).unwrap_err().to_string();
        assert!(e.contains("stored pack"), "{e}");
    }

    #[test]
    fn hostile_blocks_are_refused() {
        let stored = store_pack("p", &fixture_pack()).unwrap();
        let head = PackHead::decode("p", &stored).unwrap();
        let stor = head.entries[1];
        let word = |bytes: &mut Vec<u8>, block: u64, field: u64, v: u64| {
            let at = (stor.offset + block * STORED_BLOCK_BYTES + field * 8) as usize;
            bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
        };
        let b0 = head.stored[0];
        type Break<'a> = Box<dyn Fn(&mut Vec<u8>) + 'a>;
        let cases: Vec<(&str, Break<'_>)> = vec![
            ("a block claiming a huge part", Box::new(|b| word(b, 0, 1, u64::MAX / 2))),
            ("a part shifted", Box::new(move |b| word(b, 0, 0, b0.logical.0 + 256))),
            ("a gap between stored blocks", Box::new(move |b| word(b, 0, 2, b0.stored.0 + 1))),
            ("an empty stored block", Box::new(|b| word(b, 0, 3, 0))),
            ("an inflation beyond deflate's", Box::new(|b| word(b, 0, 3, 1))),
            ("a stored size that overflows", Box::new(|b| word(b, 0, 3, u64::MAX))),
            ("blocks out of order", Box::new(move |b| word(b, 0, 0, b0.logical.0 + (1 << 20)))),
            // A tiny file claiming a terabyte: refused before anything is allocated.
            ("a huge pack size", Box::new(|b| b[16..24].copy_from_slice(&(1u64 << 40).to_le_bytes()))),
        ];
        for (what, break_it) in cases {
            let mut bad = stored.clone();
            break_it(&mut bad);
            assert!(PackHead::decode("p", &bad).is_err(), "{what} decodes");
            assert!(unstore("p", bad).is_err(), "{what} unstores");
        }
        // Corrupt or cut deflate streams: an error, never a panic.
        let mut bad = stored.clone();
        for x in &mut bad[b0.stored.0 as usize..b0.stored.0 as usize + 64] {
            *x ^= 0x5a;
        }
        assert!(unstore("p", bad).is_err());
        let cut = stored[..stored.len() - 10].to_vec();
        assert!(unstore("p", cut).is_err());
        assert!(inflate_exact(&deflate(&[7; 1000]), 999).unwrap_err().contains("more than"));
        assert!(inflate_exact(&deflate(&[7; 1000]), 1001).unwrap_err().contains("only"));
    }
}
