//! The code cites the design notes as `docs/design.md §n`, and every section it cites exists.
//!
//! NOTE: `src_cites_the_design_notes_only_as_docs_design_md` FAILS until the citations under
//! src/ are rewritten from `DESIGN.md §n` (the notes' old home, ../shared/DESIGN.md) to
//! `docs/design.md §n`. That rewrite is a mechanical edit of src/, made once the restructured
//! code is assembled; after it this test must pass and keep passing.

use std::path::Path;

use crate::{files_under, root, shown};

/// A citation of the design notes found in a source file.
#[derive(Debug, PartialEq)]
pub struct Citation {
    pub line: usize,
    /// The text as written, e.g. `DESIGN.md` or `docs/design.md`.
    pub cited_as: String,
    /// The section numbers that follow it (`§2, §5` gives 2 and 5).
    pub sections: Vec<u32>,
}

/// The section numbers at the start of `rest`: `§2, §3 and §5`, `§2–§4` (both ends), …
fn sections_after(rest: &str) -> Vec<u32> {
    let mut out = Vec::new();
    let mut s = rest;
    loop {
        let t = s.trim_start_matches([' ', ',', '–', '-']);
        let t = t.strip_prefix("and ").unwrap_or(t);
        let Some(after) = t.strip_prefix('§') else {
            break;
        };
        let digits: String = after.chars().take_while(|c| c.is_ascii_digit()).collect();
        let Ok(n) = digits.parse() else {
            break;
        };
        out.push(n);
        s = &after[digits.len()..];
    }
    out
}

/// Every mention of the design notes in `text`: `design.md` in any case (with or without a
/// folder before it) and the short form `DESIGN §n`.
pub fn citations(text: &str) -> Vec<Citation> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let lower = line.to_ascii_lowercase();
        let mut from = 0;
        while let Some(at) = lower[from..].find("design") {
            let start = from + at;
            let rest = &line[start + "design".len()..];
            let (end, is_citation) = if rest.to_ascii_lowercase().starts_with(".md") {
                (start + "design.md".len(), true)
            } else {
                // `DESIGN §7`: the upper-case short form only, not the word "design".
                let short = &line[start..start + "design".len()] == "DESIGN"
                    && rest.trim_start().starts_with('§');
                (start + "design".len(), short)
            };
            if is_citation {
                // Include a folder written before the name (`docs/design.md`).
                let begin = line[..start]
                    .rfind(|c: char| !(c.is_ascii_alphanumeric() || "/._-".contains(c)))
                    .map_or(0, |j| {
                        j + line[j..].chars().next().map_or(1, char::len_utf8)
                    });
                out.push(Citation {
                    line: i + 1,
                    cited_as: line[begin..end].to_string(),
                    sections: sections_after(&line[end..]),
                });
            }
            from = end;
        }
    }
    out
}

/// The section numbers docs/design.md has: headings that carry `§n`.
fn design_sections() -> Vec<u32> {
    let path = root().join("docs/design.md");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    text.lines()
        .filter(|l| l.starts_with('#'))
        .flat_map(|l| {
            let at = l.find('§').unwrap_or(l.len());
            sections_after(&l[at..])
        })
        .collect()
}

fn source_files() -> Vec<std::path::PathBuf> {
    files_under(&root().join("src"), ".rs")
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// FAILS until src/ cites `docs/design.md §n` instead of `DESIGN.md §n` (see the module doc).
#[test]
fn src_cites_the_design_notes_only_as_docs_design_md() {
    let mut bare = Vec::new();
    for file in source_files() {
        for c in citations(&read(&file)) {
            if c.cited_as != "docs/design.md" {
                bare.push(format!("{}:{}: {}", shown(&file), c.line, c.cited_as));
            }
        }
    }
    assert!(
        bare.is_empty(),
        "{} citation(s) of the design notes under src/ are not `docs/design.md §n` \
         (rewrite them to docs/design.md):\n  {}",
        bare.len(),
        bare.join("\n  ")
    );
}

#[test]
fn every_cited_section_of_docs_design_md_exists() {
    let sections = design_sections();
    for n in 1..=12 {
        assert!(
            sections.contains(&n),
            "docs/design.md has no heading for §{n} (found {sections:?})"
        );
    }
    let mut missing = Vec::new();
    for file in source_files() {
        for c in citations(&read(&file)) {
            for n in c.sections {
                if !sections.contains(&n) {
                    missing.push(format!("{}:{}: §{n}", shown(&file), c.line));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "sections cited under src/ that docs/design.md does not have:\n  {}",
        missing.join("\n  ")
    );
}

#[test]
fn citations_are_found_in_every_form() {
    let text = "\
//! The camera (DESIGN.md §3).
//! affine kernel to its patch (docs/design.md §2, §5).
//! The Natural-100 chart (DESIGN §7, the paper's §3.3)
/// design the sensor; see ../shared/DESIGN.md §2–§4 and §6.
";
    let found: Vec<(usize, String, Vec<u32>)> = citations(text)
        .into_iter()
        .map(|c| (c.line, c.cited_as, c.sections))
        .collect();
    assert_eq!(
        found,
        vec![
            (1, "DESIGN.md".to_string(), vec![3]),
            (2, "docs/design.md".to_string(), vec![2, 5]),
            (3, "DESIGN".to_string(), vec![7]),
            (4, "../shared/DESIGN.md".to_string(), vec![2, 4, 6]),
        ]
    );
}
