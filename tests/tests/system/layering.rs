//! docs/ARCHITECTURE.md's crate table against the workspace's `Cargo.toml` files: the table lists
//! every member of the workspace at its path; each row names exactly the workspace crates the
//! crate uses (`uses`: dependencies and build-dependencies; `its tests also use`:
//! dev-dependencies) and only outside crates it depends on; and the arrows point up the table
//! only (a crate uses only crates above it, so no two depend on each other). Apart from the table,
//! the rule its text states: no crate under `clients/` depends on `chassisd`, directly or through
//! another workspace crate.
// Test code: helpers outside #[test] functions may unwrap and panic.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

/// The service no client may depend on.
const SERVICE: &str = "chassisd";
/// Where the client crates live.
const CLIENTS: &str = "clients/";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn toml_of(path: &Path) -> toml::Table {
    toml::from_str(&read(path)).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// One member of the workspace, as its `Cargo.toml` has it.
#[derive(Debug)]
struct Member {
    /// Its directory from the workspace root, with a `/` at the end as the table writes it.
    path: String,
    name: String,
    /// The package names of its dependencies and build-dependencies.
    deps: BTreeSet<String>,
    /// The package names of its dev-dependencies.
    dev_deps: BTreeSet<String>,
}

/// Every member the workspace `Cargo.toml` lists, in its order.
fn members() -> Vec<Member> {
    let root = root();
    let workspace = toml_of(&root.join("Cargo.toml"));
    workspace["workspace"]["members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|dir| {
            let dir = dir.as_str().unwrap();
            let manifest = toml_of(&root.join(dir).join("Cargo.toml"));
            Member {
                path: format!("{dir}/"),
                name: manifest["package"]["name"].as_str().unwrap().to_string(),
                deps: dependencies(&manifest, &["dependencies", "build-dependencies"]),
                dev_deps: dependencies(&manifest, &["dev-dependencies"]),
            }
        })
        .collect()
}

/// The package names of the dependencies of `kinds`, for every target (`[target.'cfg(…)'.…]`
/// too); a renamed dependency (`package = "…"`) by its package's name.
fn dependencies(manifest: &toml::Table, kinds: &[&str]) -> BTreeSet<String> {
    let mut sections = vec![manifest];
    if let Some(targets) = manifest.get("target").and_then(toml::Value::as_table) {
        sections.extend(targets.values().filter_map(toml::Value::as_table));
    }
    sections
        .iter()
        .flat_map(|section| kinds.iter().filter_map(|k| section.get(*k)?.as_table()))
        .flat_map(|deps| {
            deps.iter().map(|(key, spec)| {
                let package = spec.get("package").and_then(toml::Value::as_str);
                package.unwrap_or(key).to_string()
            })
        })
        .collect()
}

/// One row of the crate table.
#[derive(Debug)]
struct Row {
    path: String,
    name: String,
    uses: BTreeSet<String>,
    tests_use: BTreeSet<String>,
    outside: BTreeSet<String>,
}

/// The rows of the table under `## Crates` in docs/ARCHITECTURE.md, in their order.
fn table() -> Vec<Row> {
    let doc = read(&root().join("docs/ARCHITECTURE.md"));
    let mut lines = doc
        .lines()
        .skip_while(|line| *line != "## Crates")
        .skip_while(|line| !line.starts_with('|'));
    let first = lines.next();
    let header = cells(first.unwrap_or_else(|| panic!("no table under `## Crates`")));
    let column = |title: &str| {
        header
            .iter()
            .position(|h| h == title)
            .unwrap_or_else(|| panic!("the crate table has no column `{title}`: {header:?}"))
    };
    let (path, name) = (column("path"), column("crate"));
    let (uses, tests_use) = (column("uses"), column("its tests also use"));
    let outside = column("from outside (the main ones)");
    lines
        .skip(1) // | --- | --- |
        .take_while(|line| line.starts_with('|'))
        .map(|line| {
            let cells = cells(line);
            let name = first_ticked(&cells[name], line);
            Row {
                path: first_ticked(&cells[path], line),
                uses: crate_list(&cells[uses], &name, "uses"),
                tests_use: crate_list(&cells[tests_use], &name, "its tests also use"),
                outside: ticked(&cells[outside]).collect(),
                name,
            }
        })
        .collect()
}

/// The cells of a table line (an escaped `\|` stays in its cell).
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner
        .replace("\\|", "\u{0}")
        .split('|')
        .map(|cell| cell.trim().replace('\u{0}', "|"))
        .collect()
}

/// The `code` spans of a cell.
fn ticked(cell: &str) -> impl Iterator<Item = String> + '_ {
    cell.split('`').skip(1).step_by(2).map(str::to_string)
}

fn first_ticked(cell: &str, line: &str) -> String {
    ticked(cell)
        .next()
        .unwrap_or_else(|| panic!("no `name` in `{cell}` of the row {line}"))
}

/// A cell naming workspace crates: `—`, or `a`, `b`, … and nothing else.
fn crate_list(cell: &str, row: &str, column: &str) -> BTreeSet<String> {
    if cell == "—" {
        return BTreeSet::new();
    }
    cell.split(',')
        .map(|item| {
            let item = item.trim();
            item.strip_prefix('`')
                .and_then(|i| i.strip_suffix('`'))
                .filter(|name| !name.contains('`'))
                .unwrap_or_else(|| {
                    panic!(
                        "{row}, column `{column}`: `{item}` is not a crate name; write \
                         `name`, `name`, … or —"
                    )
                })
                .to_string()
        })
        .collect()
}

fn row_of<'a>(rows: &'a [Row], name: &str) -> &'a Row {
    rows.iter()
        .find(|row| row.name == name)
        .unwrap_or_else(|| panic!("{name} has no row in docs/ARCHITECTURE.md's crate table"))
}

fn workspace_crates(names: &BTreeSet<String>, members: &[Member]) -> BTreeSet<String> {
    let workspace: BTreeSet<&str> = members.iter().map(|m| m.name.as_str()).collect();
    names
        .iter()
        .filter(|name| workspace.contains(name.as_str()))
        .cloned()
        .collect()
}

fn report(problems: &[String]) {
    assert!(
        problems.is_empty(),
        "docs/ARCHITECTURE.md's crate table and the workspace disagree:\n  {}",
        problems.join("\n  ")
    );
}

#[test]
fn the_crate_table_lists_every_workspace_member_at_its_path() {
    let members = members();
    let rows = table();
    assert!(
        !members.is_empty() && !rows.is_empty(),
        "nothing to compare"
    );
    let mut problems = Vec::new();
    for member in &members {
        match rows.iter().filter(|row| row.name == member.name).count() {
            0 => problems.push(format!("{} ({}) has no row", member.name, member.path)),
            1 => {}
            n => problems.push(format!("{} has {n} rows", member.name)),
        }
        if let Some(row) = rows.iter().find(|row| row.name == member.name)
            && row.path != member.path
        {
            let (table, cargo) = (&row.path, &member.path);
            problems.push(format!(
                "{}: the table says {table}, the workspace {cargo}",
                row.name
            ));
        }
    }
    for row in &rows {
        if !members.iter().any(|m| m.name == row.name) {
            problems.push(format!("{} has a row and is no workspace member", row.name));
        }
    }
    report(&problems);
}

#[test]
fn the_crate_table_names_the_workspace_crates_each_crate_uses() {
    let members = members();
    let rows = table();
    let mut problems = Vec::new();
    let mut compare =
        |crate_name: &str, column: &str, table: &BTreeSet<String>, cargo: &BTreeSet<String>| {
            for name in table.difference(cargo) {
                problems.push(format!(
                    "{crate_name}, `{column}`: {name} is not in its Cargo.toml"
                ));
            }
            for name in cargo.difference(table) {
                problems.push(format!("{crate_name}, `{column}`: {name} is missing"));
            }
        };
    for member in &members {
        let row = row_of(&rows, &member.name);
        let uses = workspace_crates(&member.deps, &members);
        let tests_use = &workspace_crates(&member.dev_deps, &members) - &uses;
        compare(&member.name, "uses", &row.uses, &uses);
        compare(
            &member.name,
            "its tests also use",
            &row.tests_use,
            &tests_use,
        );
    }
    report(&problems);
}

#[test]
fn every_crate_uses_only_crates_above_it_in_the_table() {
    let rows = table();
    let mut problems = Vec::new();
    for (at, row) in rows.iter().enumerate() {
        for used in row.uses.iter().chain(&row.tests_use) {
            match rows.iter().position(|r| &r.name == used) {
                Some(above) if above < at => {}
                Some(_) => problems.push(format!("{} uses {used}, listed below it", row.name)),
                None => problems.push(format!("{} uses {used}, which has no row", row.name)),
            }
        }
    }
    report(&problems);
}

#[test]
fn the_outside_crates_the_table_names_are_dependencies() {
    let members = members();
    let rows = table();
    let mut problems = Vec::new();
    for member in &members {
        for name in &row_of(&rows, &member.name).outside {
            if !member.deps.contains(name) && !member.dev_deps.contains(name) {
                problems.push(format!("{}: {name} is not in its Cargo.toml", member.name));
            }
        }
    }
    report(&problems);
}

/// From the `Cargo.toml` files alone, whatever the table says: a client's dependencies of every
/// kind, and theirs (normal and build) in turn.
#[test]
fn no_client_crate_depends_on_chassisd() {
    let members = members();
    let by_name: BTreeMap<&str, &Member> = members.iter().map(|m| (m.name.as_str(), m)).collect();
    assert!(
        by_name.contains_key(SERVICE),
        "{SERVICE} is no workspace member"
    );
    let clients: Vec<&Member> = members
        .iter()
        .filter(|m| m.path.starts_with(CLIENTS))
        .collect();
    assert!(!clients.is_empty(), "no crate under {CLIENTS}");
    let mut problems = Vec::new();
    for client in clients {
        // Breadth first, each crate reached remembering the one it was reached from.
        let mut from: BTreeMap<&str, &str> = BTreeMap::new();
        let mut queue: VecDeque<&str> = client
            .deps
            .iter()
            .chain(&client.dev_deps)
            .map(String::as_str)
            .filter(|name| by_name.contains_key(name))
            .inspect(|name| {
                from.insert(name, client.name.as_str());
            })
            .collect();
        while let Some(name) = queue.pop_front() {
            if name == SERVICE {
                let mut chain = vec![name];
                while let Some(previous) = from.get(chain[chain.len() - 1]) {
                    chain.push(previous);
                    if *previous == client.name {
                        break;
                    }
                }
                chain.reverse();
                problems.push(chain.join(" → "));
                break;
            }
            for next in &by_name[name].deps {
                if by_name.contains_key(next.as_str()) && !from.contains_key(next.as_str()) {
                    from.insert(next.as_str(), name);
                    queue.push_back(next.as_str());
                }
            }
        }
    }
    assert!(
        problems.is_empty(),
        "a client depends on {SERVICE}:\n  {}",
        problems.join("\n  ")
    );
}
