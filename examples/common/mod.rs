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

pub mod svg_check;

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
/// as two more curves; each band's edges are drawn too, so overlapping bands stay apart).
pub fn band_plot(
    file: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    bands: &[Band<'_>],
) -> Result<PathBuf, Box<dyn std::error::Error>> {
    let path = figure_dir().join(file);
    draw(&path, title, (x_label, y_label), series, &[], bands, false)?;
    Ok(path)
}

/// [`line_plot`] of `lines`, with `dots` drawn as markers over them: a value that should
/// follow a line (an ensemble statistic against the filter's own) stays visible where it
/// does, instead of an identical curve hiding under it.
pub fn lines_and_dots_plot(
    file: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    lines: &[Series<'_>],
    dots: &[Series<'_>],
) -> Result<PathBuf, Box<dyn std::error::Error>> {
    let path = figure_dir().join(file);
    draw(&path, title, (x_label, y_label), lines, dots, &[], false)?;
    Ok(path)
}

/// [`line_plot`] with one unit on x as long as one on y (ellipses look like ellipses): the
/// shorter range is widened about its centre to the plot area's aspect.
pub fn equal_axes_plot(
    file: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
) -> Result<PathBuf, Box<dyn std::error::Error>> {
    let path = figure_dir().join(file);
    draw(&path, title, (x_label, y_label), series, &[], &[], true)?;
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

/// The canvas height, the plot's width (the legend panel is to its right) and the legend's
/// font size, in pixels.
const HEIGHT: u32 = 540;
const PLOT_WIDTH: u32 = 860;
const LEGEND_FONT: f64 = 14.0;
const TITLE_FONT: f64 = 20.0;

/// The legend panel's width: the longest label at [`svg_check::text_width`]'s estimate after
/// its swatch (42 px), and a margin; at least 240 px.
fn legend_width(labels: impl Iterator<Item = usize>) -> u32 {
    let longest = labels.max().unwrap_or(0) as f64;
    (42.0 + svg_check::CHAR_WIDTH * LEGEND_FONT * longest + 16.0)
        .ceil()
        .max(240.0) as u32
}

/// Renders the plot of [`band_plot`] into `path`: the title across the top, the chart on the
/// left, its legend in a panel of its own on the right (as wide as its longest label needs),
/// so it never covers the data; then checks that every text and shape is inside the canvas
/// ([`svg_check`]) and returns an error naming what is not.
fn draw(
    path: &std::path::Path,
    title: &str,
    (x_label, y_label): (&str, &str),
    series: &[Series<'_>],
    dots: &[Series<'_>],
    bands: &[Band<'_>],
    equal_axes: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let finite = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite();
    let points = series
        .iter()
        .chain(dots)
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
    // Data never touches the frame: 5 % of the span on y, and on x too for a picture in the
    // plane (equal axes); a time axis keeps its ends.
    let pad = 0.05 * (y1 - y0);
    (y0, y1) = (y0 - pad, y1 + pad);
    if equal_axes {
        let pad = 0.05 * (x1 - x0);
        (x0, x1) = (x0 - pad, x1 + pad);
    }
    let labels = bands
        .iter()
        .map(|b| b.label)
        .chain(series.iter().chain(dots).map(|s| s.label));
    let width = PLOT_WIDTH + legend_width(labels.map(|l| l.chars().count()));
    let root = SVGBackend::new(path, (width, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;
    // The title across the whole canvas, its font shrunk if it would not fit in it.
    let room = f64::from(width) - 24.0;
    let title_font =
        TITLE_FONT.min(room / (svg_check::CHAR_WIDTH * title.chars().count().max(1) as f64));
    let root = root.titled(title, ("sans-serif", title_font.floor()))?;
    let (plot_area, legend_area) = root.split_horizontally(PLOT_WIDTH);
    let builder = |x: (f64, f64), y: (f64, f64)| {
        ChartBuilder::on(&plot_area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)
    };
    if equal_axes {
        // Units per pixel equal on both axes: widen the range with fewer about its centre.
        let (w, h) = builder((x0, x1), (y0, y1))?.plotting_area().dim_in_pixel();
        let (per_x, per_y) = ((x1 - x0) / f64::from(w), (y1 - y0) / f64::from(h));
        if per_x > per_y {
            let (c, half) = ((y0 + y1) / 2.0, per_x * f64::from(h) / 2.0);
            (y0, y1) = (c - half, c + half);
        } else {
            let (c, half) = ((x0 + x1) / 2.0, per_y * f64::from(w) / 2.0);
            (x0, x1) = (c - half, c + half);
        }
    }
    let mut chart = builder((x0, x1), (y0, y1))?;
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
            colour(i).mix(0.08).filled(),
        )))?;
        // The edges, thin and in the band's colour: two overlapping bands (±√P of x and of
        // y) would otherwise blend into one tint.
        for edge in [
            kept.iter().map(|&(x, lo, _)| (x, lo)).collect::<Vec<_>>(),
            kept.iter().map(|&(x, _, hi)| (x, hi)).collect(),
        ] {
            chart.draw_series(LineSeries::new(edge, colour(i).mix(0.8).stroke_width(1)))?;
        }
    }
    for (i, s) in series.iter().enumerate() {
        let style = colour(i).stroke_width(2);
        chart.draw_series(LineSeries::new(
            s.points.iter().copied().filter(finite),
            style,
        ))?;
    }
    // The legend panel: one row per band (a swatch with its edge) and per line (a stroke).
    let row = |k: usize| 40 + 26 * k as i32;
    let font = ("sans-serif", LEGEND_FONT).into_font();
    for (k, b) in bands.iter().enumerate() {
        legend_area.draw(&Rectangle::new(
            [(8, row(k) - 6), (34, row(k) + 6)],
            colour(k).mix(0.08).filled(),
        ))?;
        legend_area.draw(&Rectangle::new(
            [(8, row(k) - 6), (34, row(k) + 6)],
            colour(k).mix(0.8).stroke_width(1),
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
    // Dots: hollow circles in the colours after the lines', every `stride`-th point (about
    // 60 per curve, so the line under them stays visible).
    for (j, d) in dots.iter().enumerate() {
        let c = colour(series.len() + j);
        let stride = (d.points.len() / 60).max(1);
        chart.draw_series(
            d.points
                .iter()
                .copied()
                .filter(finite)
                .step_by(stride)
                .map(|p| Circle::new(p, 4, c.stroke_width(2))),
        )?;
        let k = bands.len() + series.len() + j;
        legend_area.draw(&Circle::new((21, row(k)), 4, c.stroke_width(2)))?;
        legend_area.draw(&Text::new(d.label, (42, row(k) - 7), font.clone()))?;
    }
    root.present()?;
    let problems = svg_check::outside_canvas(&std::fs::read_to_string(path)?, 1.0)?;
    if !problems.is_empty() {
        return Err(format!("{}: {}", path.display(), problems.join("; ")).into());
    }
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
