//! Delimited text (CSV and its cousins): the separator detected, the header
//! record read within a bound (quotes, a BOM, CR line ends, blank lines), the
//! fields decoded (UTF-8, else Windows-1252) and the rows streamed.

use anyhow::{anyhow, bail, Result};

use super::*;

/// One CSV field as text: UTF-8, or Windows-1252 where the options allow it.
/// `None` when the bytes are no UTF-8 and only UTF-8 is accepted.
pub(super) fn decode_field<'a>(
    bytes: &'a [u8],
    encoding: Encoding,
    fell_back: &mut bool,
) -> Option<std::borrow::Cow<'a, str>> {
    match (encoding, std::str::from_utf8(bytes)) {
        (Encoding::Latin1, _) => Some(encoding_rs::WINDOWS_1252.decode_without_bom_handling(bytes).0),
        (_, Ok(s)) => Some(std::borrow::Cow::Borrowed(s)),
        (Encoding::Utf8, Err(_)) => None,
        (Encoding::Auto, Err(_)) => {
            *fell_back = true;
            Some(encoding_rs::WINDOWS_1252.decode_without_bom_handling(bytes).0)
        }
    }
}

/// Reads CSV from any reader (the first line is the header).
#[cfg(test)]
pub fn read_csv<R: std::io::Read>(reader: R, delimiter: u8, options: &ReadOptions) -> Result<PlacementSet> {
    let mut report = Report::default();
    let mut rows = Vec::new();
    let kind = stream_csv(reader, delimiter, options, true, &mut report, &mut |p| {
        rows.push(p);
        Ok(())
    })?;
    let attribute_names = Vec::new();
    Ok(PlacementSet { kind, rows, report, declared_epsg: None, attribute_names })
}

/// The CSV reader of every pass over an inventory (the header's and the rows'),
/// so both see the same columns.
pub(super) fn csv_reader<R: std::io::Read>(reader: R, delimiter: u8) -> csv::Reader<R> {
    csv::ReaderBuilder::new().delimiter(delimiter).flexible(true).trim(csv::Trim::All).from_reader(reader)
}

/// Most bytes of a CSV header record.
pub const MAX_HEADER_BYTES: usize = 1 << 20;

/// The first record of a CSV file, up to its line break outside quotes (a
/// header cell may hold one: what a spreadsheet writes for Alt+Enter), as
/// [`header_record_with`] with the separator not known yet.
///
/// # Errors
/// A header over `limit` bytes, or a read error.
pub fn header_record(reader: impl std::io::Read, limit: usize) -> Result<Vec<u8>> {
    header_record_with(reader, limit, None)
}

/// The first record of a CSV file with quotes as the CSV reader reads them:
/// a `"` opens a quoted field only at the start of a field (after the
/// `separator`, or any of `,`, `;`, a tab or `|` when it is not known yet),
/// `""` inside one is a quote, and elsewhere `"` is a character (`dbh (")`).
/// The record ends at a line feed, a carriage return (with the line feed
/// after it) outside quotes; blank lines before it are skipped.
///
/// # Errors
/// A header over `limit` bytes, or a read error.
pub fn header_record_with(reader: impl std::io::Read, limit: usize, separator: Option<u8>) -> Result<Vec<u8>> {
    use std::io::BufRead;
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        FieldStart,
        Unquoted,
        Quoted,
        QuoteInQuoted,
        /// After a carriage return that ended the record: a line feed may follow.
        Ended,
    }
    let is_separator = |b: u8| match separator {
        Some(d) => b == d,
        None => matches!(b, b',' | b';' | b'\t' | b'|'),
    };
    let mut r = std::io::BufReader::new(reader.take(limit as u64 + 1));
    let mut out = Vec::new();
    let mut state = State::FieldStart;
    let mut content = false;
    loop {
        let buf = r.fill_buf()?;
        if buf.is_empty() {
            break;
        }
        let mut used = buf.len();
        let mut done = false;
        for (i, &b) in buf.iter().enumerate() {
            let at = out.len() + i;
            if state == State::Ended {
                used = i + usize::from(b == b'\n');
                done = true;
                break;
            }
            // A UTF-8 byte-order mark is no part of the first field.
            if at < 3 && b == [0xef, 0xbb, 0xbf][at] && !content {
                continue;
            }
            let terminator = b == b'\n' || b == b'\r';
            if terminator && !content && state == State::FieldStart {
                continue; // a blank line before the header
            }
            content = true;
            state = match (state, b) {
                (State::Quoted, b'"') => State::QuoteInQuoted,
                (State::Quoted, _) => State::Quoted,
                (State::FieldStart | State::QuoteInQuoted, b'"') => State::Quoted,
                (_, b'\n') => {
                    used = i + 1;
                    done = true;
                    break;
                }
                (_, b'\r') => State::Ended,
                (_, b) if is_separator(b) => State::FieldStart,
                _ => State::Unquoted,
            };
        }
        out.extend_from_slice(&buf[..used]);
        r.consume(used);
        if out.len() > limit {
            bail!("the header (the first line) is over {} KiB without its end: is this a CSV file?", limit / 1024);
        }
        if done {
            break;
        }
    }
    Ok(out)
}

/// Reads the header line (UTF-8 or Windows-1252, as the fields) and detects its columns.
pub(super) fn header_columns<R: std::io::Read>(rdr: &mut csv::Reader<R>, options: &ReadOptions) -> Result<Columns> {
    let mut fell_back = false;
    let header: Vec<String> = rdr
        .byte_headers()
        .map_err(|e| anyhow!("cannot read the CSV header: {e}"))?
        .iter()
        .map(|h| decode_field(h, Encoding::Auto, &mut fell_back).unwrap_or_default().into_owned())
        .collect();
    let refs: Vec<&str> = header.iter().map(String::as_str).collect();
    detect_columns_with(&refs, options)
}

/// Streams CSV rows: each usable row goes to `f` as it is read (memory stays
/// constant whatever the file size); skipped rows are counted in `report`.
/// Returns the coordinate kind of the header.
pub fn stream_csv<R: std::io::Read>(
    reader: R,
    delimiter: u8,
    options: &ReadOptions,
    with_attributes: bool,
    report: &mut Report,
    f: &mut dyn FnMut(Placement) -> Result<()>,
) -> Result<CoordKind> {
    let mut rdr = csv_reader(reader, delimiter);
    let mut cols = header_columns(&mut rdr, options)?;
    if options.swap_xy {
        std::mem::swap(&mut cols.x, &mut cols.y);
    }
    let number = if delimiter == b',' { parse_f64 } else { parse_decimal_comma };
    let mut record = csv::ByteRecord::new();
    let mut row = 0u64;
    loop {
        match rdr.read_byte_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                row += 1;
                report.rows += 1;
                report.skip(&format!("unreadable CSV ({})", e.kind_name()), row);
                continue;
            }
        }
        row += 1;
        report.rows += 1;
        let mut row_fell_back = false;
        let mut utf8_error = false;
        let mut get = |c: Option<usize>| {
            let field = record.get(c?)?;
            let text = decode_field(field, options.encoding, &mut row_fell_back);
            utf8_error |= text.is_none();
            text
        };
        let (x, y) = (get(Some(cols.x)), get(Some(cols.y)));
        let (z, height, species, yaw, id) =
            (get(cols.z), get(cols.height), get(cols.species), get(cols.yaw), get(cols.id));
        let (dbh, crown) = (get(cols.dbh), get(cols.crown.map(|c| c.0)));
        let attrs: Vec<Option<String>> = if with_attributes {
            cols.attrs
                .iter()
                .map(|(i, _)| get(Some(*i)).map(|t| t.trim().to_string()).filter(|t| !t.is_empty()))
                .collect()
        } else {
            Vec::new()
        };
        if utf8_error {
            report.skip("not UTF-8 (read it with --encoding latin1)", row);
            continue;
        }
        if row_fell_back {
            report.not_utf8 += 1;
        }
        let (Some(x), Some(y)) = (x.as_deref().and_then(number), y.as_deref().and_then(number)) else {
            report.skip("missing or non-numeric coordinates", row);
            continue;
        };
        let p = Placement {
            x,
            y,
            z: z.as_deref().and_then(number),
            height_m: height.as_deref().and_then(number).map(|h| h as f32),
            dbh_cm: dbh.as_deref().and_then(number).map(|d| (d * cols.dbh_unit.to_cm()) as f32),
            crown_m: crown
                .as_deref()
                .and_then(number)
                .map(|c| if cols.crown.is_some_and(|c| c.1) { 2.0 * c } else { c } as f32),
            species: species.as_deref().map(str::trim).filter(|s| !s.is_empty()).map(str::to_string),
            yaw_deg: yaw.as_deref().and_then(number).map(|v| v as f32),
            id: id.as_deref().and_then(number_id),
            id_text: id.as_deref().and_then(text_id),
            attrs,
            row,
            dated: false,
        };
        if let Some(p) = accept(p, cols.kind, report) {
            report.kept += 1;
            if cols.id.is_some() && p.id.is_none() {
                report.count_text_id(p.row, p.id_text.is_some(), id.as_deref().is_some_and(id_too_long));
            }
            f(p)?;
        }
    }
    Ok(cols.kind)
}

pub(super) trait CsvErrorKind {
    fn kind_name(&self) -> &'static str;
}

impl CsvErrorKind for csv::Error {
    fn kind_name(&self) -> &'static str {
        match self.kind() {
            csv::ErrorKind::Utf8 { .. } => "not UTF-8",
            csv::ErrorKind::UnequalLengths { .. } => "wrong number of fields",
            csv::ErrorKind::Io(_) => "I/O error",
            _ => "malformed record",
        }
    }
}
