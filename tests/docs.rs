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
const TOP: [&str; 14] = [
    "crates/",
    "nodes/",
    "simcell/",
    ".ci/",
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

/// Commands the docs show, from their code blocks and inline code: `softcontact …` (however it is run),
/// the node binaries and the launch scripts, each as its program and arguments.
fn documented_commands() -> Vec<(String, Vec<String>)> {
    let mut docs: Vec<PathBuf> = documents().into_iter().filter(|p| p.extension().is_some_and(|e| e == "md")).collect();
    docs.sort();
    let mut out = vec![];
    for doc in docs {
        let text = std::fs::read_to_string(&doc).unwrap_or_default();
        let mut snippets: Vec<String> = vec![];
        let mut in_block = false;
        for line in text.lines() {
            if line.trim_start().starts_with("```") {
                in_block = !in_block;
            } else if in_block {
                snippets.push(line.to_string());
            } else {
                snippets.extend(line.split('`').skip(1).step_by(2).map(str::to_string));
            }
        }
        for snippet in snippets.iter().filter(|s| !s.contains("cargo ")) {
            // Commands chained with `&&`, `;` or `|`, or started with `&`, each on its own; comments cut.
            let snippet = snippet.split(" #").next().unwrap_or("");
            for part in snippet.split(['&', ';', '|', '\'']) {
                let words: Vec<&str> = part.split_whitespace().collect();
                // `softcontact` as the command itself, a built binary or a script anywhere (after `--run`).
                let Some(start) = words.iter().enumerate().position(|(i, w)| {
                    (i == 0 && *w == "softcontact")
                        || w.starts_with("target/release/")
                        || w.starts_with("launch-scripts/")
                }) else {
                    continue;
                };
                let program = words[start].rsplit('/').next().unwrap_or("").to_string();
                let known = [
                    "softcontact",
                    "lwr_driver",
                    "ft_sensor",
                    "sim_arm",
                    "lwr_control",
                    "contact_estimator",
                    "deformation_controller",
                    "sim.sh",
                    "robot.sh",
                    "launch.sh",
                ];
                if !known.contains(&program.as_str()) {
                    continue;
                }
                let args: Vec<String> = words[start + 1..].iter().map(|w| w.to_string()).collect();
                out.push((format!("{}: {program}", doc.strip_prefix(root()).unwrap_or(&doc).display()), args));
            }
        }
        // `cargo run … --bin NAME -- ARGS`
        for line in text.lines().filter(|l| l.contains("cargo run")) {
            let words: Vec<&str> = line.split(" #").next().unwrap_or("").split_whitespace().collect();
            let (Some(bin), Some(dashes)) =
                (words.iter().position(|w| *w == "--bin"), words.iter().position(|w| *w == "--"))
            else {
                continue;
            };
            let program = words.get(bin + 1).unwrap_or(&"").to_string();
            let args = words[dashes + 1..].iter().map(|w| w.trim_end_matches('`').to_string()).collect();
            out.push((format!("{}: {program}", doc.strip_prefix(root()).unwrap_or(&doc).display()), args));
        }
    }
    out
}

fn binary(name: &str) -> PathBuf {
    // The test runs from target/<profile>/deps; the binaries are one folder up.
    let exe = std::env::current_exe().unwrap();
    exe.parent().and_then(Path::parent).unwrap().join(name)
}

/// Every option a documented command uses is one its program accepts (its `--help` lists it), every
/// subcommand exists, and every `-p name:=value` names a parameter of the node's YAML in `config/`.
#[test]
fn every_documented_command_uses_options_its_program_has() {
    let mut wrong = vec![];
    let mut checked = 0;
    for (where_, args) in documented_commands() {
        let program = where_.rsplit(": ").next().unwrap().to_string();
        let mut help_args: Vec<String> = vec![];
        let mut rest: &[String] = &args;
        if program == "softcontact" {
            // The subcommand, and `bench`'s own.
            for _ in 0..2 {
                match rest.first() {
                    Some(w) if !w.starts_with('-') && w.chars().all(|c| c.is_ascii_lowercase() || c == '-') => {
                        help_args.push(w.clone());
                        rest = &rest[1..];
                        if help_args[0] != "bench" {
                            break;
                        }
                    }
                    _ => break,
                }
            }
        }
        // A launch script's `--run` starts another command.
        let rest: Vec<&String> = rest.iter().take_while(|w| *w != "--run").collect();
        let path =
            if program.ends_with(".sh") { root().join("launch-scripts").join(&program) } else { binary(&program) };
        let help = std::process::Command::new(&path).args(&help_args).arg("--help").output();
        let Ok(help) = help else {
            wrong.push(format!("{where_} {args:?}: {} does not run", path.display()));
            continue;
        };
        let shown = format!("{}{}", String::from_utf8_lossy(&help.stdout), String::from_utf8_lossy(&help.stderr));
        if !help.status.success() {
            wrong.push(format!("{where_} {help_args:?} --help fails: {shown}"));
            continue;
        }
        checked += 1;
        for (i, word) in rest.iter().enumerate() {
            let flag = word.strip_prefix("--").map(|f| f.split('=').next().unwrap_or(""));
            if let Some(flag) = flag.filter(|f| !f.is_empty() && *f != "help")
                && !shown.contains(&format!("--{flag}"))
            {
                wrong.push(format!(
                    "{where_} {args:?}: --{flag} is not an option of `{program} {}`",
                    help_args.join(" ")
                ));
            }
            if *word == "-p" && !program.ends_with(".sh") && program != "softcontact" {
                let name = rest.get(i + 1).map_or("", |v| v.split(":=").next().unwrap_or(""));
                let yaml =
                    std::fs::read_to_string(root().join("config").join(format!("{program}.yaml"))).unwrap_or_default();
                if !yaml.lines().any(|l| l.trim_start().starts_with(&format!("{name}:"))) {
                    wrong.push(format!("{where_} {args:?}: `{name}` is not a parameter in config/{program}.yaml"));
                }
            }
        }
    }
    assert!(checked >= 20, "only {checked} documented commands found");
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// Topic names are declared once, in `msgs/src/topics.rs`: no product source (its tests aside) spells
/// one of the graph's names as a string.
#[test]
fn topic_names_are_declared_once() {
    let declared = std::fs::read_to_string(root().join("msgs/src/topics.rs")).unwrap();
    let names: Vec<&str> =
        declared.lines().filter_map(|l| l.split("Topic::new(\"").nth(1)?.split('"').next()).collect();
    assert!(names.len() >= 15, "{names:?}");
    let mut spelled = vec![];
    for doc in documents() {
        let relative = doc.strip_prefix(root()).unwrap_or(&doc).to_string_lossy().to_string();
        let product =
            ["nodes/src/", "simcell/src/", "cli/src/", "crates/", "msgs/src/"].iter().any(|p| relative.starts_with(p))
                && relative.ends_with(".rs")
                && !relative.contains("/tests/")
                && relative != "msgs/src/topics.rs";
        if !product {
            continue;
        }
        let text = std::fs::read_to_string(&doc).unwrap_or_default();
        let code = text.split("#[cfg(test)]").next().unwrap_or("");
        for (n, line) in code.lines().enumerate() {
            if let Some(name) = names.iter().find(|name| line.contains(&format!("\"{name}\""))) {
                spelled.push(format!("{relative}:{}: {name}", n + 1));
            }
        }
    }
    assert!(spelled.is_empty(), "topic names spelled outside msgs/src/topics.rs:\n{}", spelled.join("\n"));
}

/// No product source file over [`MAX_FILE_LINES`] lines before its tests, and no function over
/// [`MAX_FUNCTION_LINES`] lines (as `cargo fmt` lays it out: from its `fn` line to the brace that closes
/// it at the same indentation).
#[test]
fn no_source_file_or_function_outgrows_its_limit() {
    let mut over = vec![];
    for doc in documents() {
        let relative = doc.strip_prefix(root()).unwrap_or(&doc).to_string_lossy().to_string();
        let product =
            ["nodes/src/", "simcell/src/", "cli/src/", "crates/", "msgs/src/"].iter().any(|p| relative.starts_with(p))
                && relative.ends_with(".rs")
                && !relative.contains("/tests/")
                && !relative.ends_with("/tests.rs");
        if !product {
            continue;
        }
        let text = std::fs::read_to_string(&doc).unwrap();
        let lines: Vec<&str> = text.lines().take_while(|l| !l.starts_with("#[cfg(test)]")).collect();
        if lines.len() > MAX_FILE_LINES {
            over.push(format!("{relative}: {} lines", lines.len()));
        }
        for (name, length) in functions(&lines) {
            if length > MAX_FUNCTION_LINES {
                over.push(format!("{relative} {name}: {length} lines"));
            }
        }
    }
    assert!(
        over.is_empty(),
        "over the limits ({MAX_FILE_LINES} lines a file, {MAX_FUNCTION_LINES} a function):\n{}",
        over.join("\n")
    );
}

const MAX_FILE_LINES: usize = 800;
const MAX_FUNCTION_LINES: usize = 100;

/// Each function of `lines` (a formatted Rust file) with its length in lines.
fn functions(lines: &[&str]) -> Vec<(String, usize)> {
    let mut out = vec![];
    for (i, line) in lines.iter().enumerate() {
        let code = line.trim_start();
        let indent = line.len() - code.len();
        let signature = ["pub(crate) ", "pub(super) ", "pub ", "const ", "async ", "unsafe ", "extern \"C\" "]
            .iter()
            .fold(code, |c, prefix| c.strip_prefix(prefix).unwrap_or(c));
        let Some(rest) = signature.strip_prefix("fn ") else { continue };
        let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        if code.ends_with('}') || code.ends_with(';') {
            continue; // on one line, or a declaration without a body
        }
        let closing = format!("{}}}", " ".repeat(indent));
        let end = lines[i + 1..].iter().position(|l| *l == closing || l.starts_with(&format!("{closing} ")));
        if let Some(end) = end {
            out.push((name, end + 2));
        }
    }
    out
}
