//! The mismatch study's JSON and plots.

use super::*;

/// Writes the JSON and the plots: `<prefix>_sigma<σ in mm, '.' → 'p'>mm` per noise
/// level (box plot of the steady-state error per scenario and controller,
/// log y; diverged trials are left out and marked in the table) and
/// `<prefix>_traces` (distance to the setpoint over time, trial 0 at the
/// last σ, hover-thrust scenario or else the first). Returns the files.
pub fn write_mismatch(
    result: &MismatchResult,
    out: &OutputPaths,
) -> Result<Vec<PathBuf>, ExperimentError> {
    write_json(&out.json, result)?;
    let mut files = vec![out.json.clone()];
    let c = &result.config;

    for &sigma in &c.sigmas {
        let mut plot = BoxPlot::new(
            format!(
                "Steady-state error under model mismatch, σ = {} mm (last {} s of {} s)",
                sigma * 1000.0,
                c.steady_window,
                c.duration
            ),
            "scenario",
            "mean distance to the setpoint [m] (log)",
        );
        plot.log_y = true;
        plot.size = (1100, 650);
        plot.categories = c.scenarios.iter().map(|s| s.name.clone()).collect();
        for &k in &c.controllers {
            plot.series.push(BoxSeries {
                name: k.label().to_string(),
                color: k.color(),
                values: c
                    .scenarios
                    .iter()
                    .map(|sc| {
                        result
                            .trials
                            .iter()
                            .filter(|t| {
                                t.sigma == sigma
                                    && t.scenario == sc.name
                                    && t.controller == k.name()
                                    && !t.diverged
                            })
                            .filter_map(|t| t.steady_error)
                            .map(|e| e.max(1e-5))
                            .collect()
                    })
                    .collect(),
            });
        }
        // No dot in the stem (the writers set the extension): 0.1 mm → "0p1mm".
        let stem = format!("sigma{}mm", sigma * 1000.0).replace('.', "p");
        let [svg, png] = write_box_plot(&out.plot(&stem), &plot)?;
        files.extend([svg, png]);
    }

    let scenario = c
        .scenarios
        .iter()
        .find(|s| s.name == "hover")
        .or(c.scenarios.first())
        .map(|s| s.name.clone())
        .unwrap_or_default();
    let mut line = LinePlot::new(
        format!(
            "Distance to the setpoint, scenario \"{scenario}\", σ = {} mm (trial 0)",
            c.sigmas.last().copied().unwrap_or(0.0) * 1000.0
        ),
        "time [s]",
        "|p − p_ref| [m] (log)",
    );
    line.log_y = true;
    line.size = (1000, 650);
    for (name, k, trace) in &result.traces {
        if *name != scenario {
            continue;
        }
        let points = trace
            .iter()
            .map(|(t, e)| {
                (
                    *t,
                    (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt().max(1e-4),
                )
            })
            .collect();
        line.series.push(Series::new(k.label(), k.color(), points));
    }
    let [svg, png] = write_line_plot(&out.plot("traces"), &line)?;
    files.extend([svg, png]);
    Ok(files)
}
