//! No import circle between softvk's modules: at every level of the module tree, the graph of
//! which sibling module names which (through `crate::a::b` or `super::b` paths in code, not in
//! comments or test modules) has no cycle, so each module's imports say where it sits and a
//! module can be lifted into a crate of its own with what it names below it.
//!
//! The check reads the sources (it needs no device). A path is attributed to the first level
//! where it leaves the naming file's module: `crate::raster::gpu` named from `fit::mesh_fit`
//! is an edge `fit -> raster` at the top; `super::iteration` named from `bench::fits` is
//! `fits -> iteration` inside `bench`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// `(parent module, from, to)` → the first `file:line` that names it.
type Edges = BTreeMap<(String, String, String), String>;

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module a file holds: `raster/gpu/mod.rs` → `[raster, gpu]`.
fn module_of(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The module paths `line` names, absolute: `crate::a::b…` as `[a, b, …]`, and `super::…`
/// resolved against `me`.
fn named_paths(line: &str, me: &[String]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes: Vec<char> = line.chars().collect();
    let mut i = 0;
    while i < bytes.len() {
        let starts_word = i == 0 || !is_ident(bytes[i - 1]);
        let rest: String = bytes[i..].iter().collect();
        if starts_word && (rest.starts_with("crate::") || rest.starts_with("super::")) {
            let mut segments: Vec<String> = Vec::new();
            let mut j = i;
            loop {
                let start = j;
                while j < bytes.len() && is_ident(bytes[j]) {
                    j += 1;
                }
                segments.push(bytes[start..j].iter().collect());
                if bytes[j..].starts_with(&[':', ':']) {
                    j += 2;
                } else {
                    break;
                }
            }
            let resolved = if segments[0] == "crate" {
                segments[1..].to_vec()
            } else {
                let ups = segments.iter().take_while(|s| *s == "super").count();
                let mut base = me[..me.len().saturating_sub(ups)].to_vec();
                base.extend(segments[ups..].iter().cloned());
                base
            };
            // Only module names (lower case): a type or a glob ends the path.
            let modules: Vec<String> = resolved
                .into_iter()
                .take_while(|s| s.chars().next().is_some_and(|c| c.is_ascii_lowercase()))
                .collect();
            out.push(modules);
            i = j.max(i + 1);
        } else {
            i += 1;
        }
    }
    out
}

/// The edges of one crate's module tree, `shown` being how its `src/` appears in messages.
fn edges(src: &Path, shown: &str) -> Edges {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut edges = Edges::new();
    for path in files {
        let rel = path.strip_prefix(src).unwrap();
        let me = module_of(rel);
        if me.last().is_some_and(|m| m == "tests") || me.iter().any(|m| m == "test_support") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        // A file's own unit tests come last: what they name is not the module's.
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap();
        for (n, line) in code.lines().enumerate() {
            let line = line.trim_start();
            if line.starts_with("//") {
                continue;
            }
            for to in named_paths(line, &me) {
                let common = me.iter().zip(&to).take_while(|(a, b)| a == b).count();
                if common < me.len() && common < to.len() {
                    let key = (
                        me[..common].join("::"),
                        me[common].clone(),
                        to[common].clone(),
                    );
                    edges
                        .entry(key)
                        .or_insert_with(|| format!("{shown}/{}:{}", rel.display(), n + 1));
                }
            }
        }
    }
    edges
}

/// The cycles of one level's graph, each with the edges that close it.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    // Tarjan's strongly connected components; a component of two or more is a circle.
    struct State<'g> {
        graph: &'g BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'g str, usize>,
        low: BTreeMap<&'g str, usize>,
        stack: Vec<&'g str>,
        found: Vec<Vec<String>>,
    }
    fn visit<'g>(s: &mut State<'g>, v: &'g str) {
        let i = s.index.len();
        s.index.insert(v, i);
        s.low.insert(v, i);
        s.stack.push(v);
        for w in s.graph.get(v).into_iter().flatten() {
            if !s.index.contains_key(w.as_str()) {
                visit(s, w);
                let lw = s.low[w.as_str()];
                s.low.insert(v, s.low[v].min(lw));
            } else if s.stack.contains(&w.as_str()) {
                let iw = s.index[w.as_str()];
                s.low.insert(v, s.low[v].min(iw));
            }
        }
        if s.low[v] == s.index[v] {
            let at = s.stack.iter().rposition(|x| *x == v).unwrap();
            let component: Vec<String> = s.stack.drain(at..).map(String::from).collect();
            if component.len() > 1 {
                s.found.push(component);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.found
}

fn circles(edges: &Edges) -> Vec<String> {
    let mut levels: BTreeMap<&str, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (parent, from, to) in edges.keys() {
        levels
            .entry(parent)
            .or_default()
            .entry(from.clone())
            .or_default()
            .insert(to.clone());
    }
    let mut report = Vec::new();
    for (parent, graph) in &levels {
        for component in cycles(graph) {
            let mut lines = vec![format!(
                "in `{}`: {} name each other",
                if parent.is_empty() { "crate" } else { parent },
                component.join(", ")
            )];
            for a in &component {
                for b in &component {
                    let key = (parent.to_string(), a.clone(), b.clone());
                    if let Some(at) = edges.get(&key) {
                        lines.push(format!("    {a} -> {b} at {at}"));
                    }
                }
            }
            report.push(lines.join("\n"));
        }
    }
    report
}

/// `(parent module, from, to)`.
type Edge = (&'static str, &'static str, &'static str);

#[test]
fn no_module_names_a_module_that_names_it_back() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // Each crate of the workspace, with edges the scan must find in it (so that the graph is the
    // real one). Between crates cargo itself refuses a circle.
    let crates: [(&str, &[Edge]); 5] = [
        (
            "crates/softvk-gpu/src",
            &[("", "primitives", "gpu"), ("", "fmath", "gpu")],
        ),
        (
            "crates/softvk-raster/src",
            &[("", "raster", "gpu"), ("", "lighting", "mesh")],
        ),
        (
            "crates/softvk-fit/src",
            &[("", "fit", "io"), ("fit", "mesh_fit", "driver")],
        ),
        (
            "crates/softvk-field/src",
            &[("", "field_fit", "probe"), ("", "probe", "field")],
        ),
        (
            "src",
            &[("", "recon", "nn"), ("bench", "fits", "iteration")],
        ),
    ];
    for (src, known) in crates {
        let edges = edges(&root.join(src), src);
        for &(parent, from, to) in known {
            let key = (parent.to_string(), from.to_string(), to.to_string());
            assert!(
                edges.contains_key(&key),
                "{src}: no edge {from} -> {to} in `{parent}`: the scan is broken"
            );
        }
        let found = circles(&edges);
        assert!(
            found.is_empty(),
            "{src}: import circles:\n{}",
            found.join("\n")
        );
    }
}

#[test]
fn the_check_finds_a_circle_and_names_where() {
    let me = |m: &str| m.split("::").map(String::from).collect::<Vec<_>>();
    assert_eq!(
        named_paths(
            "use crate::raster::gpu::{Renderer, x};",
            &me("fit::mesh_fit")
        ),
        vec![me("raster::gpu")]
    );
    assert_eq!(
        named_paths(
            "let t = super::super::iteration::Shape;",
            &me("bench::fits::inner")
        ),
        vec![me("bench::iteration")]
    );
    assert!(named_paths("supercrate::a; my_crate::b", &me("x")).is_empty());
    let mut edges = Edges::new();
    for (from, to) in [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")] {
        edges.insert(("m".into(), from.into(), to.into()), format!("{from}.rs:1"));
    }
    let found = circles(&edges);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].contains("in `m`") && found[0].contains("c -> a at c.rs:1"),
        "{}",
        found[0]
    );
    assert!(!found[0].contains("-> d"), "{}", found[0]);
}
