//! Every relative link in README.md and docs/**/*.md resolves to a file or a directory of the
//! repository.
//!
//! Links are markdown links and images, `[text](target)` and `![alt](target)`, and reference
//! definitions, `[label]: target`, outside fenced code blocks and inline code spans. Skipped:
//! URLs with a scheme (`https:`, `mailto:`, …) and pure `#anchors`. A target's `#fragment` and
//! `?query` are dropped; the rest is resolved against the linking file's own directory (a
//! leading `/` against the repository's root).

use std::path::{Path, PathBuf};

use crate::{files_under, root, shown};

/// One link found in a markdown file.
#[derive(Debug, PartialEq)]
pub struct Link {
    pub line: usize,
    pub target: String,
}

/// The markdown files whose links are checked: README.md and every .md under docs/.
fn markdown_files() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md")];
    files.extend(files_under(&root().join("docs"), ".md"));
    files
}

/// The text of `line` with inline code spans blanked out (so a link shown as code is not read).
fn without_code_spans(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '`' {
            out.push(c);
            continue;
        }
        // A span opens with a run of n backticks and closes with the next run of exactly n.
        let mut n = 1;
        while chars.peek() == Some(&'`') {
            chars.next();
            n += 1;
        }
        let rest: String = chars.clone().collect();
        let fence = "`".repeat(n);
        let mut search = 0;
        let mut close = None;
        while let Some(i) = rest[search..].find(&fence) {
            let at = search + i;
            let after = rest[at + n..].chars().next();
            if after != Some('`') {
                close = Some(at);
                break;
            }
            search = at + n;
            while rest[search..].starts_with('`') {
                search += 1;
            }
        }
        match close {
            Some(at) => {
                let skipped = rest[..at + n].chars().count();
                for _ in 0..skipped {
                    chars.next();
                }
                out.push(' ');
            }
            // No closing run: the backticks are literal text.
            None => out.push_str(&fence),
        }
    }
    out
}

/// The target inside `(...)` starting just after the `(`: up to the matching `)`, without an
/// optional title (`"title"`) and without angle brackets (`<target>`).
fn target_of(after_paren: &str) -> Option<String> {
    let mut depth = 0usize;
    let mut end = None;
    for (i, c) in after_paren.char_indices() {
        match c {
            '(' => depth += 1,
            ')' if depth == 0 => {
                end = Some(i);
                break;
            }
            ')' => depth -= 1,
            _ => {}
        }
    }
    let inner = after_paren[..end?].trim();
    let target = if let Some(rest) = inner.strip_prefix('<') {
        rest.split('>').next().unwrap_or("")
    } else {
        inner.split_whitespace().next().unwrap_or("")
    };
    Some(target.to_string())
}

/// Every link of a markdown document, with its 1-based line.
pub fn extract_links(text: &str) -> Vec<Link> {
    let mut links = Vec::new();
    let mut fence: Option<String> = None;
    for (i, raw) in text.lines().enumerate() {
        let trimmed = raw.trim_start();
        if let Some(open) = &fence {
            if trimmed.starts_with(open.as_str()) {
                fence = None;
            }
            continue;
        }
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            let marker: String = trimmed
                .chars()
                .take_while(|&c| c == '`' || c == '~')
                .collect();
            fence = Some(marker);
            continue;
        }
        let line = without_code_spans(raw);
        // Reference definitions: `[label]: target`.
        let t = line.trim_start();
        if t.starts_with('[')
            && !t.starts_with("[^")
            && let Some(close) = t.find("]:")
        {
            let target = t[close + 2..].split_whitespace().next().unwrap_or("");
            let target = target.trim_start_matches('<').trim_end_matches('>');
            if !target.is_empty() {
                links.push(Link {
                    line: i + 1,
                    target: target.to_string(),
                });
            }
        }
        // Inline links and images: `](target)`.
        let mut from = 0;
        while let Some(at) = line[from..].find("](") {
            let start = from + at + 2;
            if let Some(target) = target_of(&line[start..])
                && !target.is_empty()
            {
                links.push(Link {
                    line: i + 1,
                    target,
                });
            }
            from = start;
        }
    }
    links
}

/// Whether a target leaves the repository (a URL with a scheme) or stays in the page (`#…`).
fn is_external_or_anchor(target: &str) -> bool {
    if target.starts_with('#') {
        return true;
    }
    // A scheme: a letter, then letters, digits, `+`, `.` or `-`, then `:`.
    match target.find(':') {
        Some(colon) => {
            let scheme = &target[..colon];
            let mut chars = scheme.chars();
            chars.next().is_some_and(|c| c.is_ascii_alphabetic())
                && chars.all(|c| c.is_ascii_alphanumeric() || "+.-".contains(c))
        }
        None => false,
    }
}

/// The path a relative target names, from the linking file's directory.
fn resolve(file: &Path, target: &str) -> PathBuf {
    let path = target.split(['#', '?']).next().unwrap_or("");
    let path = path.replace("%20", " ");
    match path.strip_prefix('/') {
        Some(from_root) => root().join(from_root),
        None => file.parent().unwrap_or(Path::new(".")).join(path),
    }
}

#[test]
fn every_relative_link_in_the_documentation_resolves() {
    let files = markdown_files();
    assert!(
        files.len() > 1,
        "expected README.md and docs/**/*.md, found {files:?}"
    );
    let mut checked = 0;
    let mut broken = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
        for link in extract_links(&text) {
            if is_external_or_anchor(&link.target) {
                continue;
            }
            checked += 1;
            if !resolve(file, &link.target).exists() {
                broken.push(format!("{}:{}: {}", shown(file), link.line, link.target));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "{} broken relative link(s) of {checked}:\n  {}",
        broken.len(),
        broken.join("\n  ")
    );
    println!(
        "{checked} relative links in {} markdown files resolve",
        files.len()
    );
}

#[test]
fn links_are_read_as_markdown_reads_them() {
    let text = "\
See [the design](docs/design.md#2-the-method) and ![a](img/a.png \"title\").
Not `[code](not/a/link.md)`, nor [x](https://example.org) nor [y](#anchor).
[ref]: ../other.md
```sh
[fenced](not/a/link.md)
```
[paren](a_(b).md) and [angle](<with space.md>)
";
    let targets: Vec<(usize, String)> = extract_links(text)
        .into_iter()
        .map(|l| (l.line, l.target))
        .collect();
    assert_eq!(
        targets,
        vec![
            (1, "docs/design.md#2-the-method".to_string()),
            (1, "img/a.png".to_string()),
            (2, "https://example.org".to_string()),
            (2, "#anchor".to_string()),
            (3, "../other.md".to_string()),
            (7, "a_(b).md".to_string()),
            (7, "with space.md".to_string()),
        ]
    );
    assert!(is_external_or_anchor("https://example.org"));
    assert!(is_external_or_anchor("mailto:someone@example.org"));
    assert!(is_external_or_anchor("#anchor"));
    assert!(!is_external_or_anchor("docs/design.md#anchor"));
    assert!(!is_external_or_anchor("../src/l3/"));
    assert_eq!(
        resolve(&root().join("docs/guide.md"), "../README.md?plain=1#top"),
        root().join("docs/../README.md")
    );
}
