//! The floor plan, enforced: the size limits and the import graph of `src/` (docs/design.md,
//! "Module map"). A file over 1,000 lines, a function over 150 lines (outside SIMD kernels and
//! tests), a `too_many_arguments` allowance or an import cycle between files fails here.
//!
//! The source is read as text with a small lexer of our own (comments, strings and character
//! literals blanked out, braces matched): pulling in a Rust parser for four counts would cost
//! more build time than these checks are worth.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_FILE_LINES: usize = 1000;
const MAX_FN_LINES: usize = 150;

fn src_files() -> Vec<(PathBuf, String)> {
    fn walk(dir: &Path, out: &mut Vec<(PathBuf, String)>) {
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| e.expect("directory entry").path())
            .collect();
        entries.sort();
        for path in entries {
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&path)
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                out.push((path, text));
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut out = Vec::new();
    walk(&root, &mut out);
    out.into_iter()
        .map(|(p, t)| (p.strip_prefix(&root).expect("under src").to_path_buf(), t))
        .collect()
}

/// The text with comments, string and character literals replaced by spaces (newlines kept),
/// so that braces and paths can be matched on what is code.
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for x in &mut out[from..to] {
            if *x != b'\n' {
                *x = b' ';
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            let end = b[i..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |p| i + p);
            blank(&mut out, i, end);
            i = end;
        } else if b[i..].starts_with(b"/*") {
            let (mut depth, mut j) = (1, i + 2);
            while j < b.len() && depth > 0 {
                if b[j..].starts_with(b"/*") {
                    depth += 1;
                    j += 2;
                } else if b[j..].starts_with(b"*/") {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j);
            i = j;
        } else if b[i] == b'r'
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
            && b.get(i + 1).is_some_and(|&c| c == b'#' || c == b'"')
        {
            let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
            if b.get(i + 1 + hashes) != Some(&b'"') {
                i += 1;
                continue;
            }
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let start = i + 2 + hashes;
            let end = b[start..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(b.len(), |p| start + p + close.len());
            blank(&mut out, i, end);
            i = end;
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            blank(&mut out, i, (j + 1).min(b.len()));
            i = j + 1;
        } else if b[i] == b'\'' {
            // A character literal ('x', '\n', '\u{..}', '{'), not a lifetime ('a).
            let end = if b.get(i + 1) == Some(&b'\\') {
                b[i + 2..]
                    .iter()
                    .position(|&c| c == b'\'')
                    .map(|p| i + 2 + p + 1)
            } else {
                let ch_len = text[i + 1..].chars().next().map_or(1, char::len_utf8);
                (b.get(i + 1 + ch_len) == Some(&b'\'')).then_some(i + 2 + ch_len)
            };
            match end {
                Some(end) => {
                    blank(&mut out, i, end);
                    i = end;
                }
                None => i += 1,
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The byte index just past the brace that closes the one at `open`.
fn matching_brace(code: &[u8], open: usize) -> usize {
    let mut depth = 0usize;
    for (k, &c) in code.iter().enumerate().skip(open) {
        match c {
            b'{' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return k + 1;
                }
            }
            _ => {}
        }
    }
    code.len()
}

/// Byte ranges of `#[cfg(test)]` items (test modules and helpers): not counted.
fn test_ranges(code: &str) -> Vec<(usize, usize)> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(p) = code[from..].find("#[cfg(test)]") {
        let at = from + p;
        let semi = code[at..].find(';').map(|q| at + q);
        let brace = code[at..].find('{').map(|q| at + q);
        match (brace, semi) {
            (Some(o), s) if s.is_none_or(|s| o < s) => out.push((at, matching_brace(b, o))),
            _ => {}
        }
        from = at + 1;
    }
    out
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// Each function with a body: (name, first line, line count, is a SIMD kernel).
fn functions(code: &str) -> Vec<(String, usize, usize, bool)> {
    let b = code.as_bytes();
    let tests = test_ranges(code);
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(p) = code[from..].find("fn ") {
        let at = from + p;
        from = at + 3;
        if at > 0 && is_ident(b[at - 1]) || tests.iter().any(|&(s, e)| (s..e).contains(&at)) {
            continue;
        }
        let name: String = code[at + 3..]
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if name.is_empty() {
            continue;
        }
        let (Some(open), semi) = (
            code[at..].find('{').map(|q| at + q),
            code[at..].find(';').map(|q| at + q),
        ) else {
            continue;
        };
        if semi.is_some_and(|s| s < open) {
            continue; // a declaration without a body
        }
        let close = matching_brace(b, open);
        let first = code[..at].matches('\n').count() + 1;
        let last = code[..close].matches('\n').count() + 1;
        // The attributes just above the signature.
        let head_start = code[..at].rfind(['}', ';']).map_or(0, |q| q + 1);
        let simd = code[head_start..at].contains("target_feature");
        out.push((name, first, last - first + 1, simd));
    }
    out
}

#[test]
fn no_source_file_is_over_the_limit() {
    let over: Vec<String> = src_files()
        .iter()
        .filter(|(_, t)| t.lines().count() > MAX_FILE_LINES)
        .map(|(p, t)| format!("src/{}: {} lines", p.display(), t.lines().count()))
        .collect();
    assert!(
        over.is_empty(),
        "files over {MAX_FILE_LINES} lines:\n{}",
        over.join("\n")
    );
}

#[test]
fn no_function_is_over_the_limit() {
    let mut over = Vec::new();
    for (path, text) in src_files() {
        if path.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        for (name, line, n, simd) in functions(&code_only(&text)) {
            if n > MAX_FN_LINES && !simd {
                over.push(format!(
                    "src/{}:{line} fn {name}: {n} lines",
                    path.display()
                ));
            }
        }
    }
    assert!(
        over.is_empty(),
        "functions over {MAX_FN_LINES} lines:\n{}",
        over.join("\n")
    );
}

#[test]
fn no_too_many_arguments_allowance() {
    let found: Vec<String> = src_files()
        .iter()
        .filter(|(_, t)| code_only(t).contains("too_many_arguments"))
        .map(|(p, _)| format!("src/{}", p.display()))
        .collect();
    assert!(
        found.is_empty(),
        "a struct beats a long argument list; allowances in:\n{}",
        found.join("\n")
    );
}

/// The module path of a file: `l3/render/fast/mod.rs` → `["l3", "render", "fast"]`.
fn module_path(path: &Path) -> Vec<String> {
    let mut parts: Vec<String> = path
        .with_extension("")
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The files each file imports from, through `crate::`, `super::` and `self::` paths (a
/// parent declaring its children with `mod` is not an import).
fn import_graph() -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let files = src_files();
    let modules: BTreeSet<Vec<String>> = files.iter().map(|(p, _)| module_path(p)).collect();
    let mut graph = BTreeMap::new();
    for (path, text) in &files {
        let me = module_path(path);
        let is_dir_module = matches!(
            path.file_name().and_then(|n| n.to_str()),
            Some("mod.rs" | "lib.rs" | "main.rs")
        );
        let code = code_only(text);
        let tests = test_ranges(&code);
        let mut code_b = code.into_bytes();
        for (s, e) in tests {
            code_b[s..e].fill(b' ');
        }
        let code = String::from_utf8_lossy(&code_b).into_owned();
        let mut edges = BTreeSet::new();
        let mut resolve = |full: Vec<String>| {
            for k in (1..=full.len()).rev() {
                if modules.contains(&full[..k]) {
                    if full[..k] != me[..] {
                        edges.insert(full[..k].to_vec());
                    }
                    return;
                }
            }
        };
        let b = code.as_bytes();
        for root in ["crate::", "super::", "self::"] {
            let mut from = 0;
            while let Some(p) = code[from..].find(root) {
                let at = from + p;
                from = at + root.len();
                if at > 0 && (is_ident(b[at - 1]) || b[at - 1] == b':') {
                    continue;
                }
                let mut base: Vec<String> = match root {
                    "crate::" => vec![],
                    "super::" if is_dir_module => me[..me.len().saturating_sub(1)].to_vec(),
                    "super::" => me[..me.len().saturating_sub(1)].to_vec(),
                    _ if is_dir_module => me.clone(),
                    _ => me[..me.len().saturating_sub(1)].to_vec(),
                };
                // The rest of the path, and any `{a, b::c}` group after it (one level).
                let mut j = from;
                let mut segs = Vec::new();
                loop {
                    let seg: String = code[j..]
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    if seg.is_empty() {
                        break;
                    }
                    j += seg.len();
                    segs.push(seg);
                    if code[j..].starts_with("::") {
                        j += 2;
                    } else {
                        break;
                    }
                }
                while segs.first().is_some_and(|s| s == "super") {
                    segs.remove(0);
                    base.pop();
                }
                let mut full = base.clone();
                full.extend(segs.iter().cloned());
                if code[j..].starts_with('{') {
                    let end = matching_brace(b, j);
                    for item in code[j + 1..end - 1].split(',') {
                        let head: String = item
                            .trim()
                            .chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_')
                            .collect();
                        if !head.is_empty() {
                            let mut f = full.clone();
                            f.push(head);
                            resolve(f);
                        }
                    }
                } else {
                    resolve(full);
                }
            }
        }
        graph.insert(me, edges);
    }
    graph
}

#[test]
fn no_import_cycle_between_files() {
    let graph = import_graph();
    // Tarjan's strongly connected components, iteratively small: the graph has ~150 nodes.
    struct State<'g> {
        graph: &'g BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'g Vec<String>, usize>,
        low: BTreeMap<&'g Vec<String>, usize>,
        stack: Vec<&'g Vec<String>>,
        cycles: Vec<Vec<String>>,
    }
    fn visit<'g>(s: &mut State<'g>, v: &'g Vec<String>) {
        let i = s.index.len();
        s.index.insert(v, i);
        s.low.insert(v, i);
        s.stack.push(v);
        for w in s.graph.get(v).into_iter().flatten() {
            let Some((w, _)) = s.graph.get_key_value(w) else {
                continue;
            };
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if s.stack.contains(&w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                comp.push(w.join("::"));
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                s.cycles.push(comp);
            }
        }
    }
    let mut s = State {
        graph: &graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: vec![],
        cycles: vec![],
    };
    for v in graph.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    let shown: Vec<String> = s.cycles.iter().map(|c| c.join(" ↔ ")).collect();
    assert!(
        shown.is_empty(),
        "files that import each other:\n{}",
        shown.join("\n")
    );
}

#[test]
fn the_lexer_blanks_what_is_not_code() {
    let code =
        code_only("let s = \"{ fn x() {\"; // fn y() {\nlet c = '{'; let l: &'a str = r#\"}\"#;");
    assert!(!code.contains("fn x") && !code.contains("fn y"));
    assert_eq!(code.matches('{').count(), 0);
    assert!(code.contains("&'a str"));
    let fns = functions("fn a() {\n  if x { y }\n}\n#[cfg(test)]\nmod tests {\n fn b() {}\n}\n");
    assert_eq!(fns, vec![("a".to_string(), 1, 3, false)]);
}
