//! Helpers shared by the examples: the `--json` and `--quick` flags, the figure folder, line
//! plots, and what an example's run returns ([`Output`], [`Headline`]).
//!
//! Layout: example `X` is `examples/X.rs` (its flags and `main`), and its body, the paper's
//! reproduction (experiment, tables, figures, JSON), is `examples/reproductions/X.rs`, module
//! `X` of the `estim-reproductions` library (`examples/reproductions/lib.rs`, which also holds
//! this module as `common`): `X.rs` runs one, `papers.rs` all of them, and the `estim`
//! package's tests (`tests/it`) check them. Each reproduction reaches these helpers as
//! `crate::common`.

use core::fmt;
use std::path::PathBuf;

/// A headline number: the paper's claim next to what estim computes, and why they differ.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Headline {
    /// What is compared.
    pub quantity: String,
    /// The paper's value or sentence.
    pub paper: String,
    /// estim's value(s).
    pub estim: String,
    /// Why they differ, or what the comparison rests on (empty when they simply agree).
    pub note: String,
}

impl fmt::Display for Headline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: paper {}, estim {}",
            self.quantity, self.paper, self.estim
        )?;
        if !self.note.is_empty() {
            write!(f, " ({})", self.note)?;
        }
        Ok(())
    }
}

/// What an example's run returns: its `--json` object and its headline comparisons.
pub struct Output {
    /// The object printed as the last stdout line with `--json`.
    pub json: serde_json::Value,
    /// The paper's claims next to estim's values.
    pub headlines: Vec<Headline>,
}

use plotters::prelude::*;

/// Whether `--json` was passed: then the example prints one JSON object as its last stdout line.
pub fn json_requested() -> bool {
    std::env::args().any(|a| a == "--json")
}

/// Whether `--quick` was passed: a faithful but smaller run (fewer Monte Carlo realizations).
pub fn quick_requested() -> bool {
    std::env::args().any(|a| a == "--quick")
}

/// `figures/` in cargo's target directory (created if missing): see [`target_dir`].
pub fn figure_dir() -> PathBuf {
    let runtime = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from);
    let built = option_env!("CARGO_TARGET_DIR").map(PathBuf::from);
    let dir = target_dir(runtime, built).join("figures");
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// Cargo's target directory, where the examples write their figures and the main job its
/// `papers.md`: `$CARGO_TARGET_DIR` at run time (`runtime`) if set, else as it was when the
/// example was built (`built`), else `target/` under the workspace root, as cargo itself
/// chooses (a `build.target-dir` in a cargo config file is not seen). The workspace root is
/// two levels above this library's manifest (`examples/reproductions`), not the manifest's
/// own folder: cargo builds every member of the workspace into the root's `target/`.
pub fn target_dir(runtime: Option<PathBuf>, built: Option<PathBuf>) -> PathBuf {
    runtime.or(built).unwrap_or_else(|| {
        let manifest = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        // examples/reproductions → the workspace root (`ancestors` starts at the path itself).
        let root = manifest.ancestors().nth(2).unwrap_or(manifest);
        root.join("target")
    })
}

/// One named curve of a line plot.
pub struct Series<'a> {
    /// Legend label.
    pub label: &'a str,
    /// (x, y) points.
    pub points: Vec<(f64, f64)>,
}

/// A shaded band (e.g. ±σ about an estimate) drawn under the lines of a plot. Band i takes
/// the colour of line i, so a band given in the same order as its estimate's line matches it.
pub struct Band<'a> {
    /// Legend label.
    pub label: &'a str,
    /// (x, lower, upper) points.
    pub points: Vec<(f64, f64, f64)>,
}

/// Writes an SVG line plot of `series` to `target/figures/<file>` and returns its path.
/// Non-finite points are skipped. Errors are returned, not panicked on: a figure that fails
/// to render should not stop an example's numbers.
pub fn line_plot(
    file: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
) -> Result<PathBuf, Box<dyn std::error::Error>> {
    band_plot(file, title, x_label, y_label, series, &[])
}

/// [`line_plot`] with shaded `bands` under the lines (a ±σ envelope reads as one region, not
/// as two more curves).
pub fn band_plot(
    file: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    bands: &[Band<'_>],
) -> Result<PathBuf, Box<dyn std::error::Error>> {
    let path = figure_dir().join(file);
    draw(&path, title, x_label, y_label, series, bands)?;
    Ok(path)
}

/// Okabe & Ito's colour-blind-safe palette (Wong, *Nature Methods* 8, 2011), without its
/// yellow, which has too little contrast on white.
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),   // blue
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(230, 159, 0),   // orange
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(0, 0, 0),       // black
];

/// A tick label with 4 significant digits at most, no "-0", and 0 for a value that is zero
/// up to rounding on an axis spanning `span` (a tick at −1.1e-16 is the zero tick).
fn tick(v: f64, span: f64) -> String {
    if v.abs() <= 1e-9 * span.abs() {
        return "0".to_string();
    }
    if v.abs() >= 1e5 || v.abs() < 1e-3 {
        return format!("{v:.2e}");
    }
    let text = format!("{v:.4}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Renders the plot of [`band_plot`] into `path`: the chart on the left, its legend in a
/// panel of its own on the right, so it never covers the data.
fn draw(
    path: &std::path::Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    bands: &[Band<'_>],
) -> Result<(), Box<dyn std::error::Error>> {
    let finite = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite();
    let points = series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .chain(
            bands
                .iter()
                .flat_map(|b| b.points.iter().flat_map(|&(x, lo, hi)| [(x, lo), (x, hi)])),
        )
        .filter(finite);
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in points {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !(x0 < x1) {
        x1 = x0 + 1.0;
    }
    if !(y0 < y1) {
        y1 = y0 + 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    let root = SVGBackend::new(path, (1100, 540)).into_drawing_area();
    root.fill(&WHITE)?;
    let (plot_area, legend_area) = root.split_horizontally(860);
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .x_label_formatter(&|v| tick(*v, x1 - x0))
        .y_label_formatter(&|v| tick(*v, y1 - y0))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let colour = |i: usize| PALETTE[i % PALETTE.len()];
    for (i, b) in bands.iter().enumerate() {
        let kept: Vec<_> = b
            .points
            .iter()
            .copied()
            .filter(|&(x, lo, hi)| x.is_finite() && lo.is_finite() && hi.is_finite())
            .collect();
        let outline = kept
            .iter()
            .map(|&(x, _, hi)| (x, hi))
            .chain(kept.iter().rev().map(|&(x, lo, _)| (x, lo)));
        chart.draw_series(std::iter::once(Polygon::new(
            outline.collect::<Vec<_>>(),
            colour(i).mix(0.18).filled(),
        )))?;
    }
    for (i, s) in series.iter().enumerate() {
        let style = colour(i).stroke_width(2);
        chart.draw_series(LineSeries::new(
            s.points.iter().copied().filter(finite),
            style,
        ))?;
    }
    // The legend panel: one row per band (a swatch) and per line (a stroke).
    let row = |k: usize| 60 + 26 * k as i32;
    let font = ("sans-serif", 14).into_font();
    for (k, b) in bands.iter().enumerate() {
        legend_area.draw(&Rectangle::new(
            [(8, row(k) - 6), (34, row(k) + 6)],
            colour(k).mix(0.18).filled(),
        ))?;
        legend_area.draw(&Text::new(b.label, (42, row(k) - 7), font.clone()))?;
    }
    for (i, s) in series.iter().enumerate() {
        let k = bands.len() + i;
        legend_area.draw(&PathElement::new(
            vec![(8, row(k)), (34, row(k))],
            colour(i).stroke_width(2),
        ))?;
        legend_area.draw(&Text::new(s.label, (42, row(k) - 7), font.clone()))?;
    }
    root.present()?;
    Ok(())
}

/// A progress bar for `runs` Monte Carlo realizations on stderr, fed by
/// `MonteCarlo::run_with_progress`; indicatif draws it only when stderr is a terminal, so logs
/// and the main job's output stay clean.
pub fn progress_bar(label: &str, runs: usize) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(runs as u64);
    let style =
        indicatif::ProgressStyle::with_template("{msg} {bar:40} {pos}/{len} runs, ETA {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_message(label.to_string());
    bar
}

/// The average NEES of each labelled run at times (k + 1)·`period`, each value capped at
/// `cap`, over the shaded consistency band [lower, upper], written to `file`; prints where it
/// went (a figure that fails to render is reported, not fatal).
pub fn nees_band_plot(
    file: &str,
    title: &str,
    period: f64,
    nees: &[(&str, &[f64])],
    cap: f64,
    (lower, upper): (f64, f64),
    band_label: &str,
) {
    let at = |k: usize| (k + 1) as f64 * period;
    let series: Vec<Series<'_>> = nees
        .iter()
        .map(|&(label, values)| Series {
            label,
            points: values
                .iter()
                .enumerate()
                .map(|(k, v)| (at(k), v.min(cap)))
                .collect(),
        })
        .collect();
    let steps = nees.iter().map(|(_, v)| v.len()).max().unwrap_or(0);
    let band = Band {
        label: band_label,
        points: (0..steps).map(|k| (at(k), lower, upper)).collect(),
    };
    match band_plot(file, title, "time (s)", "average NEES", &series, &[band]) {
        Ok(path) => println!("figure: {}", path.display()),
        Err(e) => eprintln!("figure not written: {e}"),
    }
}
