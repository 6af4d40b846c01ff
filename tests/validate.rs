//! `dynaflow validate` on broken graphs: every case is reported with its line:col and a hint,
//! the CLI exits 2, and no input makes validation panic.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use dynaflow_engine::diag::Severity;
use dynaflow_engine::yaml::line_col;
use dynaflow_engine::{LoadRequest, load_str};

/// `(line, col, code, text the message or hint must contain)`.
type Expect = (usize, usize, &'static str, &'static str);

fn check(file: &str, expected: &[Expect]) {
    let path = common::repo().join("tests/graphs/invalid").join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    let req = LoadRequest { all_variants: true, ..LoadRequest::default() };
    let loaded = load_str(file, &text, None, &dynaflow::registry(), &req);
    let errors: Vec<(usize, usize, &str, String)> = loaded
        .diagnostics
        .iter()
        .filter(|d| d.severity == Severity::Error)
        .map(|d| {
            let (l, c) = d.span.map_or((0, 0), |s| line_col(&text, s.offset));
            (l, c, d.code, format!("{} | {}", d.message, d.hint.clone().unwrap_or_default()))
        })
        .collect();
    assert!(loaded.graph.is_none(), "{file}: invalid graph resolved");
    for (line, col, code, needle) in expected {
        assert!(
            errors.iter().any(|(l, c, k, m)| l == line && c == col && k == code && m.contains(needle)),
            "{file}: expected {code} at {line}:{col} containing {needle:?}; got {errors:#?}"
        );
    }
    assert_eq!(errors.len(), expected.len(), "{file}: unexpected extra errors: {errors:#?}");
    for d in loaded.diagnostics.iter().filter(|d| d.is_error()) {
        assert!(d.hint.is_some() || d.code == "bad-value" || d.code == "variant", "{file}: error without hint: {d:?}");
    }
    // The CLI agrees and exits 2, printing file:line:col.
    let out = common::bin().arg("validate").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{file}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    for (line, col, _, _) in expected {
        assert!(stderr.contains(&format!("{file}:{line}:{col}:")), "{file}: CLI output lacks {line}:{col}:\n{stderr}");
    }
}

#[test]
fn yaml_syntax_error() {
    check("yaml_syntax.yaml", &[(4, 3, "yaml-syntax", "YAML syntax error")]);
}

#[test]
fn unknown_op() {
    check("unknown_op.yaml", &[(3, 17, "unknown-op", "did you mean `testing.test_pattern`?")]);
}

#[test]
fn misspelt_param() {
    check("misspelt_param.yaml", &[(5, 27, "unknown-param", "did you mean `width`?")]);
}

#[test]
fn ill_typed_and_out_of_range_params() {
    check(
        "bad_param_value.yaml",
        &[
            (5, 23, "param-range", "-3 is out of range 1..=100000000"),
            (5, 36, "param-range", "finite"),
            (5, 49, "param-type", "expects integer"),
            (9, 29, "param-value", "`gausian` is not one of"),
        ],
    );
}

#[test]
fn typed_enum_list_map_and_format_params_and_wired_inputs() {
    // Every value of a typed parameter (an enum, each item of a list, each key and
    // value of a map, a format of its own) is checked where it is written; a rule's wired
    // input must be connected; a retired operator names its replacement; a variant that
    // swaps a node's operator is checked against the new one.
    check(
        "typed_params.yaml",
        &[
            (4, 53, "param-value", "`zigzag` is not one of `static`, `xyz`"),
            (6, 107, "param-value", "param `classes[1]`: `persn`"),
            (7, 116, "param-value", "param `values` key `chiar`"),
            (7, 133, "param-type", "param `values.cup` expects number in 0..=1"),
            (9, 3, "missing-input", "required input `pose` (pose) is not connected"),
            (10, 14, "unknown-op", "`mask` -> `cull_mask`"),
            (11, 55, "param-value", "param `intrinsics`: expected `fr1`"),
            (14, 83, "param-value", "variant `flow_rule`: node `people`: param `motion_model`: `affine`"),
        ],
    );
}

#[test]
fn every_default_is_a_valid_value_of_its_parameter() {
    // Each operator's defaults, written into a graph as values, pass its own validation: a
    // typed default out of its declared range, or of the wrong shape, is caught here.
    let registry = dynaflow::registry();
    for op in registry.iter() {
        let params: serde_json::Map<String, serde_json::Value> =
            op.params.iter().filter_map(|p| Some((p.name.to_owned(), p.default.to_json()?))).collect();
        let text =
            format!("name: t\nnodes:\n  n: {{ op: {}, params: {} }}\n", op.name, serde_json::Value::Object(params));
        let loaded = load_str("t.yaml", &text, None, &registry, &LoadRequest::default());
        let bad: Vec<_> = loaded.diagnostics.iter().filter(|d| d.code.starts_with("param-")).collect();
        assert!(bad.is_empty(), "{}: {bad:#?}\n{text}", op.name);
    }
}

#[test]
fn type_mismatched_edge() {
    check("type_mismatch.yaml", &[(6, 14, "port-type-mismatch", "outputs of that type: `camera.tick`")]);
}

#[test]
fn cycle_without_delay() {
    check("cycle.yaml", &[(10, 10, "cycle", "delay: 1")]);
}

#[test]
fn missing_input() {
    check("missing_input.yaml", &[(4, 3, "missing-input", "in: { a: camera.tick }")]);
}

#[test]
fn bad_variants() {
    check(
        "bad_variant.yaml",
        &[(9, 5, "unknown-node", "did you mean `fuse`?"), (11, 23, "unknown-param", "variant `wrong_param`")],
    );
}

#[test]
fn unknown_nodes_and_ports() {
    check(
        "unknown_refs.yaml",
        &[
            (7, 10, "unknown-node", "did you mean `camera`?"),
            (8, 10, "unknown-port", "did you mean `tick`?"),
            (9, 7, "unknown-port", "has no input `c`"),
            (12, 18, "bad-port-ref", "write `camera.image`"),
        ],
    );
}

#[test]
fn duplicate_ids() {
    check("duplicate_id.yaml", &[(4, 3, "duplicate-id", "duplicate node id `camera`")]);
}

#[test]
fn structural_errors() {
    check(
        "structure.yaml",
        &[
            (2, 1, "unknown-key", "did you mean `seed`?"),
            (4, 47, "bad-value", "record policy"),
            (5, 3, "bad-id", "letters, digits"),
            (5, 3, "missing-input", "required input `input`"),
            (9, 37, "bad-value", "did you mean `lockstep`?"),
            (9, 70, "bad-value", "at least 1"),
        ],
    );
}

#[test]
fn unknown_variant_on_the_command_line() {
    let out = common::bin()
        .args(["run", "--no-progress", "--variant", "no_detectr"])
        .arg(common::repo().join("graphs/engine_smoke.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("unknown variant `no_detectr`") && stderr.contains("did you mean `no_detector`?"),
        "{stderr}"
    );
}

#[test]
fn bad_set_override_points_at_the_node() {
    let out = common::bin().args(["validate"]).arg(common::repo().join("graphs/engine_smoke.yaml")).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let out = common::bin()
        .args(["run", "--no-progress", "--set", "camera.frame=3"])
        .arg(common::repo().join("graphs/engine_smoke.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("did you mean `frames`?"));
}

#[test]
fn a_set_value_error_names_the_flag_it_came_from() {
    // A `--set` value's error pointed at the YAML node and read as if the
    // file held the value. Now every error on an overridden value names the flag, at the node
    // it overrides: validation errors (range, type, unknown key) and an operator refusing the
    // value when it is built (a misspelt class), which before had no location at all.
    let graph = common::repo().join("graphs/octomap.yaml");
    let text = std::fs::read_to_string(&graph).unwrap();
    let at = text.find("  map:").unwrap() + 2;
    let (line, col) = line_col(&text, at);
    let cases = [
        ("map.resolution=0.0001", "error[param-range]", "param `resolution` = 0.0001 is out of range"),
        ("map.resolution=abc", "error[param-type]", "param `resolution` expects number"),
        ("map.resolutio=0.1", "error[unknown-param]", "did you mean `resolution`?"),
        ("map.dynamic_classes=persn", "error[param-value]", "did you mean `person`?"),
    ];
    for (set, code, says) in cases {
        let out = common::bin()
            .args(["run", "--no-progress", "--record", "none", "--frames", "1", "--set", set, "--out"])
            .arg(std::env::temp_dir().join("dynaflow-set-origin"))
            .arg(&graph)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{set}: {stderr}");
        let first = stderr.lines().next().unwrap_or_default();
        let want = format!("octomap.yaml:{line}:{col}: {code}: `--set {set}`: node `map`: ");
        assert!(first.contains(&want) && first.contains(says), "{set}: wanted `{want}` … `{says}` in\n{stderr}");
    }
    // A value written in the file is reported as the file's, with no flag named.
    let dir = common::TempDir::new("set-origin");
    let bad = dir.path().join("g.yaml");
    std::fs::write(&bad, text.replace("dynamic_classes: \"\"", "dynamic_classes: persn")).unwrap();
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "1", "--variant", "ghosts", "--out"])
        .arg(dir.path())
        .arg(&bad)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("error[param-value]: node `map`: param `dynamic_classes[0]`") && !stderr.contains("--set"),
        "{stderr}"
    );
}

#[test]
fn unused_outputs_are_warnings() {
    let text = "name: w\nnodes:\n  camera: { op: testing.test_pattern, record: { image: none } }\n  p: { op: passthrough, in: { input: camera.tick } }\n";
    let loaded = load_str("w.yaml", text, None, &dynaflow::registry(), &LoadRequest::default());
    assert!(loaded.graph.is_some());
    let w: Vec<_> = loaded.diagnostics.iter().filter(|d| d.severity == Severity::Warning).collect();
    assert_eq!(w.len(), 1, "{w:?}");
    assert_eq!(w[0].code, "unused-output");
    assert!(w[0].message.contains("camera.image"));
}

#[test]
fn every_shipped_graph_validates() {
    for entry in std::fs::read_dir(common::repo().join("graphs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "yaml") {
            let out = common::bin().arg("validate").arg(&path).output().unwrap();
            assert_eq!(out.status.code(), Some(0), "{}: {}", path.display(), String::from_utf8_lossy(&out.stderr));
        }
    }
}

const VALID: &str = include_str!("../graphs/engine_smoke.yaml");

fn assert_sane(text: &str) {
    let loaded = load_str(
        "fuzz.yaml",
        text,
        None,
        &dynaflow::registry(),
        &LoadRequest { all_variants: true, ..Default::default() },
    );
    for d in &loaded.diagnostics {
        if let Some(s) = d.span {
            assert!(s.offset + s.len <= text.len(), "span out of bounds: {d:?}");
        }
        let _ = loaded.source.plain(d);
        let _ = format!("{:?}", loaded.source.report(d));
    }
    assert_eq!(loaded.graph.is_some(), !loaded.has_errors());
}

/// Random inputs drawn from a seeded generator (reproducible; the failing case is printed).
const CASES: u64 = 256;

/// Arbitrary text never panics the validator and every span lies inside the text.
#[test]
fn arbitrary_text_never_panics() {
    for case in 0..CASES {
        let mut rng = common::Rng::new(case);
        let len = rng.below(201);
        let text: String = (0..len)
            .map(|_| match rng.below(4) {
                // Mostly printable ASCII, some multi-byte text, some whitespace.
                0..=1 => char::from(0x20 + rng.below(0x5f) as u8),
                2 => char::from_u32(0xa0 + rng.below(0x2f00) as u32).unwrap_or('é'),
                _ => *rng.pick(&['\n', '\t', ' ', ':', '-']),
            })
            .collect();
        assert_sane(&text);
    }
}

/// YAML-ish token soup: structure characters, keys the schema knows, odd values.
#[test]
fn token_soup_never_panics() {
    const TOKENS: &[&str] = &[
        "name: g\n",
        "nodes:\n",
        "  a: ",
        "  b: ",
        "{ op: testing.test_pattern }",
        "{ op: passthrough, in: { input: a.image } }",
        "op: ",
        "in: ",
        "params: ",
        "{",
        "}",
        "[",
        "]",
        ": ",
        ", ",
        "\n",
        "    ",
        "- ",
        "&x ",
        "*x",
        "~",
        "'q'",
        "\"d\"",
        "1e999",
        "-1",
        ".nan",
        "delay: 1",
        "join: latest",
        "queue: { drop_oldest: 2 }",
        "variants:\n",
        "  v: { a: { disabled: true } }",
        "a.tick",
        "a.image",
        "b.output",
        "record: every 2",
        "é",
        "\t",
        "---\n",
        "...\n",
        "!!str ",
        "? ",
        "|\n",
    ];
    for case in 0..CASES {
        let mut rng = common::Rng::new(1000 + case);
        let n = rng.below(40);
        let text: String = (0..n).map(|_| *rng.pick(TOKENS)).collect();
        assert_sane(&text);
    }
}

/// Single-character mutations of a valid graph.
#[test]
fn mutated_valid_graph_never_panics() {
    for case in 0..CASES {
        let mut rng = common::Rng::new(2000 + case);
        let pos = rng.below(VALID.len() as u64) as usize;
        let ch = *rng.pick(&[' ', ':', '{', '}', '-', '\n', 'x', '.', '#', '"']);
        let mut text = VALID.to_owned();
        if text.is_char_boundary(pos) {
            text.insert(pos, ch);
        }
        assert_sane(&text);
    }
}

#[test]
fn a_variant_that_decides_with_ground_truth_must_declare_it() {
    // The direct route, through an oracle operator and through a statistics node; the
    // declared variant, the base graph (ground truth only in statistics) and the disabled
    // oracle node pass.
    check(
        "undeclared_oracle.yaml",
        &[
            (
                11,
                61,
                "undeclared-oracle",
                "variant `gt_masks` decides with ground truth but does not declare `oracle: true`: cull/mask <- camera.gt_mask",
            ),
            // The oracle node's input is written in the base graph; the variant enables it.
            (
                5,
                42,
                "undeclared-oracle",
                "variant `gt_boxes` decides with ground truth but does not declare `oracle: true`: boxes/mask <- camera.gt_mask",
            ),
            (14, 31, "undeclared-oracle", "cull/detections <- boxes.detections (from camera.gt_mask)"),
            (19, 30, "undeclared-oracle", "cull/key_frame <- stats.stats (from camera.gt_mask)"),
        ],
    );
}

#[test]
fn oracles_are_marked_in_the_resolved_graph_and_unused_declarations_warned() {
    let text = std::fs::read_to_string(common::repo().join("tests/graphs/invalid/undeclared_oracle.yaml")).unwrap();
    let load = |variant: Option<&str>| {
        let req = LoadRequest { variant: variant.map(str::to_owned), ..LoadRequest::default() };
        load_str("undeclared_oracle.yaml", &text, None, &dynaflow::registry(), &req)
    };
    let base = load(None);
    assert_eq!(base.graph.as_ref().map(|g| g.oracle.clone()), Some(None), "{:?}", base.diagnostics);
    let declared = load(Some("declared"));
    assert_eq!(declared.graph.unwrap().oracle, Some(vec!["cull/mask <- camera.gt_mask".to_owned()]));
    // `oracle: true` where nothing decides with ground truth: a warning, and the mark stays.
    let text = "name: t\noracle: true\nnodes:\n  camera: { op: synth, params: { frames: 4 } }\n  flow: { op: lk_flow, in: { image: camera.rgb } }\n";
    let loaded = load_str("t.yaml", text, None, &dynaflow::registry(), &LoadRequest::default());
    let warning = loaded.diagnostics.iter().find(|d| d.code == "unused-oracle").unwrap();
    assert_eq!(warning.severity, Severity::Warning);
    assert_eq!(line_col(text, warning.span.unwrap().offset), (2, 1));
    assert_eq!(loaded.graph.unwrap().oracle, Some(vec![]));
}

#[test]
fn every_shipped_graph_declares_its_oracles() {
    // Each shipped graph and variant validates (an undeclared oracle is an error), and the
    // ones that decide with ground truth are exactly those documented as oracles.
    let mut oracles = Vec::new();
    for entry in std::fs::read_dir(common::repo().join("graphs")).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        let file = path.file_name().unwrap().to_string_lossy().into_owned();
        let spec_variants: Vec<String> = {
            let doc = dynaflow_engine::yaml::parse(&text).unwrap();
            dynaflow_engine::spec::parse_graph(&doc).0.variants.into_iter().map(|v| v.name).collect()
        };
        for variant in std::iter::once(None).chain(spec_variants.into_iter().map(Some)) {
            let req = LoadRequest { variant: variant.clone(), ..LoadRequest::default() };
            let loaded = load_str(&file, &text, None, &dynaflow::registry(), &req);
            let g = loaded.graph.unwrap_or_else(|| panic!("{file} {variant:?}: {:?}", loaded.diagnostics));
            assert!(
                !loaded.diagnostics.iter().any(|d| d.code == "unused-oracle"),
                "{file} {variant:?} declares an oracle it is not"
            );
            if g.oracle.is_some() {
                oracles.push(format!("{} {}", g.name, variant.as_deref().unwrap_or("base")));
            }
        }
    }
    oracles.sort();
    let expected = [
        "culling depth_consistency",
        "culling epipolar_adaptive",
        "culling mask",
        "culling mask_or_epipolar",
        "culling pspnet",
        "culling semantic_prior",
        "default masked",
        "mg_slam oracle",
        "mg_slam oracle_S",
        "octomap base",
        "octomap by_class",
        "octomap ghosts",
        "orb_baseline masked",
        "pspnet_slam oracle",
        "yg_slam oracle",
        "yg_slam oracle_detector_m",
        "yoec_dslam oracle",
        "yoec_dslam oracle_masks",
        "ysag oracle",
    ];
    assert_eq!(oracles, expected);
}

#[test]
fn a_tracker_without_what_its_sensor_needs() {
    // The stereo matcher without the right image, the stereo tracker without the rig.
    check(
        "track_stereo_unwired.yaml",
        &[
            (5, 3, "missing-input", "`right` (image) is not connected | wire it, e.g. `in: { right: camera.right }`"),
            (8, 3, "missing-input", "required input `stereo` (stereo_rig) is not connected"),
        ],
    );
    // The RGB-D tracker without depth; the retired `pnp_track` names its replacements.
    check(
        "track_rgbd_no_depth.yaml",
        &[
            (5, 3, "missing-input", "required input `depth` (depth) is not connected"),
            (9, 9, "unknown-op", "`op: track_rgbd`"),
        ],
    );
}
