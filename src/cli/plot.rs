//! Plots written as PNG: `dynaflow eval --plot` (top view of both trajectories, ATE over time).

use std::path::Path;
use std::sync::OnceLock;

use dynaflow_slam::eval::Evaluation;
use nalgebra::{Matrix3, Vector3};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// DejaVu Sans (see `assets/fonts/SOURCE.md`): plots need no system font.
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

fn fonts() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| register_font(FAMILY, FontStyle::Normal, FONT).map_err(|_| "embedded font is invalid".into()))
        .clone()
}

/// The two directions the ground truth moves most along (a "top view" that works whatever
/// axis the world calls up), as unit vectors.
fn view_axes(points: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let n = points.len().max(1) as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let cov = points.iter().fold(Matrix3::zeros(), |c, p| c + (p - mean) * (p - mean).transpose()) / n;
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let (a, b) = (eig.eigenvectors.column(order[0]).into_owned(), eig.eigenvectors.column(order[1]).into_owned());
    if a.iter().chain(b.iter()).all(|v| v.is_finite()) { (a, b) } else { (Vector3::x(), Vector3::y()) }
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo.is_finite() && hi.is_finite() { (lo, hi) } else { (0.0, 1.0) }
}

/// Write the evaluation plot to `path` (PNG, 1400 x 600).
pub fn evaluation(e: &Evaluation, title: &str, path: &Path) -> Result<(), String> {
    fonts()?;
    let (w, h) = (1400u32, 600u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let gt: Vec<Vector3<f64>> = e.series.iter().map(|s| s.1).collect();
    let (ax, ay) = view_axes(&gt);
    let plane = |p: &Vector3<f64>| (p.dot(&ax), p.dot(&ay));
    let g2: Vec<(f64, f64)> = gt.iter().map(plane).collect();
    let e2: Vec<(f64, f64)> = e.series.iter().map(|s| plane(&s.2)).collect();
    let t0 = e.series.first().map_or(0.0, |s| s.0);
    let errs: Vec<(f64, f64)> = e.series.iter().map(|s| (s.0 - t0, s.3)).collect();
    let draw = |buf: &mut [u8]| -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::with_buffer(buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, (FAMILY, 24))?;
        let (left, right) = root.split_horizontally(620);
        // Equal scales on both axes.
        let (x0, x1) = range(g2.iter().chain(&e2).map(|p| p.0));
        let (y0, y1) = range(g2.iter().chain(&e2).map(|p| p.1));
        let half = 0.55 * (x1 - x0).max(y1 - y0).max(1e-3);
        let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let mut top = ChartBuilder::on(&left)
            .caption("top view (plane of largest motion)", (FAMILY, 18))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)?;
        top.configure_mesh().x_desc("m").y_desc("m").label_style((FAMILY, 13)).draw()?;
        top.draw_series(LineSeries::new(g2.iter().copied(), BLACK.stroke_width(2)))?
            .label("ground truth")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        top.draw_series(LineSeries::new(e2.iter().copied(), RED.stroke_width(2)))?
            .label(format!("estimate ({:?}-aligned)", e.align).to_lowercase())
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        top.configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        let tmax = errs.last().map_or(1.0, |p| p.0).max(1e-3);
        let emax = errs.iter().map(|p| p.1).fold(0.0, f64::max).max(1e-6) * 1.1;
        let mut err = ChartBuilder::on(&right)
            .caption(
                format!(
                    "ATE over time: rmse {:.4} m, median {:.4} m, max {:.4} m",
                    e.ate.rmse, e.ate.median, e.ate.max
                ),
                (FAMILY, 18),
            )
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..tmax, 0.0..emax)?;
        err.configure_mesh().x_desc("time (s)").y_desc("ATE (m)").label_style((FAMILY, 13)).draw()?;
        err.draw_series(LineSeries::new(errs.iter().copied(), BLUE.stroke_width(2)))?;
        root.present()?;
        Ok(())
    };
    draw(&mut buf).map_err(|e| format!("cannot draw the plot: {e}"))?;
    save_png(w, h, image::ExtendedColorType::Rgb8, &buf, path)
}

/// Render with `draw` into a `w x h` PNG at `path`.
fn png(
    w: u32,
    h: u32,
    path: &Path,
    draw: impl FnOnce(&mut [u8]) -> Result<(), Box<dyn std::error::Error>>,
) -> Result<(), String> {
    fonts()?;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    draw(&mut buf).map_err(|e| format!("cannot draw the plot: {e}"))?;
    save_png(w, h, image::ExtendedColorType::Rgb8, &buf, path)
}

/// An image file read by its content, not its name (a JPEG named `.png` is read as a JPEG).
pub fn open_image(path: &Path) -> Result<image::DynamicImage, String> {
    image::ImageReader::open(path)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .decode()
        .map_err(|e| format!("cannot decode: {e}"))
}

/// A PNG file's bytes: `data` is `w x h` pixels of `color`.
pub fn png_bytes(w: u32, h: u32, color: image::ExtendedColorType, data: &[u8]) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(data, w, h, color)
        .map_err(|e| format!("cannot encode a PNG: {e}"))?;
    Ok(out)
}

/// Write a PNG as a new file renamed into place (`files::write_atomic`).
pub fn save_png(w: u32, h: u32, color: image::ExtendedColorType, data: &[u8], path: &Path) -> Result<(), String> {
    let bytes = png_bytes(w, h, color, data)?;
    dynaflow_engine::files::write_atomic(path, &bytes).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    let p = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (p.floor() as usize, p.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (p - lo as f64)
}

/// The chart both bar-like plots draw on: one column per label (names rotated under the
/// axis, in an area `label_area` pixels high), values from 0 to `ymax` upwards.
fn columns<'a, 'b>(
    root: &'a DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    title: &str,
    labels: &[&str],
    label_area: u32,
    y_desc: Option<&str>,
    ymax: f64,
) -> Result<
    ChartContext<
        'a,
        BitMapBackend<'b>,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    Box<dyn std::error::Error>,
> {
    let n = labels.len();
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 20))
        .margin(20)
        .x_label_area_size(label_area)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..n as f64 - 0.5, 0.0..ymax)?;
    let name = |x: &f64| {
        let i = x.round();
        if (x - i).abs() < 1e-6 && i >= 0.0 {
            labels.get(i as usize).map_or(String::new(), |l| (*l).to_string())
        } else {
            String::new()
        }
    };
    let mut mesh = chart.configure_mesh();
    mesh.disable_x_mesh()
        .x_labels(n)
        .x_label_formatter(&name)
        .x_label_style((FAMILY, 13).into_font().transform(FontTransform::Rotate90))
        .label_style((FAMILY, 13));
    if let Some(d) = y_desc {
        mesh.y_desc(d);
    }
    mesh.draw()?;
    Ok(chart)
}

/// A box plot per label (median, quartiles, whiskers to min and max, every value as a dot).
pub fn boxes(values: &std::collections::BTreeMap<String, Vec<f64>>, title: &str, path: &Path) -> Result<(), String> {
    let groups: Vec<(&String, Vec<f64>)> = values
        .iter()
        .filter(|(_, v)| !v.is_empty())
        .map(|(k, v)| {
            let mut v = v.clone();
            v.sort_by(f64::total_cmp);
            (k, v)
        })
        .collect();
    if groups.is_empty() {
        return Ok(());
    }
    let (w, h) = ((200 + 110 * groups.len() as u32).max(600), 600u32);
    let ymax = groups.iter().flat_map(|g| g.1.iter().copied()).fold(0.0, f64::max).max(1e-6) * 1.1;
    png(w, h, path, |buf| {
        let root = BitMapBackend::with_buffer(buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let labels: Vec<&str> = groups.iter().map(|g| g.0.as_str()).collect();
        let mut chart = columns(&root, title, &labels, 130, None, ymax)?;
        for (i, (_, v)) in groups.iter().enumerate() {
            let x = i as f64;
            let (q1, med, q3) = (quantile(v, 0.25), quantile(v, 0.5), quantile(v, 0.75));
            let (lo, hi) = (v[0], v[v.len() - 1]);
            chart
                .draw_series(std::iter::once(Rectangle::new([(x - 0.3, q1), (x + 0.3, q3)], BLUE.mix(0.3).filled())))?;
            chart.draw_series(std::iter::once(Rectangle::new([(x - 0.3, q1), (x + 0.3, q3)], BLUE.stroke_width(1))))?;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(x - 0.3, med), (x + 0.3, med)],
                RED.stroke_width(2),
            )))?;
            chart.draw_series(std::iter::once(PathElement::new(vec![(x, lo), (x, q1)], BLACK)))?;
            chart.draw_series(std::iter::once(PathElement::new(vec![(x, q3), (x, hi)], BLACK)))?;
            chart.draw_series(v.iter().map(|&y| Circle::new((x, y), 3, BLACK.filled())))?;
        }
        root.present()?;
        Ok(())
    })
}

/// One stacked bar per run: each node's share of the time per frame.
pub fn stacked(runs: &[(String, Vec<(String, f64)>)], title: &str, path: &Path) -> Result<(), String> {
    if runs.is_empty() {
        return Ok(());
    }
    let mut names: Vec<&String> = runs.iter().flat_map(|r| r.1.iter().map(|n| &n.0)).collect();
    names.sort();
    names.dedup();
    let color = |name: &String| {
        let i = names.iter().position(|n| *n == name).unwrap_or(0) as u16;
        let [r, g, b] = dynaflow_engine::msg::class_rgb(i + 1);
        RGBColor(r, g, b)
    };
    let (w, h) = ((300 + 90 * runs.len() as u32).max(700), 650u32);
    let ymax = runs.iter().map(|r| r.1.iter().map(|n| n.1).sum::<f64>()).fold(0.0, f64::max).max(1e-6) * 1.1;
    png(w, h, path, |buf| {
        let root = BitMapBackend::with_buffer(buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let labels: Vec<&str> = runs.iter().map(|r| r.0.as_str()).collect();
        let mut chart = columns(&root, title, &labels, 150, Some("ms"), ymax)?;
        for name in &names {
            let mut first = true;
            for (i, (_, nodes)) in runs.iter().enumerate() {
                let below: f64 = nodes.iter().take_while(|n| &&n.0 != name).map(|n| n.1).sum();
                let Some(v) = nodes.iter().find(|n| &&n.0 == name).map(|n| n.1) else { continue };
                let x = i as f64;
                let s = chart.draw_series(std::iter::once(Rectangle::new(
                    [(x - 0.35, below), (x + 0.35, below + v)],
                    color(name).filled(),
                )))?;
                if first {
                    let c = color(name);
                    s.label(name.as_str())
                        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], c.filled()));
                    first = false;
                }
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FAMILY, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
        Ok(())
    })
}
