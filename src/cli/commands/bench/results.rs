//! What a bench produces from its runs: a row per run read from its summary (typed node
//! reports), the papers' tables (markdown and CSV), the plots, and `--compare`'s recordings.

use super::*;

/// What a run gave.
#[derive(Clone, Debug, Default)]
pub(super) struct Row {
    pub(super) ok: bool,
    pub(super) error: String,
    /// The run decided with ground truth (its summary's `oracle`): a bound, not a result.
    pub(super) oracle: bool,
    pub(super) frames: u64,
    pub(super) wall_s: f64,
    pub(super) ate: Option<[f64; 4]>,
    pub(super) rpe: Option<[f64; 2]>,
    /// Whole-run wall time per frame, milliseconds.
    pub(super) ms_per_frame: f64,
    /// Busy milliseconds per frame of each node.
    pub(super) nodes: Vec<(String, f64)>,
    /// Each `label_accuracy` node's pooled precision and recall (a rule's labels against the
    /// generator's masks), by node.
    pub(super) labels: Vec<(String, f64, f64)>,
    pub(super) trajectory: Option<(PathBuf, PathBuf)>,
    /// The ATE's alignment (`sim3` for a monocular tracker).
    pub(super) sim3: bool,
    /// The bench was interrupted: the run was stopped, or never started.
    pub(super) interrupted: bool,
}

/// A finished job's row, from its folder (summary, stderr, trajectories) and exit status.
pub(super) fn read_row(job: &Job, exit_ok: bool) -> Row {
    let files = RunFiles::new(&job.dir, &job.name, job.variant.as_deref());
    let summary = Summary::read(&files.summary());
    let mut row = Row { ok: exit_ok, ..Row::default() };
    let s = match summary {
        Ok(s) => s,
        Err(e) => {
            // No summary: the run was refused before it started (the first error line says
            // why) or could not write one.
            let err = std::fs::read_to_string(job.dir.join("stderr.txt")).unwrap_or_default();
            let first = err.lines().find(|l| l.contains("error")).map(str::trim);
            row.ok = false;
            row.error = first.map_or(e, str::to_owned);
            return row;
        }
    };
    if let Some(f) = s.run.failures.first() {
        row.ok = false;
        row.error = format!("`{}` failed: {}", f.node, f.error);
    } else if !row.ok {
        row.error = format!("run {:?}", s.run.status).to_lowercase();
    }
    row.interrupted = s.run.status == dynaflow_engine::runtime::RunStatus::Interrupted;
    row.oracle = s.run.oracle.is_some();
    row.frames = s.run.frames;
    row.wall_s = s.run.wall_s;
    row.ms_per_frame = 1e3 * row.wall_s / row.frames.max(1) as f64;
    if let Some(a) = &s.ate {
        row.ate = Some([a.rmse, a.mean, a.median, a.std]);
        if !a.rmse.is_finite() && row.ok {
            // A tracker that reports no finite error has not been evaluated: never a number.
            row.ok = false;
            row.error = format!("ATE rmse is {}", a.rmse);
        }
    }
    let node = s.ate.as_ref().and_then(|a| a.node.clone()).unwrap_or_else(|| "track".into());
    row.sim3 = s.ate.as_ref().is_some_and(|a| a.align == "sim3");
    for n in &s.run.nodes {
        row.nodes.push((n.node.clone(), 1e3 * n.busy_s / row.frames.max(1) as f64));
    }
    for (name, report) in s.reports() {
        match report {
            NodeReport::Tracker(t) => {
                if name == node
                    && let Some(rpe) = &t.rpe
                {
                    row.rpe = Some([rpe.translation_rmse, rpe.rotation_rmse_deg]);
                }
                if let Some(why) = &t.not_initialised_because
                    && row.ok
                {
                    row.ok = false;
                    row.error = format!("`{name}`: {why}");
                }
            }
            NodeReport::LabelAccuracy(a) if a.frames > 0 => row.labels.push((name.to_owned(), a.precision, a.recall)),
            _ => {}
        }
    }
    let est = files.node_file(&node, "trajectory.txt");
    let gt = files.node_file(&node, "groundtruth.txt");
    if est.exists() && gt.exists() {
        row.trajectory = Some((gt, est));
    }
    row
}

pub(super) fn fmt_cm(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{:.2}", 100.0 * v))
}

/// `--compare`: per graph and sequence, the runs side by side in one recording; a run left
/// out (failed, or no recording) is named.
pub(super) fn compare_variants(jobs: &[Job], rows: &[Row], out: &Path) {
    let mut groups: BTreeMap<(String, String), Vec<(&Job, &Row)>> = BTreeMap::new();
    for (j, r) in jobs.iter().zip(rows) {
        groups.entry((j.name.clone(), j.sequence())).or_default().push((j, r));
    }
    for ((graph, sequence), members) in groups {
        let mut runs = Vec::new();
        for (j, r) in members {
            let file = RunFiles::new(&j.dir, &j.name, j.variant.as_deref()).run_file("mcap");
            if !r.ok {
                eprintln!("compare {graph} {sequence}: `{}` left out: the run failed ({})", j.variant_name(), r.error);
                continue;
            }
            match dynaflow_recordings::diff::compare::read_run(j.variant_name(), &file) {
                Ok(run) => runs.push(run),
                Err(e) => eprintln!("compare {graph} {sequence}: `{}` left out: {e}", j.variant_name()),
            }
        }
        if runs.len() < 2 {
            eprintln!("compare {graph} {sequence}: fewer than two runs to compare");
            continue;
        }
        let path = out.join(format!("compare-{graph}-{sequence}.rrd"));
        match dynaflow_recordings::diff::compare::write_compare(&runs, &path) {
            Ok(_) => println!("wrote {} ({} runs side by side)", path.display(), runs.len()),
            Err(e) => eprintln!("compare {graph} {sequence}: {e}"),
        }
    }
}

/// Print and write the tables and plots; exit 0 when every row is ok, else 1.
pub(super) fn report(jobs: &[Job], rows: &[Row], out: &Path) -> u8 {
    let (md, csv) = tables(jobs, rows);
    print!("{md}");
    if let Err(e) = std::fs::create_dir_all(out) {
        eprintln!("error: cannot create {}: {e}", out.display());
        return EXIT_FAILED;
    }
    let write = |name: &str, text: &str| {
        let p = out.join(name);
        std::fs::write(&p, text).map_err(|e| eprintln!("error: {}: {e}", p.display())).is_ok()
    };
    if !(write("bench.md", &md) && write("bench.csv", &csv)) {
        return EXIT_FAILED;
    }
    if let Err(e) = plots(jobs, rows, out) {
        eprintln!("warning: plots: {e}");
    }
    if rows.iter().all(|r| r.ok) { EXIT_OK } else { EXIT_FAILED }
}

/// The markdown and CSV tables.
pub(super) fn tables(jobs: &[Job], rows: &[Row]) -> (String, String) {
    // Improvement over orb_baseline's plain graph on the same sequence.
    let baseline: BTreeMap<String, f64> = jobs
        .iter()
        .zip(rows)
        .filter(|(j, _)| j.name == "orb_baseline" && j.variant.is_none())
        .filter_map(|(j, r)| r.ate.map(|a| (j.sequence(), a[0])))
        .collect();
    let mut md = String::from(
        "Variants marked (oracle) decide with ground truth (masks, boxes or poses from the generator or the dataset): they bound what a rule can do, they are not results.\n\n| graph | variant | sequence | ATE rmse (cm) | mean | median | std | RPE t (cm) | RPE r (deg) | ms/frame | vs orb_baseline | labels precision / recall (generator masks) |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut csv = String::from(
        "graph,variant,sequence,status,frames,ate_rmse_m,ate_mean_m,ate_median_m,ate_std_m,rpe_t_m,rpe_r_deg,ms_per_frame,improvement_pct,error,oracle,labels_precision_recall\n",
    );
    for (j, r) in jobs.iter().zip(rows) {
        let improvement = match (r.ate, baseline.get(&j.sequence())) {
            (Some(a), Some(b)) if *b > 0.0 && !(j.name == "orb_baseline" && j.variant.is_none()) => {
                Some(100.0 * (b - a[0]) / b)
            }
            _ => None,
        };
        let ate = r.ate.map(|a| a.map(Some)).unwrap_or([None; 4]);
        let variant = if r.oracle { format!("{} (oracle)", j.variant_name()) } else { j.variant_name().to_owned() };
        let rpe = r.rpe.map(|a| a.map(Some)).unwrap_or([None; 2]);
        let labels =
            |sep: &str| r.labels.iter().map(|(n, p, q)| format!("{n} {p:.2}/{q:.2}")).collect::<Vec<_>>().join(sep);
        if r.ok {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {} | {} |\n",
                j.name,
                variant,
                j.sequence(),
                fmt_cm(ate[0]),
                fmt_cm(ate[1]),
                fmt_cm(ate[2]),
                fmt_cm(ate[3]),
                fmt_cm(rpe[0]),
                rpe[1].map_or_else(|| "-".into(), |v| format!("{v:.3}")),
                r.ms_per_frame,
                improvement.map_or_else(|| "-".into(), |v| format!("{v:+.0} %")),
                if r.labels.is_empty() { "-".to_owned() } else { labels("; ") },
            ));
        } else {
            md.push_str(&format!(
                "| {} | {} | {} | **{}**: {} | | | | | | | | |\n",
                j.name,
                variant,
                j.sequence(),
                if r.interrupted { "interrupted" } else { "failed" },
                r.error.replace('|', "/")
            ));
        }
        let f = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:.6}"));
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{:.3},{},\"{}\",{},{}\n",
            j.name,
            j.variant_name(),
            j.sequence(),
            if r.ok {
                "ok"
            } else if r.interrupted {
                "interrupted"
            } else {
                "failed"
            },
            r.frames,
            f(ate[0]),
            f(ate[1]),
            f(ate[2]),
            f(ate[3]),
            f(rpe[0]),
            f(rpe[1]),
            r.ms_per_frame,
            improvement.map_or_else(String::new, |v| format!("{v:.1}")),
            r.error.replace('"', "'"),
            r.oracle,
            labels(" "),
        ));
    }
    (md, csv)
}

/// Trajectory plots per run, ATE per variant, time per node.
pub(super) fn plots(jobs: &[Job], rows: &[Row], out: &Path) -> Result<(), String> {
    for (j, r) in jobs.iter().zip(rows) {
        // A failed run (e.g. a tracker that never initialised) has no trajectory to plot.
        let Some((gt, est)) = r.trajectory.as_ref().filter(|_| r.ok) else { continue };
        let read = |p: &Path| dynaflow_datasets::tum::read_trajectory(p).map_err(|e| e.to_string());
        let align = if r.sim3 { Align::Sim3 } else { Align::Se3 };
        let e = evaluate(&read(gt)?, &read(est)?, 0.01, align, 1).map_err(|e| e.to_string())?;
        let oracle = if r.oracle { " (oracle)" } else { "" };
        let title =
            format!("{} {}{oracle} {}: ATE {:.2} cm", j.name, j.variant_name(), j.sequence(), 100.0 * e.ate.rmse);
        crate::cli::plot::evaluation(&e, &title, &j.dir.join("trajectory.png"))?;
    }
    let runs: Vec<(String, &Row)> = jobs
        .iter()
        .zip(rows)
        .filter(|(_, r)| r.ok)
        .map(|(j, r)| (format!("{} {}{}", j.name, j.variant_name(), if r.oracle { " (oracle)" } else { "" }), r))
        .collect();
    let mut ate: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for (label, r) in &runs {
        if let Some(a) = r.ate {
            ate.entry(label.clone()).or_default().push(100.0 * a[0]);
        }
    }
    crate::cli::plot::boxes(&ate, "ATE rmse per variant (cm), over sequences", &out.join("ate.png"))?;
    let stacks: Vec<(String, Vec<(String, f64)>)> =
        runs.iter().filter(|(_, r)| !r.nodes.is_empty()).map(|(label, r)| (label.clone(), r.nodes.clone())).collect();
    crate::cli::plot::stacked(&stacks, "busy ms per frame, per node", &out.join("time.png"))
}
