//! Dependency hygiene: the default build compiles no zenoh crate; the `zenoh`
//! feature brings it in (so this check can fail). Reads cargo's own dependency tree.
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
