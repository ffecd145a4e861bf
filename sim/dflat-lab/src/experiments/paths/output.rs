//! The paths study's plots and JSON.

use super::*;

/// Points per box of the path-error box plot (see [`quantile_sketch`]).
const BOX_QUANTILES: usize = 401;

/// The `n` evenly spaced quantiles (0, 1/(n−1), …, 1; type 7) of the finite
/// values, or the values themselves when there are at most `n`. With
/// n = 401 the quartiles and the median are exact and the whiskers and
/// extremes nearly so, while the plot draws at most a few hundred outlier
/// marks instead of thousands of pooled ticks (the JSON has the exact
/// statistics).
fn quantile_sketch(values: &[f64], n: usize) -> Vec<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.len() <= n || n < 2 {
        return v;
    }
    v.sort_by(f64::total_cmp);
    (0..n)
        .map(|i| quantile(&v, i as f64 / (n - 1) as f64))
        .collect()
}

fn speed_label(v: f64) -> String {
    format!("{v} m/s")
}

fn color(c: &ControllerSpec, k: usize) -> RGBColor {
    match c.name() {
        // Apart from their finite-difference namesakes (blue, green).
        "fmpc-est" => RGBColor(23, 190, 207),
        "pd-est" => RGBColor(188, 189, 34),
        "df-mr-smooth" => RGBColor(148, 103, 189),
        name => controller_color(name, k),
    }
}

/// Writes the JSON and the plots (stems under the plot prefix):
///
/// * `_boxplot` — path error per controller and speed (pooled ticks, drawn
///   through 401 evenly spaced quantiles, which keep the quartiles and the
///   extremes and bound the SVG size);
/// * `_flown_<v>ms` — the flown paths (trial 0 per controller), reference
///   black, x (north) right and y (east) up as in the paper's figure;
/// * `_smoothness` — per-trial mean |Δu| per tick \[deg\], box per
///   controller and speed; `_saturation` — per-trial saturated share [%];
/// * `_dsl` — the DSL flights coloured by speed (east right, north up) and
///   `_dsl_speed` — speed vs distance flown.
///
/// Returns the files written.
pub fn write_paths(
    result: &PathsResult,
    out: &OutputPaths,
) -> Result<Vec<PathBuf>, ExperimentError> {
    write_json(&out.json, result)?;
    let mut files = vec![out.json.clone()];
    let mut push = |p: [PathBuf; 2]| files.extend(p);
    let speeds = &result.config.speeds;
    let categories: Vec<String> = speeds.iter().map(|v| speed_label(*v)).collect();

    // Box plot of path error.
    let mut bp = BoxPlot::new(
        "Path error on the L path (vision-like sensing, all ticks of all trials)",
        "desired speed",
        "path error [m]",
    );
    bp.size = (1000, 700);
    bp.categories = categories.clone();
    for (k, c) in result.controllers.iter().enumerate() {
        bp.series.push(BoxSeries {
            name: format!("{} ({})", c.label(), c.describe()),
            color: color(c, k),
            values: speeds
                .iter()
                .map(|v| {
                    result
                        .pooled_errors
                        .iter()
                        .find(|p| p.0 == c.name() && p.1 == *v)
                        .map(|p| quantile_sketch(&p.2, BOX_QUANTILES))
                        .unwrap_or_default()
                })
                .collect(),
        });
    }
    push(write_box_plot(&out.plot("boxplot"), &bp)?);

    // Per-trial smoothness and saturation.
    let per_trial = |f: fn(&Metrics) -> f64| -> Vec<BoxSeries> {
        result
            .controllers
            .iter()
            .enumerate()
            .map(|(k, c)| BoxSeries {
                name: c.label().to_string(),
                color: color(c, k),
                values: speeds
                    .iter()
                    .map(|v| {
                        result
                            .trials
                            .iter()
                            .filter(|t| t.controller == c.name() && t.speed == *v)
                            .map(|t| f(&t.metrics))
                            .collect()
                    })
                    .collect(),
            })
            .collect()
    };
    let mut sm = BoxPlot::new(
        "Command smoothness on the L path (per trial)",
        "desired speed",
        "mean |Δu| per tick [deg]",
    );
    sm.size = (1000, 700);
    sm.categories = categories.clone();
    sm.series = per_trial(|m| m.smoothness_deg);
    push(write_box_plot(&out.plot("smoothness"), &sm)?);
    let mut sat = BoxPlot::new(
        "Saturated commands on the L path (±35°, per trial)",
        "desired speed",
        "ticks at saturation [%]",
    );
    sat.size = (1000, 700);
    sat.categories = categories;
    sat.series = per_trial(|m| 100.0 * m.saturation_share);
    push(write_box_plot(&out.plot("saturation"), &sat)?);

    // Flown paths, one file per speed (paper's layout: x right, y up).
    let reference: Vec<(f64, f64)> = paths::L_XY.iter().map(|p| (p[0], p[1])).collect();
    for &v in speeds {
        let mut pp = PathPlot::new(
            format!("L path at {v} m/s: one trial per controller"),
            "x (north) [m]",
            "y (east) [m]",
        );
        pp.size = (900, 800);
        pp.reference = reference.clone();
        for (k, c) in result.controllers.iter().enumerate() {
            if let Some(f) = result
                .flown
                .iter()
                .find(|f| f.controller == c.name() && f.speed == v)
            {
                pp.series.push(Series::new(
                    c.label(),
                    color(c, k),
                    f.positions.iter().map(|p| (p.x, p.y)).collect(),
                ));
            }
        }
        push(write_path_plot(&out.plot(&format!("flown_{v}ms")), &pp)?);
    }

    // DSL demonstration.
    if !result.dsl.is_empty() {
        let max_speed = result
            .dsl
            .iter()
            .map(|f| f.max_speed)
            .fold(0.0, f64::max)
            .max(1.0);
        let bin = 2.0;
        let mut pp = PathPlot::new(
            "DSL with Discrete-Flatness: D 10 m/s, S 3 m/s, L 8 m/s (colour: speed)",
            "east [m]",
            "north [m]",
        );
        pp.size = (1100, 600);
        let mut named = Vec::new();
        for f in &result.dsl {
            if !pp.reference.is_empty() {
                // Separate the letters' references with a gap (NaN is skipped
                // by the plot, but a polyline would join them: draw each as
                // its own black series instead).
                pp.series.push(Series::new(
                    "",
                    crate::plot::REFERENCE_BLACK,
                    north_up(&f.waypoints),
                ));
            } else {
                pp.reference = north_up(&f.waypoints);
            }
        }
        // Room for the legend left of the D: an invisible one-point series
        // widens the east range.
        let (west, top) = result
            .dsl
            .iter()
            .flat_map(|f| f.positions.iter().chain(&f.waypoints))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(w, t), p| {
                (w.min(p.y), t.max(p.x))
            });
        if west.is_finite() && top.is_finite() {
            pp.series.push(Series::new(
                "",
                RGBColor(255, 255, 255),
                vec![(west - 16.0, top)],
            ));
        }
        for f in &result.dsl {
            pp.series.extend(speed_series(
                &north_up(&f.positions),
                &f.speeds,
                bin,
                (max_speed / bin).ceil() * bin,
                true,
                &mut named,
            ));
        }
        push(write_path_plot(&out.plot("dsl"), &pp)?);

        let mut lp = LinePlot::new(
            "DSL flights: speed along the path",
            "distance flown [m]",
            "horizontal speed [m/s]",
        );
        lp.size = (1000, 700);
        let palette = [
            RGBColor(255, 127, 14),
            RGBColor(148, 103, 189),
            RGBColor(23, 190, 207),
        ];
        for (j, f) in result.dsl.iter().enumerate() {
            let mut s = 0.0;
            let mut pts = Vec::with_capacity(f.positions.len());
            for (i, p) in f.positions.iter().enumerate() {
                if i > 0 {
                    let d = p - f.positions[i - 1];
                    s += d.x.hypot(d.y);
                }
                pts.push((s, f.speeds.get(i).copied().unwrap_or(f64::NAN)));
            }
            let c = palette[j % palette.len()];
            lp.series.push(Series::new(
                format!("{} (desired {} m/s)", f.letter, f.speed),
                c,
                pts.clone(),
            ));
            let end = pts.last().map_or(0.0, |p| p.0);
            lp.series
                .push(Series::new("", c, vec![(0.0, f.speed), (end, f.speed)]));
        }
        push(write_line_plot(&out.plot("dsl_speed"), &lp)?);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_sketch_keeps_quartiles_and_extremes() {
        let values: Vec<f64> = (0..10_000).map(|i| ((i * 7919) % 10_000) as f64).collect();
        let sketch = quantile_sketch(&values, BOX_QUANTILES);
        assert_eq!(sketch.len(), BOX_QUANTILES);
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        let mut s = sketch.clone();
        s.sort_by(f64::total_cmp);
        for q in [0.0, 0.25, 0.5, 0.75, 1.0] {
            assert_eq!(quantile(&s, q), quantile(&sorted, q), "q = {q}");
        }
        // Small samples pass through (finite values only).
        assert_eq!(quantile_sketch(&[1.0, f64::NAN, 2.0], 401), vec![1.0, 2.0]);
    }
}
