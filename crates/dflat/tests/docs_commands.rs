//! Every command the docs show runs as shown, at least as far as parsing:
//! each `dflat …` command in README.md and docs/*.md (fenced code blocks
//! and inline code, also as `cargo run … -- SUB …`) names a subcommand
//! whose `--help` parses, and every `--flag` it names appears in that
//! subcommand's help; each `cargo test|bench|run -p PKG --test|--bench|
//! --example NAME` names a workspace package and a target it has, and a
//! `--lib FILTER` names a module or function the package has.
//!
//! The pages and every subcommand's `--help` name no issue numbers or
//! work sessions (the docs speak of the product as it is).
//!
//! The extractor and the checker are unit-tested below on made-up commands
//! (a made-up flag, subcommand, package and test target each fail).

#![cfg(all(feature = "sitl", feature = "lab", feature = "tuning"))]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// One command as the docs show it.
#[derive(Debug, Clone, PartialEq)]
struct Shown {
    /// `page:line`.
    at: String,
    /// The command's words, from `dflat` or `cargo` on, up to a shell
    /// separator (`|`, `>`, `&&`, `;`, `#`) or the end of the line / span.
    words: Vec<String>,
}

/// The shell words that end a command.
fn ends_command(word: &str) -> bool {
    matches!(word, "|" | ">" | ">>" | "&&" | "||" | ";" | "\\" | "2>&1")
        || word.starts_with('#')
        || word.starts_with("2>")
}

/// A word as a command sees it: without the brackets of an optional part
/// (`[--out F]`), quotes and a trailing punctuation of prose.
fn clean(word: &str) -> String {
    word.trim_matches(|c| matches!(c, '[' | ']' | '`' | '"' | '\'' | '(' | ')'))
        .trim_end_matches([',', ':', '.'])
        .to_owned()
}

/// Whether `word` (as written, before [`clean`]) is the `dflat` binary,
/// also as a built one (`target/release/dflat`, `./dflat`); not `dflat:`
/// (a STATUSTEXT's prefix) nor `crates/dflat` (a directory).
fn is_dflat(word: &str) -> bool {
    let word = word.trim_matches(|c| matches!(c, '[' | ']' | '`' | '"' | '\'' | '('));
    word == "dflat"
        || (word.ends_with("/dflat") && (word.contains("target/") || word.starts_with("./")))
}

/// The commands in one candidate text (a code line or an inline span). A
/// command starts the text or, with `anywhere` (a code line), follows a
/// shell separator (`cd /tmp && sudo -u dflat dflat daemon …`); before it
/// may stand `$`, a box-drawing `│`, `VAR=value` words and `sudo -u USER`.
/// Words elsewhere (`the dflat binary`, `dflat: setpoint refused`) are prose.
fn commands_in(text: &str, anywhere: bool) -> Vec<Vec<String>> {
    let raw: Vec<&str> = text.split_whitespace().collect();
    let mut found = Vec::new();
    let mut at_start = true;
    let mut i = 0;
    while i < raw.len() {
        let w = clean(raw[i]);
        let next = raw.get(i + 1).map(|n| clean(n)).unwrap_or_default();
        let starts = (is_dflat(raw[i])
            && !is_dflat(&next)
            && next.starts_with(|c: char| c.is_ascii_lowercase()))
            || (w == "cargo" && matches!(next.as_str(), "run" | "test" | "bench"));
        if at_start && starts {
            let mut words = vec![w];
            let mut consumed = 1;
            for r in &raw[i + 1..] {
                if ends_command(r) {
                    break;
                }
                consumed += 1;
                let c = clean(r);
                if !c.is_empty() {
                    words.push(c);
                }
            }
            i += consumed;
            found.push(words);
            if !anywhere {
                break;
            }
            at_start = false;
            continue;
        }
        let preamble = matches!(w.as_str(), "$" | "│" | "sudo" | "-u")
            || (w.contains('=') && !w.starts_with('-'))
            || (i > 0 && clean(raw[i - 1]) == "-u");
        if ends_command(raw[i]) && anywhere {
            at_start = true;
        } else if !preamble {
            at_start = false;
            if !anywhere {
                break;
            }
        }
        i += 1;
    }
    found
}

/// The commands shown in one page: in fenced code blocks (each line) and
/// in inline code spans (which may run over a line break).
fn extract(page: &str, text: &str) -> Vec<Shown> {
    let mut shown = Vec::new();
    let mut fenced = false;
    // An inline span open across lines: its start line and text so far.
    let mut span: Option<(usize, String)> = None;
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            span = None;
            continue;
        }
        if fenced {
            for words in commands_in(line, true) {
                shown.push(Shown {
                    at: format!("{page}:{line_no}"),
                    words,
                });
            }
            continue;
        }
        if line.trim().is_empty() {
            span = None;
        }
        for c in line.chars() {
            if c == '`' {
                match span.take() {
                    Some((start, code)) => {
                        for words in commands_in(&code, false) {
                            shown.push(Shown {
                                at: format!("{page}:{start}"),
                                words,
                            });
                        }
                    }
                    None => span = Some((line_no, String::new())),
                }
            } else if let Some((_, code)) = &mut span {
                code.push(c);
            }
        }
        if let Some((_, code)) = &mut span {
            code.push(' ');
        }
    }
    shown
}

/// A subcommand's help, or `None` when `dflat PATH --help` fails.
type Help<'a> = dyn FnMut(&[String]) -> Option<String> + 'a;

/// The subcommands a help text lists (its `Commands:` section).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next().map(str::to_owned))
        .collect()
}

/// The flags a help text lists: `--name` words (up to `=`, `,`, `[` or `<`).
fn flags(help: &str) -> Vec<String> {
    help.split_whitespace()
        .filter(|w| w.starts_with("--") && w.len() > 2)
        .map(|w| {
            w.split(['=', ',', '[', '<', ')'])
                .next()
                .unwrap_or(w)
                .to_owned()
        })
        .collect()
}

/// Checks one `dflat` command (its words after `dflat`): the subcommand
/// path parses with `--help`, every flag is in that help. A subcommand
/// word may list alternatives, `noise-sweep|paths`.
fn check_dflat(at: &str, args: &[String], help: &mut Help<'_>) -> Vec<String> {
    let shown = format!("dflat {}", args.join(" "));
    let Some(top) = help(&[]) else {
        return vec![format!("{at}: `dflat --help` fails")];
    };
    let mut problems = Vec::new();
    // Every alternative path: [[experiment, paths], [experiment, phase], …].
    let mut paths: Vec<(Vec<String>, String)> = vec![(Vec::new(), top)];
    let mut rest = args.iter().peekable();
    while let Some(word) = rest.peek() {
        // `dflat experiment …`: any of them.
        if word.starts_with('-') || matches!(word.as_str(), "…" | "...") {
            break;
        }
        let listed = subcommands(&paths[0].1);
        if listed.is_empty() {
            break;
        }
        let mut next = Vec::new();
        for alt in word.split('|').filter(|a| !a.is_empty()) {
            if !listed.iter().any(|l| l == alt) {
                problems.push(format!(
                    "{at}: `{shown}`: `{alt}` is not a subcommand of `dflat {}`",
                    paths[0].0.join(" ")
                ));
                continue;
            }
            for (path, _) in &paths {
                let mut p = path.clone();
                p.push(alt.to_owned());
                match help(&p) {
                    Some(h) => next.push((p, h)),
                    None => problems.push(format!(
                        "{at}: `{shown}`: `dflat {} --help` fails",
                        p.join(" ")
                    )),
                }
            }
        }
        if next.is_empty() {
            return problems;
        }
        paths = next;
        rest.next();
    }
    if paths[0].0.is_empty() {
        problems.push(format!("{at}: `{shown}`: no subcommand"));
        return problems;
    }
    for word in rest {
        let Some(flag) = word.strip_prefix("--").filter(|f| !f.is_empty()) else {
            continue;
        };
        let flag = format!("--{}", flag.split('=').next().unwrap_or(flag));
        for (path, text) in &paths {
            if !flags(text).contains(&flag) {
                problems.push(format!(
                    "{at}: `{shown}`: `dflat {}` has no `{flag}`",
                    path.join(" ")
                ));
            }
        }
    }
    problems
}

/// A workspace package: its name and directory.
#[derive(Debug, Clone)]
struct Package {
    name: String,
    dir: PathBuf,
}

/// What the checks of `cargo` commands need to know of the workspace.
trait Workspace {
    fn package(&self, name: &str) -> Option<&Package>;
    fn packages(&self) -> &[Package];
    /// Whether `pkg` has a target of `kind` (`test`, `bench`, `example`).
    fn has_target(&self, pkg: &Package, kind: &str, name: &str) -> bool;
    /// Whether `pkg`'s library has a module or function named `name`.
    fn has_item(&self, pkg: &Package, name: &str) -> bool;
}

/// Checks one `cargo test|bench|run` command; a `cargo run` of the `dflat`
/// binary checks its arguments after `--` as a `dflat` command.
fn check_cargo(at: &str, words: &[String], ws: &dyn Workspace, help: &mut Help<'_>) -> Vec<String> {
    let shown = words.join(" ");
    let (cargo_args, bin_args) = match words.iter().position(|w| w == "--") {
        Some(i) => (&words[2..i], Some(&words[i + 1..])),
        None => (&words[2..], None),
    };
    let mut problems = Vec::new();
    let mut pkgs: Vec<&Package> = Vec::new();
    let mut named = false;
    let mut workspace = false;
    let mut targets: Vec<(&str, &str)> = Vec::new();
    let mut lib = false;
    let mut filter: Option<&str> = None;
    let mut other_binary = false;
    let mut it = cargo_args.iter();
    while let Some(w) = it.next() {
        match w.as_str() {
            "-p" | "--package" => match it.next().inspect(|_| named = true) {
                Some(name) => match ws.package(name) {
                    Some(p) => pkgs.push(p),
                    None => problems.push(format!("{at}: `{shown}`: no package `{name}`")),
                },
                None => problems.push(format!("{at}: `{shown}`: `-p` without a package")),
            },
            "--workspace" | "--all" => workspace = true,
            "--test" | "--bench" | "--example" | "--bin" => {
                if w != "--test" {
                    other_binary = true;
                }
                if let Some(name) = it.next() {
                    targets.push((w.trim_start_matches("--"), name.as_str()));
                }
            }
            "--lib" => lib = true,
            "--features" | "-F" | "--target-dir" | "-j" | "--jobs" | "--profile" => {
                it.next();
            }
            s if !s.starts_with('-') && filter.is_none() => filter = Some(s),
            _ => {}
        }
    }
    if !named && !workspace {
        pkgs.extend(ws.package("dflat"));
    }
    let scope: Vec<&Package> = if workspace {
        ws.packages().iter().collect()
    } else {
        pkgs.clone()
    };
    for (kind, name) in &targets {
        if *kind == "bin" || scope.is_empty() {
            continue;
        }
        if !scope.iter().any(|p| ws.has_target(p, kind, name)) {
            let names: Vec<&str> = scope.iter().map(|p| p.name.as_str()).collect();
            problems.push(format!(
                "{at}: `{shown}`: no {kind} target `{name}` in {}",
                names.join(", ")
            ));
        }
    }
    if let (true, false, Some(f)) = (lib, scope.is_empty(), filter) {
        let item = f.rsplit("::").next().unwrap_or(f);
        if !scope.iter().any(|p| ws.has_item(p, item)) {
            problems.push(format!(
                "{at}: `{shown}`: no module or function `{item}` in the library"
            ));
        }
    }
    let runs_dflat =
        words[1] == "run" && !other_binary && !workspace && pkgs.iter().all(|p| p.name == "dflat");
    if let (true, Some(args)) = (runs_dflat, bin_args) {
        problems.extend(check_dflat(at, args, help));
    }
    problems
}

/// Every problem of the commands shown.
fn check(shown: &[Shown], ws: &dyn Workspace, help: &mut Help<'_>) -> Vec<String> {
    let mut problems = Vec::new();
    for s in shown {
        if s.words[0] == "dflat" || s.words[0].ends_with("/dflat") {
            problems.extend(check_dflat(&s.at, &s.words[1..], help));
        } else {
            problems.extend(check_cargo(&s.at, &s.words, ws, help));
        }
    }
    problems
}

// ---- the real workspace and binary ----------------------------------------

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("crates/dflat is two below the root")
        .to_path_buf()
}

/// The workspace as its manifests and files say.
struct Tree {
    packages: Vec<Package>,
}

impl Tree {
    fn read(root: &Path) -> Self {
        let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml");
        let members = manifest
            .split("members = [")
            .nth(1)
            .and_then(|m| m.split(']').next())
            .expect("workspace members");
        let packages = members
            .split(',')
            .map(|m| m.trim().trim_matches('"'))
            .filter(|m| !m.is_empty())
            .map(|m| {
                let dir = root.join(m);
                let text =
                    std::fs::read_to_string(dir.join("Cargo.toml")).expect("member manifest");
                let name = text
                    .lines()
                    .find_map(|l| l.strip_prefix("name = "))
                    .expect("package name")
                    .trim_matches('"')
                    .to_owned();
                Package { name, dir }
            })
            .collect();
        Self { packages }
    }
}

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

impl Workspace for Tree {
    fn package(&self, name: &str) -> Option<&Package> {
        self.packages.iter().find(|p| p.name == name)
    }

    fn packages(&self) -> &[Package] {
        &self.packages
    }

    fn has_target(&self, pkg: &Package, kind: &str, name: &str) -> bool {
        let dir = match kind {
            "test" => "tests",
            "bench" => "benches",
            _ => "examples",
        };
        let manifest = std::fs::read_to_string(pkg.dir.join("Cargo.toml")).unwrap_or_default();
        pkg.dir.join(dir).join(format!("{name}.rs")).exists()
            || pkg.dir.join(dir).join(name).join("main.rs").exists()
            || manifest.contains(&format!("[[{kind}]]\nname = \"{name}\""))
    }

    fn has_item(&self, pkg: &Package, name: &str) -> bool {
        let mut files = Vec::new();
        rust_files(&pkg.dir.join("src"), &mut files);
        files.iter().any(|f| {
            f.file_stem().is_some_and(|s| s == name)
                || std::fs::read_to_string(f).is_ok_and(|t| {
                    t.contains(&format!("mod {name}")) || t.contains(&format!("fn {name}"))
                })
        })
    }
}

/// README.md and docs/*.md.
fn pages(root: &Path) -> Vec<PathBuf> {
    let mut pages: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    pages.insert(0, root.join("README.md"));
    pages
}

/// Commands the docs already show for work that is being written beside
/// them (the lab's preview study). Each must fail to parse: once it
/// parses, the test fails until it is removed from here.
const PENDING: &[&str] = &[];

/// `dflat PATH --help` of the built binary, cached.
fn binary_help() -> impl FnMut(&[String]) -> Option<String> {
    let mut cache: HashMap<Vec<String>, Option<String>> = HashMap::new();
    move |path: &[String]| {
        cache
            .entry(path.to_vec())
            .or_insert_with(|| {
                let out = Command::new(env!("CARGO_BIN_EXE_dflat"))
                    .args(path)
                    .arg("--help")
                    .output()
                    .expect("run dflat");
                out.status
                    .success()
                    .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
            })
            .clone()
    }
}

#[test]
fn every_command_the_docs_show_parses() {
    let root = root();
    let tree = Tree::read(&root);
    let mut shown = Vec::new();
    for page in pages(&root) {
        let text = std::fs::read_to_string(&page).expect("page");
        let name = page
            .strip_prefix(&root)
            .unwrap_or(&page)
            .display()
            .to_string();
        shown.extend(extract(&name, &text));
    }
    let dflat = shown.iter().filter(|s| s.words[0] != "cargo").count();
    assert!(dflat >= 20, "only {dflat} dflat commands found: {shown:#?}");
    let mut help = binary_help();
    let mut problems = check(&shown, &tree, &mut help);
    // A pending command must fail (else it has landed: remove it here).
    for pending in PENDING {
        let before = problems.len();
        problems.retain(|p| !p.contains(&format!("`{pending}`")));
        assert!(
            problems.len() < before,
            "`{pending}` parses now (or the docs no longer show it): remove it from PENDING"
        );
    }
    assert!(
        problems.is_empty(),
        "{} of {} commands shown in the docs do not parse:\n{}",
        problems.len(),
        shown.len(),
        problems.join("\n")
    );
}

#[test]
fn the_binary_refuses_a_made_up_flag() {
    // What the checker stands for: a flag not in the help is not accepted.
    let out = Command::new(env!("CARGO_BIN_EXE_dflat"))
        .args(["demo", "--made-up-flag"])
        .output()
        .expect("run dflat");
    assert!(!out.status.success());
    let mut help = binary_help();
    let demo = help(&["demo".to_owned()]).expect("demo --help");
    assert!(!flags(&demo).contains(&"--made-up-flag".to_owned()));
    assert!(flags(&demo).contains(&"--stream".to_owned()));
}

// ---- the extractor and the checker on made-up commands ---------------------

/// A made-up `dflat`: `demo [--speed] [--out]`, `experiment {paths, phase}
/// [--out]`, `daemon --config`.
fn fake_help(path: &[String]) -> Option<String> {
    let p: Vec<&str> = path.iter().map(String::as_str).collect();
    Some(
        match p.as_slice() {
            [] => "Usage: dflat <COMMAND>\n\nCommands:\n  demo  Fly\n  experiment  Study\n  daemon  Run\n  help  Print\n\nOptions:\n  -h, --help  Print help\n",
            ["demo"] => "Usage: dflat demo [OPTIONS]\n\nOptions:\n      --speed <SPEED>  m/s\n      --out <OUT>  dir\n  -h, --help\n",
            ["experiment"] => "Usage: dflat experiment <COMMAND>\n\nCommands:\n  paths  L\n  phase  P\n\nOptions:\n  -h, --help\n",
            ["experiment", "paths"] | ["experiment", "phase"] => "Usage: dflat experiment paths [OPTIONS]\n\nOptions:\n      --out <OUT>\n      --trials=<N>\n",
            ["daemon"] => "Usage: dflat daemon --config <CONFIG>\n\nOptions:\n      --config <CONFIG>\n",
            _ => return None,
        }
        .to_owned(),
    )
}

struct FakeWs(Vec<Package>);

impl Workspace for FakeWs {
    fn package(&self, name: &str) -> Option<&Package> {
        self.0.iter().find(|p| p.name == name)
    }
    fn packages(&self) -> &[Package] {
        &self.0
    }
    fn has_target(&self, pkg: &Package, kind: &str, name: &str) -> bool {
        pkg.name == "dflat-e2e" && kind == "test" && name == "e2e_demo"
    }
    fn has_item(&self, pkg: &Package, name: &str) -> bool {
        pkg.name == "dflat-tuning" && name == "review_tests"
    }
}

fn fake_ws() -> FakeWs {
    let p = |n: &str| Package {
        name: n.to_owned(),
        dir: PathBuf::from(n),
    };
    FakeWs(vec![p("dflat"), p("dflat-e2e"), p("dflat-tuning")])
}

fn problems_of(page: &str) -> Vec<String> {
    let shown = extract("page.md", page);
    check(&shown, &fake_ws(), &mut fake_help)
}

#[test]
fn the_extractor_finds_commands_in_blocks_and_inline_code() {
    let page = "Run `dflat demo --speed 5` or\n`cargo run --release -- demo\n--out x` and `dflat-lab` (a crate).\n\n```sh\n$ dflat daemon --config a.toml  # comment --nope\ncd /tmp && sudo -u dflat dflat demo | head --lines 1\n```\n";
    let words: Vec<String> = extract("p.md", page)
        .iter()
        .map(|s| format!("{} {}", s.at, s.words.join(" ")))
        .collect();
    assert_eq!(
        words,
        [
            "p.md:1 dflat demo --speed 5",
            "p.md:2 cargo run --release -- demo --out x",
            "p.md:6 dflat daemon --config a.toml",
            "p.md:7 dflat demo",
        ]
    );
}

#[test]
fn a_made_up_flag_fails() {
    assert!(problems_of("`dflat demo --speed 5 --out o`").is_empty());
    let p = problems_of("`dflat demo --speed 5 --made-up 3`");
    assert_eq!(p.len(), 1, "{p:?}");
    assert!(p[0].contains("has no `--made-up`"), "{p:?}");
    // In a block, in a `cargo run`, behind brackets and with `=`.
    assert_eq!(problems_of("```\ndflat demo [--nope]\n```\n").len(), 1);
    assert_eq!(
        problems_of("`cargo run --release -- demo --nope=1`").len(),
        1
    );
    assert!(problems_of("`dflat experiment paths --trials=3`").is_empty());
}

#[test]
fn a_made_up_subcommand_fails() {
    assert_eq!(problems_of("`dflat learn`").len(), 1);
    assert_eq!(problems_of("`dflat experiment sweep`").len(), 1);
    // Alternatives are each checked, and a flag against each.
    assert!(problems_of("`dflat experiment paths|phase [--out D]`").is_empty());
    assert_eq!(problems_of("`dflat experiment paths|nope`").len(), 1);
    // Prose that merely names the daemon is a command without flags.
    assert!(problems_of("```\n  │ dflat daemon (sys 1, comp 191) │\n```\n").is_empty());
}

#[test]
fn a_made_up_package_or_target_fails() {
    assert!(problems_of("`cargo test -p dflat-e2e --test e2e_demo`").is_empty());
    assert!(problems_of("`cargo test --workspace --test e2e_demo -- --nocapture`").is_empty());
    assert_eq!(
        problems_of("`cargo test -p dflat-daemon --test e2e_demo`").len(),
        1
    );
    assert_eq!(
        problems_of("`cargo test -p dflat --test e2e_demo`").len(),
        1
    );
    assert_eq!(
        problems_of("`cargo test -p dflat --lib tuning::review_tests`").len(),
        1
    );
    assert!(problems_of("`cargo test -p dflat-tuning --lib review_tests`").is_empty());
    // Another binary's arguments are not dflat's.
    assert!(problems_of("`cargo run -p dflat-tuning --bin other -- --any`").is_empty());
}

/// The words that tie a text to the project's history instead of the
/// product: an issue number, a work session, what was removed.
fn history_words(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    let mut found = Vec::new();
    for (i, _) in lower.match_indices("issue") {
        let rest = &lower[i + 5..];
        let rest = rest.strip_prefix(['-', ' ', '#']).unwrap_or("");
        if rest.starts_with(|c: char| c.is_ascii_digit()) {
            found.push(lower[i..(i + 8).min(lower.len())].to_owned());
        }
    }
    for phrase in ["this session", "since removed", "before this change"] {
        if lower.contains(phrase) {
            found.push(phrase.to_owned());
        }
    }
    found
}

#[test]
fn the_docs_and_the_help_name_no_issue_or_session() {
    let root = root();
    let mut problems = Vec::new();
    for page in pages(&root) {
        let text = std::fs::read_to_string(&page).expect("page");
        for (n, line) in text.lines().enumerate() {
            for w in history_words(line) {
                problems.push(format!("{}:{}: {w}", page.display(), n + 1));
            }
        }
    }
    let mut help = binary_help();
    let top = help(&[]).expect("dflat --help");
    for sub in subcommands(&top) {
        let path = vec![sub.clone()];
        let Some(text) = help(&path) else { continue };
        for w in history_words(&text) {
            problems.push(format!("dflat {sub} --help: {w}"));
        }
        for nested in subcommands(&text) {
            let p = vec![sub.clone(), nested.clone()];
            for w in history_words(&help(&p).unwrap_or_default()) {
                problems.push(format!("dflat {sub} {nested} --help: {w}"));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn history_words_are_found() {
    assert_eq!(history_words("the tilt cone (issue 17)"), ["issue 17"]);
    assert_eq!(history_words("#preview-issue-39-first"), ["issue-39"]);
    assert_eq!(history_words("a switch since removed"), ["since removed"]);
    assert!(history_words("the issue's budget; no issues here").is_empty());
}
