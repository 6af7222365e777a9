//! Helpers shared by the examples: the `--json` and `--quick` flags, the figure folder, line
//! plots, and what an example's run returns ([`Output`], [`Headline`]).
//!
//! Layout: example `X` is `examples/X.rs` (its flags and `main`), and its body, the paper's
//! reproduction (experiment, tables, figures, JSON), is `examples/reproductions/X.rs`, which
//! `X.rs` names with `#[path]`; `papers.rs` includes every paper's body the same way, and the
//! `estim` package's tests (`tests/it`) include them to check the reproductions. Each
//! reproduction reaches these helpers as `crate::common`.
#![allow(dead_code)] // each example uses a subset

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

/// `figures/` in cargo's target directory (created if missing): `$CARGO_TARGET_DIR` when set
/// (at run time, else when the example was built), else `target/` under the workspace root.
pub fn figure_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .or_else(|| option_env!("CARGO_TARGET_DIR").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target"));
    let dir = target.join("figures");
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// One named curve of a line plot.
pub struct Series<'a> {
    /// Legend label.
    pub label: &'a str,
    /// (x, y) points.
    pub points: Vec<(f64, f64)>,
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
    let path = figure_dir().join(file);
    draw_lines(&path, title, x_label, y_label, series)?;
    Ok(path)
}

/// Renders the line plot of [`line_plot`] into `path`.
fn draw_lines(
    path: &std::path::Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
) -> Result<(), Box<dyn std::error::Error>> {
    let finite = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in finite() {
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
    let root = SVGBackend::new(path, (900, 540)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()?;
    for (i, s) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                s.points
                    .iter()
                    .copied()
                    .filter(|(x, y)| x.is_finite() && y.is_finite()),
                color.stroke_width(2),
            ))?
            .label(s.label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
