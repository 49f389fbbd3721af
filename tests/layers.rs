//! The layers import only downwards: no two top-level modules of `src/` may
//! reach each other through `crate::` paths (directly or round a circle),
//! and nothing but the app itself imports the app. A cycle ties every module
//! on it into one piece that cannot be read, tested or changed apart; this
//! test names the imports that close one.
//!
//! It reads the source, not the compiler's view: every `crate::NAME` path
//! and every name of a `use crate::{...}` group outside comments and test
//! code (`#[cfg(test)]` items and the files of `#[cfg(test)] mod` lines).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const SRC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/src");

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level module a file belongs to (`src/model/chain.rs` -> `model`).
fn top_module(file: &Path) -> String {
    let rel = file.strip_prefix(SRC).expect("under src");
    let first = rel.components().next().expect("a component");
    first
        .as_os_str()
        .to_string_lossy()
        .trim_end_matches(".rs")
        .to_string()
}

/// The text without `//` comments.
fn without_comments(text: &str) -> String {
    text.lines()
        .map(|l| match l.find("//") {
            Some(i) if !l[..i].contains('"') => &l[..i],
            _ => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The text without the items under `#[cfg(test)]`: from the attribute to
/// the end of the item (its `;`, or the `}` that closes its first `{`).
/// Also returns the names of `#[cfg(test)] mod NAME;` declarations, whose
/// files are test code.
fn without_tests(text: &str) -> (String, Vec<String>) {
    let mut out = String::new();
    let mut test_mods = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..at]);
        let item = &rest[at + "#[cfg(test)]".len()..];
        let (semi, brace) = (item.find(';'), item.find('{'));
        let end = match (semi, brace) {
            (Some(s), b) if b.is_none_or(|b| s < b) => {
                let decl = item[..s].trim();
                if decl.contains("mod ")
                    && let Some(name) = decl.split_whitespace().last()
                {
                    test_mods.push(name.to_string());
                }
                s + 1
            }
            (_, Some(b)) => {
                let mut depth = 0usize;
                let mut end = item.len();
                for (i, c) in item[b..].char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' => {
                            depth -= 1;
                            if depth == 0 {
                                end = b + i + 1;
                                break;
                            }
                        }
                        _ => {}
                    }
                }
                end
            }
            _ => item.len(),
        };
        rest = &item[end..];
    }
    out.push_str(rest);
    (out, test_mods)
}

/// The top-level modules a file's code names through `crate::`.
fn imports(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        let after = &rest[at + "crate::".len()..];
        if let Some(group) = after.strip_prefix('{') {
            // `use crate::{a::b, c, d::{e, f}}`: the names at depth 1.
            let mut depth = 1usize;
            let mut start = true;
            let mut name = String::new();
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    ',' if depth == 1 => start = true,
                    c if depth == 1 && start && (c.is_alphanumeric() || c == '_') => name.push(c),
                    _ if depth == 1 && start && !name.is_empty() => {
                        found.insert(std::mem::take(&mut name));
                        start = false;
                    }
                    _ => {}
                }
            }
            if !name.is_empty() {
                found.insert(name);
            }
        } else {
            let name: String = after
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                found.insert(name);
            }
        }
        rest = after;
    }
    found
}

/// `module -> (imported module -> files that import it)`, over the library's
/// modules (the binary's `main.rs` and `lib.rs` itself left out).
fn graph() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let mut files = Vec::new();
    rust_files(Path::new(SRC), &mut files);
    files.sort();
    let modules: BTreeSet<String> = files.iter().map(|f| top_module(f)).collect();
    let mut parsed = Vec::new();
    let mut test_files: BTreeSet<PathBuf> = BTreeSet::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("source");
        let (code, test_mods) = without_tests(&without_comments(&text));
        let dir = if f
            .file_name()
            .is_some_and(|n| n == "mod.rs" || n == "lib.rs")
        {
            f.parent().expect("dir").to_path_buf()
        } else {
            f.with_extension("")
        };
        for m in test_mods {
            test_files.insert(dir.join(format!("{m}.rs")));
            test_files.insert(dir.join(&m).join("mod.rs"));
        }
        parsed.push((f.clone(), code));
    }
    let mut g: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (f, code) in parsed {
        let from = top_module(&f);
        if from == "main" || from == "lib" || test_files.contains(&f) {
            continue;
        }
        g.entry(from.clone()).or_default();
        for to in imports(&code) {
            if to != from && modules.contains(&to) {
                let rel = f
                    .strip_prefix(SRC)
                    .expect("under src")
                    .display()
                    .to_string();
                g.entry(from.clone())
                    .or_default()
                    .entry(to)
                    .or_default()
                    .insert(rel);
            }
        }
    }
    g
}

/// The strongly connected components with more than one module (Tarjan).
fn cycles(g: &BTreeMap<String, BTreeMap<String, BTreeSet<String>>>) -> Vec<Vec<String>> {
    struct Walk<'a> {
        g: &'a BTreeMap<String, BTreeMap<String, BTreeSet<String>>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        found: Vec<Vec<String>>,
    }
    fn visit<'a>(w: &mut Walk<'a>, v: &'a str) {
        let i = w.index.len();
        w.index.insert(v, i);
        w.low.insert(v, i);
        w.stack.push(v);
        let g = w.g;
        for to in g.get(v).into_iter().flat_map(|e| e.keys()) {
            let to = to.as_str();
            if !w.index.contains_key(to) {
                visit(w, to);
                let l = w.low[v].min(w.low[to]);
                w.low.insert(v, l);
            } else if w.stack.contains(&to) {
                let l = w.low[v].min(w.index[to]);
                w.low.insert(v, l);
            }
        }
        if w.low[v] == w.index[v] {
            let mut comp = Vec::new();
            while let Some(x) = w.stack.pop() {
                comp.push(x.to_string());
                if x == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                w.found.push(comp);
            }
        }
    }
    let mut w = Walk {
        g,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for v in g.keys() {
        if !w.index.contains_key(v.as_str()) {
            visit(&mut w, v);
        }
    }
    w.found
}

#[test]
fn the_top_level_modules_import_only_downwards() {
    let g = graph();
    assert!(g.len() > 10, "too few modules found: {:?}", g.keys());
    let found = cycles(&g);
    let mut report = String::new();
    for comp in &found {
        report.push_str(&format!("cycle through {}:\n", comp.join(", ")));
        for from in comp {
            for (to, files) in &g[from] {
                if comp.contains(to) {
                    let files: Vec<&str> = files.iter().map(String::as_str).collect();
                    report.push_str(&format!("  {from} -> {to} ({})\n", files.join(", ")));
                }
            }
        }
    }
    assert!(found.is_empty(), "{report}");
}

#[test]
fn only_the_app_imports_the_app() {
    let g = graph();
    for (from, edges) in &g {
        if from != "app" && from != "cli" {
            assert!(
                !edges.contains_key("app"),
                "{from} imports the app: {:?}",
                edges.get("app")
            );
        }
    }
}

#[test]
fn the_reader_sees_groups_comments_and_test_code() {
    let code = "use crate::{effects::{self, Effect}, signals::Signals};\nlet x = crate::model::Model::new();\n// crate::app::App\n#[cfg(test)]\nmod tests {\n    use crate::testing::x;\n}\n#[cfg(test)]\nmod more;\n";
    let (code, test_mods) = without_tests(&without_comments(code));
    assert_eq!(test_mods, ["more"]);
    let found: Vec<String> = imports(&code).into_iter().collect();
    assert_eq!(found, ["effects", "model", "signals"]);
    // A circle is found and named.
    let mut g: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (a, b) in [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")] {
        g.entry(a.into()).or_default().entry(b.into()).or_default();
    }
    g.entry("d".into()).or_default();
    assert_eq!(cycles(&g), vec![vec!["a", "b", "c"]]);
}
