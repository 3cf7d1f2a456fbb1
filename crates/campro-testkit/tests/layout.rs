//! The architecture's rule "no import cycle in any crate", checked on the sources: every
//! `crate::` and `super::` path in a module's code (not its tests, comments, `mod`
//! declarations or re-exports) is an edge to the module file it names; no crate may have
//! a cycle of such edges.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

type Module = Vec<String>;

/// Every module of the crate rooted at `src`, by path (`["targets", "camera2"]`).
fn modules(src: &Path, dir: &Path, out: &mut BTreeMap<Module, String>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            modules(src, &p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            let rel = p.strip_prefix(src).unwrap().with_extension("");
            let mut m: Module = rel.iter().map(|c| c.to_string_lossy().into_owned()).collect();
            if matches!(m.last().map(String::as_str), Some("mod" | "lib" | "main")) {
                m.pop();
            }
            out.insert(m, std::fs::read_to_string(&p).unwrap());
        }
    }
}

/// The module files `code` (of module `m`) refers to.
fn edges(m: &Module, code: &str, all: &BTreeMap<Module, String>) -> BTreeSet<Module> {
    let code = code.split("#[cfg(test)]").next().unwrap_or("");
    let mut out = BTreeSet::new();
    for stmt in code.lines().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n").split(';') {
        let s = stmt.trim();
        if ["pub use", "pub(crate) use", "mod ", "pub mod"].iter().any(|p| s.starts_with(p)) {
            continue;
        }
        for (anchor, base) in [("crate::", Vec::new()), ("super::", m[..m.len().saturating_sub(1)].to_vec())] {
            for (i, _) in s.match_indices(anchor) {
                let preceded = s[..i].chars().last().is_some_and(|c| c.is_alphanumeric() || c == '_');
                if preceded {
                    continue;
                }
                let mut path = base.clone();
                for seg in s[i + anchor.len()..].split("::") {
                    let seg: String =
                        seg.chars().take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_').collect();
                    if seg.is_empty() {
                        break;
                    }
                    path.push(seg);
                }
                if let Some(t) = (1..=path.len()).rev().map(|k| path[..k].to_vec()).find(|p| all.contains_key(p)) {
                    if &t != m {
                        out.insert(t);
                    }
                }
            }
        }
    }
    out
}

/// A cycle through `start`, if any (depth-first search).
fn cycle(graph: &BTreeMap<Module, BTreeSet<Module>>) -> Option<Vec<Module>> {
    fn visit(
        v: &Module,
        g: &BTreeMap<Module, BTreeSet<Module>>,
        path: &mut Vec<Module>,
        done: &mut BTreeSet<Module>,
    ) -> Option<Vec<Module>> {
        if let Some(i) = path.iter().position(|p| p == v) {
            return Some(path[i..].to_vec());
        }
        if done.contains(v) {
            return None;
        }
        path.push(v.clone());
        for w in g.get(v).into_iter().flatten() {
            if let Some(c) = visit(w, g, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(v.clone());
        None
    }
    let mut done = BTreeSet::new();
    graph.keys().find_map(|v| visit(v, graph, &mut Vec::new(), &mut done))
}

#[test]
fn no_crate_has_an_import_cycle() {
    let root = campro_testkit::workspace_root();
    for crate_src in [
        "src",
        "crates/campro-cli/src",
        "crates/campro-eval/src",
        "crates/campro-train/src",
        "crates/campro-testkit/src",
        "jni-bridge/src",
    ] {
        let src = root.join(crate_src);
        let mut all = BTreeMap::new();
        modules(&src, &src, &mut all);
        assert!(all.len() > 1 || crate_src.contains("jni"), "{crate_src}: no modules found");
        let graph: BTreeMap<Module, BTreeSet<Module>> =
            all.iter().map(|(m, code)| (m.clone(), edges(m, code, &all))).collect();
        if let Some(c) = cycle(&graph) {
            panic!("{crate_src}: import cycle {}", c.iter().map(|m| m.join("::")).collect::<Vec<_>>().join(" -> "));
        }
    }
}

/// The checker finds a cycle when there is one (two modules naming each other).
#[test]
fn the_checker_sees_a_planted_cycle() {
    let mut all = BTreeMap::new();
    all.insert(vec!["a".to_string()], "use crate::b::X;\nfn f() {}".to_string());
    all.insert(vec!["b".to_string()], "fn g() { crate::a::f() }".to_string());
    all.insert(vec!["c".to_string()], "pub use crate::a::f;".to_string());
    let graph: BTreeMap<Module, BTreeSet<Module>> = all.iter().map(|(m, c)| (m.clone(), edges(m, c, &all))).collect();
    assert!(graph[&vec!["c".to_string()]].is_empty(), "a re-export is not an edge");
    assert_eq!(cycle(&graph).map(|c| c.len()), Some(2));
}
