//! No circle of imports between the source files of any crate: a file that imports another
//! (a `crate::`, `super::` or `self::` path, or a child module's) is never imported back by it,
//! directly or around a longer circle.
//!
//! A path is followed to the file that defines what it names: `crate::Profile`, re-exported by
//! `lib.rs` (`pub use family::Profile`), is an import of `family.rs`, not of `lib.rs`. A module's
//! `pub use` lines are its face, not its imports, and `mod x;` declares a child without using it.
//! Test modules inside a file (`#[cfg(test)] mod tests { … }`) are left out; test files
//! (`tests.rs`, `*_tests.rs`, `scenarios.rs`) count like any other.

#![allow(clippy::panic)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One crate's source files, by module path (`["agilex_v2", "family"]`; the root is `[]`).
struct Crate {
    files: BTreeMap<Vec<String>, PathBuf>,
    texts: BTreeMap<Vec<String>, String>,
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or_else(|| panic!("the workspace"))
        .to_path_buf()
}

/// The workspace members' source roots (`src/lib.rs` and `src/main.rs` each make a crate).
fn crate_roots() -> Vec<PathBuf> {
    let manifest = std::fs::read_to_string(workspace().join("Cargo.toml"))
        .unwrap_or_else(|e| panic!("Cargo.toml: {e}"));
    let members: Vec<String> = manifest
        .split_once("members = [")
        .and_then(|(_, rest)| rest.split_once(']'))
        .map(|(list, _)| {
            list.split(',')
                .map(|m| m.trim().trim_matches('"').to_string())
                .filter(|m| !m.is_empty())
                .collect()
        })
        .unwrap_or_else(|| panic!("the workspace members"));
    assert!(members.len() > 10, "{members:?}");
    let mut roots = Vec::new();
    for member in members {
        for root in ["src/lib.rs", "src/main.rs"] {
            let path = workspace().join(&member).join(root);
            if path.exists() {
                roots.push(path);
            }
        }
    }
    roots
}

/// The text of a file without its inline test modules and comments.
fn code_of(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut code = String::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("#[cfg(test)]")
            && lines
                .peek()
                .is_some_and(|next| next.trim_start().starts_with("mod ") && next.ends_with('{'))
        {
            break;
        }
        if trimmed.starts_with("//") {
            continue;
        }
        code.push_str(line);
        code.push('\n');
    }
    code
}

/// The modules a file declares with `mod name;` (its children kept in files).
fn children(code: &str) -> Vec<String> {
    code.lines()
        .filter_map(|line| {
            let line = line.trim();
            let rest = line
                .strip_prefix("pub mod ")
                .or_else(|| line.strip_prefix("pub(crate) mod "))
                .or_else(|| line.strip_prefix("mod "))?;
            rest.strip_suffix(';').map(str::to_string)
        })
        .collect()
}

fn load(root: &Path) -> Crate {
    let mut krate = Crate {
        files: BTreeMap::new(),
        texts: BTreeMap::new(),
    };
    let mut queue = vec![(Vec::new(), root.to_path_buf())];
    while let Some((module, path)) = queue.pop() {
        let code = code_of(&path);
        let dir = if module.is_empty() || path.ends_with("mod.rs") {
            path.parent()
                .unwrap_or_else(|| panic!("a folder"))
                .to_path_buf()
        } else {
            path.with_extension("")
        };
        for child in children(&code) {
            let mut child_module = module.clone();
            child_module.push(child.clone());
            let file = dir.join(format!("{child}.rs"));
            let folder = dir.join(&child).join("mod.rs");
            if file.exists() {
                queue.push((child_module, file));
            } else if folder.exists() {
                queue.push((child_module, folder));
            }
        }
        krate.files.insert(module.clone(), path);
        krate.texts.insert(module, code);
    }
    krate
}

/// The paths a file's code names: every `crate::…`, `super::…` and `self::…` path, and the
/// `use` trees (`use crate::{a::B, c::D};` names `crate::a::B` and `crate::c::D`), without its
/// `pub use` lines.
fn paths_in(code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut statement = String::new();
    for line in code.lines() {
        let trimmed = line.trim_start();
        if statement.is_empty() && !trimmed.starts_with("use ") {
            for start in ["crate::", "super::", "self::"] {
                let mut rest = line;
                while let Some(at) = rest.find(start) {
                    let before = rest[..at].chars().next_back();
                    let tail = &rest[at..];
                    let end = tail
                        .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                        .unwrap_or(tail.len());
                    if !before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                        out.push(segments(&tail[..end]));
                    }
                    rest = &tail[end.max(1)..];
                }
            }
            continue;
        }
        statement.push_str(trimmed);
        if trimmed.ends_with(';') {
            if let Some(tree) = statement.strip_prefix("use ") {
                expand(tree.trim_end_matches(';'), &mut Vec::new(), &mut out);
            }
            statement.clear();
        }
    }
    out
}

fn segments(path: &str) -> Vec<String> {
    path.split("::")
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect()
}

/// The paths of a `use` tree (`a::{b, c::{d, e}}`).
fn expand(tree: &str, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    let tree = tree.trim();
    if let Some(open) = tree.find('{') {
        let head = segments(tree[..open].trim_end_matches("::"));
        let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
        let depth = prefix.len();
        prefix.extend(head);
        let mut level = 0;
        let mut start = 0;
        for (i, c) in inner.char_indices() {
            match c {
                '{' => level += 1,
                '}' => level -= 1,
                ',' if level == 0 => {
                    expand(&inner[start..i], prefix, out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        expand(&inner[start..], prefix, out);
        prefix.truncate(depth);
    } else if !tree.is_empty() {
        let mut path = prefix.clone();
        path.extend(segments(tree.split(" as ").next().unwrap_or(tree)));
        out.push(path);
    }
}

impl Crate {
    /// The module a path from `from` starts in, and the rest of the path; `None` for another
    /// crate's path.
    fn absolute(&self, from: &[String], path: &[String]) -> Option<Vec<String>> {
        let first = path.first()?;
        let mut base: Vec<String> = match first.as_str() {
            "crate" => Vec::new(),
            "self" => from.to_vec(),
            "super" => from.to_vec(),
            name if self
                .files
                .contains_key(&[from, &[name.to_string()]].concat()) =>
            {
                from.to_vec()
            }
            _ => return None,
        };
        let mut rest = path;
        if first == "crate" || first == "self" {
            rest = &path[1..];
        }
        while rest.first().is_some_and(|s| s == "super") {
            base.pop();
            rest = &rest[1..];
        }
        base.extend(rest.iter().cloned());
        Some(base)
    }

    /// The file that defines what an absolute path names, following `pub use` re-exports.
    fn defining_file(&self, path: &[String], depth: usize) -> Option<Vec<String>> {
        let mut module = path.to_vec();
        while !self.files.contains_key(&module) {
            module.pop();
        }
        let rest = &path[module.len()..];
        let Some(name) = rest.first() else {
            return Some(module);
        };
        if depth > 8 {
            return Some(module);
        }
        let code = &self.texts[&module];
        for line in code.lines() {
            let Some(tree) = line.trim().strip_prefix("pub use ") else {
                continue;
            };
            let mut targets = Vec::new();
            expand(tree.trim_end_matches(';'), &mut Vec::new(), &mut targets);
            for target in targets {
                let glob = target.last().is_some_and(|s| s == "*");
                let named = target.last() == Some(name);
                if !(named || glob) {
                    continue;
                }
                let Some(absolute) = self.absolute(&module, &target) else {
                    continue;
                };
                let mut absolute = absolute;
                if glob {
                    absolute.pop();
                    let Some(file) = self.defining_file(&absolute, depth + 1) else {
                        continue;
                    };
                    if !defines(&self.texts[&file], name) {
                        continue;
                    }
                    absolute.push(name.clone());
                }
                absolute.extend(rest[1..].iter().cloned());
                return self.defining_file(&absolute, depth + 1);
            }
        }
        Some(module)
    }

    /// Every file's imports of other files.
    fn imports(&self) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
        let mut edges = BTreeMap::new();
        for (module, code) in &self.texts {
            let private: String = code
                .lines()
                .filter(|l| !l.trim_start().starts_with("pub use "))
                .map(|l| format!("{l}\n"))
                .collect();
            let targets: BTreeSet<Vec<String>> = paths_in(&private)
                .iter()
                .filter_map(|path| self.absolute(module, path))
                .filter_map(|path| self.defining_file(&path, 0))
                .filter(|target| target != module)
                .collect();
            edges.insert(module.clone(), targets);
        }
        edges
    }
}

/// Whether `code` defines an item called `name`.
fn defines(code: &str, name: &str) -> bool {
    [
        "struct", "enum", "fn", "trait", "type", "const", "static", "mod",
    ]
    .iter()
    .any(|kind| {
        code.lines().any(|l| {
            l.trim_start()
                .trim_start_matches("pub ")
                .trim_start_matches("pub(crate) ")
                .strip_prefix(kind)
                .and_then(|r| r.strip_prefix(' '))
                .is_some_and(|r| {
                    r.starts_with(name)
                        && !r[name.len()..].starts_with(|c: char| c.is_alphanumeric() || c == '_')
                })
        })
    })
}

/// The circles of a graph: its strongly connected parts of more than one file (Tarjan).
fn circles(edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<Vec<Vec<String>>> {
    struct Walk<'a> {
        edges: &'a BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'a Vec<String>, usize>,
        low: BTreeMap<&'a Vec<String>, usize>,
        stack: Vec<&'a Vec<String>>,
        found: Vec<Vec<Vec<String>>>,
    }
    impl<'a> Walk<'a> {
        fn visit(&mut self, node: &'a Vec<String>) {
            let n = self.index.len();
            self.index.insert(node, n);
            self.low.insert(node, n);
            self.stack.push(node);
            for next in self.edges.get(node).into_iter().flatten() {
                if !self.index.contains_key(next) {
                    self.visit(next);
                    let low = self.low[next].min(self.low[node]);
                    self.low.insert(node, low);
                } else if self.stack.contains(&next) {
                    let low = self.index[next].min(self.low[node]);
                    self.low.insert(node, low);
                }
            }
            if self.low[node] == self.index[node] {
                let mut part = Vec::new();
                while let Some(top) = self.stack.pop() {
                    part.push(top.clone());
                    if top == node {
                        break;
                    }
                }
                if part.len() > 1 {
                    self.found.push(part);
                }
            }
        }
    }
    let mut walk = Walk {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for node in edges.keys() {
        if !walk.index.contains_key(node) {
            walk.visit(node);
        }
    }
    walk.found
}

#[test]
fn no_source_file_imports_one_that_imports_it_back() {
    let mut report = Vec::new();
    let mut files = 0;
    for root in crate_roots() {
        let krate = load(&root);
        files += krate.files.len();
        for circle in circles(&krate.imports()) {
            let names: Vec<String> = circle
                .iter()
                .map(|m| {
                    krate.files[m]
                        .strip_prefix(workspace())
                        .unwrap_or(&krate.files[m])
                        .display()
                        .to_string()
                })
                .collect();
            report.push(names.join(" ↔ "));
        }
    }
    assert!(files > 200, "only {files} source files found");
    assert!(
        report.is_empty(),
        "circles of imports:\n{}",
        report.join("\n")
    );
}

/// The check sees a circle: two files that import each other, and three around a circle.
#[test]
fn a_circle_of_imports_is_found() {
    let module = |name: &str| vec![name.to_string()];
    let mut edges = BTreeMap::new();
    edges.insert(module("a"), BTreeSet::from([module("b")]));
    edges.insert(module("b"), BTreeSet::from([module("a")]));
    edges.insert(module("c"), BTreeSet::from([module("d")]));
    edges.insert(module("d"), BTreeSet::from([module("e")]));
    edges.insert(module("e"), BTreeSet::from([module("c")]));
    edges.insert(module("f"), BTreeSet::from([module("a")]));
    let mut found: Vec<usize> = circles(&edges).iter().map(Vec::len).collect();
    found.sort();
    assert_eq!(found, [2, 3]);
    let mut paths = Vec::new();
    expand("crate::{a::B, c::{d, E as F}}", &mut Vec::new(), &mut paths);
    assert_eq!(
        paths,
        [
            segments("crate::a::B"),
            segments("crate::c::d"),
            segments("crate::c::E")
        ]
    );
}
