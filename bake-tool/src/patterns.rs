//! Name patterns of the command line (`--map`, `--leaf-material`,
//! `--branch-material`): one rule for all of them.

/// Whether `label` matches `pattern`: case-insensitive; with `*` a glob (`*`
/// alone matches everything), without one a substring.
pub fn pattern_matches(pattern: &str, label: &str) -> bool {
    let p = pattern.to_lowercase();
    let l = label.to_lowercase();
    if !p.contains('*') {
        return l.contains(&p);
    }
    // Glob with '*' only.
    let parts: Vec<&str> = p.split('*').collect();
    let mut rest = l.as_str();
    for (i, part) in parts.iter().enumerate() {
        if part.is_empty() {
            continue;
        }
        if i == 0 {
            if !rest.starts_with(part) {
                return false;
            }
            rest = &rest[part.len()..];
        } else if let Some(at) = rest.find(part) {
            rest = &rest[at + part.len()..];
        } else {
            return false;
        }
    }
    parts.last().is_none_or(|last| last.is_empty() || l.ends_with(last))
}

#[cfg(test)]
mod tests {
    use super::pattern_matches;

    #[test]
    fn patterns() {
        assert!(pattern_matches("quercus*", "Quercus robur"));
        assert!(!pattern_matches("quercus*", "Acer quercus"));
        assert!(pattern_matches("*robur", "Quercus robur"));
        assert!(pattern_matches("oak", "Red Oak"));
        assert!(pattern_matches("q*r", "quercus robur"));
        assert!(!pattern_matches("pinus*", "Quercus"));
        assert!(pattern_matches("*", "anything") && pattern_matches("*", ""));
        assert!(pattern_matches("*leaf*", "Oak_Leaves_Leaf01"));
    }
}
