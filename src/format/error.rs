//! Typed decode errors shared by every Sylva decoder.
//!
//! Every decoder takes the name of what it decodes (a file path or URL) and
//! returns a [`DecodeError`] that names it, so a user reading the message knows
//! which file is broken and why.

use std::fmt;

/// A file that could not be decoded: which file, and what was wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {problem}")]
pub struct DecodeError {
    /// Path or URL of the file, as given to the decoder.
    pub file: String,
    /// What was wrong.
    pub problem: Problem,
}

impl DecodeError {
    /// Builds an error for `file`.
    #[must_use]
    pub fn new(file: impl Into<String>, problem: Problem) -> Self {
        Self { file: file.into(), problem }
    }
}

/// What was wrong with a file. Each variant says where (field, index, offset).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    /// The file does not start with the expected magic bytes.
    #[error("not a {expected} file (magic bytes {found:?})")]
    BadMagic {
        /// Human-readable name of the expected kind of file.
        expected: &'static str,
        /// The first bytes found.
        found: Vec<u8>,
    },
    /// A version this build cannot read.
    #[error("format version {found} is not supported (the newest this build reads is version {supported})")]
    UnsupportedVersion {
        /// Version in the file.
        found: u32,
        /// Newest version this build reads.
        supported: u32,
    },
    /// The file ends before a structure it declares.
    #[error("truncated: {what} needs bytes {start}..{end} but the file has {len} bytes")]
    Truncated {
        /// The structure being read.
        what: String,
        /// First byte of the structure.
        start: u64,
        /// One past its last byte.
        end: u64,
        /// Bytes in the file.
        len: u64,
    },
    /// A count, size or index outside what the format allows.
    #[error("{what} = {value} is out of range ({allowed})")]
    OutOfRange {
        /// The field, with its index.
        what: String,
        /// The value found.
        value: u64,
        /// What is allowed.
        allowed: String,
    },
    /// A float that is NaN or infinite.
    #[error("{what} is not a finite number ({value})")]
    NotFinite {
        /// The field, with its index.
        what: String,
        /// The value found.
        value: f64,
    },
    /// Anything else that is inconsistent.
    #[error("{0}")]
    Invalid(String),
    /// Malformed JSON, or JSON that does not match the schema.
    #[error("invalid JSON: {0}")]
    Json(String),
}

/// Checks that a float is finite, naming the field otherwise.
pub(crate) fn finite(what: impl fmt::Display, value: f64) -> Result<f64, Problem> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Problem::NotFinite { what: what.to_string(), value })
    }
}

/// Checks every component of a float array.
pub(crate) fn finite_all(what: &str, values: &[f32]) -> Result<(), Problem> {
    for (i, v) in values.iter().enumerate() {
        finite(format_args!("{what}[{i}]"), f64::from(*v))?;
    }
    Ok(())
}

/// Checks `value <= max`.
pub(crate) fn at_most(what: impl fmt::Display, value: u64, max: u64) -> Result<u64, Problem> {
    if value <= max {
        Ok(value)
    } else {
        Err(Problem::OutOfRange { what: what.to_string(), value, allowed: format!("at most {max}") })
    }
}

/// A bounds-checked little-endian reader over a byte slice. Reads never panic.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Self { bytes }
    }

    /// The bytes `start..start+len`, or a `Truncated` problem naming `what`.
    pub(crate) fn slice(&self, what: &str, start: u64, len: u64) -> Result<&'a [u8], Problem> {
        let end = start.checked_add(len);
        match end {
            Some(end) if end <= self.bytes.len() as u64 => Ok(&self.bytes[start as usize..end as usize]),
            _ => Err(Problem::Truncated {
                what: what.to_string(),
                start,
                end: end.unwrap_or(u64::MAX),
                len: self.bytes.len() as u64,
            }),
        }
    }

    pub(crate) fn u16(&self, what: &str, at: u64) -> Result<u16, Problem> {
        let b = self.slice(what, at, 2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    pub(crate) fn u32(&self, what: &str, at: u64) -> Result<u32, Problem> {
        let b = self.slice(what, at, 4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub(crate) fn i32(&self, what: &str, at: u64) -> Result<i32, Problem> {
        Ok(self.u32(what, at)? as i32)
    }

    pub(crate) fn u64(&self, what: &str, at: u64) -> Result<u64, Problem> {
        let b = self.slice(what, at, 8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    pub(crate) fn magic(&self, expected_name: &'static str, magic: &[u8; 4]) -> Result<(), Problem> {
        let found = &self.bytes[..self.bytes.len().min(4)];
        if found == magic {
            Ok(())
        } else {
            Err(Problem::BadMagic { expected: expected_name, found: found.to_vec() })
        }
    }
}

/// Copies `bytes` into a vector of Pod records of `size_of::<T>()` bytes each.
/// The caller has checked that `bytes.len()` is a multiple of the record size.
pub(crate) fn pod_vec<T: bytemuck::Pod>(bytes: &[u8]) -> Vec<T> {
    // `pod_collect_to_vec` copies, so the source needs no alignment.
    bytemuck::pod_collect_to_vec(bytes)
}
