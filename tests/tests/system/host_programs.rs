//! Every program the tests and CI's scripts execute is installed, or required, by `scripts/test`
//! before anything else runs: a machine without one fails at the start, loudly, never in a test
//! 14 minutes in.
//!
//! The list lives in `scripts/host-programs` (program, Debian package), read by `scripts/test`.
//! This test reads the code that executes programs — `Command::new("…")`, `run_in(ns, "…")`,
//! `Path::new("…")` handed to a spawn, `ip netns exec NS "…"`, Python's `subprocess` calls, Node's
//! `spawn`/`execFileSync`, and every command of the shell scripts — and fails on a program the
//! list does not name. Programs run inside the SocketCAN VM (its tests and `scripts/vm/vcan-suite`)
//! come from the VM's own userland instead: the list names them as `vm:PACKAGE`, and
//! `scripts/vm/run-in-vm` must unpack that package; so do programs run inside the package's
//! installation test's container (`scripts/package-install-tests-guest`, the maintainer scripts),
//! whose packages `scripts/package-install-tests` must name.
// Test code: helpers may unwrap and panic.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// One entry of `scripts/host-programs`.
#[derive(Debug, Clone)]
struct Entry {
    package: String,
}

/// `scripts/host-programs`: `PROGRAM PACKAGE [CHECK…]` per line, `#` comments. A program may
/// have two lines: one for this machine, one for the VM (`vm:PACKAGE`).
fn host_programs(text: &str) -> BTreeMap<String, Vec<Entry>> {
    let mut map: BTreeMap<String, Vec<Entry>> = BTreeMap::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut words = line.split_whitespace();
        let program = words.next().unwrap().to_string();
        let package = words
            .next()
            .unwrap_or_else(|| panic!("scripts/host-programs: '{line}' names no package"))
            .to_string();
        map.entry(program).or_default().push(Entry { package });
    }
    map
}

/// Every tracked file of the repository (the test must see what a fresh clone has).
fn tracked_files() -> Vec<PathBuf> {
    let out = std::process::Command::new("git")
        .arg("-C")
        .arg(root())
        .args(["ls-files", "-z"])
        .output()
        .expect("git ls-files");
    assert!(out.status.success(), "git ls-files failed");
    out.stdout
        .split(|b| *b == 0)
        .filter(|p| !p.is_empty())
        .map(|p| PathBuf::from(String::from_utf8_lossy(p).into_owned()))
        .collect()
}

/// A bare program name, or an absolute path to one in the system's directories (its base name).
fn program_name(word: &str) -> Option<String> {
    for dir in ["/usr/bin/", "/bin/", "/usr/sbin/", "/sbin/"] {
        if let Some(rest) = word.strip_prefix(dir) {
            return program_name(rest);
        }
    }
    let ok = !word.is_empty()
        && word.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && word
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '+'));
    ok.then(|| word.to_string())
}

/// The string literal starting at `text` (after optional blanks and `&`), if any.
fn literal_at(text: &str) -> Option<&str> {
    let text = text.trim_start().trim_start_matches('&');
    let rest = text.strip_prefix('"')?;
    rest.split('"').next()
}

/// Programs Rust code executes by name.
fn rust_programs(source: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut take = |literal: Option<&str>| {
        if let Some(name) = literal.and_then(program_name) {
            found.insert(name);
        }
    };
    for (i, _) in source.match_indices("Command::new(") {
        take(literal_at(&source[i + "Command::new(".len()..]));
    }
    // `run_in(ns, "nft", …)`: the program is the second argument.
    for (i, _) in source.match_indices("run_in(") {
        let args = &source[i + "run_in(".len()..];
        if let Some(comma) = args.find(',') {
            take(literal_at(&args[comma + 1..]));
        }
    }
    // `spawn_program(label, Path::new("ip"), …)`, `Tmux::start(dir, "tmux", …)`.
    // Helpers that run their first argument: a test's `Tool::spawn("candump", …)`, the
    // provenance's `output("git", &[…])`.
    for helper in ["Tool::spawn(", "output("] {
        for (i, _) in source.match_indices(helper) {
            if source[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_') {
                continue;
            }
            take(literal_at(&source[i + helper.len()..]));
        }
    }
    for pattern in ["Path::new(", "Tmux::start("] {
        for (i, _) in source.match_indices(pattern) {
            let args = &source[i + pattern.len()..];
            let literal = if pattern == "Path::new(" {
                literal_at(args)
            } else {
                args.find(',').and_then(|c| literal_at(&args[c + 1..]))
            };
            // Only what is handed to a spawn: a literal naming a file in the system's
            // directories, or a bare name beside `spawn_program`.
            let context = &source[i.saturating_sub(60)..i];
            if let Some(l) = literal
                && (pattern == "Tmux::start("
                    || l.starts_with("/usr/bin/")
                    || l.starts_with("/bin/")
                    || context.contains("spawn_program"))
            {
                take(Some(l));
            }
        }
    }
    // `["netns", "exec", ns, "python3"]` and `["--", "sh", "-c"]`: a program after exec's
    // namespace or after `--`.
    for (i, _) in source.match_indices("\"exec\",") {
        let rest = &source[i + "\"exec\",".len()..];
        if let Some(comma) = rest.find(',') {
            take(literal_at(&rest[comma + 1..]));
        }
    }
    for (i, _) in source.match_indices("\"--\",") {
        take(literal_at(&source[i + "\"--\",".len()..]));
    }
    found
}

/// Programs Python code executes: the first element of a literal argument list.
fn python_programs(source: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for call in [
        "subprocess.run(",
        "subprocess.Popen(",
        "subprocess.check_output(",
        "subprocess.check_call(",
    ] {
        for (i, _) in source.match_indices(call) {
            let args = source[i + call.len()..].trim_start();
            if let Some(list) = args.strip_prefix('[')
                && let Some(name) = literal_at(list).and_then(program_name)
            {
                found.insert(name);
            }
        }
    }
    found
}

/// Programs Node code executes by name.
fn node_programs(source: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for call in ["spawn(", "execFileSync(", "execFile(", "spawnSync("] {
        for (i, _) in source.match_indices(call) {
            if let Some(name) = literal_at(&source[i + call.len()..]).and_then(program_name) {
                found.insert(name);
            }
        }
    }
    found
}

const SHELL_BUILTINS: &[&str] = &[
    ".",
    ":",
    "[",
    "[[",
    "]]",
    "alias",
    "break",
    "builtin",
    "case",
    "cd",
    "command",
    "continue",
    "declare",
    "do",
    "done",
    "echo",
    "elif",
    "else",
    "esac",
    "eval",
    "exec",
    "exit",
    "export",
    "false",
    "fi",
    "for",
    "function",
    "getopts",
    "hash",
    "if",
    "in",
    "jobs",
    "kill",
    "let",
    "local",
    "mapfile",
    "printf",
    "pwd",
    "read",
    "readarray",
    "return",
    "select",
    "set",
    "shift",
    "shopt",
    "source",
    "test",
    "then",
    "time",
    "trap",
    "true",
    "type",
    "ulimit",
    "umask",
    "unset",
    "until",
    "wait",
    "while",
    "{",
    "}",
    "!",
];

/// Builtins after which the next word is again a command.
const BUILTIN_WRAPPERS: &[&str] = &["exec", "command", "time"];

/// Programs that run their arguments as a command (after their options).
const PROGRAM_WRAPPERS: &[&str] = &[
    "nice", "xargs", "timeout", "env", "sudo", "flock", "setsid", "unshare", "setpriv", "prlimit",
    "taskset", "chrt", "nsenter",
];

/// The code of a shell script as words, with quoted text blanked (it is data), except a
/// single-quoted argument of `bash -c`/`sh -c` (code) and `$(…)` inside double quotes.
#[derive(Debug, PartialEq)]
enum Token {
    Word(String),
    /// `;`, `&&`, `||`, `|`, `&`, `(`, `$(`, `)`, a newline: a command may start after it.
    Break(char),
}

fn shell_tokens(script: &str) -> Vec<Token> {
    let mut tokens = Vec::new();
    let mut word = String::new();
    let chars: Vec<char> = script.chars().collect();
    let mut i = 0;
    let mut heredoc: Option<String> = None;
    let flush = |word: &mut String, tokens: &mut Vec<Token>| {
        if !word.is_empty() {
            tokens.push(Token::Word(std::mem::take(word)));
        }
    };
    // Whether the last two words were `bash -c` / `sh -c`.
    let code_follows = |tokens: &Vec<Token>| {
        matches!(
            tokens.as_slice(),
            [.., Token::Word(shell), Token::Word(flag)]
                if (shell == "bash" || shell == "sh") && flag == "-c"
        )
    };
    while i < chars.len() {
        let c = chars[i];
        if let Some(end) = &heredoc {
            // Skip the heredoc's body (data) up to its terminator line.
            let line_end = chars[i..]
                .iter()
                .position(|&c| c == '\n')
                .map_or(chars.len(), |p| i + p);
            let line: String = chars[i..line_end].iter().collect();
            if line.trim() == end {
                heredoc = None;
            }
            i = line_end + 1;
            continue;
        }
        match c {
            '#' if word.is_empty() => {
                while i < chars.len() && chars[i] != '\n' {
                    i += 1;
                }
                continue;
            }
            '\\' if chars.get(i + 1) == Some(&'\n') => {
                flush(&mut word, &mut tokens);
                i += 2;
                continue;
            }
            '\'' => {
                let end = chars[i + 1..]
                    .iter()
                    .position(|&c| c == '\'')
                    .map_or(chars.len(), |p| i + 1 + p);
                let inner: String = chars[i + 1..end.min(chars.len())].iter().collect();
                if word.is_empty() && code_follows(&tokens) {
                    // The code, then a word in its place: what follows are arguments.
                    tokens.push(Token::Break(' '));
                    tokens.extend(shell_tokens(&inner));
                    tokens.push(Token::Break(' '));
                    tokens.push(Token::Word("'code'".into()));
                } else {
                    word.push_str("'q'");
                }
                i = end + 1;
                continue;
            }
            '"' => {
                // Blank the text; keep command substitutions inside as code.
                let mut j = i + 1;
                while j < chars.len() && chars[j] != '"' {
                    if chars[j] == '\\' {
                        j += 2;
                        continue;
                    }
                    if chars[j] == '$' && chars.get(j + 1) == Some(&'(') {
                        let (inner, end) = balanced(&chars, j + 2);
                        if inner.starts_with('(') {
                            // `$((…))`: arithmetic, not a command.
                            j = end + 1;
                            continue;
                        }
                        tokens.push(Token::Break(' '));
                        tokens.extend(shell_tokens(&inner));
                        tokens.push(Token::Break(' '));
                        j = end + 1;
                        continue;
                    }
                    j += 1;
                }
                word.push_str("\"q\"");
                i = j + 1;
                continue;
            }
            '$' if chars.get(i + 1) == Some(&'(') && chars.get(i + 2) == Some(&'(') => {
                // `$((…))`: arithmetic, a word.
                let (_, end) = balanced(&chars, i + 2);
                word.push_str("$arith");
                i = end + 1;
                continue;
            }
            '(' if word.ends_with('=') => {
                // `NAME=(…)`: an array of words, data.
                let (_, end) = balanced(&chars, i + 1);
                word.push_str("(array)");
                i = end + 1;
                continue;
            }
            '$' if chars.get(i + 1) == Some(&'(') => {
                flush(&mut word, &mut tokens);
                let (inner, end) = balanced(&chars, i + 2);
                tokens.push(Token::Break(' '));
                tokens.extend(shell_tokens(&inner));
                tokens.push(Token::Break(' '));
                word.push_str("$sub");
                i = end + 1;
                continue;
            }
            '$' if chars.get(i + 1) == Some(&'{') => {
                let end = chars[i..]
                    .iter()
                    .position(|&c| c == '}')
                    .map_or(chars.len(), |p| i + p);
                word.push_str("$var");
                i = end + 1;
                continue;
            }
            '<' if chars.get(i + 1) == Some(&'<') && chars.get(i + 2) == Some(&'<') => {
                // A here-string (`<<<"$text"`): its word is data, the line goes on.
                flush(&mut word, &mut tokens);
                i += 3;
                continue;
            }
            '<' if chars.get(i + 1) == Some(&'<') && chars.get(i + 2) != Some(&'<') => {
                // A heredoc: its terminator is the next word, unquoted.
                let mut j = i + 2;
                while j < chars.len() && matches!(chars[j], '-' | ' ') {
                    j += 1;
                }
                let end: String = chars[j..]
                    .iter()
                    .take_while(|c| !c.is_whitespace())
                    .filter(|c| !matches!(c, '\'' | '"'))
                    .collect();
                heredoc = Some(end);
                // The rest of this line is still code.
                let line_end = chars[j..]
                    .iter()
                    .position(|&c| c == '\n')
                    .map_or(chars.len(), |p| j + p);
                let rest: String = chars[j..line_end].iter().collect();
                let rest = rest.split_once(char::is_whitespace).map_or("", |r| r.1);
                flush(&mut word, &mut tokens);
                tokens.extend(shell_tokens(rest));
                tokens.push(Token::Break(' '));
                i = line_end + 1;
                continue;
            }
            ';' | '|' | '&' | '(' | ')' | '\n' => {
                flush(&mut word, &mut tokens);
                tokens.push(Token::Break(c));
            }
            ' ' | '\t' => flush(&mut word, &mut tokens),
            _ => word.push(c),
        }
        i += 1;
    }
    flush(&mut word, &mut tokens);
    tokens
}

/// The text from `start` to its matching `)`, and the index of that `)`.
fn balanced(chars: &[char], start: usize) -> (String, usize) {
    let mut depth = 1;
    let mut j = start;
    let mut quote: Option<char> = None;
    while j < chars.len() {
        let c = chars[j];
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None => match c {
                '\'' | '"' => quote = Some(c),
                '(' => depth += 1,
                ')' => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                _ => {}
            },
        }
        j += 1;
    }
    (chars[start..j.min(chars.len())].iter().collect(), j)
}

/// The programs a shell script runs: every word in a command's place that is not a builtin, a
/// keyword, a function of the script, a variable, an assignment or a path.
fn shell_programs(script: &str) -> BTreeSet<String> {
    let tokens = shell_tokens(script);
    // Functions the script defines (`name() {`): not programs.
    let functions: BTreeSet<String> = script
        .lines()
        .filter_map(|line| {
            let (name, rest) = line.trim_start().split_once("()")?;
            let body = rest.trim_start();
            (body.starts_with('{') || body.starts_with('(')).then(|| name.trim().to_string())
        })
        .collect();
    let mut found = BTreeSet::new();
    let mut at_command = true;
    // Inside `case … in`: the patterns (`--pack)`, `v1|v2)`) are not commands.
    let mut cases = 0usize;
    let mut in_pattern = false;
    let mut awaiting_in = false;
    let mut previous_semicolon = false;
    let mut previous_word = String::new();
    for token in &tokens {
        let semicolon = matches!(token, Token::Break(';'));
        match token {
            Token::Word(w) if cases > 0 && w == "esac" => {
                cases -= 1;
                in_pattern = false;
            }
            Token::Word(w) if awaiting_in => {
                // `case WORD in`: the patterns follow `in`.
                if w == "in" {
                    awaiting_in = false;
                    in_pattern = true;
                }
            }
            Token::Word(_) if in_pattern => {}
            Token::Break(')') if in_pattern => {
                in_pattern = false;
                at_command = true;
            }
            _ if in_pattern => {}
            Token::Break(_) => {
                at_command = true;
                if semicolon && previous_semicolon && cases > 0 {
                    in_pattern = true;
                }
            }
            Token::Word(w) if w == "case" && at_command => {
                cases += 1;
                awaiting_in = true;
                at_command = false;
            }
            Token::Word(word) if at_command => {
                let w = word.as_str();
                if w == "-v" || w == "-V" {
                    // `command -v NAME` asks whether NAME exists; it runs nothing.
                    at_command = previous_word != "command";
                    previous_word = w.to_string();
                    continue;
                }
                previous_word = w.to_string();
                if w.contains('=') && !w.starts_with('=') || w.starts_with('-') {
                    // An assignment before the command, or an option of a wrapper.
                    continue;
                }
                if BUILTIN_WRAPPERS.contains(&w) {
                    continue;
                }
                if PROGRAM_WRAPPERS.contains(&w) {
                    found.insert(w.to_string());
                    continue;
                }
                if matches!(
                    w,
                    "if" | "then" | "else" | "elif" | "do" | "while" | "until" | "!"
                ) || w == "{"
                {
                    continue;
                }
                at_command = false;
                if w.chars().all(|c| c.is_ascii_digit()) {
                    // A number after a wrapper (`timeout 20`): the command follows.
                    at_command = true;
                    continue;
                }
                if SHELL_BUILTINS.contains(&w) || functions.contains(w) {
                    continue;
                }
                if let Some(name) = program_name(w) {
                    found.insert(name);
                }
            }
            Token::Word(_) => {}
        }
        previous_semicolon = semicolon;
    }
    found
}

/// The workspace's own binaries (built by cargo before the tests run).
fn workspace_binaries() -> BTreeSet<String> {
    let mut names: BTreeSet<String> = BTreeSet::new();
    for manifest in tracked_files()
        .into_iter()
        .filter(|p| p.file_name().is_some_and(|n| n == "Cargo.toml"))
    {
        let text = std::fs::read_to_string(root().join(&manifest)).unwrap();
        let dir = root().join(manifest.parent().unwrap());
        let package = text
            .lines()
            .skip_while(|l| l.trim() != "[package]")
            .find_map(|l| l.trim().strip_prefix("name = "))
            .map(|n| n.trim_matches('"').to_string());
        if let Some(package) = &package
            && dir.join("src/main.rs").exists()
        {
            names.insert(package.clone());
        }
        let mut in_bin = false;
        for line in text.lines() {
            let line = line.trim();
            if line.starts_with('[') {
                in_bin = line == "[[bin]]";
            } else if in_bin && let Some(name) = line.strip_prefix("name = ") {
                names.insert(name.trim_matches('"').to_string());
            }
        }
        if dir.join("src/bin").is_dir() {
            for entry in std::fs::read_dir(dir.join("src/bin")).unwrap() {
                let path = entry.unwrap().path();
                if let Some(stem) = path.file_stem() {
                    names.insert(stem.to_string_lossy().into_owned());
                }
            }
        }
    }
    names
}

/// The script that makes the system `path` runs in, when that is not this machine: the SocketCAN
/// VM (its PATH is the VM's busybox and can-utils), or the container of the package's installation
/// test (its Debian system; the package's maintainer scripts run there too).
fn guest_of(path: &Path) -> Option<&'static str> {
    if path.file_stem().is_some_and(|s| s == "vcan") || path == Path::new("scripts/vm/vcan-suite") {
        Some("scripts/vm/run-in-vm")
    } else if path == Path::new("scripts/package-install-tests-guest")
        || path.starts_with("deploy/debian")
    {
        Some("scripts/package-install-tests")
    } else {
        None
    }
}

/// Every program executed by the repository's code, with the files that execute it.
fn executed_programs() -> BTreeMap<String, BTreeSet<(PathBuf, Option<&'static str>)>> {
    let mut all: BTreeMap<String, BTreeSet<(PathBuf, Option<&'static str>)>> = BTreeMap::new();
    for path in tracked_files() {
        if path == Path::new("tests/tests/system/host_programs.rs") {
            // This file's examples are data.
            continue;
        }
        let full = root().join(&path);
        let name = path.to_string_lossy();
        let found = if name.ends_with(".rs") {
            rust_programs(&std::fs::read_to_string(&full).unwrap())
        } else if name.ends_with(".py") {
            python_programs(&std::fs::read_to_string(&full).unwrap())
        } else if name.ends_with(".cjs") || name.ends_with(".js") || name.ends_with(".mjs") {
            node_programs(&std::fs::read_to_string(&full).unwrap())
        } else if is_shell_script(&full) {
            let text = std::fs::read_to_string(&full).unwrap();
            let mut found = shell_programs(&text);
            // A virtualenv (`"$PYTHON" -m venv`) needs python3 and its venv module.
            if text.contains("-m venv") {
                found.extend(["python3".to_string(), "venv".to_string()]);
            }
            found
        } else {
            continue;
        };
        for program in found {
            all.entry(program)
                .or_default()
                .insert((path.clone(), guest_of(&path)));
        }
    }
    all
}

fn is_shell_script(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    let first = text.lines().next().unwrap_or("");
    first.starts_with("#!") && (first.ends_with("bash") || first.ends_with("/sh"))
}

#[test]
fn scripts_test_installs_or_requires_every_program_the_tests_execute() {
    let list =
        host_programs(&std::fs::read_to_string(root().join("scripts/host-programs")).unwrap());
    let ours = workspace_binaries();
    assert!(ours.contains("chassisd"), "workspace binaries: {ours:?}");
    let executed = executed_programs();
    // The scanner itself sees what it must: a few programs known to be executed.
    for known in ["ip", "nft", "tc", "unshare", "tmux", "node", "npm", "cargo"] {
        assert!(
            executed.contains_key(known),
            "the scan missed {known}: {executed:?}"
        );
    }
    let mut missing = Vec::new();
    for (program, files) in &executed {
        if ours.contains(program) || program == "cargo" {
            continue;
        }
        for (file, guest) in files {
            let entries = list.get(program).map_or(&[][..], Vec::as_slice);
            let ok = entries
                .iter()
                .any(|e| match (e.package.strip_prefix("vm:"), guest) {
                    (None, None) => true,
                    (Some(package), Some(maker)) => std::fs::read_to_string(root().join(maker))
                        .unwrap()
                        .contains(package),
                    _ => false,
                });
            if !ok {
                missing.push(format!(
                    "{program} (executed by {}{})",
                    file.display(),
                    guest.map_or(String::new(), |maker| format!(", inside {maker}'s guest"))
                ));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "scripts/host-programs does not name these programs (add `PROGRAM PACKAGE`, or \
         `PROGRAM vm:PACKAGE` for the VM's userland):\n  {}",
        missing.join("\n  ")
    );
}

#[test]
fn scripts_test_requires_the_list_before_anything_else() {
    let script = std::fs::read_to_string(root().join("scripts/test")).unwrap();
    let require = script
        .find("scripts/require-programs")
        .expect("scripts/test does not run scripts/require-programs");
    for later in ["cargo fmt", "cargo clippy", "cargo build", "cargo test"] {
        let at = script
            .find(later)
            .unwrap_or_else(|| panic!("no {later} in scripts/test"));
        assert!(
            require < at,
            "scripts/test runs {later} before checking its programs"
        );
    }
}

#[test]
fn the_shell_scan_finds_commands_and_skips_data() {
    let script = r#"#!/usr/bin/env bash
# a comment naming curl
die() { printf 'x: %s\n' "$*" >&2; exit 1; }
VAR=$(awk '{ print "wget" }' file | sort -u)
if ! command -v nft >/dev/null; then die "no nft: apt-get install nftables"; fi
unshare --net -- bash -c '
    ip link set lo up
    exec pytest -q
' name
echo "$(readlink -f x) $((n + 1))" && timeout 5 socat - x
ARGS=(gzip -9
    -c file)
count=$((count + 1))
cat <<EOF
gcc would be data here
EOF
for x in a b; do cp "$x" /tmp; done
grep -qxF "$line" <<<"$text" || wc -l <<<"$text"
lintian "$deb"
"#;
    let found = shell_programs(script);
    let want: BTreeSet<String> = [
        "awk", "bash", "cat", "cp", "grep", "ip", "lintian", "pytest", "readlink", "socat", "sort",
        "timeout", "unshare", "wc",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    assert_eq!(found, want);
}

#[test]
fn the_rust_scan_finds_each_form_of_execution() {
    let source = r#"
        Command::new("ip").args(["netns", "add"]);
        let out = run_in(ns, "nft", &[rule]);
        env.spawn_program("x", Path::new("/usr/bin/prlimit"), &args, &[]);
        Command::new("ip").args(["netns", "exec", &ns, "tcpdump"]);
        Command::new("unshare").args(["--net", "--", "sh", "-c"]);
        let p = Path::new("/tmp/file");
        Command::new(bin("chassisd"));
    "#;
    let found: Vec<String> = rust_programs(source).into_iter().collect();
    assert_eq!(found, ["ip", "nft", "prlimit", "sh", "tcpdump", "unshare"]);
}
