//! A minimal SVG line chart for the review page: data series as polylines
//! (each tagged with its name and range, so the page can be checked by
//! parsing it), events as vertical markers. No fonts to embed: the
//! browser renders the text.

use std::fmt::Write as _;

/// One data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend name (also the `data-name` attribute).
    pub name: String,
    /// Stroke colour (CSS).
    pub color: &'static str,
    /// (x, y) points; non-finite ones break the line.
    pub points: Vec<(f64, f64)>,
    /// Dashed stroke.
    pub dashed: bool,
}

/// A vertical marker at x.
#[derive(Debug, Clone)]
pub struct Marker {
    /// Position on the x axis.
    pub x: f64,
    /// Label (tooltip and `data-label`).
    pub label: String,
    /// Colour (CSS).
    pub color: &'static str,
}

/// A labelled band over an x span (a supervisor state).
#[derive(Debug, Clone)]
pub struct Band {
    /// Start and end on the x axis.
    pub x0: f64,
    /// End on the x axis.
    pub x1: f64,
    /// Label (drawn in the band when wide enough, and its tooltip).
    pub label: String,
    /// Fill colour (CSS).
    pub color: &'static str,
}

/// Most points a series keeps: above it, min/max thinning per x bucket
/// (each bucket keeps its first, smallest, largest and last point, in x
/// order), so peaks survive and a 10-minute flight stays small.
pub const MAX_POINTS: usize = 2400;

/// Min/max thinning of `points` to at most about `max` points (see
/// [`MAX_POINTS`]); non-finite points are kept as line breaks.
pub fn thin(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max {
        return points.to_vec();
    }
    let buckets = (max / 4).max(1);
    let per = points.len().div_ceil(buckets);
    let mut out = Vec::with_capacity(4 * buckets + 8);
    for chunk in points.chunks(per) {
        if chunk.iter().any(|p| !(p.0.is_finite() && p.1.is_finite())) {
            // Keep the break: the finite ends around it and one NaN.
            let mut pen = false;
            for p in chunk {
                let ok = p.0.is_finite() && p.1.is_finite();
                if ok != pen {
                    out.push(*p);
                    pen = ok;
                }
            }
            continue;
        }
        let (mut lo, mut hi) = (0, 0);
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[lo].1 {
                lo = i;
            }
            if p.1 > chunk[hi].1 {
                hi = i;
            }
        }
        let mut idx = [0, lo, hi, chunk.len() - 1];
        idx.sort_unstable();
        let mut last = usize::MAX;
        for i in idx {
            if i != last {
                out.push(chunk[i]);
                last = i;
            }
        }
    }
    out
}

/// A chart.
#[derive(Debug, Clone, Default)]
pub struct Chart {
    /// Id of the `<svg>` element.
    pub id: String,
    /// Title above the plot.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// The series.
    pub series: Vec<Series>,
    /// Markers (state changes, guard events).
    pub markers: Vec<Marker>,
    /// Equal scales on both axes (a map).
    pub equal_axes: bool,
    /// Labelled bands (supervisor states) behind the series.
    pub bands: Vec<Band>,
    /// A time axis the page's script may zoom, pan and put the cursor on
    /// (linked across the page).
    pub time_axis: bool,
    /// For the map: (t, x, y) samples of the vehicle, for the time cursor.
    pub track: Vec<(f64, f64, f64)>,
}

const W: f64 = 900.0;
const H: f64 = 300.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 30.0;
const BOTTOM: f64 = 45.0;

fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return None;
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    Some((lo - pad, hi + pad))
}

/// Escapes text for XML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-12 && out.len() < 20 {
        out.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    out
}

impl Chart {
    /// The chart as an `<svg>` element.
    pub fn to_svg(&self) -> String {
        let height = if self.equal_axes { 600.0 } else { H };
        let all = || self.series.iter().flat_map(|s| s.points.iter());
        let xr = range(all().map(|p| p.0).chain(self.markers.iter().map(|m| m.x)));
        let yr = range(all().map(|p| p.1));
        let mut svg = String::new();
        let _ = write!(
            svg,
            r#"<svg id="{}" class="chart{}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {height}" width="100%" preserveAspectRatio="xMidYMid meet" font-family="sans-serif" font-size="12""#,
            esc(&self.id),
            if self.time_axis { " time" } else { "" }
        );
        let (Some((mut x0, mut x1)), Some((mut y0, mut y1))) = (xr, yr) else {
            let _ = write!(
                svg,
                r#"><text x="{}" y="18" text-anchor="middle" font-size="15">{}</text><text x="100" y="80">no data</text></svg>"#,
                W / 2.0,
                esc(&self.title)
            );
            return svg;
        };
        let pw = W - LEFT - RIGHT;
        let ph = height - TOP - BOTTOM;
        if self.equal_axes {
            // Same metres per pixel on both axes.
            let scale = ((x1 - x0) / pw).max((y1 - y0) / ph);
            let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
            (x0, x1) = (cx - scale * pw / 2.0, cx + scale * pw / 2.0);
            (y0, y1) = (cy - scale * ph / 2.0, cy + scale * ph / 2.0);
        }
        let px = |x: f64| LEFT + (x - x0) / (x1 - x0) * pw;
        let py = |y: f64| TOP + (1.0 - (y - y0) / (y1 - y0)) * ph;
        // The mapping, for the page's script (zoom, pan, cursor).
        let _ = write!(
            svg,
            r#" data-x0="{x0}" data-x1="{x1}" data-y0="{y0}" data-y1="{y1}" data-left="{LEFT}" data-top="{TOP}" data-pw="{pw}" data-ph="{ph}">"#
        );
        let _ = write!(
            svg,
            r#"<text x="{}" y="18" text-anchor="middle" font-size="15">{}</text>"#,
            W / 2.0,
            esc(&self.title)
        );
        let clip = format!("clip-{}", esc(&self.id));
        let _ = write!(
            svg,
            r#"<clipPath id="{clip}"><rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}"/></clipPath>"#
        );
        let _ = write!(
            svg,
            r##"<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="#888"/>"##
        );
        svg.push_str(r#"<g class="xticks">"#);
        for t in ticks(x0, x1) {
            let _ = write!(
                svg,
                r##"<line x1="{0:.1}" x2="{0:.1}" y1="{TOP}" y2="{1:.1}" stroke="#eee"/><text x="{0:.1}" y="{2:.1}" text-anchor="middle">{3}</text>"##,
                px(t),
                TOP + ph,
                TOP + ph + 15.0,
                fmt_tick(t)
            );
        }
        svg.push_str("</g>");
        for t in ticks(y0, y1) {
            let _ = write!(
                svg,
                r##"<line x1="{LEFT}" x2="{0:.1}" y1="{1:.1}" y2="{1:.1}" stroke="#eee"/><text x="{2:.1}" y="{3:.1}" text-anchor="end">{4}</text>"##,
                LEFT + pw,
                py(t),
                LEFT - 5.0,
                py(t) + 4.0,
                fmt_tick(t)
            );
        }
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text transform="translate(15 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            LEFT + pw / 2.0,
            height - 8.0,
            esc(&self.x_label),
            TOP + ph / 2.0,
            esc(&self.y_label)
        );
        // Everything on the time axis sits in one group the script scales.
        let _ = write!(svg, r#"<g clip-path="url(#{clip})"><g class="plot">"#);
        for b in &self.bands {
            let (a, z) = (px(b.x0.max(x0)), px(b.x1.min(x1)));
            if z <= a {
                continue;
            }
            let _ = write!(
                svg,
                r#"<rect class="band" data-label="{0}" x="{1:.1}" y="{TOP}" width="{2:.1}" height="{ph}" fill="{3}" fill-opacity="0.16"><title>{0}: {4:.2}–{5:.2} s</title></rect>"#,
                esc(&b.label),
                a,
                z - a,
                b.color,
                b.x0,
                b.x1
            );
            if z - a > 8.0 * b.label.len() as f64 {
                let _ = write!(
                    svg,
                    r#"<text class="band-label" x="{:.1}" y="{:.1}" font-size="10" fill="{}">{}</text>"#,
                    a + 3.0,
                    TOP + ph - 4.0,
                    b.color,
                    esc(&b.label)
                );
            }
        }
        for m in &self.markers {
            let _ = write!(
                svg,
                r#"<line class="marker" data-label="{}" x1="{2:.1}" x2="{2:.1}" y1="{TOP}" y2="{3:.1}" stroke="{1}" stroke-width="1.5" vector-effect="non-scaling-stroke"><title>{0} at {4:.2}</title></line>"#,
                esc(&m.label),
                m.color,
                px(m.x),
                TOP + ph,
                m.x
            );
        }
        for s in &self.series {
            let points = thin(&s.points, MAX_POINTS);
            let finite: Vec<&(f64, f64)> = points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            let (lo, hi) = finite
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.1), b.max(p.1))
                });
            let mut d = String::new();
            let mut pen_up = true;
            for p in &points {
                if !(p.0.is_finite() && p.1.is_finite()) {
                    pen_up = true;
                    continue;
                }
                let _ = write!(
                    d,
                    "{}{:.1},{:.1}",
                    if pen_up { "M" } else { "L" },
                    px(p.0),
                    py(p.1)
                );
                pen_up = false;
            }
            let _ = write!(
                svg,
                r#"<path class="series" data-name="{}" data-points="{}" data-min="{lo}" data-max="{hi}" d="{d}" fill="none" stroke="{}" stroke-width="1.3" vector-effect="non-scaling-stroke"{}/>"#,
                esc(&s.name),
                finite.len(),
                s.color,
                if s.dashed {
                    r#" stroke-dasharray="6 3""#
                } else {
                    ""
                }
            );
        }
        svg.push_str("</g></g>");
        if !self.track.is_empty() {
            let track: Vec<String> = self
                .track
                .iter()
                .map(|(t, x, y)| format!("[{t:.2},{:.1},{:.1}]", px(*x), py(*y)))
                .collect();
            let _ = write!(
                svg,
                r##"<circle class="vehicle" r="6" cx="-20" cy="-20" fill="#e80" stroke="#333" data-track="[{}]"/>"##,
                track.join(",")
            );
        }
        for (i, s) in self.series.iter().enumerate() {
            let ly = TOP + 14.0 + 15.0 * i as f64;
            let _ = write!(
                svg,
                r#"<line x1="{0:.1}" x2="{1:.1}" y1="{2:.1}" y2="{2:.1}" stroke="{3}" stroke-width="2"/><text x="{4:.1}" y="{5:.1}">{6}</text>"#,
                LEFT + pw - 170.0,
                LEFT + pw - 150.0,
                ly,
                s.color,
                LEFT + pw - 145.0,
                ly + 4.0,
                esc(&s.name)
            );
        }
        svg.push_str("</svg>");
        svg
    }
}

fn fmt_tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}
