//! `cargo xtask import-circles`: the circles among each crate's modules.
//!
//! A module imports another when its code (tests and comments left out)
//! names a path into it: `crate::a::b::Item`, `super::Item`, a child module
//! by its name (`json::write()`, the parent's half of a parent ↔ child
//! circle), or a `use` tree
//! such as `crate::{a::X, b::{Y, Z}}`. A path is resolved to the deepest
//! module it names; an item a module re-exports (`pub use`) is followed to
//! the module that defines it, and re-exports do not count as imports
//! themselves (they are a facade, not a dependency). Every crate root
//! (`lib.rs`, `main.rs`, `bin/*.rs`) is read with the module files its `mod`
//! items name. A circle is a set of two or more modules each reachable from
//! every other (a strongly connected component of the import graph).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

/// The crates whose modules are checked, relative to the workspace root.
pub const CRATES: [&str; 6] = ["rbf-core", "wire", "firmware", "firmware-harness", "trainer", "xtask"];

/// One module of a crate's tree: its path from the root and its file.
#[derive(Clone, Debug)]
struct Module {
    /// `a::b` (empty for the crate root).
    path: Vec<String>,
    /// The file holding it.
    file: PathBuf,
    /// Its code without comments and test modules.
    code: String,
}

/// Modules that import each other, with what ties them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Circle {
    /// The modules' files, relative to the workspace root, sorted.
    pub files: Vec<String>,
    /// `importer -> imported` for each import inside the circle.
    pub ties: Vec<(String, String)>,
}

/// `cargo xtask import-circles`: prints every circle and fails if there is one.
pub fn import_circles() -> anyhow::Result<()> {
    let root = crate::workspace_root();
    let mut circles = Vec::new();
    for krate in CRATES {
        circles.extend(find(&root, krate)?);
    }
    for (i, circle) in circles.iter().enumerate() {
        println!("circle {}: {}", i + 1, circle.files.join(", "));
        for (from, to) in &circle.ties {
            println!("  {from} -> {to}");
        }
    }
    if !circles.is_empty() {
        bail!(
            "{} import circle(s) among the modules of {}",
            circles.len(),
            CRATES.join(", ")
        );
    }
    println!("import circles: none in {}", CRATES.join(", "));
    Ok(())
}

/// The circles among the modules of `krate` (a folder of `root` with `src/`).
pub fn find(root: &Path, krate: &str) -> anyhow::Result<Vec<Circle>> {
    let src = root.join(krate).join("src");
    let mut roots = Vec::new();
    for name in ["lib.rs", "main.rs"] {
        if src.join(name).is_file() {
            roots.push(src.join(name));
        }
    }
    if let Ok(bins) = std::fs::read_dir(src.join("bin")) {
        let mut bins: Vec<PathBuf> = bins.filter_map(|e| e.ok().map(|e| e.path())).collect();
        bins.sort();
        roots.extend(bins.into_iter().filter(|p| p.extension().is_some_and(|e| e == "rs")));
    }
    let mut circles = Vec::new();
    for crate_root in roots {
        let modules = tree(&crate_root)?;
        let edges = imports(&modules);
        for component in strongly_connected(&edges) {
            let name = |i: usize| {
                modules[i]
                    .file
                    .strip_prefix(root)
                    .unwrap_or(&modules[i].file)
                    .display()
                    .to_string()
            };
            let mut ties: Vec<(String, String)> = component
                .iter()
                .flat_map(|&from| {
                    let edges = &edges;
                    component
                        .iter()
                        .filter(move |&&to| edges[from].contains(&to))
                        .map(move |&to| (from, to))
                })
                .map(|(from, to)| (name(from), name(to)))
                .collect();
            ties.sort();
            let mut files: Vec<String> = component.iter().map(|&i| name(i)).collect();
            files.sort();
            circles.push(Circle { files, ties });
        }
    }
    Ok(circles)
}

/// The module tree under the crate root file `root_file`.
fn tree(root_file: &Path) -> anyhow::Result<Vec<Module>> {
    let mut modules = Vec::new();
    let mut pending = vec![(Vec::new(), root_file.to_path_buf())];
    while let Some((path, file)) = pending.pop() {
        let text = std::fs::read_to_string(&file).with_context(|| format!("{}: cannot read", file.display()))?;
        let code = without_tests(&without_comments(&text));
        // Where this file's child modules live: beside a root or mod.rs,
        // else in the folder named after the file.
        let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let dir = file.parent().unwrap_or(Path::new("."));
        let children_dir = if path.is_empty() || stem == "mod" {
            dir.to_path_buf()
        } else {
            dir.join(stem)
        };
        for child in declared_modules(&code) {
            let candidates = [
                children_dir.join(format!("{child}.rs")),
                children_dir.join(&child).join("mod.rs"),
            ];
            if let Some(found) = candidates.into_iter().find(|c| c.is_file()) {
                let mut child_path = path.clone();
                child_path.push(child);
                pending.push((child_path, found));
            }
        }
        modules.push(Module { path, file, code });
    }
    modules.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(modules)
}

/// For each module, the modules it imports (indices into `modules`).
fn imports(modules: &[Module]) -> Vec<BTreeSet<usize>> {
    let index: BTreeMap<&[String], usize> = modules
        .iter()
        .enumerate()
        .map(|(i, m)| (m.path.as_slice(), i))
        .collect();
    let known: BTreeSet<Vec<String>> = modules.iter().map(|m| m.path.clone()).collect();
    let reexports: Vec<BTreeMap<String, Vec<String>>> = modules.iter().map(|m| reexported(m, &known)).collect();
    modules
        .iter()
        .enumerate()
        .map(|(i, module)| {
            let mut to = BTreeSet::new();
            for (path, is_reexport) in referenced_paths(module, &known) {
                if is_reexport {
                    continue;
                }
                if let Some(j) = resolve(&path, &index, &reexports)
                    && j != i
                {
                    to.insert(j);
                }
            }
            to
        })
        .collect()
}

/// The module `path` (absolute) names: the deepest module prefix, followed
/// through re-exports of the item after it (a few hops at most).
fn resolve(
    path: &[String],
    index: &BTreeMap<&[String], usize>,
    reexports: &[BTreeMap<String, Vec<String>>],
) -> Option<usize> {
    let mut path = path.to_vec();
    for _ in 0..4 {
        let depth = (0..=path.len()).rev().find(|&d| index.contains_key(&path[..d]))?;
        let module = index[&path[..depth]];
        let Some(item) = path.get(depth) else {
            return Some(module);
        };
        match reexports[module].get(item) {
            Some(target) if target != &path => path = target.clone(),
            _ => return Some(module),
        }
    }
    None
}

/// `name -> absolute path` for every item `module` re-exports with `pub use`.
fn reexported(module: &Module, known: &BTreeSet<Vec<String>>) -> BTreeMap<String, Vec<String>> {
    let mut out = BTreeMap::new();
    for statement in use_statements(&module.code).into_iter().filter(|s| s.public) {
        for path in statement.paths {
            if let Some(absolute) = absolute(&module.path, &path, known)
                && let Some(name) = absolute.last()
            {
                out.insert(name.clone(), absolute);
            }
        }
    }
    out
}

/// Every path `module` names into its crate, absolute, and whether it
/// comes from a re-export.
fn referenced_paths(module: &Module, known: &BTreeSet<Vec<String>>) -> Vec<(Vec<String>, bool)> {
    let mut out = Vec::new();
    for statement in use_statements(&module.code) {
        for path in statement.paths {
            if let Some(absolute) = absolute(&module.path, &path, known) {
                out.push((absolute, statement.public));
            }
        }
    }
    // Paths in code outside `use` items: `crate::a::b`, `super::x`, and a
    // child module named without `self::` (`json::write(…)` in a parent:
    // the parent's half of a parent ↔ child circle).
    let code = without_use_items(&module.code);
    let children: Vec<String> = known
        .iter()
        .filter(|k| k.len() == module.path.len() + 1 && k.starts_with(&module.path))
        .filter_map(|k| k.last().map(|child| format!("{child}::")))
        .collect();
    let anchors = ["crate::".to_owned(), "super::".to_owned()].into_iter().chain(children);
    for anchor in anchors {
        let anchor = anchor.as_str();
        let mut from = 0;
        while let Some(at) = code[from..].find(anchor).map(|i| i + from) {
            from = at + anchor.len();
            let before = code[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let mut tokens = Tokens::new(&code[at..]);
            for path in tokens.use_tree() {
                if let Some(absolute) = absolute(&module.path, &path, known) {
                    out.push((absolute, false));
                }
            }
        }
    }
    out
}

/// `path` (as written in module `at`, whose child modules are among
/// `known`) from the crate root; `None` for a path outside the crate
/// (another crate, `std`).
fn absolute(at: &[String], path: &[String], known: &BTreeSet<Vec<String>>) -> Option<Vec<String>> {
    let (first, rest) = path.split_first()?;
    match first.as_str() {
        "crate" => Some(rest.to_vec()),
        "super" => {
            let mut base = at.get(..at.len().checked_sub(1)?)?.to_vec();
            let mut rest = rest;
            while let Some(("super", tail)) = rest.split_first().map(|(h, t)| (h.as_str(), t)) {
                base.pop()?;
                rest = tail;
            }
            base.extend_from_slice(rest);
            Some(base)
        }
        "self" => {
            let mut base = at.to_vec();
            base.extend_from_slice(rest);
            Some(base)
        }
        // A child module named without `self::` (2018 paths).
        _ => {
            let mut base = at.to_vec();
            base.push(first.clone());
            known.contains(&base).then(|| {
                base.extend_from_slice(rest);
                base
            })
        }
    }
}

/// One `use` item: its paths, and whether it is `pub` (a re-export).
struct UseStatement {
    public: bool,
    paths: Vec<Vec<String>>,
}

/// The `use` items of `code`.
fn use_statements(code: &str) -> Vec<UseStatement> {
    let mut out = Vec::new();
    for (start, end) in use_item_spans(code) {
        let text = &code[start..end];
        let public = text.starts_with("pub");
        let Some(after) = text.find("use ").map(|i| i + 4) else {
            continue;
        };
        let paths = Tokens::new(&text[after..]).use_tree();
        out.push(UseStatement { public, paths });
    }
    out
}

/// Byte ranges of the `use` items (from `use`/`pub use`/`pub(crate) use` to `;`).
fn use_item_spans(code: &str) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut line_start = 0;
    for line in code.split_inclusive('\n') {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        let is_use = trimmed.starts_with("use ")
            || (trimmed.starts_with("pub") && trimmed.split_whitespace().nth(1) == Some("use"));
        if is_use {
            let start = line_start + indent;
            if let Some(end) = code[start..].find(';') {
                spans.push((start, start + end + 1));
            }
        }
        line_start += line.len();
    }
    spans
}

/// `code` with its `use` items blanked out.
fn without_use_items(code: &str) -> String {
    let mut out = code.to_owned();
    for (start, end) in use_item_spans(code) {
        out.replace_range(start..end, &" ".repeat(end - start));
    }
    out
}

/// The names of the out-of-line modules `code` declares (`mod name;`).
fn declared_modules(code: &str) -> Vec<String> {
    code.lines()
        .filter_map(|line| {
            let words: Vec<&str> = line.split_whitespace().collect();
            let at = words.iter().position(|w| *w == "mod")?;
            let name = words.get(at + 1)?.strip_suffix(';')?;
            let visibility_only = words[..at].iter().all(|w| w.starts_with("pub"));
            visibility_only.then(|| name.to_owned())
        })
        .collect()
}

/// `text` without `//` and `/* */` comments and without the contents of
/// string and char literals (so that neither is read as code).
fn without_comments(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < bytes.len() {
        let rest = &text[i..];
        if rest.starts_with("//") {
            let end = rest.find('\n').unwrap_or(rest.len());
            i += end;
        } else if rest.starts_with("/*") {
            let end = rest.find("*/").map_or(rest.len(), |e| e + 2);
            out.extend(rest[..end].chars().filter(|&c| c == '\n'));
            i += end;
        } else if rest.starts_with('"') {
            // Skip to the closing quote, honouring escapes.
            let mut j = 1;
            while j < rest.len() {
                match rest.as_bytes()[j] {
                    b'\\' => j += 2,
                    b'"' => break,
                    _ => j += 1,
                }
            }
            let end = (j + 1).min(rest.len());
            out.push_str("\"\"");
            out.extend(rest[..end].chars().filter(|&c| c == '\n'));
            i += end;
        } else {
            let c = rest.chars().next().unwrap_or(' ');
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// `code` without the modules under `#[cfg(test)]` (inline `mod … { … }`).
fn without_tests(code: &str) -> String {
    let mut out = code.to_owned();
    while let Some(at) = out.find("#[cfg(test)]") {
        let after = at + "#[cfg(test)]".len();
        let Some(open) = out[after..].find(['{', ';']).map(|i| i + after) else {
            out.replace_range(at..after, "");
            continue;
        };
        let head = &out[after..open];
        if !head.contains("mod ") {
            // Another item under the attribute: only the attribute goes.
            out.replace_range(at..after, "");
            continue;
        }
        if out[open..].starts_with(';') {
            // `mod tests;`: the declaration goes, so its file is not read.
            out.replace_range(at..=open, "");
            continue;
        }
        let mut depth = 0usize;
        let mut end = out.len();
        for (k, c) in out[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + k + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        out.replace_range(at..end, "");
    }
    out
}

/// A tiny tokenizer for paths and `use` trees.
struct Tokens<'a> {
    text: &'a str,
    at: usize,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Self {
        Tokens { text, at: 0 }
    }

    fn skip_space(&mut self) {
        while self.text[self.at..].starts_with(char::is_whitespace) {
            self.at += self.text[self.at..].chars().next().map_or(1, char::len_utf8);
        }
    }

    fn eat(&mut self, token: &str) -> bool {
        self.skip_space();
        if self.text[self.at..].starts_with(token) {
            self.at += token.len();
            true
        } else {
            false
        }
    }

    fn ident(&mut self) -> Option<String> {
        self.skip_space();
        let rest = &self.text[self.at..];
        let len = rest
            .char_indices()
            .find(|&(_, c)| !(c.is_alphanumeric() || c == '_'))
            .map_or(rest.len(), |(i, _)| i);
        if len == 0 {
            return None;
        }
        self.at += len;
        Some(rest[..len].to_owned())
    }

    /// The paths of a `use` tree (or of a plain path) at the cursor.
    fn use_tree(&mut self) -> Vec<Vec<String>> {
        let mut out = Vec::new();
        self.tree(&mut Vec::new(), &mut out, 0);
        out
    }

    fn tree(&mut self, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>, depth: usize) {
        if depth > 16 {
            return;
        }
        if self.eat("{") {
            loop {
                if self.eat("}") {
                    break;
                }
                let keep = prefix.len();
                self.tree(prefix, out, depth + 1);
                prefix.truncate(keep);
                if !self.eat(",") {
                    self.eat("}");
                    break;
                }
            }
            return;
        }
        if self.eat("*") {
            out.push(prefix.clone());
            return;
        }
        let Some(name) = self.ident() else {
            if !prefix.is_empty() {
                out.push(prefix.clone());
            }
            return;
        };
        if name == "self" && !prefix.is_empty() {
            out.push(prefix.clone());
            return;
        }
        prefix.push(name);
        if self.eat("::") {
            self.tree(prefix, out, depth + 1);
        } else {
            out.push(prefix.clone());
        }
    }
}

/// The strongly connected components of two or more nodes (Tarjan), each sorted.
fn strongly_connected(edges: &[BTreeSet<usize>]) -> Vec<Vec<usize>> {
    struct State<'a> {
        edges: &'a [BTreeSet<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(s: &mut State<'_>, v: usize) {
        s.index[v] = Some(s.next);
        s.low[v] = s.next;
        s.next += 1;
        s.stack.push(v);
        s.on_stack[v] = true;
        for &w in s.edges[v].iter() {
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                Some(_) => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack[w] = false;
                component.push(w);
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort_unstable();
                s.out.push(component);
            }
        }
    }
    let n = edges.len();
    let mut state = State {
        edges,
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if state.index[v].is_none() {
            visit(&mut state, v);
        }
    }
    state.out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A crate `demo` under a temporary root with `files` (path under src/, text).
    fn demo(files: &[(&str, &str)]) -> tempfile::TempDir {
        let dir = tempfile::TempDir::new().unwrap();
        for (path, text) in files {
            let file = dir.path().join("demo/src").join(path);
            std::fs::create_dir_all(file.parent().unwrap()).unwrap();
            std::fs::write(file, text).unwrap();
        }
        dir
    }

    #[test]
    fn two_modules_that_import_each_other_are_a_circle_named_with_their_ties() {
        let dir = demo(&[
            ("lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
            ("a.rs", "use crate::b::{B, helper};\npub struct A;\n"),
            (
                "b.rs",
                "pub struct B;\npub fn helper() -> crate::a::A { crate::a::A }\n",
            ),
            ("c.rs", "use crate::a::A;\n"),
        ]);
        let circles = find(dir.path(), "demo").unwrap();
        assert_eq!(circles.len(), 1, "{circles:?}");
        assert_eq!(circles[0].files, ["demo/src/a.rs", "demo/src/b.rs"]);
        assert_eq!(
            circles[0].ties,
            [
                ("demo/src/a.rs".to_owned(), "demo/src/b.rs".to_owned()),
                ("demo/src/b.rs".to_owned(), "demo/src/a.rs".to_owned())
            ]
        );
    }

    #[test]
    fn comments_tests_reexports_and_other_crates_make_no_circle() {
        let dir = demo(&[
            ("lib.rs", "pub mod a;\npub mod b;\npub use a::A;\n"),
            // A doc link, a string and a test module name b; the import of
            // A through the root's re-export resolves to a itself.
            (
                "a.rs",
                "//! See [`crate::b::B`].\npub struct A;\nconst S: &str = \"crate::b::B\";\n\
                 fn f() -> crate::A { A }\n#[cfg(test)]\nmod tests {\n    use crate::b::B;\n}\n",
            ),
            ("b.rs", "use crate::A;\nuse other_crate::b::B;\npub struct B;\n"),
        ]);
        assert_eq!(find(dir.path(), "demo").unwrap(), []);
    }

    #[test]
    fn a_circle_through_super_and_a_nested_folder_is_found() {
        let dir = demo(&[
            ("main.rs", "mod fit;\n"),
            ("fit.rs", "mod rbf;\nuse rbf::Net;\npub fn map() {}\n"),
            ("fit/rbf.rs", "pub struct Net;\nfn g() { super::map() }\n"),
        ]);
        let circles = find(dir.path(), "demo").unwrap();
        assert_eq!(circles.len(), 1, "{circles:?}");
        assert_eq!(circles[0].files, ["demo/src/fit.rs", "demo/src/fit/rbf.rs"]);
    }

    #[test]
    fn a_parent_calling_its_child_by_name_and_the_child_reading_super_is_a_circle() {
        let dir = demo(&[
            ("main.rs", "mod cli;\n"),
            (
                "cli.rs",
                "mod json;\npub struct Args;\npub fn run() { json::write() }\n",
            ),
            ("cli/json.rs", "use super::Args;\npub fn write() {}\n"),
        ]);
        let circles = find(dir.path(), "demo").unwrap();
        assert_eq!(circles.len(), 1, "{circles:?}");
        assert_eq!(circles[0].files, ["demo/src/cli.rs", "demo/src/cli/json.rs"]);
    }
}
