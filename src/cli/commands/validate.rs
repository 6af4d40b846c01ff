//! `dynaflow validate`.

use std::path::PathBuf;

use dynaflow_engine::LoadRequest;

use crate::cli::{EXIT_BAD_INPUT, EXIT_OK};

pub fn validate(graphs: &[PathBuf], json: bool) -> u8 {
    let req = LoadRequest { all_variants: true, ..LoadRequest::default() };
    let registry = crate::registry();
    let mut bad = false;
    let mut all = Vec::new();
    for path in graphs {
        match dynaflow_engine::load(path, &registry, &req) {
            Ok(loaded) => {
                bad |= loaded.has_errors();
                if json {
                    if let Some(items) = loaded.source.to_json(&loaded.diagnostics).as_array() {
                        all.extend(items.iter().cloned());
                    }
                } else {
                    super::print_diagnostics(&loaded);
                    if !loaded.has_errors() {
                        let variants = loaded.spec.as_ref().map_or(0, |s| s.variants.len());
                        eprintln!(
                            "{}: ok ({} nodes, {variants} variants)",
                            path.display(),
                            loaded.graph.as_ref().map_or(0, |g| g.nodes.len())
                        );
                    }
                }
            }
            Err(e) => {
                bad = true;
                if json {
                    all.push(serde_json::json!({"file": path.display().to_string(), "severity": "error", "code": "io", "message": e.to_string()}));
                } else {
                    eprintln!("error: cannot read graph file {}: {e}", path.display());
                }
            }
        }
    }
    if json {
        say!("{}", serde_json::Value::Array(all));
    }
    if bad { EXIT_BAD_INPUT } else { EXIT_OK }
}
