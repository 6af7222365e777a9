//! Checks a written SVG figure: every text (titles, axis labels, tick labels, legend entries)
//! and every shape (legend swatches, lines, bands) lies inside the canvas. Plain text parsing
//! of what plotters' SVG backend writes: `<svg width height>`, `<text x y font-size
//! text-anchor transform=rotate(..)>`, `<rect x y width height>`, `<line>`, `<polyline
//! points>`, `<polygon points>`, `<circle cx cy r>`.
//!
//! A text's extent is estimated, not measured (no font is loaded): its width is 0.6 × font
//! size per character, about the widest average advance of the common sans-serif faces
//! (DejaVu Sans ≈ 0.55-0.6 em, Liberation Sans/Arial ≈ 0.5 em), so a label that passes fits in
//! any of them; its height is one font size.

/// Estimated advance of one character, in font sizes.
pub const CHAR_WIDTH: f64 = 0.6;

/// The estimated width in pixels of `text` at `font_size`.
pub fn text_width(text: &str, font_size: f64) -> f64 {
    CHAR_WIDTH * font_size * text.chars().count() as f64
}

/// What lies outside the canvas of the SVG document `svg`, one line each (empty: all inside).
/// `tolerance` pixels of overhang are allowed (anti-aliased stroke ends).
pub fn outside_canvas(svg: &str, tolerance: f64) -> Result<Vec<String>, String> {
    let root = element(svg, "svg").ok_or("no <svg> element")?;
    let width = number(root, "width").ok_or("<svg> has no width")?;
    let height = number(root, "height").ok_or("<svg> has no height")?;
    let inside = |(x0, y0, x1, y1): (f64, f64, f64, f64)| {
        x0 >= -tolerance && y0 >= -tolerance && x1 <= width + tolerance && y1 <= height + tolerance
    };
    let mut problems = Vec::new();
    let mut rest = svg;
    while let Some(start) = rest.find('<') {
        rest = &rest[start + 1..];
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        let Some(end) = rest.find('>') else { break };
        let tag = &rest[..end];
        let bounds = match name.as_str() {
            "text" => {
                let body_end = rest.find("</text>").unwrap_or(end);
                let content = unescape(rest.get(end + 1..body_end).unwrap_or(""));
                text_box(tag, &content).map(|b| (b, format!("text {content:?}")))
            }
            "rect" => match (
                number(tag, "x"),
                number(tag, "y"),
                number(tag, "width"),
                number(tag, "height"),
            ) {
                (Some(x), Some(y), Some(w), Some(h)) => Some(((x, y, x + w, y + h), "rect".into())),
                _ => None,
            },
            "line" => match (
                number(tag, "x1"),
                number(tag, "y1"),
                number(tag, "x2"),
                number(tag, "y2"),
            ) {
                (Some(a), Some(b), Some(c), Some(d)) => {
                    Some(((a.min(c), b.min(d), a.max(c), b.max(d)), "line".into()))
                }
                _ => None,
            },
            "polyline" | "polygon" => attribute(tag, "points")
                .and_then(points_box)
                .map(|b| (b, name.clone())),
            "circle" => match (number(tag, "cx"), number(tag, "cy"), number(tag, "r")) {
                (Some(x), Some(y), Some(r)) => {
                    Some(((x - r, y - r, x + r, y + r), "circle".into()))
                }
                _ => None,
            },
            _ => None,
        };
        if let Some((b, what)) = bounds
            && !inside(b)
        {
            problems.push(format!(
                "{what} spans x {:.0}..{:.0}, y {:.0}..{:.0}: outside the {width} × {height} canvas",
                b.0, b.1, b.2, b.3
            ));
        }
        rest = &rest[end..];
    }
    Ok(problems)
}

/// The box (x0, y0, x1, y1) of a text element: anchored at (x, y) (`text-anchor` start,
/// middle or end; plotters sets `dy` so that y is the top, or the centre with
/// `dominant-baseline`), turned by a `rotate(a, cx, cy)` transform of a multiple of 90°.
fn text_box(tag: &str, content: &str) -> Option<(f64, f64, f64, f64)> {
    let (x, y) = (number(tag, "x")?, number(tag, "y")?);
    let size = number(tag, "font-size").unwrap_or(16.0);
    let w = text_width(content, size);
    let (left, right) = match attribute(tag, "text-anchor") {
        Some("middle") => (-w / 2.0, w / 2.0),
        Some("end") => (-w, 0.0),
        _ => (0.0, w),
    };
    // Vertical extent about y: plotters' `dy="0.76em"` puts the top at y; otherwise y may be
    // the baseline (text above it) or the centre: take the union, which covers all three.
    let (top, bottom) = match attribute(tag, "dy") {
        Some(dy) if dy.ends_with("em") => (0.0, size),
        _ => (-size, size / 2.0),
    };
    let corners = [(left, top), (right, top), (left, bottom), (right, bottom)];
    let rotation = attribute(tag, "transform").and_then(|t| {
        let inner = t.strip_prefix("rotate(")?.strip_suffix(')')?;
        let mut v = inner.split([',', ' ']).filter(|s| !s.is_empty());
        let a: f64 = v.next()?.parse().ok()?;
        let cx: f64 = v.next().and_then(|s| s.parse().ok()).unwrap_or(0.0);
        let cy: f64 = v.next().and_then(|s| s.parse().ok()).unwrap_or(0.0);
        Some((a.to_radians(), cx, cy))
    });
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for (dx, dy) in corners {
        let (mut px, mut py) = (x + dx, y + dy);
        if let Some((a, cx, cy)) = rotation {
            let (s, c) = a.sin_cos();
            let (rx, ry) = (px - cx, py - cy);
            (px, py) = (cx + c * rx - s * ry, cy + s * rx + c * ry);
        }
        (x0, y0, x1, y1) = (x0.min(px), y0.min(py), x1.max(px), y1.max(py));
    }
    Some((x0, y0, x1, y1))
}

fn points_box(points: &str) -> Option<(f64, f64, f64, f64)> {
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    let mut any = false;
    for pair in points.split_whitespace() {
        let (x, y) = pair.split_once(',')?;
        let (x, y): (f64, f64) = (x.parse().ok()?, y.parse().ok()?);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        any = true;
    }
    any.then_some((x0, y0, x1, y1))
}

/// The attributes of the first `<name ...>` element.
fn element<'a>(svg: &'a str, name: &str) -> Option<&'a str> {
    let start = svg.find(&format!("<{name} "))?;
    let end = svg[start..].find('>')?;
    Some(&svg[start..start + end])
}

fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let start = tag.find(&key)? + key.len();
    let end = tag[start..].find('"')?;
    Some(&tag[start..start + end])
}

fn number(tag: &str, name: &str) -> Option<f64> {
    attribute(tag, name)?.trim_end_matches("px").parse().ok()
}

fn unescape(text: &str) -> String {
    text.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}
