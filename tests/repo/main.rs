//! Checks on the repository itself rather than on the crate's behaviour: the documentation's
//! relative links resolve (`links`), and the code's citations of the design notes point at
//! `docs/design.md` and at sections it has (`design_refs`), and `src/` keeps its floor plan:
//! file and function sizes, no long argument lists, no import cycle between files (`structure`).
//!
//! `cargo test --test repo`; one of them with e.g. `cargo test --test repo links`.

mod design_refs;
mod links;
mod structure;

use std::path::{Path, PathBuf};

/// The repository's root (where Cargo.toml is).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every file under `dir` (recursively) whose name ends with `suffix`, sorted.
pub fn files_under(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.ends_with(suffix))
            {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// `path` relative to the repository's root, for messages.
pub fn shown(path: &Path) -> String {
    path.strip_prefix(root())
        .unwrap_or(path)
        .display()
        .to_string()
}
