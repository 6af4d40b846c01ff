//! `dynaflow octree FILE [--plot OUT.png]`: what an OctoMap file (`.ot`, `.bt`) holds, and a
//! top-down picture of its occupied voxels, without octovis.

use std::path::PathBuf;

use dynaflow_octomap::{OcTree, read};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow octree` arguments.
#[derive(Debug, clap::Args)]
pub struct OctreeArgs {
    /// An OctoMap file (`.ot` or `.bt`), ours or OctoMap's.
    pub file: PathBuf,
    /// Draw the occupied voxels seen from above (x right, y up; the voxel's colour, or its
    /// height for a plain OcTree) into this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Pixels per voxel edge in the plot.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=32))]
    pub scale: u32,
}

/// Exit 0 with a JSON summary on stdout; 2 for a missing, corrupt or truncated file.
pub fn octree(args: &OctreeArgs) -> u8 {
    let tree = match read(&args.file) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    let leaves = tree.leaves();
    let occupied: Vec<_> = leaves.iter().filter(|l| tree.is_occupied(&l.node)).collect();
    let volume = |ls: &[&dynaflow_octomap::Leaf]| ls.iter().map(|l| f64::from(l.size).powi(3)).sum::<f64>();
    let res = tree.params().resolution;
    let grid = tree.grid();
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for l in &occupied {
        let c = grid.node_centre(l.key, l.size);
        let half = f64::from(l.size) * res / 2.0;
        for i in 0..3 {
            lo[i] = lo[i].min(c[i] - half);
            hi[i] = hi[i].max(c[i] + half);
        }
    }
    let summary = serde_json::json!({
        "file": args.file.display().to_string(),
        "type": if tree.semantic() { "ColorOcTree" } else { "OcTree" },
        "resolution": res,
        "nodes": tree.size(),
        "leaves": leaves.len(),
        "occupied_leaves": occupied.len(),
        "occupied_volume_m3": volume(&occupied) * res.powi(3),
        "occupied_bounds": if occupied.is_empty() { serde_json::Value::Null } else { serde_json::json!({"min": lo, "max": hi}) },
    });
    println!("{summary}");
    if let Some(out) = &args.plot {
        if occupied.is_empty() {
            eprintln!("error: {}: no occupied voxel to draw", args.file.display());
            return EXIT_FAILED;
        }
        if let Err(e) = dynaflow_engine::files::refuse_overwriting_inputs("--plot", out, [args.file.as_path()]) {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
        let img = plot(&tree, &occupied, lo, hi, args.scale);
        let (w, h) = img.dimensions();
        if let Err(e) = crate::cli::plot::save_png(w, h, image::ExtendedColorType::Rgb8, img.as_raw(), out) {
            eprintln!("error: {e}");
            return EXIT_FAILED;
        }
    }
    EXIT_OK
}

/// Occupied voxels from above, lowest first so the highest is what shows.
fn plot(
    tree: &OcTree,
    occupied: &[&dynaflow_octomap::Leaf],
    lo: [f64; 3],
    hi: [f64; 3],
    scale: u32,
) -> image::RgbImage {
    let res = tree.params().resolution;
    let cells = |a: usize| ((hi[a] - lo[a]) / res).ceil().max(1.0) as u32;
    let (w, h) = ((cells(0) * scale).min(8192), (cells(1) * scale).min(8192));
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut order: Vec<_> = occupied.to_vec();
    let grid = tree.grid();
    order.sort_by(|a, b| grid.node_centre(a.key, a.size)[2].total_cmp(&grid.node_centre(b.key, b.size)[2]));
    for l in order {
        let c = grid.node_centre(l.key, l.size);
        let half = f64::from(l.size) * res / 2.0;
        let color = if tree.semantic() && l.node.color_set() {
            l.node.color
        } else {
            // Height from blue (low) to red (high).
            let t = ((c[2] - lo[2]) / (hi[2] - lo[2]).max(1e-9)).clamp(0.0, 1.0);
            [(255.0 * t) as u8, 60, (255.0 * (1.0 - t)) as u8]
        };
        let px = |v: f64, a: usize| ((v - lo[a]) / res * f64::from(scale)).round().max(0.0) as u32;
        let (x0, x1) = (px(c[0] - half, 0), px(c[0] + half, 0).min(w));
        // Image rows grow downwards; y grows up.
        let (y0, y1) = (h.saturating_sub(px(c[1] + half, 1)), h.saturating_sub(px(c[1] - half, 1)));
        for y in y0..y1.min(h) {
            for x in x0..x1 {
                img.put_pixel(x, y, image::Rgb(color));
            }
        }
    }
    img
}
