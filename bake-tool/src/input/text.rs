//! Text as inventories write it, shared by every reader: numbers with a
//! decimal point or comma, the separator of a delimited header line.

/// The field separator of a header line: the most frequent of `,` `;` tab `|`
/// outside quotes (a comma when none occurs).
#[must_use]
pub fn detect_delimiter(header_line: &[u8]) -> u8 {
    let mut counts = [0usize; 4];
    let mut quoted = false;
    for &b in header_line {
        match b {
            b'"' => quoted = !quoted,
            _ if quoted => {}
            b',' => counts[0] += 1,
            b';' => counts[1] += 1,
            b'\t' => counts[2] += 1,
            b'|' => counts[3] += 1,
            _ => {}
        }
    }
    let best = (0..4).max_by_key(|&i| (counts[i], usize::from(i == 0))).unwrap_or(0);
    if counts[best] == 0 {
        b','
    } else {
        [b',', b';', b'\t', b'|'][best]
    }
}

/// A number as written with a decimal point (`52.37`, `1e3`), trimmed; none
/// for an empty or unreadable field.
pub fn parse_f64(s: &str) -> Option<f64> {
    let t = s.trim();
    if t.is_empty() {
        return None;
    }
    t.parse::<f64>().ok()
}

/// A number of a CSV whose separator is not a comma: `52.37`, or with a
/// decimal comma as European spreadsheets write it, `52,37` or `1.234,5`.
pub fn parse_decimal_comma(s: &str) -> Option<f64> {
    parse_f64(s).or_else(|| {
        let (int, frac) = s.trim().rsplit_once(',')?;
        if frac.is_empty() || !frac.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        // Thousands separators: groups of three digits after the first.
        let mut groups = int.split('.');
        let first = groups.next()?;
        let rest: Vec<&str> = groups.collect();
        if !rest.iter().all(|g| g.len() == 3 && g.bytes().all(|b| b.is_ascii_digit())) {
            return None;
        }
        format!("{first}{}.{frac}", rest.concat()).parse().ok()
    })
}
