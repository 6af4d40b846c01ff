//! Dependency hygiene: the default build compiles no zenoh crate and no PyO3; the `zenoh` and
//! `python` features bring them in (so this check can fail). Reads cargo's own dependency tree.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

/// The crates of `dynaflow`'s build (normal and build dependencies) with `features`.
fn tree(features: &[&str]) -> Vec<String> {
    let out = std::process::Command::new(env!("CARGO"))
        .current_dir(common::repo())
        .args(["tree", "--offline", "--locked", "-p", "dynaflow", "-e", "normal,build", "--prefix", "none"])
        .args(features)
        .output()
        .unwrap();
    assert!(out.status.success(), "cargo tree: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

#[test]
fn the_default_build_has_no_zenoh_crate_and_the_feature_adds_it() {
    let default = tree(&[]);
    assert!(default.iter().any(|c| c == "dynaflow-engine"), "{default:?}");
    let zenoh: Vec<&String> = default.iter().filter(|c| c.starts_with("zenoh")).collect();
    assert!(zenoh.is_empty(), "the default build compiles {zenoh:?}");
    assert!(!default.iter().any(|c| c == "dynaflow-net"));
    let with = tree(&["--features", "zenoh"]);
    assert!(with.iter().any(|c| c == "zenoh") && with.iter().any(|c| c == "dynaflow-net"), "{with:?}");
}

#[test]
fn the_default_build_links_no_python_and_the_feature_adds_it() {
    let default = tree(&[]);
    let pyo3: Vec<&String> = default.iter().filter(|c| c.starts_with("pyo3")).collect();
    assert!(pyo3.is_empty(), "the default build compiles {pyo3:?}");
    let with = tree(&["--features", "python"]);
    assert!(with.iter().any(|c| c == "pyo3"), "{with:?}");
}

/// Each workspace crate's normal dependencies on other workspace crates, from `cargo metadata`.
fn workspace_edges() -> std::collections::BTreeMap<String, Vec<String>> {
    let out = std::process::Command::new(env!("CARGO"))
        .current_dir(common::repo())
        .args(["metadata", "--offline", "--locked", "--no-deps", "--format-version", "1"])
        .output()
        .unwrap();
    assert!(out.status.success(), "cargo metadata: {}", String::from_utf8_lossy(&out.stderr));
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut edges = std::collections::BTreeMap::new();
    for p in meta["packages"].as_array().unwrap() {
        let mut deps: Vec<String> = p["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"].is_null())
            .filter_map(|d| d["name"].as_str()?.strip_prefix("dynaflow-").map(str::to_owned))
            .collect();
        deps.sort();
        edges.insert(p["name"].as_str().unwrap().to_owned(), deps);
    }
    edges
}

#[test]
fn the_crate_table_in_the_architecture_doc_is_the_dependency_graph() {
    let doc = std::fs::read_to_string(common::repo().join("docs/architecture.md")).unwrap();
    let section = doc.split("### Who may depend on whom").nth(1).unwrap();
    let mut documented = std::collections::BTreeMap::new();
    for row in section.lines().filter(|l| l.starts_with("| `dynaflow")) {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let name = cells[1].trim_matches('`').to_owned();
        let mut deps: Vec<String> =
            if cells[2] == "none" { vec![] } else { cells[2].split(", ").map(str::to_owned).collect() };
        deps.sort();
        documented.insert(name, deps);
    }
    assert_eq!(documented, workspace_edges(), "docs/architecture.md's crate table against cargo metadata");
}

#[test]
fn a_library_file_over_600_lines_says_why_in_its_first_lines() {
    fn walk(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().map(Result::unwrap) {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let root = common::repo();
    let mut files = Vec::new();
    walk(&root.join("src"), &mut files);
    for krate in workspace_edges().keys().filter_map(|k| k.strip_prefix("dynaflow-")) {
        walk(&root.join(krate).join("src"), &mut files);
    }
    assert!(files.len() > 100, "{} files", files.len());
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            let head: String = text.lines().take(12).collect::<Vec<_>>().join("\n");
            (text.lines().count() > 600 && !head.contains("Why one file of this size")).then(|| f.display().to_string())
        })
        .collect();
    assert!(long.is_empty(), "over 600 lines without saying why in the first 12: {long:?}");
}
