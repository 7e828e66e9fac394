//! Name patterns of the command line (`--map`, `--leaf-material`,
//! `--branch-material`): one rule for all of them.

/// Whether `label` matches `pattern`: case-insensitive; with `*` a glob (`*`
/// alone matches everything), without one a substring.
pub fn pattern_matches(pattern: &str, label: &str) -> bool {
    if !pattern.contains('*') {
        return label.to_lowercase().contains(&pattern.to_lowercase());
    }
    sylva::format::attributes::glob_matches(pattern, label)
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
