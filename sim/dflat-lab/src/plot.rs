//! Plot helpers: thin plotters wrappers that write every figure twice, as
//! `<stem>.svg` and `<stem>.png`.
//!
//! * [`write_line_plot`] — several series over a linear or logarithmic x
//!   axis (e.g. the paper's Fig. 3: output error vs noise σ);
//! * [`write_path_plot`] — x-y paths with the reference in black and equal
//!   axis scales (the paper's Fig. 5);
//! * [`write_box_plot`] — Tukey box plots per category, several series side
//!   by side in each (the paper's Fig. 4: path error per speed × controller).
//!
//! Colours follow the paper: Discrete-Flatness red ([`DF_RED`]), Flatness
//! MPC blue ([`FMPC_BLUE`]), PD green ([`PD_GREEN`]); [`controller_color`]
//! maps a controller name to its colour. Text uses the vendored DejaVu Sans
//! (registered with plotters' ab_glyph backend on first use), so no system
//! fonts are needed. SVG text references the family `sans-serif`.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Once;

use nalgebra::Vector3;
use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub use plotters::style::RGBColor;

use dflat_sim::SimError;

/// Discrete-Flatness MPC: red.
pub const DF_RED: RGBColor = RGBColor(214, 39, 40);
/// Flatness MPC: blue.
pub const FMPC_BLUE: RGBColor = RGBColor(31, 119, 180);
/// PD: green.
pub const PD_GREEN: RGBColor = RGBColor(44, 160, 44);
/// Reference paths: black.
pub const REFERENCE_BLACK: RGBColor = RGBColor(0, 0, 0);

/// Further colours for series that are not one of the three controllers.
const PALETTE: [RGBColor; 6] = [
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(23, 190, 207),
];

const FONT: &str = "sans-serif";
static FONT_ONCE: Once = Once::new();

/// Registers the vendored DejaVu Sans as plotters' `sans-serif` (idempotent).
pub fn register_font() {
    FONT_ONCE.call_once(|| {
        // The font is vendored and valid; a failure would only lose text.
        let _ = plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            include_bytes!("../assets/DejaVuSans.ttf"),
        );
    });
}

/// The paper's colour for a controller name: names containing "df" → red,
/// "fmpc" or "flatness" → blue, "pd" → green; otherwise a palette colour
/// chosen by `index`.
pub fn controller_color(name: &str, index: usize) -> RGBColor {
    let n = name.to_ascii_lowercase();
    if n.contains("fmpc") || n.contains("flatness mpc") || n == "flatness" {
        FMPC_BLUE
    } else if n.contains("df") || n.contains("discrete") {
        DF_RED
    } else if n == "pd" || n.starts_with("pd ") || n.starts_with("pd-") || n.contains(" pd") {
        PD_GREEN
    } else {
        PALETTE[index % PALETTE.len()]
    }
}

/// NED positions as map points `(east, north)` \[m\], for path plots with
/// north up.
pub fn north_up(points: &[Vector3<f64>]) -> Vec<(f64, f64)> {
    points.iter().map(|p| (p.y, p.x)).collect()
}

/// One named, coloured series of (x, y) points.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry (empty: no entry).
    pub name: String,
    /// Line / marker colour.
    pub color: RGBColor,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// Also mark every point with a small circle.
    pub markers: bool,
}

impl Series {
    /// A line series without markers.
    pub fn new(name: impl Into<String>, color: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            color,
            points,
            markers: false,
        }
    }
}

/// A plot's `new(title, x_label, y_label)`, documented `$doc`, the other
/// fields set as given.
macro_rules! labelled_new {
    ($doc:literal, $($field:ident: $value:expr),+ $(,)?) => {
        #[doc = $doc]
        pub fn new(
            title: impl Into<String>,
            x_label: impl Into<String>,
            y_label: impl Into<String>,
        ) -> Self {
            Self {
                title: title.into(),
                x_label: x_label.into(),
                y_label: y_label.into(),
                $($field: $value),+
            }
        }
    };
}

/// A line plot with several series.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    /// Title above the chart.
    pub title: String,
    /// x-axis label (with units).
    pub x_label: String,
    /// y-axis label (with units).
    pub y_label: String,
    /// Logarithmic x axis (points with x ≤ 0 are dropped).
    pub log_x: bool,
    /// Logarithmic y axis (points with y ≤ 0 are dropped).
    pub log_y: bool,
    /// The series.
    pub series: Vec<Series>,
    /// Image size \[px\].
    pub size: (u32, u32),
}

impl LinePlot {
    labelled_new!(
        "An empty 900×600 linear plot.",
        log_x: false,
        log_y: false,
        series: Vec::new(),
        size: (900, 600),
    );
}

/// An x-y path plot: reference in black, flown paths in colour, equal scales.
#[derive(Debug, Clone, PartialEq)]
pub struct PathPlot {
    /// Title above the chart.
    pub title: String,
    /// x-axis label (e.g. "east \[m\]").
    pub x_label: String,
    /// y-axis label (e.g. "north \[m\]").
    pub y_label: String,
    /// The reference path (drawn black, legend "reference").
    pub reference: Vec<(f64, f64)>,
    /// The flown paths.
    pub series: Vec<Series>,
    /// Image size \[px\].
    pub size: (u32, u32),
}

impl PathPlot {
    labelled_new!(
        "An empty 800×800 path plot.",
        reference: Vec::new(),
        series: Vec::new(),
        size: (800, 800),
    );
}

/// One series of a box plot: a sample of values per category.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSeries {
    /// Legend entry.
    pub name: String,
    /// Box colour.
    pub color: RGBColor,
    /// `values[g]`: the sample for category g (may be empty).
    pub values: Vec<Vec<f64>>,
}

/// Box plots per category (x) with one box per series in each.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxPlot {
    /// Title above the chart.
    pub title: String,
    /// x-axis label (e.g. "desired speed [m/s]").
    pub x_label: String,
    /// y-axis label (e.g. "path error \[m\]").
    pub y_label: String,
    /// Category names, left to right.
    pub categories: Vec<String>,
    /// The series.
    pub series: Vec<BoxSeries>,
    /// Logarithmic y axis (values ≤ 0 are dropped).
    pub log_y: bool,
    /// Image size \[px\].
    pub size: (u32, u32),
}

impl BoxPlot {
    labelled_new!(
        "An empty 900×600 box plot.",
        categories: Vec::new(),
        series: Vec::new(),
        log_y: false,
        size: (900, 600),
    );
}

/// Tukey box statistics of a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxStats {
    /// Lower whisker: smallest value ≥ q1 − 1.5·IQR.
    pub whisker_lo: f64,
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Upper whisker: largest value ≤ q3 + 1.5·IQR.
    pub whisker_hi: f64,
}

impl BoxStats {
    /// Statistics of the finite values (None when there are none), and the
    /// outliers beyond the whiskers.
    pub fn from_values(values: &[f64]) -> Option<(Self, Vec<f64>)> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let q = |p| crate::harness::quantile(&v, p);
        let (q1, median, q3) = (q(0.25), q(0.5), q(0.75));
        let iqr = q3 - q1;
        let (lo_fence, hi_fence) = (q1 - 1.5 * iqr, q3 + 1.5 * iqr);
        let whisker_lo = v.iter().copied().find(|x| *x >= lo_fence).unwrap_or(q1);
        let whisker_hi = v
            .iter()
            .rev()
            .copied()
            .find(|x| *x <= hi_fence)
            .unwrap_or(q3);
        let outliers = v
            .iter()
            .copied()
            .filter(|x| *x < whisker_lo || *x > whisker_hi)
            .collect();
        Some((
            Self {
                whisker_lo,
                q1,
                median,
                q3,
                whisker_hi,
            },
            outliers,
        ))
    }
}

/// Writes `plot` to `<stem>.svg` and `<stem>.png`; returns both paths.
pub fn write_line_plot(stem: &Path, plot: &LinePlot) -> Result<[PathBuf; 2], SimError> {
    render(stem, plot)
}

/// Writes `plot` to `<stem>.svg` and `<stem>.png`; returns both paths.
pub fn write_path_plot(stem: &Path, plot: &PathPlot) -> Result<[PathBuf; 2], SimError> {
    render(stem, plot)
}

/// Writes `plot` to `<stem>.svg` and `<stem>.png`; returns both paths.
pub fn write_box_plot(stem: &Path, plot: &BoxPlot) -> Result<[PathBuf; 2], SimError> {
    render(stem, plot)
}

type DrawResult = Result<(), String>;

/// A plot [`render`] can draw on any backend.
trait Drawable {
    /// Image size \[px\].
    fn size(&self) -> (u32, u32);
    /// Draws the plot on `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult;
}

impl Drawable for LinePlot {
    fn size(&self) -> (u32, u32) {
        self.size
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        draw_line_plot(root, self)
    }
}

impl Drawable for PathPlot {
    fn size(&self) -> (u32, u32) {
        self.size
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        draw_path_plot(root, self)
    }
}

impl Drawable for BoxPlot {
    fn size(&self) -> (u32, u32) {
        self.size
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        draw_box_plot(root, self)
    }
}

/// Draws with an SVG and a bitmap backend, creating the parent directory.
fn render(stem: &Path, plot: &impl Drawable) -> Result<[PathBuf; 2], SimError> {
    let size = plot.size();
    register_font();
    if let Some(dir) = stem.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let svg_path = stem.with_extension("svg");
    let png_path = stem.with_extension("png");
    let fail = |path: &Path| {
        let file = path.display().to_string();
        move |message: String| SimError::Plot { file, message }
    };
    {
        let root = SVGBackend::new(&svg_path, size).into_drawing_area();
        plot.draw(&root)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
            .map_err(fail(&svg_path))?;
    }
    {
        let root = BitMapBackend::new(&png_path, size).into_drawing_area();
        plot.draw(&root)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
            .map_err(fail(&png_path))?;
    }
    Ok([svg_path, png_path])
}

/// `[min, max]` of finite values, padded by 5 % (±1 or ±10 % when flat);
/// logarithmic ranges are padded multiplicatively.
fn padded_range(values: impl Iterator<Item = f64>, log: bool) -> Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && (!log || *v > 0.0))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return if log { 0.1..10.0 } else { 0.0..1.0 };
    }
    if log {
        let (l, h) = (lo.ln(), hi.ln());
        let pad = if h > l { 0.05 * (h - l) } else { 10f64.ln() };
        (l - pad).exp()..(h + pad).exp()
    } else if hi > lo {
        let pad = 0.05 * (hi - lo);
        lo - pad..hi + pad
    } else {
        let pad = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        lo - pad..hi + pad
    }
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn title_font() -> TextStyle<'static> {
    (FONT, 24).into_font().color(&BLACK)
}

/// A chart builder on `root` with the plots' common frame: `title`
/// above, margins and label areas.
fn framed<'a, 'b, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    title: &str,
) -> ChartBuilder<'a, 'b, DB> {
    let mut builder = ChartBuilder::on(root);
    builder
        .caption(title, title_font())
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(70);
    builder
}

/// The plots' axis labels and their fonts on `mesh`.
fn labelled<'m, 'a, 'b, X, Y, DB>(
    mesh: &'m mut plotters::chart::MeshStyle<'a, 'b, X, Y, DB>,
    x_label: &'m str,
    y_label: &'m str,
) -> &'m mut plotters::chart::MeshStyle<'a, 'b, X, Y, DB>
where
    X: Ranged<ValueType: std::fmt::Debug>,
    Y: Ranged<ValueType: std::fmt::Debug>,
    DB: DrawingBackend,
{
    mesh.x_desc(x_label)
        .y_desc(y_label)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
}

/// An `f64` axis range a chart can be built on and its mesh labelled.
trait Axis: AsRangedCoord<Value = f64, CoordDescType: ValueFormatter<f64>> {}

impl<T: AsRangedCoord<Value = f64, CoordDescType: ValueFormatter<f64>>> Axis for T {}

/// A chart on `DB` over the x and y coordinates `X`, `Y`.
type XyChart<'a, DB, X, Y> = ChartContext<'a, DB, Cartesian2d<X, Y>>;

/// A [`framed`] chart on `root` over `xr` × `yr` with its mesh drawn,
/// [`labelled`] `(x_label, y_label)`.
fn labelled_chart<'a, DB, XR, YR>(
    root: &'a DrawingArea<DB, Shift>,
    title: &str,
    (x_label, y_label): (&str, &str),
    xr: XR,
    yr: YR,
) -> Result<XyChart<'a, DB, XR::CoordDescType, YR::CoordDescType>, String>
where
    DB: DrawingBackend,
    XR: Axis,
    YR: Axis,
{
    let mut chart = framed(root, title)
        .build_cartesian_2d(xr, yr)
        .map_err(err)?;
    labelled(&mut chart.configure_mesh(), x_label, y_label)
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// Draws `s` through its points `pts` (2 px; its markers when it has
/// them) with its legend entry when it has a name; returns whether it had
/// one.
fn draw_line_series<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    s: &Series,
    pts: Vec<(f64, f64)>,
) -> Result<bool, String>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate<From = (f64, f64)>,
{
    let color = s.color;
    let anno = chart
        .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
        .map_err(err)?;
    let named = !s.name.is_empty();
    if named {
        anno.label(s.name.as_str()).legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
        });
    }
    if s.markers {
        chart
            .draw_series(pts.iter().map(|p| Circle::new(*p, 3, color.filled())))
            .map_err(err)?;
    }
    Ok(named)
}

/// The legend box at `position`.
fn draw_legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .label_font((FONT, 14))
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .position(position)
        .draw()
        .map_err(err)
}

fn draw_line_plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    plot: &LinePlot,
) -> DrawResult {
    let keep = |&(x, y): &(f64, f64)| {
        x.is_finite() && y.is_finite() && (!plot.log_x || x > 0.0) && (!plot.log_y || y > 0.0)
    };
    let xs = plot
        .series
        .iter()
        .flat_map(|s| s.points.iter().filter(|p| keep(p)).map(|p| p.0));
    let ys = plot
        .series
        .iter()
        .flat_map(|s| s.points.iter().filter(|p| keep(p)).map(|p| p.1));
    let xr = padded_range(xs, plot.log_x);
    let yr = padded_range(ys, plot.log_y);
    match (plot.log_x, plot.log_y) {
        (false, false) => line_chart(root, plot, xr, yr, &keep),
        (true, false) => line_chart(root, plot, xr.log_scale(), yr, &keep),
        (false, true) => line_chart(root, plot, xr, yr.log_scale(), &keep),
        (true, true) => line_chart(root, plot, xr.log_scale(), yr.log_scale(), &keep),
    }
}

fn line_chart<DB, XR, YR>(
    root: &DrawingArea<DB, Shift>,
    plot: &LinePlot,
    xr: XR,
    yr: YR,
    keep: &dyn Fn(&(f64, f64)) -> bool,
) -> DrawResult
where
    DB: DrawingBackend,
    XR: Axis,
    YR: Axis,
{
    root.fill(&WHITE).map_err(err)?;
    let labels = (plot.x_label.as_str(), plot.y_label.as_str());
    let mut chart = labelled_chart(root, &plot.title, labels, xr, yr)?;
    let mut named = false;
    for s in &plot.series {
        let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(|p| keep(p)).collect();
        named |= draw_line_series(&mut chart, s, pts)?;
    }
    if named {
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}

fn draw_path_plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    plot: &PathPlot,
) -> DrawResult {
    root.fill(&WHITE).map_err(err)?;
    let all = || {
        plot.reference
            .iter()
            .chain(plot.series.iter().flat_map(|s| s.points.iter()))
            .filter(|p| p.0.is_finite() && p.1.is_finite())
    };
    let mut xr = padded_range(all().map(|p| p.0), false);
    let mut yr = padded_range(all().map(|p| p.1), false);
    // Equal scales: widen the narrower range to the plotting area's aspect
    // (the area is the image minus margins, label areas and caption).
    let (w, h) = root.dim_in_pixel();
    let area_w = (w as f64 - 2.0 * 15.0 - 70.0).max(1.0);
    let area_h = (h as f64 - 2.0 * 15.0 - 50.0 - 40.0).max(1.0);
    let (dx, dy) = (xr.end - xr.start, yr.end - yr.start);
    let scale = (dx / area_w).max(dy / area_h);
    let (cx, cy) = ((xr.start + xr.end) / 2.0, (yr.start + yr.end) / 2.0);
    xr = cx - scale * area_w / 2.0..cx + scale * area_w / 2.0;
    yr = cy - scale * area_h / 2.0..cy + scale * area_h / 2.0;

    let labels = (plot.x_label.as_str(), plot.y_label.as_str());
    let mut chart = labelled_chart(root, &plot.title, labels, xr, yr)?;
    if !plot.reference.is_empty() {
        chart
            .draw_series(LineSeries::new(
                plot.reference.iter().copied(),
                REFERENCE_BLACK.stroke_width(3),
            ))
            .map_err(err)?
            .label("reference")
            .legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], REFERENCE_BLACK.stroke_width(3))
            });
    }
    for s in &plot.series {
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        draw_line_series(&mut chart, s, pts)?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

fn draw_box_plot<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, plot: &BoxPlot) -> DrawResult {
    let keep = |v: &f64| v.is_finite() && (!plot.log_y || *v > 0.0);
    let ys = plot
        .series
        .iter()
        .flat_map(|s| s.values.iter().flatten().copied().filter(keep));
    let yr = padded_range(ys, plot.log_y);
    if plot.log_y {
        box_chart(root, plot, yr.log_scale(), &keep)
    } else {
        box_chart(root, plot, yr, &keep)
    }
}

fn box_chart<DB, YR>(
    root: &DrawingArea<DB, Shift>,
    plot: &BoxPlot,
    yr: YR,
    keep: &dyn Fn(&f64) -> bool,
) -> DrawResult
where
    DB: DrawingBackend,
    YR: AsRangedCoord<Value = f64>,
    YR::CoordDescType: ValueFormatter<f64>,
{
    root.fill(&WHITE).map_err(err)?;
    let n_cat = plot.categories.len().max(1);
    let mut chart = framed(root, &plot.title)
        .build_cartesian_2d(0.0..n_cat as f64, yr)
        .map_err(err)?;
    labelled(
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .x_label_formatter(&|_| String::new()),
        &plot.x_label,
        &plot.y_label,
    )
    .draw()
    .map_err(err)?;
    // Category names under the axis, centred on each category.
    let y_low = chart.y_range().start;
    for (g, name) in plot.categories.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(g as f64 + 0.5, y_low));
        root.draw(&Text::new(
            name.clone(),
            (px, py + 8),
            TextStyle::from((FONT, 14).into_font()).pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(err)?;
    }
    let n_series = plot.series.len().max(1);
    let slot = 0.8 / n_series as f64;
    for (i, s) in plot.series.iter().enumerate() {
        let color = s.color;
        for (g, values) in s.values.iter().enumerate().take(n_cat) {
            let v: Vec<f64> = values.iter().copied().filter(|x| keep(x)).collect();
            let Some((b, outliers)) = BoxStats::from_values(&v) else {
                continue;
            };
            let centre = g as f64 + 0.1 + slot * (i as f64 + 0.5);
            let (l, r) = (centre - 0.35 * slot, centre + 0.35 * slot);
            let (wl, wr) = (centre - 0.15 * slot, centre + 0.15 * slot);
            let style = color.stroke_width(2);
            chart
                .draw_series([
                    Rectangle::new([(l, b.q1), (r, b.q3)], color.mix(0.25).filled()),
                    Rectangle::new([(l, b.q1), (r, b.q3)], style),
                ])
                .map_err(err)?;
            chart
                .draw_series([
                    PathElement::new(vec![(l, b.median), (r, b.median)], BLACK.stroke_width(2)),
                    PathElement::new(vec![(centre, b.q3), (centre, b.whisker_hi)], style),
                    PathElement::new(vec![(centre, b.q1), (centre, b.whisker_lo)], style),
                    PathElement::new(vec![(wl, b.whisker_hi), (wr, b.whisker_hi)], style),
                    PathElement::new(vec![(wl, b.whisker_lo), (wr, b.whisker_lo)], style),
                ])
                .map_err(err)?;
            chart
                .draw_series(outliers.iter().map(|y| Circle::new((centre, *y), 3, style)))
                .map_err(err)?;
        }
        // Legend entry: an invisible series carrying the label.
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(err)?
            .label(s.name.as_str())
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 6), (x + 20, y + 6)], color.mix(0.5).filled())
            });
    }
    if !plot.series.is_empty() {
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    Ok(())
}
