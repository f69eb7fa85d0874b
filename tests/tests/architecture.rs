//! ARCHITECTURE.md's rules, checked against the source tree: no module circles inside a
//! crate, every source file opens with a `//!` line saying what it owns, and the code map
//! names every source file of each crate.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every `.rs` file below `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries {
            let path = e.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The crates under `crates/`, by folder name.
fn crates() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(root().join("crates"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The module path of a file below a crate's `src` (`a/b.rs` and `a/b/mod.rs` -> `a::b`,
/// `lib.rs` and `main.rs` -> the crate root, empty).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The code of a file without its `#[cfg(test)]` tail, comments and string contents.
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]").next().unwrap_or("");
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let mut in_str = false;
        let mut prev = ' ';
        let mut kept = String::new();
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if in_str {
                if c == '"' && prev != '\\' {
                    in_str = false;
                    kept.push('"');
                }
                prev = if prev == '\\' && c == '\\' { ' ' } else { c };
            } else if c == '/' && chars.get(i + 1) == Some(&'/') {
                break;
            } else if c == '\'' && chars.get(i + 2) == Some(&'\'') {
                // A character literal such as '"'.
                i += 3;
                continue;
            } else if c == '\''
                && chars.get(i + 1) == Some(&'\\')
                && chars.get(i + 3) == Some(&'\'')
            {
                i += 4;
                continue;
            } else {
                if c == '"' {
                    in_str = true;
                }
                kept.push(c);
                prev = c;
            }
            i += 1;
        }
        out.push_str(&kept);
        out.push('\n');
    }
    out
}

/// The module paths a file's code names: `crate::a::b`, `super::x` (relative to `module`),
/// and the items of `crate::{a, b::c}` groups.
fn references(module: &[String], code: &str) -> Vec<Vec<String>> {
    let words = |s: &str| -> Vec<String> {
        s.split("::")
            .map(|w| {
                w.chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect::<String>()
            })
            .take_while(|w| !w.is_empty())
            .collect()
    };
    let mut out = Vec::new();
    for (i, _) in code.match_indices("crate::") {
        let before = code[..i].chars().last();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let rest = &code[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let inner = group.split('}').next().unwrap_or("");
            for item in inner.split(',') {
                let w = words(item.trim());
                if !w.is_empty() {
                    out.push(w);
                }
            }
        } else {
            out.push(words(rest));
        }
    }
    for (i, _) in code.match_indices("super::") {
        let before = code[..i].chars().last();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        let mut rest = &code[i..];
        // `super` of module `a::b` (`a/b.rs` or `a/b/mod.rs`) is `a`.
        let mut base: Vec<String> = module.to_vec();
        while let Some(r) = rest.strip_prefix("super::") {
            base.pop();
            rest = r;
        }
        base.extend(words(rest));
        out.push(base);
    }
    out
}

/// Strongly connected components with more than one module (Tarjan).
fn circles(graph: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<Vec<Vec<String>>> {
    struct State<'a> {
        graph: &'a BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'a Vec<String>, usize>,
        low: BTreeMap<&'a Vec<String>, usize>,
        stack: Vec<&'a Vec<String>>,
        on_stack: BTreeSet<&'a Vec<String>>,
        next: usize,
        found: Vec<Vec<Vec<String>>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a Vec<String>) {
        s.index.insert(v, s.next);
        s.low.insert(v, s.next);
        s.next += 1;
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in &s.graph[v] {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on_stack.remove(w);
                component.push(w.clone());
                if w == v {
                    break;
                }
            }
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
        on_stack: BTreeSet::new(),
        next: 0,
        found: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    s.found
}

/// The modules of one crate's `src` that name each other, grouped by `group` (a module's
/// path to the node it belongs to): a file's module depends on another file's module when
/// its code names it (or an item in it). A parent naming its child, or a child naming an
/// ancestor, is the module tree itself and is not counted; nor is a group naming itself.
fn module_graph(
    src: &Path,
    group: impl Fn(&[String]) -> Vec<String>,
) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let files = rust_files(src);
    let modules: BTreeSet<Vec<String>> = files.iter().map(|f| module_of(src, f)).collect();
    let mut graph: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = modules
        .iter()
        .map(|m| (group(m), BTreeSet::new()))
        .collect();
    for file in &files {
        let module = module_of(src, file);
        let text = std::fs::read_to_string(file).unwrap();
        for path in references(&module, &code(&text)) {
            let target = (1..=path.len())
                .rev()
                .map(|k| path[..k].to_vec())
                .find(|p| modules.contains(p));
            let Some(target) = target else { continue };
            let ancestor = target.len() < module.len() && module.starts_with(&target);
            let descendant = target.len() > module.len() && target.starts_with(&module);
            let (from, to) = (group(&module), group(&target));
            if from != to && !ancestor && !descendant {
                graph.get_mut(&from).unwrap().insert(to);
            }
        }
    }
    graph
}

/// Module circles inside one crate's `src` (see [`module_graph`]).
fn module_circles(src: &Path) -> Vec<Vec<Vec<String>>> {
    circles(&module_graph(src, |m| m.to_vec()))
}

/// Circles between a crate's top-level modules (a folder such as `real/` counts as one
/// module with everything below it), which [`module_circles`] cannot see when they pass
/// through different files of a folder.
fn top_level_circles(src: &Path) -> Vec<Vec<Vec<String>>> {
    circles(&module_graph(src, |m| m.iter().take(1).cloned().collect()))
}

#[test]
fn no_crate_has_folder_circles() {
    let mut all = Vec::new();
    for name in crates()
        .into_iter()
        .chain(["../xtask".into(), "../tests".into()])
    {
        let src = root().join("crates").join(&name).join("src");
        for circle in top_level_circles(&src) {
            let names: Vec<String> = circle.iter().map(|m| m.join("::")).collect();
            all.push(format!("{name}: {}", names.join(" -> ")));
        }
    }
    assert!(
        all.is_empty(),
        "top-level module circles:\n{}",
        all.join("\n")
    );
}

#[test]
fn no_crate_has_module_circles() {
    let mut all = Vec::new();
    for name in crates()
        .into_iter()
        .chain(["../xtask".into(), "../tests".into()])
    {
        let src = root().join("crates").join(&name).join("src");
        for circle in module_circles(&src) {
            let names: Vec<String> = circle.iter().map(|m| m.join("::")).collect();
            all.push(format!("{name}: {}", names.join(" -> ")));
        }
    }
    assert!(all.is_empty(), "module circles:\n{}", all.join("\n"));
}

/// The checker finds a circle when there is one.
#[test]
fn a_circle_between_sibling_modules_is_found() {
    let dir = std::env::temp_dir().join(format!("bitt-arch-circle-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("c")).unwrap();
    std::fs::write(dir.join("lib.rs"), "//! x\nmod a;\nmod b;\nmod c;\n").unwrap();
    std::fs::write(dir.join("a.rs"), "//! a\nuse crate::b::B;\npub struct A;\n").unwrap();
    std::fs::write(dir.join("b.rs"), "//! b\npub struct B(crate::c::d::D);\n").unwrap();
    std::fs::write(dir.join("c/mod.rs"), "//! c\npub mod d;\n").unwrap();
    std::fs::write(
        dir.join("c/d.rs"),
        "//! d\n// crate::b in a comment\npub struct D(super::super::a::A);\n",
    )
    .unwrap();
    let found = module_circles(&dir);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(found.len(), 1, "{found:?}");
    let mut names: Vec<String> = found[0].iter().map(|m| m.join("::")).collect();
    names.sort();
    assert_eq!(names, ["a", "b", "c::d"]);
}

/// A circle through two files of one folder (`c/d.rs` names `b`, `b` names `c/e.rs`) is no
/// circle between files, but one between the top-level modules `b` and `c`.
#[test]
fn a_circle_through_a_folder_is_found() {
    let dir = std::env::temp_dir().join(format!("bitt-arch-folder-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("c")).unwrap();
    std::fs::write(dir.join("lib.rs"), "//! x\nmod b;\nmod c;\n").unwrap();
    std::fs::write(dir.join("b.rs"), "//! b\npub struct B(crate::c::e::E);\n").unwrap();
    std::fs::write(dir.join("c/mod.rs"), "//! c\npub mod d;\npub mod e;\n").unwrap();
    std::fs::write(dir.join("c/d.rs"), "//! d\npub struct D(crate::b::B);\n").unwrap();
    std::fs::write(dir.join("c/e.rs"), "//! e\npub struct E;\n").unwrap();
    let files = module_circles(&dir);
    let folders = top_level_circles(&dir);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(files.is_empty(), "{files:?}");
    assert_eq!(folders.len(), 1, "{folders:?}");
    let mut names: Vec<String> = folders[0].iter().map(|m| m.join("::")).collect();
    names.sort();
    assert_eq!(names, ["b", "c"]);
}

#[test]
fn every_source_file_opens_with_what_it_owns() {
    let mut missing = Vec::new();
    for name in crates() {
        for file in rust_files(&root().join("crates").join(&name).join("src")) {
            let text = std::fs::read_to_string(&file).unwrap();
            if !text.trim_start().starts_with("//!") {
                missing.push(file.display().to_string());
            }
        }
    }
    assert!(
        missing.is_empty(),
        "no opening //! line:\n{}",
        missing.join("\n")
    );
}

/// Each crate's section of ARCHITECTURE.md names each of its source files (by file name,
/// module path or folder), apart from the crate roots, `mod.rs`, `error.rs` and `tests.rs`.
#[test]
fn the_code_map_names_every_source_file() {
    let map = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let sections: Vec<&str> = map.split("\n### ").collect();
    let mut unnamed = Vec::new();
    for name in crates() {
        let heading = format!("`crates/{name}`");
        let Some(section) = sections.iter().find(|s| s.starts_with(&heading)) else {
            unnamed.push(format!("crates/{name} has no section"));
            continue;
        };
        let dir = root().join("crates").join(&name);
        for file in rust_files(&dir) {
            let rel = file.strip_prefix(&dir).unwrap();
            let stem = rel.file_stem().unwrap().to_string_lossy().into_owned();
            if ["lib", "main", "mod", "error", "tests"].contains(&stem.as_str()) {
                continue;
            }
            let in_src = rel.strip_prefix("src").unwrap_or(rel);
            let rel_s = in_src.to_string_lossy().into_owned();
            let folder = in_src
                .parent()
                .map(|p| format!("{}/", p.to_string_lossy()))
                .filter(|p| p != "/");
            let named = section.contains(&format!("{stem}.rs"))
                || section.contains(&rel_s)
                || section.contains(&format!("`{stem}`"))
                || section.contains(&rel_s.trim_end_matches(".rs").replace('/', "::"))
                || folder.is_some_and(|f| section.contains(&format!("`{f}`")));
            if !named {
                unnamed.push(format!("crates/{name}/{}", rel.display()));
            }
        }
    }
    assert!(
        unnamed.is_empty(),
        "ARCHITECTURE.md does not name:\n{}",
        unnamed.join("\n")
    );
}

/// The `[profile.<name>.package.<crate>]` sections of the workspace's Cargo.toml with their
/// `opt-level`.
fn opt_levels(manifest: &str, profile: &str) -> BTreeMap<String, String> {
    let head = format!("[profile.{profile}.package.");
    let mut out = BTreeMap::new();
    let mut current: Option<String> = None;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            current = line
                .strip_prefix(&head)
                .and_then(|rest| rest.strip_suffix(']'))
                .map(|name| name.trim_matches('"').to_string());
        } else if let (Some(name), Some(level)) = (&current, line.strip_prefix("opt-level")) {
            let level = level.trim_start().trim_start_matches('=').trim();
            out.insert(name.clone(), level.trim_matches('"').to_string());
        }
    }
    out
}

/// Cargo.toml's release profile leaves the GPU stack and ndarray unoptimised (a shorter first
/// build); the `gpu` profile, which `cargo xtask gpu-bundle` builds, optimises every one of
/// them again, and flex and burn-dispatch are never among them.
#[test]
fn the_gpu_profile_optimises_what_the_release_profile_does_not() {
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let release = opt_levels(&manifest, "release");
    let gpu = opt_levels(&manifest, "gpu");
    let lowered: Vec<&String> = release
        .iter()
        .filter(|(_, level)| level.as_str() != "3")
        .map(|(name, _)| name)
        .collect();
    assert!(lowered.len() >= 20, "{release:?}");
    for name in &lowered {
        assert_eq!(
            gpu.get(*name).map(String::as_str),
            Some("3"),
            "[profile.gpu.package.{name}] must set opt-level = 3"
        );
    }
    for hot in ["burn-flex", "burn-dispatch", "burn-autodiff", "gemm", "*"] {
        assert!(
            !lowered.iter().any(|n| n.as_str() == hot),
            "{hot} is on the CPU path and must stay optimised"
        );
    }
}

#[test]
fn opt_levels_reads_package_sections() {
    let manifest = "[profile.release]\nopt-level = 3\n[profile.release.package.\"*\"]\ndebug = false\n\
                    [profile.release.package.naga]\nopt-level = 0\n[profile.gpu.package.naga]\nopt-level = 3\n";
    assert_eq!(
        opt_levels(manifest, "release"),
        BTreeMap::from([("naga".to_string(), "0".to_string())])
    );
    assert_eq!(
        opt_levels(manifest, "gpu"),
        BTreeMap::from([("naga".to_string(), "3".to_string())])
    );
}
