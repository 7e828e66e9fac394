//! The layer rule, checked: every `crate::`, `super::` and `sylva::` path in
//! the Rust sources is resolved to the file it names, and
//!
//! - a file imports only from its own layer or the layers below it, as the
//!   `layers` block of `docs/ARCHITECTURE.md` lists them (written once, there);
//! - no two files import each other, directly or round a longer loop.
//!
//! A violation names the file and line of the import. `planted_violations_fail`
//! shows that both checks fail on an upward import and on a cycle.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

/// One crate's sources: its root folder (relative to the workspace), its root
/// module file, the crate name others use for it, and each file's text.
struct Crate {
    name: &'static str,
    dir: &'static str,
    /// `path → text`, the path relative to the workspace (`src/render/cull.rs`).
    files: BTreeMap<String, String>,
    /// Files whose `crate::` is another root (a binary's `main.rs` and the
    /// modules it declares itself): `file → its root`.
    roots: HashMap<String, String>,
}

/// A reference from one file to another, where it is written.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct Edge {
    from: String,
    line: usize,
    to: String,
    /// The path as written (`crate::render::cull::canopy_keeps`).
    path: String,
}

/// The layers, top first: each a name and the files and folders (ending in
/// `/`) it holds. A file belongs to the longest entry that names it.
struct Layers {
    layers: Vec<(String, Vec<String>)>,
}

impl Layers {
    /// Reads the first ```` ```layers ```` block of `markdown`: one layer a line,
    /// `name  entry entry…`, top first; `#` starts a comment.
    fn parse(markdown: &str) -> Result<Self, String> {
        let start = markdown.find("```layers\n").ok_or("no ```layers block")? + "```layers\n".len();
        let end = markdown[start..].find("```").ok_or("the ```layers block is not closed")? + start;
        let mut layers = Vec::new();
        for line in markdown[start..end].lines() {
            let line = line.split('#').next().unwrap_or("").trim();
            let mut words = line.split_whitespace();
            let Some(name) = words.next() else { continue };
            let entries: Vec<String> = words.map(str::to_string).collect();
            if entries.is_empty() {
                return Err(format!("layer {name} lists no files"));
            }
            layers.push((name.to_string(), entries));
        }
        Ok(Self { layers })
    }

    /// The layer of `file` (its index, 0 the top) and the entry that placed it.
    fn of(&self, file: &str) -> Option<(usize, &str)> {
        let mut best: Option<(usize, &str)> = None;
        for (i, (_, entries)) in self.layers.iter().enumerate() {
            for e in entries {
                let hit = if e.ends_with('/') { file.starts_with(e.as_str()) } else { file == e };
                if hit && best.is_none_or(|(_, b)| e.len() > b.len()) {
                    best = Some((i, e));
                }
            }
        }
        best
    }
}

/// The text with comments and the insides of string and char literals blanked
/// (newlines kept, so line numbers hold).
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    let blank = |out: &mut Vec<u8>, c: u8| out.push(if c == b'\n' { b'\n' } else { b' ' });
    while i < b.len() {
        let c = b[i];
        if c == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                out.push(b' ');
                i += 1;
            }
        } else if c == b'/' && b.get(i + 1) == Some(&b'*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                    depth += 1;
                    out.extend_from_slice(b"  ");
                    i += 2;
                } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                    depth -= 1;
                    out.extend_from_slice(b"  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    blank(&mut out, b[i]);
                    i += 1;
                }
            }
        } else if c == b'r'
            && matches!(b.get(i + 1), Some(b'"' | b'#'))
            && (i == 0 || !is_ident(b[i - 1]) || (b[i - 1] == b'b' && (i == 1 || !is_ident(b[i - 2]))))
        {
            // A raw string: r"…", r#"…"#.
            let mut j = i + 1;
            while b.get(j) == Some(&b'#') {
                j += 1;
            }
            if b.get(j) != Some(&b'"') {
                out.push(c);
                i += 1;
                continue;
            }
            let hashes = j - i - 1;
            out.extend(std::iter::repeat_n(b' ', j + 1 - i));
            i = j + 1;
            while i < b.len() {
                if b[i] == b'"' && b[i + 1..].iter().take(hashes).filter(|&&h| h == b'#').count() == hashes {
                    out.extend(std::iter::repeat_n(b' ', 1 + hashes));
                    i += 1 + hashes;
                    break;
                }
                blank(&mut out, b[i]);
                i += 1;
            }
        } else if c == b'"' {
            out.push(b' ');
            i += 1;
            while i < b.len() && b[i] != b'"' {
                if b[i] == b'\\' {
                    blank(&mut out, b[i]);
                    i += 1;
                }
                if i < b.len() {
                    blank(&mut out, b[i]);
                    i += 1;
                }
            }
            out.push(b' ');
            i += 1;
        } else if c == b'\'' {
            // A char literal ('x', '\n', '\''), not a lifetime ('a).
            let close = if b.get(i + 1) == Some(&b'\\') {
                // The escaped character, then the closing quote ('\'', '\n', '\u{…}').
                b.get(i + 3..).and_then(|r| r.iter().position(|&x| x == b'\'')).map(|p| i + 3 + p)
            } else if b.get(i + 2) == Some(&b'\'') {
                Some(i + 2)
            } else {
                // Multi-byte UTF-8 char literals: up to 4 bytes.
                (3..=5).map(|k| i + k).find(|&k| b.get(k) == Some(&b'\'') && b[i + 1] >= 0x80)
            };
            match close {
                Some(end) => {
                    out.extend(std::iter::repeat_n(b' ', end + 1 - i));
                    i = end + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// A `use` tree without whitespace, `A as B` written `A@B`.
fn squeeze(tree: &str) -> String {
    let words: Vec<&str> = tree.split_whitespace().collect();
    let mut out = String::new();
    for w in words {
        if w == "as" {
            out.push('@');
        } else {
            out.push_str(w);
        }
    }
    out
}

/// Expands a `use` tree (`crate::{a::B, c::{d, e}}`, spaces removed) into paths.
fn expand_use(tree: &str) -> Vec<String> {
    let Some(open) = tree.find('{') else { return vec![tree.to_string()] };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.len() - 1];
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (k, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&inner[start..k]);
                start = k + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts
        .into_iter()
        .filter(|p| !p.is_empty())
        .flat_map(|p| expand_use(p).into_iter().map(move |q| format!("{prefix}{q}")))
        .collect()
}

/// A path a file writes: where (byte offset), the path, and whether it is a
/// `use` of a child module by its bare name (`use columns::X`).
struct Written {
    at: usize,
    path: String,
    relative: bool,
}

/// Every path a file writes that starts at `crate`, `super`, `self` or one of
/// `externs` (other crates of the workspace), and every `use` whose first
/// segment may name a child module (resolved only if it does).
fn paths_in(code: &str, externs: &[&str]) -> Vec<Written> {
    let mut out = Vec::new();
    let b = code.as_bytes();
    // `use` statements (their groups expanded), then every other path.
    let mut used = vec![false; b.len()];
    let mut from = 0;
    while let Some(k) = code[from..].find("use ") {
        let at = from + k;
        from = at + 4;
        if at > 0 && is_ident(b[at - 1]) {
            continue;
        }
        let Some(end) = code[at..].find(';').map(|e| at + e) else { break };
        let tree = squeeze(&code[at + 4..end]);
        let tree = tree.trim_start_matches("::").to_string();
        let starts = |p: &str| {
            ["crate::", "super::", "self::"].iter().any(|s| p.starts_with(s))
                || externs.iter().any(|e| p.starts_with(&format!("{e}::")))
        };
        for p in expand_use(&tree) {
            let p = p.split('@').next().unwrap_or(&p).to_string();
            if starts(&p) {
                out.push(Written { at, path: p, relative: false });
            } else if p.contains("::") && p.bytes().next().is_some_and(|c| c.is_ascii_lowercase()) {
                out.push(Written { at, path: p, relative: true });
            }
        }
        used[at..end].iter_mut().for_each(|u| *u = true);
        from = end;
    }
    let heads: Vec<&str> = ["crate", "super", "self"].into_iter().chain(externs.iter().copied()).collect();
    let mut i = 0;
    while i < b.len() {
        if used[i] || (i > 0 && (is_ident(b[i - 1]) || b[i - 1] == b':')) {
            i += 1;
            continue;
        }
        let Some(head) = heads.iter().find(|h| code[i..].starts_with(&format!("{h}::"))) else {
            i += 1;
            continue;
        };
        let mut j = i + head.len();
        while code[j..].starts_with("::") {
            let seg = code[j + 2..].bytes().take_while(|&c| is_ident(c)).count();
            if seg == 0 {
                break;
            }
            j += 2 + seg;
        }
        out.push(Written { at: i, path: code[i..j].to_string(), relative: false });
        i = j;
    }
    out
}

/// The inline modules of a file (`mod tests { … }`): their byte ranges and names.
fn inline_mods(code: &str) -> Vec<(usize, usize, String)> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(k) = code[from..].find("mod ") {
        let at = from + k;
        from = at + 4;
        if at > 0 && is_ident(b[at - 1]) {
            continue;
        }
        let name: String = code[at + 4..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let after = code[at + 4 + name.len()..].trim_start();
        if name.is_empty() || !after.starts_with('{') {
            continue;
        }
        let open = code.len() - after.len();
        let mut depth = 0;
        let mut end = code.len();
        for (k, c) in code[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + k;
                        break;
                    }
                }
                _ => {}
            }
        }
        out.push((open, end, name));
    }
    out
}

impl Crate {
    fn read(root: &Path, name: &'static str, dir: &'static str) -> Self {
        let mut files = BTreeMap::new();
        let mut stack = vec![root.join(dir)];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
                let p = entry.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    let rel = p.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
                    files.insert(rel, std::fs::read_to_string(&p).unwrap());
                }
            }
        }
        Self { name, dir, files, roots: HashMap::new() }
    }

    /// The module path of a file (`src/render/cull.rs` → `[render, cull]`).
    fn module_of(&self, file: &str) -> Vec<String> {
        let root = self.roots.get(file).map_or(format!("{}/lib.rs", self.dir), Clone::clone);
        let base = Path::new(&root).parent().unwrap().to_string_lossy().to_string();
        let rel = file.strip_prefix(&format!("{base}/")).unwrap_or(file).trim_end_matches(".rs");
        let mut m: Vec<String> = rel.split('/').map(str::to_string).collect();
        if matches!(m.last().map(String::as_str), Some("mod" | "lib" | "main")) {
            m.pop();
        }
        m
    }

    /// The file that holds module `m` (relative to `file`'s root), if any.
    fn file_of(&self, file: &str, m: &[String]) -> Option<String> {
        let root = self.roots.get(file).map_or(format!("{}/lib.rs", self.dir), Clone::clone);
        if m.is_empty() {
            return Some(root);
        }
        let base = Path::new(&root).parent().unwrap().to_string_lossy().to_string();
        let joined = m.join("/");
        [format!("{base}/{joined}.rs"), format!("{base}/{joined}/mod.rs")]
            .into_iter()
            .find(|f| self.files.contains_key(f))
    }

    /// Follows `pub use child::Name` re-exports in `file` (a module root) to
    /// the child file that defines `name`.
    fn reexport(&self, file: &str, name: &str) -> Option<Vec<String>> {
        let code = code_only(self.files.get(file)?);
        // `pub use x::{A, B};` or `pub use self::x::A;`
        let mut from = 0;
        while let Some(k) = code[from..].find("pub use ") {
            let at = from + k;
            let end = at + code[at..].find(';')?;
            from = end;
            let tree = squeeze(&code[at + 8..end]);
            for p in expand_use(tree.trim_start_matches("self::")) {
                let segs: Vec<&str> = p.split("::").collect();
                // `x::A@B`: `A` exported as `B`.
                let exported = segs.last()?.rsplit('@').next().unwrap_or("");
                if exported == name && segs.len() > 1 && !matches!(segs[0], "crate" | "super") {
                    let mut m = self.module_of(file);
                    m.extend(segs[..segs.len() - 1].iter().map(|s| (*s).to_string()));
                    return Some(m);
                }
            }
        }
        None
    }

    /// Resolves a written path to the file it names (`None`: outside this
    /// crate, or a name the resolution cannot place).
    fn resolve(&self, file: &str, path: &str, inline: &[String], relative: bool) -> Option<String> {
        let segs: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
        let mut m = self.module_of(file);
        m.extend(inline.iter().cloned());
        let mut rest = &segs[..];
        // The crate's own name reaches its library root, from the binary too.
        let lib = format!("{}/lib.rs", self.dir);
        let file = if rest.first() == Some(&self.name) { lib.as_str() } else { file };
        match rest.first()? {
            &"crate" => {
                m.clear();
                rest = &rest[1..];
            }
            &"self" => rest = &rest[1..],
            &"super" => {
                while rest.first() == Some(&"super") {
                    m.pop()?;
                    rest = &rest[1..];
                }
            }
            h if *h == self.name => {
                m.clear();
                rest = &rest[1..];
            }
            // A bare first segment: a child module, or nothing of this crate.
            h if relative => {
                let mut child = m.clone();
                child.push((*h).to_string());
                self.file_of(file, &child)?;
            }
            _ => return None,
        }
        // The longest module prefix that is a file.
        let mut best = self.file_of(file, &m)?;
        let mut k = 0;
        while k < rest.len() {
            let mut next = m.clone();
            next.push(rest[k].to_string());
            match self.file_of(file, &next) {
                Some(f) => {
                    best = f;
                    m = next;
                    k += 1;
                }
                None => break,
            }
        }
        // A name a module root re-exports from one of its children.
        if k < rest.len() {
            if let Some(child) = self.reexport(&best, rest[k]) {
                if let Some(f) = self.file_of(file, &child) {
                    best = f;
                }
            }
        }
        Some(best)
    }

    /// Every reference from one file of the crate to another of it (or, for
    /// `externs`, to `sylva`'s files: those edges are returned with `to`
    /// prefixed by `sylva:`).
    fn edges(&self, other: Option<&Crate>) -> Vec<Edge> {
        let externs: Vec<&str> = other.map(|o| o.name).into_iter().chain([self.name]).collect();
        let mut out = BTreeSet::new();
        for (file, text) in &self.files {
            let code = code_only(text);
            let mods = inline_mods(&code);
            let line_of = |at: usize| code[..at].bytes().filter(|&c| c == b'\n').count() + 1;
            for Written { at, path, relative } in paths_in(&code, &externs) {
                let line = line_of(at);
                let inline: Vec<String> =
                    mods.iter().filter(|(a, e, _)| *a <= at && at < *e).map(|(_, _, n)| n.clone()).collect();
                let to = match other {
                    Some(o) if path.starts_with(&format!("{}::", o.name)) => {
                        let lib = format!("{}/lib.rs", o.dir);
                        o.resolve(&lib, &path.replacen(o.name, "crate", 1), &[], false)
                    }
                    _ => self.resolve(file, &path, &inline, relative),
                };
                if let Some(to) = to {
                    if &to != file && !is_ancestor_root(&to, file) {
                        out.insert(Edge { from: file.clone(), line, to, path });
                    }
                }
            }
        }
        out.into_iter().collect()
    }
}

/// Whether `to` is `file`'s crate root or a module root (`mod.rs`) above it,
/// named only to reach a sibling through it (`super::x`, `crate::x`): the
/// resolution above already went on into the sibling where it could.
fn is_ancestor_root(to: &str, file: &str) -> bool {
    let dir = to.rsplit_once('/').map_or("", |(d, _)| d);
    (to.ends_with("/mod.rs") || to.ends_with("/lib.rs") || to.ends_with("/main.rs"))
        && file.starts_with(&format!("{dir}/"))
}

/// Upward imports: an edge from a file to a file of a higher layer.
fn upward(layers: &Layers, edges: &[Edge]) -> Vec<String> {
    let mut out = Vec::new();
    for e in edges {
        let (Some((from, _)), Some((to, _))) = (layers.of(&e.from), layers.of(&e.to)) else { continue };
        if to < from {
            out.push(format!(
                "{}:{}: `{}` imports {} (layer {}) from layer {}: a layer imports only from itself and the layers below",
                e.from, e.line, e.path, e.to, layers.layers[to].0, layers.layers[from].0
            ));
        }
    }
    out
}

/// Files the layers do not place.
fn unplaced(layers: &Layers, files: &[&String]) -> Vec<String> {
    files
        .iter()
        .filter(|f| layers.of(f).is_none())
        .map(|f| format!("{f}: in no layer of docs/ARCHITECTURE.md's ```layers block"))
        .collect()
}

/// File cycles (strongly connected sets of two or more files), each with the
/// imports that close it.
fn cycles(edges: &[Edge]) -> Vec<String> {
    let mut nodes: Vec<&str> = edges.iter().flat_map(|e| [e.from.as_str(), e.to.as_str()]).collect();
    nodes.sort_unstable();
    nodes.dedup();
    let index: HashMap<&str, usize> = nodes.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    let mut adj = vec![Vec::new(); nodes.len()];
    for e in edges {
        adj[index[e.from.as_str()]].push(index[e.to.as_str()]);
    }
    // Tarjan's strongly connected components.
    struct T<'a> {
        adj: &'a [Vec<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(t: &mut T, v: usize) {
        t.index[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        for k in 0..t.adj[v].len() {
            let w = t.adj[v][k];
            match t.index[w] {
                None => {
                    visit(t, w);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(i) if t.on[w] => t.low[v] = t.low[v].min(i),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.index[v] {
            let mut set = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on[w] = false;
                set.push(w);
                if w == v {
                    break;
                }
            }
            if set.len() > 1 {
                t.out.push(set);
            }
        }
    }
    let n = nodes.len();
    let mut t =
        T { adj: &adj, index: vec![None; n], low: vec![0; n], on: vec![false; n], stack: vec![], next: 0, out: vec![] };
    for v in 0..n {
        if t.index[v].is_none() {
            visit(&mut t, v);
        }
    }
    t.out
        .iter()
        .map(|set| {
            let members: BTreeSet<&str> = set.iter().map(|&v| nodes[v]).collect();
            let inside: Vec<String> = edges
                .iter()
                .filter(|e| members.contains(e.from.as_str()) && members.contains(e.to.as_str()))
                .map(|e| format!("  {}:{} `{}` → {}", e.from, e.line, e.path, e.to))
                .collect();
            format!(
                "an import cycle between {}:\n{}",
                members.into_iter().collect::<Vec<_>>().join(", "),
                inside.join("\n")
            )
        })
        .collect()
}

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The two crates as they are on disk: `sylva` (its binary's modules rooted
/// at `src/cli/main.rs`) and `sylva-bake` (library and binary).
fn read_workspace() -> (Crate, Crate) {
    let root = workspace();
    let mut sylva = Crate::read(&root, "sylva", "src");
    let cli: Vec<String> = sylva.files.keys().filter(|f| f.starts_with("src/cli/")).cloned().collect();
    for f in cli {
        sylva.roots.insert(f, "src/cli/main.rs".into());
    }
    let mut bake = Crate::read(&root, "sylva_bake", "bake-tool/src");
    // The binary declares modules of its own beside the library's.
    let main = "bake-tool/src/main.rs".to_string();
    let own: Vec<String> = code_only(&bake.files[&main])
        .lines()
        .filter_map(|l| l.trim().strip_prefix("mod ").and_then(|m| m.strip_suffix(';')).map(str::to_string))
        .collect();
    let in_binary: Vec<String> = bake
        .files
        .keys()
        .filter(|f| {
            own.iter()
                .any(|m| f.as_str() == format!("bake-tool/src/{m}.rs") || f.starts_with(&format!("bake-tool/src/{m}/")))
        })
        .cloned()
        .collect();
    for f in in_binary.into_iter().chain([main]) {
        bake.roots.insert(f, "bake-tool/src/main.rs".into());
    }
    (sylva, bake)
}

fn architecture() -> String {
    std::fs::read_to_string(workspace().join("docs/ARCHITECTURE.md")).unwrap()
}

/// Every finding of both checks over both crates.
fn findings(layers: &Layers, sylva: &Crate, bake: &Crate) -> Vec<String> {
    let own = sylva.edges(None);
    let mut bake_edges = bake.edges(Some(sylva));
    let into_sylva: Vec<Edge> = bake_edges.iter().filter(|e| e.to.starts_with("src/")).cloned().collect();
    bake_edges.retain(|e| !e.to.starts_with("src/"));
    let mut out = Vec::new();
    let files: Vec<&String> = sylva.files.keys().chain(bake.files.keys()).collect();
    out.extend(unplaced(layers, &files));
    for (name, entries) in &layers.layers {
        for e in entries.iter().filter(|e| !workspace().join(e).exists()) {
            out.push(format!("layer {name} lists {e}, which does not exist"));
        }
    }
    out.extend(upward(layers, &own));
    out.extend(upward(layers, &bake_edges));
    out.extend(upward(layers, &into_sylva));
    out.extend(cycles(&own));
    out.extend(cycles(&bake_edges));
    out
}

#[test]
fn every_import_goes_down_and_no_file_cycles() {
    let layers = Layers::parse(&architecture()).unwrap();
    let (sylva, bake) = read_workspace();
    let found = findings(&layers, &sylva, &bake);
    assert!(
        found.is_empty(),
        "{} layer violations (docs/ARCHITECTURE.md, \"Layers\"):\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn planted_violations_fail() {
    let layers = Layers::parse(&architecture()).unwrap();
    let (mut sylva, bake) = read_workspace();
    // An upward import: the file formats reaching up into the renderer.
    let tile = "src/format/tile.rs".to_string();
    let text = sylva.files[&tile].clone();
    sylva.files.insert(tile.clone(), format!("use crate::render::forest::ForestRenderer;\n{text}"));
    let found = findings(&layers, &sylva, &bake);
    assert!(
        found.iter().any(|f| f
            .starts_with("src/format/tile.rs:1: `crate::render::forest::ForestRenderer` imports src/render/forest.rs")),
        "{found:#?}"
    );
    // A cycle: two files of one layer that import each other.
    sylva.files.insert(tile, text);
    let camera = "src/camera.rs".to_string();
    let geo = "src/geo.rs".to_string();
    let c = sylva.files[&camera].clone();
    let g = sylva.files[&geo].clone();
    sylva.files.insert(camera, format!("{c}\nfn planted() {{ let _ = crate::geo::planted; }}\n"));
    sylva.files.insert(geo, format!("{g}\nfn planted() {{ let _ = super::camera::planted; }}\n"));
    let found = findings(&layers, &sylva, &bake);
    assert!(found.iter().any(|f| f.starts_with("an import cycle between src/camera.rs, src/geo.rs:")), "{found:#?}");
}

#[test]
fn use_trees_and_literals() {
    let mut p = expand_use(&squeeze("crate::{format::{pack::Pack, tile}, scene::Stream}"));
    p.sort();
    assert_eq!(p, ["crate::format::pack::Pack", "crate::format::tile", "crate::scene::Stream"]);
    let code = code_only(concat!(
        "let s = \"crate::render::x\"; // crate::render::y\n",
        "let c = '\"'; let q = '\\''; crate::geo::f();\n",
        "let r = br#\"crate::render::z \" \"#; /* crate::a */ crate::sun::g();\n",
    ));
    let found: Vec<String> = paths_in(&code, &[]).into_iter().map(|w| w.path).collect();
    assert_eq!(found, ["crate::geo::f", "crate::sun::g"]);
}

/// Paths inside an inline module (`mod tests { use super::… }`) and a `use`
/// of a child module by its bare name resolve to the files they name.
#[test]
fn inline_modules_and_child_modules_resolve() {
    let (mut sylva, _) = read_workspace();
    let planted = "src/scene/streaming/tiles.rs".to_string();
    sylva.files.insert(
        planted.clone(),
        "pub fn f() {}\n#[cfg(test)]\nmod tests {\n    use super::super::report::StreamStats;\n}\n".to_string(),
    );
    let parent = "src/scene/streaming/mod.rs".to_string();
    let text = format!("{}\nuse tree_data::X;\n", sylva.files[&parent]);
    sylva.files.insert(parent.clone(), text);
    let edges = sylva.edges(None);
    assert!(
        edges.iter().any(|e| e.from == planted && e.to == "src/scene/streaming/report.rs"),
        "super inside `mod tests` is the file's own module: {edges:#?}"
    );
    assert!(edges.iter().any(|e| e.from == parent && e.to == "src/scene/streaming/tree_data.rs"));
}
