//! Records the git commit dynaflow was built from, for provenance in recordings.

fn main() {
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown".to_owned());
    // GIT_OPTIONAL_LOCKS=0: `git status` would otherwise refresh and rewrite `.git/index`, which
    // this script watches, so the next cargo invocation would rebuild the engine and every
    // crate above it (a fresh clone's first status always refreshes it).
    let dirty = std::process::Command::new("git")
        .env("GIT_OPTIONAL_LOCKS", "0")
        .args(["status", "--porcelain", "--untracked-files=no"])
        .output()
        .ok()
        .is_some_and(|o| o.status.success() && !o.stdout.is_empty());
    println!("cargo:rustc-env=DYNAFLOW_GIT_COMMIT={commit}{}", if dirty { "-dirty" } else { "" });
    for path in ["../.git/HEAD", "../.git/index"] {
        if std::path::Path::new(path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
}
