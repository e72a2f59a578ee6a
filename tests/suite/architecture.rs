//! The shape of the code: dependencies point one way. Reads `src/**/*.rs`, builds the import graph
//! from the `crate::` and `super::` paths in each file (unit tests' `#[cfg(test)] mod tests`
//! excluded) and asserts there is no circle
//! - among the top-level modules of `src/` (a folder or a file directly under `src/` is one
//!   node), and
//! - among the files of the folders listed in [`FOLDERS_WITHOUT_CIRCLES`] (a file is one node;
//!   a folder's `mod.rs` naming its own files counts, `use child::item` as much as
//!   `crate::folder::child::item`), apart from the [`KNOWN_CIRCLES`] still to be broken.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Folders of `src/` whose files must not import each other in a circle.
const FOLDERS_WITHOUT_CIRCLES: &[&str] = &["config", "sleep", "solver", "checkpoint", "measure", "plan"];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file under `dir`, as a path relative to `src/` with `/` separators.
fn rust_files(dir: &Path, out: &mut Vec<String>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p.strip_prefix(src()).unwrap().to_string_lossy().replace('\\', "/"));
        }
    }
}

/// The code of a file without comments and without its unit tests.
fn code(text: &str) -> String {
    // unit tests in a file of their own (`mod tests;`) are left out by their declaration; inline
    // ones (`mod tests {`) run to the end of the file
    let text = text.replace("#[cfg(test)]\nmod tests;", "");
    // (`pub mod tests` too: a test module other files' tests borrow from)
    let body = match ["#[cfg(test)]\nmod tests", "#[cfg(test)]\npub mod tests"].iter().filter_map(|m| text.find(m)).min() {
        Some(i) => &text[..i],
        None => &text[..],
    };
    body.lines().map(|l| l.find("//").map_or(l, |i| &l[..i])).collect::<Vec<_>>().join("\n")
}

fn ident_at(s: &[u8], mut i: usize) -> (String, usize) {
    let start = i;
    while i < s.len() && (s[i].is_ascii_alphanumeric() || s[i] == b'_') {
        i += 1;
    }
    (String::from_utf8_lossy(&s[start..i]).into_owned(), i)
}

fn skip_ws(s: &[u8], mut i: usize) -> usize {
    while i < s.len() && s[i].is_ascii_whitespace() {
        i += 1;
    }
    i
}

/// Parse a path tree at `i` (`a::b::{c, d::e}`), pushing each full path onto `out` (prefixed by
/// `prefix`). Returns the index after the tree.
fn path_tree(s: &[u8], i: usize, prefix: &[String], out: &mut Vec<Vec<String>>) -> usize {
    let mut path = prefix.to_vec();
    let mut i = skip_ws(s, i);
    loop {
        if i < s.len() && s[i] == b'{' {
            i += 1;
            loop {
                i = skip_ws(s, i);
                if i >= s.len() || s[i] == b'}' {
                    return i + 1;
                }
                i = path_tree(s, i, &path, out);
                i = skip_ws(s, i);
                if i < s.len() && s[i] == b',' {
                    i += 1;
                }
            }
        }
        let (id, j) = ident_at(s, i);
        if id.is_empty() {
            out.push(path);
            return i;
        }
        path.push(id);
        i = j;
        if s[i..].starts_with(b"::") {
            i = skip_ws(s, i + 2);
        } else {
            out.push(path);
            return i;
        }
    }
}

/// The child modules a file declares (`mod name;` or `pub mod name;`, not inline `mod name { }`).
fn child_modules(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in code.lines() {
        let l = line.trim();
        let l = l.strip_prefix("pub(crate) ").or_else(|| l.strip_prefix("pub ")).unwrap_or(l);
        if let Some(name) = l.strip_prefix("mod ").and_then(|r| r.strip_suffix(';')) {
            out.insert(name.trim().to_string());
        }
    }
    out
}

/// The `crate::`, `super::` and `self::` paths of a file's code, and the paths through the child
/// modules it declares (`child::item`, as a `mod.rs` names its own files), each as its segments
/// after `crate`, resolved against the file's own module path.
fn paths(file: &str, code: &str) -> Vec<Vec<String>> {
    // the module path of the file: a/b.rs -> [a, b]; a/mod.rs -> [a]
    let mut module: Vec<String> = file.trim_end_matches(".rs").split('/').map(String::from).collect();
    if module.last().is_some_and(|m| m == "mod" || m == "lib" || m == "main") {
        module.pop();
    }
    let children = child_modules(code);
    let s = code.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < s.len() {
        let boundary = i == 0 || !(s[i - 1].is_ascii_alphanumeric() || s[i - 1] == b'_' || s[i - 1] == b':');
        if boundary && s[i..].starts_with(b"crate::") {
            i = path_tree(s, i + 7, &[], &mut out);
        } else if boundary && s[i..].starts_with(b"super::") {
            let mut base = module.clone();
            let mut j = i;
            while s[j..].starts_with(b"super::") {
                base.pop();
                j += 7;
            }
            i = path_tree(s, j, &base, &mut out);
        } else if boundary && s[i..].starts_with(b"self::") {
            i = path_tree(s, i + 6, &module, &mut out);
        } else if boundary && (s[i].is_ascii_alphabetic() || s[i] == b'_') {
            let (id, j) = ident_at(s, i);
            if children.contains(&id) && s[j..].starts_with(b"::") {
                i = path_tree(s, i, &module, &mut out);
            } else {
                i = j;
            }
        } else {
            i += 1;
        }
    }
    out
}

/// The file a path names: the longest prefix of it that is a module file.
fn resolve(files: &BTreeSet<String>, path: &[String]) -> Option<String> {
    for n in (1..=path.len()).rev() {
        let m = path[..n].join("/");
        for f in [format!("{m}.rs"), format!("{m}/mod.rs")] {
            if files.contains(&f) {
                return Some(f);
            }
        }
    }
    None
}

/// file -> the files it names.
fn import_graph() -> BTreeMap<String, BTreeSet<String>> {
    let mut list = Vec::new();
    rust_files(&src(), &mut list);
    let files: BTreeSet<String> = list.into_iter().collect();
    let mut g = BTreeMap::new();
    for f in &files {
        let text = std::fs::read_to_string(src().join(f)).unwrap();
        let to: BTreeSet<String> = paths(f, &code(&text)).iter().filter_map(|p| resolve(&files, p)).filter(|t| t != f).collect();
        g.insert(f.clone(), to);
    }
    g
}

/// The strongly connected components of more than one node (Tarjan).
fn circles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct T<'a> {
        g: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a str) {
        let n = t.index.len();
        t.index.insert(v, n);
        t.low.insert(v, n);
        t.stack.push(v);
        t.on.insert(v);
        for w in t.g.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !t.g.contains_key(w) {
                continue;
            }
            if !t.index.contains_key(w) {
                visit(t, w);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut c = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on.remove(w);
                c.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if c.len() > 1 {
                c.sort();
                t.out.push(c);
            }
        }
    }
    let mut t = T { g, index: BTreeMap::new(), low: BTreeMap::new(), stack: Vec::new(), on: BTreeSet::new(), out: Vec::new() };
    for v in g.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

/// The graph with each node replaced by `group(node)` (edges within a group dropped).
fn grouped(g: &BTreeMap<String, BTreeSet<String>>, group: impl Fn(&str) -> Option<String>) -> BTreeMap<String, BTreeSet<String>> {
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (f, to) in g {
        let Some(a) = group(f) else { continue };
        let e = out.entry(a.clone()).or_default();
        for t in to {
            if let Some(b) = group(t).filter(|b| *b != a) {
                e.insert(b);
            }
        }
    }
    out
}

/// The top-level module of a file: its folder under `src/`, or the file itself (lib.rs and main.rs
/// are the crate root, above everything, and left out).
fn top_level(file: &str) -> Option<String> {
    match file.split_once('/') {
        Some((folder, _)) => Some(folder.to_string()),
        None if file == "lib.rs" || file == "main.rs" => None,
        None => Some(file.trim_end_matches(".rs").to_string()),
    }
}

/// The circles among the files of `folder` (a folder of `src/`).
pub fn circles_in_folder(folder: &str) -> Vec<Vec<String>> {
    let prefix = format!("{folder}/");
    circles(&grouped(&import_graph(), |f| f.starts_with(&prefix).then(|| f.to_string())))
}

/// The circles among the top-level modules of `src/`.
pub fn circles_between_folders() -> Vec<Vec<String>> {
    circles(&grouped(&import_graph(), top_level))
}

#[test]
fn no_circle_spans_more_than_one_folder() {
    let c = circles_between_folders();
    assert!(c.is_empty(), "import circles among the top-level modules of src/: {c:?}");
}

/// Circles the code still has, each to be broken rather than grown (issue 54): the solver's
/// `Simulation` is declared in `solver/mod.rs`, holds the phases' types as fields, and each
/// phase's file adds its methods to it. A circle found inside one of these passes; any other,
/// or one reaching further, fails.
const KNOWN_CIRCLES: &[&[&str]] = &[&[
    "solver/adjoint.rs",
    "solver/binning.rs",
    "solver/bodies.rs",
    "solver/emit.rs",
    "solver/mod.rs",
    "solver/preflight.rs",
    "solver/step.rs",
    "solver/walls.rs",
]];

#[test]
fn no_circle_inside_the_core_folders() {
    for folder in FOLDERS_WITHOUT_CIRCLES {
        let new: Vec<Vec<String>> = circles_in_folder(folder)
            .into_iter()
            .filter(|c| !KNOWN_CIRCLES.iter().any(|k| c.iter().all(|f| k.contains(&f.as_str()))))
            .collect();
        assert!(new.is_empty(), "import circles among the files of src/{folder}/: {new:?}");
    }
}

#[test]
fn every_checked_folder_is_a_folder_of_several_files() {
    // a folder that is a single file (or gone) would pass the circle check without being checked
    for folder in FOLDERS_WITHOUT_CIRCLES {
        let mut files = Vec::new();
        rust_files(&src().join(folder), &mut files);
        assert!(files.len() > 1, "src/{folder}/ is checked for circles but holds {} files", files.len());
    }
}

/// Folders whose files each stay under [`MAX_CODE_LINES`] lines of code: one phase or concept a
/// file.
const FOLDERS_OF_SMALL_FILES: &[&str] = &["solver"];
const MAX_CODE_LINES: usize = 300;

/// Lines of a file's code (not blank, not only a comment), its unit tests left out.
fn code_lines(text: &str) -> usize {
    code(text).lines().filter(|l| !l.trim().is_empty()).count()
}

#[test]
fn the_solver_is_one_phase_a_file() {
    for folder in FOLDERS_OF_SMALL_FILES {
        let mut files = Vec::new();
        rust_files(&src().join(folder), &mut files);
        for f in files {
            let n = code_lines(&std::fs::read_to_string(src().join(&f)).unwrap());
            assert!(n <= MAX_CODE_LINES, "src/{f} has {n} lines of code, more than {MAX_CODE_LINES}: split it by phase");
        }
    }
    assert_eq!(code_lines("// a comment\n\nlet x = 1; // and one after code\n#[cfg(test)]\nmod tests {\n}\n"), 1);
}

#[test]
fn the_graph_sees_imports_and_circles() {
    // the check can fail: a known import is found, and a made-up circle is reported
    let g = import_graph();
    assert!(g["run/mod.rs"].iter().any(|t| t.starts_with("scenario")), "run/mod.rs imports the scenario: {:?}", g["run/mod.rs"]);
    let mut fake = BTreeMap::new();
    fake.insert("a.rs".to_string(), BTreeSet::from(["b/x.rs".to_string()]));
    fake.insert("b/x.rs".to_string(), BTreeSet::from(["b/y.rs".to_string()]));
    fake.insert("b/y.rs".to_string(), BTreeSet::from(["a.rs".to_string()]));
    assert_eq!(circles(&grouped(&fake, top_level)), vec![vec!["a".to_string(), "b".to_string()]]);
    let nested = paths("checkpoint/state.rs", "use super::{format::{checksum, Header}, writer::Part};\nlet x = crate::sleep::UNITS;");
    assert!(nested.contains(&vec!["checkpoint".into(), "format".into(), "checksum".into()]), "{nested:?}");
    assert!(nested.contains(&vec!["checkpoint".into(), "writer".into(), "Part".into()]), "{nested:?}");
    assert!(nested.contains(&vec!["sleep".into(), "UNITS".into()]), "{nested:?}");
    // a mod.rs naming its own children, bare or through self::, imports them
    let own = paths("sleep/mod.rs", "mod coarsen;\npub mod units;\nuse coarsen::Coarsen;\nlet u = self::units::UNITS;\nlet c = coarsen::f();");
    assert!(own.contains(&vec!["sleep".into(), "coarsen".into(), "Coarsen".into()]), "{own:?}");
    assert!(own.contains(&vec!["sleep".into(), "units".into(), "UNITS".into()]), "{own:?}");
    assert!(own.contains(&vec!["sleep".into(), "coarsen".into(), "f".into()]), "{own:?}");
    // and a circle through a folder's mod.rs is one
    let mut through_mod = BTreeMap::new();
    through_mod.insert("sleep/mod.rs".to_string(), BTreeSet::from(["sleep/coarsen.rs".to_string()]));
    through_mod.insert("sleep/coarsen.rs".to_string(), BTreeSet::from(["sleep/mod.rs".to_string()]));
    assert_eq!(circles(&grouped(&through_mod, |f| Some(f.to_string()))).len(), 1);
}
