//! Minifies the WGSL modules of `shaders/` into `OUT_DIR` for
//! `src/render/shaders.rs`: line comments, indentation, blank lines and the
//! spaces a lexer does not need ([`squeeze`]) out (WGSL has no string
//! literals, so `//` always starts a comment). Issue 47 took the wasm's
//! shader text from 128 KB to about 73; the squeeze saves another 1.8 KB
//! of the gzipped wasm. The sources in `shaders/` stay as written.

use std::path::Path;

fn main() {
    println!("cargo:rerun-if-changed=shaders");
    let out = std::env::var("OUT_DIR").expect("OUT_DIR");
    let mut names: Vec<_> = std::fs::read_dir("shaders")
        .expect("shaders/")
        .map(|e| e.expect("an entry of shaders/").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    names.sort();
    for path in names {
        println!("cargo:rerun-if-changed={}", path.display());
        let source = std::fs::read_to_string(&path).expect("a WGSL module");
        let mut min = String::with_capacity(source.len());
        for line in source.lines() {
            let code = line.split("//").next().unwrap_or("").trim();
            if !code.is_empty() {
                min.push_str(&squeeze(code));
                min.push('\n');
            }
        }
        let file = path.file_name().expect("a file name");
        std::fs::write(Path::new(&out).join(file), min).expect("write a minified module");
    }
}

/// A line of WGSL without the spaces a lexer does not need: a space stays only
/// between two word characters (`let x`, `fn f`) and between two operator
/// characters (`* -1`, where `*-` could read as one token); beside brackets,
/// commas, colons and the rest it goes (`a + b` → `a+b`, `f(x, y)` →
/// `f(x,y)`). WGSL's template lists are found from the tokens, not the
/// spacing, so `a < b` and `a<b` read alike.
fn squeeze(line: &str) -> String {
    let word = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '.';
    let op = |c: char| "+-*/%&|^<>=!".contains(c);
    let chars: Vec<char> = line.chars().collect();
    let mut out = String::with_capacity(line.len());
    for (i, &c) in chars.iter().enumerate() {
        if c == ' ' {
            let before = out.chars().last();
            let after = chars[i + 1..].iter().copied().find(|&c| c != ' ');
            let keep = match (before, after) {
                (Some(a), Some(b)) => (word(a) && word(b)) || (op(a) && op(b)),
                _ => false,
            };
            if !keep || before == Some(' ') {
                continue;
            }
        }
        out.push(c);
    }
    out
}
