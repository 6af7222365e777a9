//! The figures' layout: every text and legend entry inside the canvas. Every figure of the
//! main job is drawn by one function (`common`'s `draw`, behind `line_plot`, `band_plot`,
//! `lines_and_dots_plot` and `equal_axes_plot`), which checks the SVG it wrote
//! (`common::svg_check`) and returns an error otherwise; these tests draw, from small
//! synthetic data, figures with the main job's titles and labels where they were too wide
//! or too many, and check the checker itself on hand-written SVG.

use crate::common::{self, Band, Series, svg_check};
use std::path::Path;

/// Reads a figure and removes it (the tests' figures are not the main job's).
fn take(path: &Path) -> String {
    let svg = std::fs::read_to_string(path).unwrap();
    let _ = std::fs::remove_file(path);
    svg
}

#[test]
fn the_checker_finds_text_and_shapes_outside_the_canvas() {
    let inside = r##"<svg width="200" height="100" viewBox="0 0 200 100">
<text x="10" y="10" dy="0.76em" text-anchor="start" font-size="10">abc</text>
<rect x="5" y="5" width="20" height="10" fill="#FFFFFF"/></svg>"##;
    assert_eq!(
        svg_check::outside_canvas(inside, 1.0).unwrap(),
        Vec::<String>::new()
    );
    // 40 characters at 10 px: 240 px estimated from x = 10, past the 200 px edge.
    let long = inside.replace(">abc<", &format!(">{}<", "m".repeat(40)));
    let problems = svg_check::outside_canvas(&long, 1.0).unwrap();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(problems[0].starts_with("text"), "{problems:?}");
    // A y-axis label turned by 270° about its anchor extends upwards: past the top here.
    let turned = r#"<svg width="200" height="100"><text x="20" y="30" dy="0.76em" text-anchor="middle" font-size="10" transform="rotate(270, 20, 30)">a label this long</text></svg>"#;
    assert_eq!(svg_check::outside_canvas(turned, 1.0).unwrap().len(), 1);
    let rect = inside.replace(r#"x="5" y="5""#, r#"x="190" y="5""#);
    assert_eq!(svg_check::outside_canvas(&rect, 1.0).unwrap().len(), 1);
}

/// lu_delays_anees: its band label (41 characters) was cut at the right edge of a fixed
/// 240 px legend panel. The panel now takes the width of its longest label.
#[test]
fn a_long_legend_label_widens_the_canvas_instead_of_being_cut() {
    let t: Vec<f64> = (0..50).map(|k| 0.2 * k as f64).collect();
    let series: Vec<Series<'_>> = ["at the time taken", "on arrival", "ignored (dropped)"]
        .iter()
        .enumerate()
        .map(|(i, &label)| Series {
            label,
            points: t.iter().map(|&t| (t, (i as f64 + 1.0) * t.sin())).collect(),
        })
        .collect();
    let band = Band {
        label: "99 % band (ANEES of a consistent filter), and then some more words",
        points: t.iter().map(|&t| (t, -0.1, 0.1)).collect(),
    };
    let path = common::band_plot(
        "layout_test_legend.svg",
        "Lu + latency, 100-sigma outliers, stuck position: RMS position error (estim's extension), longer",
        "t [s]",
        "log10 ANEES",
        &series,
        &[band],
    )
    .unwrap();
    let svg = take(&path);
    assert_eq!(
        svg_check::outside_canvas(&svg, 1.0).unwrap(),
        Vec::<String>::new()
    );
}

/// lv2_error_ellipses: a circle of radius 1 comes out round (1:1), with room to the frame.
#[test]
fn equal_axes_draw_a_circle_round() {
    let circle: Vec<(f64, f64)> = (0..=120)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 120.0;
            (3.0 + a.cos(), -2.0 + a.sin())
        })
        .collect();
    let series = [Series {
        label: "unit circle",
        points: circle,
    }];
    let path = common::equal_axes_plot(
        "layout_test_equal.svg",
        "1σ ellipse",
        "x [m]",
        "y [m]",
        &series,
    )
    .unwrap();
    let svg = take(&path);
    assert_eq!(
        svg_check::outside_canvas(&svg, 1.0).unwrap(),
        Vec::<String>::new()
    );
    // The circle is the only polyline with 121 points: its pixel box is square to within 2 px
    // (plotters rounds each point to a whole pixel: 1 px at each end).
    let points = svg
        .split("<polyline")
        .skip(1)
        .filter_map(|p| {
            let start = p.find("points=\"")? + 8;
            let end = p[start..].find('"')?;
            Some(p[start..start + end].to_string())
        })
        .find(|pts| pts.split_whitespace().count() == 121)
        .expect("the circle's polyline");
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for pair in points.split_whitespace() {
        let (x, y) = pair.split_once(',').unwrap();
        let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    assert!(
        ((x1 - x0) - (y1 - y0)).abs() <= 2.0,
        "{x0}..{x1} × {y0}..{y1}"
    );
    assert!(y1 - y0 > 300.0, "the circle fills the plot: {}", y1 - y0);
}

/// lu_sigma_bias and boje_circle_position: the dots and the band edges are drawn (a second
/// curve equal to the first no longer hides under it; two overlapping bands have edges).
#[test]
fn dots_and_band_edges_are_drawn() {
    let t: Vec<f64> = (0..300).map(|k| k as f64).collect();
    let line = Series {
        label: "filter sqrt P",
        points: t.iter().map(|&t| (t, 0.1 / (1.0 + t))).collect(),
    };
    let same = Series {
        label: "ensemble std (Monte Carlo)",
        points: line.points.clone(),
    };
    let path = common::lines_and_dots_plot(
        "layout_test_dots.svg",
        "Lu: filter sqrt P vs ensemble std of the bias error, N = 1000",
        "t [s]",
        "b [m/s^2]",
        &[line],
        &[same],
    )
    .unwrap();
    let svg = take(&path);
    assert_eq!(
        svg_check::outside_canvas(&svg, 1.0).unwrap(),
        Vec::<String>::new()
    );
    // 300 points at a stride of 5: 60 dots, and one in the legend.
    assert_eq!(svg.matches("<circle").count(), 61);

    let bands: Vec<Band<'_>> = [("±√P x", 1.0), ("±√P y", 1.2)]
        .iter()
        .map(|&(label, s)| Band {
            label,
            points: t.iter().map(|&t| (t, -s, s)).collect(),
        })
        .collect();
    let path = common::band_plot(
        "layout_test_bands.svg",
        "Boje Fig 3: position error, run 1, ±√P, Monte Carlo RMS (x)",
        "t (s)",
        "m",
        &[],
        &bands,
    )
    .unwrap();
    let svg = take(&path);
    assert_eq!(
        svg_check::outside_canvas(&svg, 1.0).unwrap(),
        Vec::<String>::new()
    );
    // Each band: its fill (a polygon) and its two edges (polylines of 300 points).
    assert_eq!(svg.matches("<polygon").count(), 2);
    let edges = svg
        .split("<polyline")
        .filter(|p| {
            p.split(" points=\"")
                .nth(1)
                .is_some_and(|q| q.split('"').next().unwrap().split_whitespace().count() == 300)
        })
        .count();
    assert_eq!(edges, 4);
}
