//! The repository's documents stand alone: the README fits a screen or two, and every path the docs and
//! the code's comments point to is in the repository, with no reference to notes kept elsewhere.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The text files of the repository a reader follows references in: Markdown, Rust, messages, YAML and
/// scripts, outside build output, vendored crates, the Python environment and committed data.
fn documents() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().to_string();
            if path.is_dir() {
                if !["target", "vendor", ".venv", ".git", "data", "out", "graph_logs"].contains(&name.as_str())
                    && !name.starts_with('.')
                {
                    walk(&path, out);
                }
            } else if ["md", "rs", "msg", "srv", "action", "yaml", "sh", "toml", "src"]
                .iter()
                .any(|ext| name.ends_with(&format!(".{ext}")))
            {
                out.push(path);
            }
        }
    }
    let mut out = vec![];
    walk(&root(), &mut out);
    out
}

/// Folders of the repository whose paths a document may name.
const TOP: [&str; 12] = [
    "crates/",
    "nodes/",
    "cli/",
    "docs/",
    "config/",
    "launch-scripts/",
    "krl/",
    "urdf/",
    "msgs/",
    "tests/",
    "tools/",
    "data/",
];

/// Paths such as `crates/contact/src/fit.rs` or `docs/safety.md` in a text: a top folder followed by path
/// characters, trailing punctuation and `::item` or `:line` suffixes cut.
fn paths_in(text: &str) -> Vec<String> {
    let mut found = vec![];
    for top in TOP {
        let mut from = 0;
        while let Some(at) = text[from..].find(top) {
            let start = from + at;
            from = start + top.len();
            // A path starts a word: not `foo/crates/` nor a URL's `…/docs/`.
            let before = text[..start].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || matches!(c, '/' | '.' | '_' | '-')) {
                continue;
            }
            let rest = &text[start..];
            let end =
                rest.find(|c: char| !(c.is_alphanumeric() || matches!(c, '/' | '.' | '_' | '-'))).unwrap_or(rest.len());
            let path = rest[..end].trim_end_matches(['.', '-', '/']);
            if path.contains('*') || path.len() <= top.len() {
                continue;
            }
            found.push(path.to_string());
        }
    }
    found
}

#[test]
fn the_readme_fits_two_screens() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(lines <= 200, "README.md has {lines} lines; the rest belongs in docs/");
}

#[test]
fn every_path_the_docs_and_comments_name_is_in_the_repository() {
    let mut dangling = vec![];
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap_or_default();
        for path in paths_in(&text) {
            // From the repository's root, or from a crate's folder (a test names `tests/peers.py`).
            let exists = doc.ancestors().take_while(|d| d.starts_with(root())).any(|d| d.join(&path).exists());
            if !exists && !doc.ends_with("docs.rs") {
                dangling.push(format!("{}: {path}", doc.strip_prefix(root()).unwrap_or(&doc).display()));
            }
        }
    }
    dangling.sort();
    dangling.dedup();
    assert!(
        dangling.is_empty(),
        "{} references to paths not in the repository:\n{}",
        dangling.len(),
        dangling.join("\n")
    );
}

#[test]
fn no_document_points_outside_the_repository() {
    let outside = ["design.md", "specs/", "../shared", "seed 00", "Seed 00", "seed-00"];
    let mut found = vec![];
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap_or_default();
        for (n, line) in text.lines().enumerate() {
            for word in outside {
                if line.contains(word) && !doc.ends_with("docs.rs") {
                    found.push(format!(
                        "{}:{}: {}",
                        doc.strip_prefix(root()).unwrap_or(&doc).display(),
                        n + 1,
                        line.trim()
                    ));
                }
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}
