//! The commands shown in README.md and docs/*.md are run, and their output
//! checked, so that what a newcomer copies works and what it prints is what
//! the page says (numbers in prose drift; these cannot).
//!
//! A ```` ```console ```` block is a session: `$ gyropath ...` lines are
//! commands, a `? N` line right after one is its expected exit status (0
//! when absent), and the lines up to the next command are its expected
//! output: standard error (progress, warnings: what a terminal shows
//! first), then standard output, trailing blanks ignored,
//! with snapbox's wildcards (`[..]` any text within a line, `...` alone on a
//! line any number of lines). The commands of one block run in turn in one
//! fresh folder that has `data/` (this repository's) beside it and
//! `../shared/` above it, so the pages' paths work as they do from a clone.
//! Every other fenced block that starts a line with `gyropath` must be
//! marked `text` (a synopsis), so no runnable command escapes the test.

use std::path::{Path, PathBuf};
use std::process::Command;

const REPO: &str = env!("CARGO_MANIFEST_DIR");

/// One command of a console block and what it should print.
struct Case {
    /// `file:line` of the command, for the failure message.
    at: String,
    args: Vec<String>,
    status: i32,
    expected: String,
}

/// The pages whose commands are run.
fn pages() -> Vec<PathBuf> {
    let mut pages = vec![Path::new(REPO).join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(Path::new(REPO).join("docs"))
        .expect("docs/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    pages.extend(docs);
    pages
}

/// Split a command line as a shell would for the quoting the pages use:
/// whitespace, and `"..."` or `'...'` around an argument or part of one.
fn split_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut quote = None;
    let mut in_word = false;
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => word.push(c),
            (None, '"' | '\'') => {
                quote = Some(c);
                in_word = true;
            }
            (None, c) if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            (None, c) => {
                word.push(c);
                in_word = true;
            }
        }
    }
    if in_word {
        words.push(word);
    }
    words
}

/// The console blocks of one page, each a list of cases; and the places
/// where an unmarked block shows a `gyropath` command.
fn blocks(page: &Path) -> (Vec<Vec<Case>>, Vec<String>) {
    let text = std::fs::read_to_string(page).expect("page");
    let name = page
        .strip_prefix(REPO)
        .unwrap_or(page)
        .display()
        .to_string();
    let mut blocks = Vec::new();
    let mut unmarked = Vec::new();
    let mut fence: Option<String> = None;
    let mut block: Vec<Case> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let at = format!("{name}:{}", i + 1);
        if let Some(info) = line.strip_prefix("```") {
            match fence.take() {
                Some(kind) => {
                    if kind == "console" {
                        blocks.push(std::mem::take(&mut block));
                    }
                }
                None => fence = Some(info.trim().to_string()),
            }
            continue;
        }
        match fence.as_deref() {
            Some("console") => {
                if let Some(command) = line.strip_prefix("$ ") {
                    block.push(Case {
                        at,
                        args: split_words(command),
                        status: 0,
                        expected: String::new(),
                    });
                } else if let Some(case) = block.last_mut() {
                    match line.strip_prefix("? ") {
                        Some(n) if case.expected.is_empty() => {
                            case.status = n.trim().parse().expect("? N: an exit status")
                        }
                        _ => {
                            case.expected.push_str(line.trim_end());
                            case.expected.push('\n');
                        }
                    }
                } else {
                    unmarked.push(format!("{at}: output before any command"));
                }
            }
            Some("text") | None => {}
            Some(_) => {
                let shown = line.trim_start().trim_start_matches("$ ");
                if shown.starts_with("gyropath ") {
                    unmarked.push(at);
                }
            }
        }
    }
    (blocks, unmarked)
}

/// A fresh folder laid out as a clone is: `work/data` is the repository's
/// `data/`, `shared` beside `work` is `../shared`.
fn workspace() -> (tempfile::TempDir, PathBuf) {
    let root = tempfile::tempdir().expect("temp dir");
    let work = root.path().join("work");
    std::fs::create_dir(&work).expect("work/");
    std::os::unix::fs::symlink(Path::new(REPO).join("data"), work.join("data")).expect("data");
    let shared = Path::new(REPO).join("../shared");
    std::os::unix::fs::symlink(&shared, root.path().join("shared")).expect("shared");
    (root, work)
}

/// Run one case in `work`; `Err` says where and how it differs.
fn run(case: &Case, work: &Path) -> Result<(), String> {
    let Some((program, args)) = case.args.split_first() else {
        return Err(format!("{}: an empty command", case.at));
    };
    if program != "gyropath" {
        return Err(format!(
            "{}: `{program}` is not gyropath: the pages' console blocks show only gyropath commands",
            case.at
        ));
    }
    let out = Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .args(args)
        .current_dir(work)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .map_err(|e| format!("{}: cannot run: {e}", case.at))?;
    let mut actual = String::new();
    for stream in [&out.stderr, &out.stdout] {
        for line in String::from_utf8_lossy(stream).lines() {
            actual.push_str(line.trim_end());
            actual.push('\n');
        }
    }
    let status = out.status.code().unwrap_or(-1);
    if status != case.status {
        return Err(format!(
            "{}: `{}` exited with {status}, the page says {}:\n{actual}",
            case.at,
            case.args.join(" "),
            case.status
        ));
    }
    snapbox::Assert::new()
        .try_eq(
            Some(&case.at),
            snapbox::Data::text(actual),
            snapbox::Data::text(case.expected.clone()),
        )
        .map_err(|e| format!("{}: `{}`:\n{e}", case.at, case.args.join(" ")))
}

#[test]
fn every_command_the_pages_show_runs_and_prints_what_they_say() {
    assert!(
        Path::new(REPO).join("../shared/real").is_dir(),
        "../shared (beside the repository) holds the real drives the pages use"
    );
    let mut failures = Vec::new();
    let mut commands = 0;
    let mut readme_commands = 0;
    for page in pages() {
        let (blocks, unmarked) = blocks(&page);
        for at in unmarked {
            failures.push(format!(
                "{at}: a gyropath command outside a console block (mark a synopsis `text`)"
            ));
        }
        for block in blocks {
            let (_root, work) = workspace();
            for case in &block {
                commands += 1;
                if page.ends_with("README.md") {
                    readme_commands += 1;
                }
                if let Err(e) = run(case, &work) {
                    failures.push(e);
                }
            }
        }
    }
    // The README's tour is the first thing a newcomer runs.
    assert!(
        readme_commands >= 5,
        "only {readme_commands} commands in README.md"
    );
    assert!(
        failures.is_empty(),
        "{} of {commands} commands differ from their pages:\n\n{}",
        failures.len(),
        failures.join("\n\n")
    );
}

#[test]
fn the_runner_reads_quotes_statuses_and_wildcards() {
    assert_eq!(
        split_words(r#"gyropath fit a.bag --mount "x=-z,y=-x,z=y"  'b c'"#),
        [
            "gyropath",
            "fit",
            "a.bag",
            "--mount",
            "x=-z,y=-x,z=y",
            "b c"
        ]
    );
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("page.md");
    std::fs::write(
        &page,
        "```console\n$ gyropath fit missing.csv\n? 1\nerror: [..]missing.csv[..]\n```\n\n```sh\ngyropath fit x.csv\n```\n",
    )
    .unwrap();
    let (blocks, unmarked) = blocks(&page);
    assert_eq!(
        unmarked.len(),
        1,
        "an unmarked block with a command is found"
    );
    let case = &blocks[0][0];
    assert_eq!(case.status, 1);
    let (_root, work) = workspace();
    run(case, &work).expect("a missing file: status 1 and the error the page shows");
    // A case whose output differs fails, and says where.
    let wrong = Case {
        expected: "error: something else\n".into(),
        ..Case {
            at: "page.md:2".into(),
            args: case.args.clone(),
            status: 1,
            expected: String::new(),
        }
    };
    let err = run(&wrong, &work).expect_err("differs");
    assert!(err.contains("page.md:2"), "{err}");
}
