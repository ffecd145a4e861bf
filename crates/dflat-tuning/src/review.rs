//! The review: a flight's report as one self-contained HTML page
//! (inline SVG and a small inline script; no CDN, no network, opens
//! offline): a header saying what flew (version, date, config and
//! `[vehicle]`, sim or real), summary numbers and statistics per phase
//! (TRACKING apart from HOLDING), then the flown path over the reference,
//! position and velocity setpoint against measured per axis, the tracking
//! error, commanded against measured attitude, thrust, solve time and tick
//! jitter, pose age and the disturbance estimate. Every time axis carries
//! the supervisor states as labelled bands, FAILSAFE and guard events in
//! red. The script links zoom and pan across the time charts and moves a
//! cursor that marks the vehicle on the path; without it the SVGs stand
//! alone. Long series are min/max thinned (`svg::thin`).

use std::fmt::Write as _;
use std::path::Path;

use crate::flightlog::{FlightCsv, FlightLog, FlightLogError};
use crate::page::{self, Header};
use crate::svg::{Chart, Marker, Series, esc};
use dflat_records::Column;

/// Commands of an offline re-run, drawn over the flown ones.
#[derive(Debug, Clone, Default)]
pub struct Overlay {
    /// What it is (e.g. `replay with tuned.toml`).
    pub label: String,
    /// Tick times \[s\] (the CSV's `t`).
    pub t: Vec<f64>,
    /// Roll, pitch \[rad\] and thrust per tick (NaN where none).
    pub command: Vec<[f64; 3]>,
}

/// What the header says: the date from the .tlog, the configuration's
/// `[vehicle]` table, and sim or real (a configuration with `[sitl]` flew
/// in simulation).
pub fn header_for(
    csv: &Path,
    log: Option<&FlightLog>,
    config: Option<&Path>,
) -> Result<Header, FlightLogError> {
    let mut h = Header {
        flight: csv.display().to_string(),
        date: log
            .filter(|l| l.start_unix_us > 0)
            .map(|l| page::utc(l.start_unix_us)),
        kind: "unknown (pass --config)".into(),
        ..Header::default()
    };
    if let Some(path) = config {
        let text = std::fs::read_to_string(path).map_err(|source| FlightLogError::Io {
            file: path.to_owned(),
            source,
        })?;
        // The tables as written (the daemon validated the file when it flew).
        let table_of = |name: &str| -> Option<String> {
            let mut out = None::<String>;
            for line in text.lines() {
                let l = line.trim();
                if l.starts_with('[') {
                    if out.is_some() {
                        break;
                    }
                    if l == format!("[{name}]") {
                        out = Some(String::new());
                    }
                } else if let Some(o) = &mut out
                    && !l.is_empty()
                {
                    o.push_str(line);
                    o.push('\n');
                }
            }
            out
        };
        h.config = Some(path.display().to_string());
        h.vehicle = Some(
            table_of("vehicle").unwrap_or_else(|| "(no [vehicle] table: the defaults)".into()),
        );
        h.kind = if table_of("sitl").is_some() {
            "sim (the configuration has a [sitl] table)".into()
        } else {
            "real vehicle (no [sitl] table in the configuration)".into()
        };
    }
    Ok(h)
}

/// The `q` quantile (nearest rank) of the finite values, NaN if none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)]
}

/// Offset from the log's clock to the CSV's (daemon) clock: each
/// SET_ATTITUDE_TARGET carries its tick time in `time_boot_ms`.
pub fn log_to_csv_offset(log: &FlightLog) -> Option<f64> {
    let d: Vec<f64> = log
        .commands
        .iter()
        .map(|c| f64::from(c.time_boot_ms) * 1e-3 - c.t)
        .collect();
    let m = quantile(&d, 0.5);
    m.is_finite().then_some(m)
}

fn col(csv: &FlightCsv, name: Column) -> Vec<f64> {
    csv.numbers(name)
        .into_iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect()
}

fn pairs(t: &[f64], v: &[f64], scale: f64) -> Vec<(f64, f64)> {
    t.iter().zip(v).map(|(t, v)| (*t, v * scale)).collect()
}

/// Summary numbers of a flight CSV, as (key, label, value, unit).
pub fn summary(csv: &FlightCsv) -> Vec<(&'static str, &'static str, f64, &'static str)> {
    let t = col(csv, Column::T);
    let pos = [Column::X, Column::Y, Column::Z].map(|c| col(csv, c));
    let re = [Column::RefX, Column::RefY, Column::RefZ].map(|c| col(csv, c));
    let err: Vec<f64> = (0..t.len())
        .map(|i| {
            (0..3)
                .map(|a| (pos[a][i] - re[a][i]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let solve = col(csv, Column::SolveUs);
    let jitter = col(csv, Column::JitterUs);
    let age = col(csv, Column::PoseAgeMs);
    let commands = col(csv, Column::Roll)
        .iter()
        .filter(|v| v.is_finite())
        .count();
    let guards = csv
        .texts(Column::Guard)
        .iter()
        .filter(|g| !g.is_empty())
        .count();
    let states = csv.texts(Column::State);
    let changes = states.windows(2).filter(|w| w[0] != w[1]).count();
    let tracking = states.iter().filter(|s| **s == "TRACKING").count();
    let period = if t.len() > 1 {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    } else {
        0.0
    };
    let duration = t.last().zip(t.first()).map_or(0.0, |(b, a)| b - a);
    vec![
        ("duration_s", "duration", duration, "s"),
        ("ticks", "ticks", t.len() as f64, ""),
        ("commands", "commands sent", commands as f64, ""),
        ("tracking_s", "time tracking", tracking as f64 * period, "s"),
        (
            "tracking_error_p50_m",
            "tracking error p50",
            quantile(&err, 0.5),
            "m",
        ),
        (
            "tracking_error_p95_m",
            "tracking error p95",
            quantile(&err, 0.95),
            "m",
        ),
        (
            "tracking_error_max_m",
            "tracking error max",
            quantile(&err, 1.0),
            "m",
        ),
        (
            "solve_us_p50",
            "solve time p50",
            quantile(&solve, 0.5),
            "µs",
        ),
        (
            "solve_us_p99",
            "solve time p99",
            quantile(&solve, 0.99),
            "µs",
        ),
        (
            "solve_us_max",
            "solve time max",
            quantile(&solve, 1.0),
            "µs",
        ),
        (
            "jitter_us_p99",
            "tick jitter p99",
            quantile(&jitter, 0.99),
            "µs",
        ),
        (
            "jitter_us_max",
            "tick jitter max",
            quantile(&jitter, 1.0),
            "µs",
        ),
        ("pose_age_ms_p50", "pose age p50", quantile(&age, 0.5), "ms"),
        (
            "pose_age_ms_p99",
            "pose age p99",
            quantile(&age, 0.99),
            "ms",
        ),
        ("guard_events", "guard / fallback events", guards as f64, ""),
        ("state_changes", "state changes", changes as f64, ""),
    ]
}

/// State changes and guard events as markers on the CSV's time axis.
fn markers(csv: &FlightCsv, t: &[f64]) -> Vec<Marker> {
    let states = csv.texts(Column::State);
    let guards = csv.texts(Column::Guard);
    let mut out = Vec::new();
    for i in 0..t.len() {
        if i > 0 && states[i] != states[i - 1] {
            out.push(Marker {
                x: t[i],
                label: format!("{} → {}", states[i - 1], states[i]),
                color: page::state_color(states[i]),
            });
        }
        if !guards[i].is_empty() {
            out.push(Marker {
                x: t[i],
                label: format!("guard: {}", guards[i]),
                color: "#d22",
            });
        }
    }
    out
}

/// The page for a flight: `csv` (required), its `log` (optional: measured
/// attitude, texts) and an optional re-run's commands.
pub fn render(
    name: &Path,
    csv: &FlightCsv,
    log: Option<&FlightLog>,
    overlay: Option<&Overlay>,
) -> String {
    let header = header_for(name, log, None).unwrap_or_default();
    render_with(name, csv, log, overlay, &header)
}

/// Central difference of `v` over ±2 ticks \[unit/s\] (NaN at gaps).
fn rate(t: &[f64], v: &[f64]) -> Vec<f64> {
    (0..t.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(2), (i + 2).min(t.len().saturating_sub(1)));
            let dt = t[b] - t[a];
            if b > a && dt > 0.0 {
                (v[b] - v[a]) / dt
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// [`render`] with the header given.
pub fn render_with(
    name: &Path,
    csv: &FlightCsv,
    log: Option<&FlightLog>,
    overlay: Option<&Overlay>,
    header: &Header,
) -> String {
    let t = col(csv, Column::T);
    let marks = markers(csv, &t);
    let bands = page::state_bands(&t, &csv.texts(Column::State));
    let chart = |id: &str, title: &str, y: &str, series: Vec<Series>| Chart {
        id: id.into(),
        title: title.into(),
        x_label: "t [s]".into(),
        y_label: y.into(),
        series,
        markers: marks.clone(),
        equal_axes: false,
        bands: bands.clone(),
        time_axis: true,
        track: Vec::new(),
    };
    let s = |name: &str, color: &'static str, points: Vec<(f64, f64)>| Series {
        name: name.into(),
        color,
        points,
        dashed: false,
    };
    let dashed = |name: &str, color: &'static str, points: Vec<(f64, f64)>| Series {
        dashed: true,
        ..s(name, color, points)
    };
    let [x, y, z] = [Column::X, Column::Y, Column::Z].map(|c| col(csv, c));
    let [rx, ry, rz] = [Column::RefX, Column::RefY, Column::RefZ].map(|c| col(csv, c));
    let mut charts = Vec::new();
    // The map: east to the right, north up.
    charts.push(Chart {
        id: "path".into(),
        title: "flown path over the reference (north up)".into(),
        x_label: "east y [m]".into(),
        y_label: "north x [m]".into(),
        series: vec![
            dashed(
                "reference",
                "#999",
                ry.iter().copied().zip(rx.iter().copied()).collect(),
            ),
            s(
                "measured",
                "#1f5fbf",
                y.iter().copied().zip(x.iter().copied()).collect(),
            ),
        ],
        markers: Vec::new(),
        equal_axes: true,
        bands: Vec::new(),
        time_axis: false,
        // The vehicle every 0.1 s, for the time cursor.
        track: (0..t.len())
            .step_by(5)
            .filter(|&i| t[i].is_finite() && x[i].is_finite() && y[i].is_finite())
            .map(|i| (t[i], y[i], x[i]))
            .collect(),
    });
    // Position and velocity, setpoint against measured, per axis.
    for (axis, (p, r)) in
        ["x (north)", "y (east)", "z (down)"]
            .iter()
            .zip([(&x, &rx), (&y, &ry), (&z, &rz)])
    {
        let key = &axis[..1];
        charts.push(chart(
            &format!("position-{key}"),
            &format!("position {axis}: setpoint vs measured"),
            "m",
            vec![
                dashed(&format!("{key} setpoint"), "#999", pairs(&t, r, 1.0)),
                s(&format!("{key} measured"), "#1f5fbf", pairs(&t, p, 1.0)),
            ],
        ));
        charts.push(chart(
            &format!("velocity-{key}"),
            &format!("velocity {axis}: setpoint vs measured (central differences)"),
            "m/s",
            vec![
                dashed(
                    &format!("v{key} setpoint"),
                    "#999",
                    pairs(&t, &rate(&t, r), 1.0),
                ),
                s(
                    &format!("v{key} measured"),
                    "#1f5fbf",
                    pairs(&t, &rate(&t, p), 1.0),
                ),
            ],
        ));
    }
    let err: Vec<f64> = (0..t.len())
        .map(|i| ((x[i] - rx[i]).powi(2) + (y[i] - ry[i]).powi(2) + (z[i] - rz[i]).powi(2)).sqrt())
        .collect();
    charts.push(chart(
        "tracking-error",
        "tracking error |measured − reference|",
        "m",
        vec![s("tracking error", "#c33", pairs(&t, &err, 1.0))],
    ));
    charts.push(chart(
        "altitude",
        "altitude (−z)",
        "m",
        vec![
            dashed("reference −z", "#999", pairs(&t, &rz, -1.0)),
            s("measured −z", "#1f5fbf", pairs(&t, &z, -1.0)),
        ],
    ));
    let mut att = vec![
        s(
            "roll command",
            "#1f5fbf",
            pairs(&t, &col(csv, Column::Roll), 180.0 / std::f64::consts::PI),
        ),
        s(
            "pitch command",
            "#c33",
            pairs(&t, &col(csv, Column::Pitch), 180.0 / std::f64::consts::PI),
        ),
    ];
    if let Some(log) = log
        && let Some(offset) = log_to_csv_offset(log)
    {
        let deg = 180.0 / std::f64::consts::PI;
        let at = |i: usize| -> Vec<(f64, f64)> {
            log.attitude
                .iter()
                .map(|a| (a.t + offset, a.euler[i] * deg))
                .collect()
        };
        att.push(dashed("roll measured", "#7fa8e8", at(0)));
        att.push(dashed("pitch measured", "#e89a9a", at(1)));
    }
    let mut thrust = vec![s(
        "thrust command",
        "#333",
        pairs(&t, &col(csv, Column::Thrust), 1.0),
    )];
    if let Some(o) = overlay {
        let deg = 180.0 / std::f64::consts::PI;
        let pick = |i: usize, sc: f64| {
            o.t.iter()
                .zip(&o.command)
                .map(|(t, c)| (*t, c[i] * sc))
                .collect()
        };
        att.push(s(&format!("roll, {}", o.label), "#2a7", pick(0, deg)));
        att.push(s(&format!("pitch, {}", o.label), "#a72", pick(1, deg)));
        thrust.push(s(&format!("thrust, {}", o.label), "#2a7", pick(2, 1.0)));
    }
    charts.push(chart(
        "attitude",
        "commanded vs measured attitude",
        "deg",
        att,
    ));
    charts.push(chart(
        "thrust",
        "thrust command (normalised)",
        "0–1",
        thrust,
    ));
    charts.push(chart(
        "timing",
        "solve time and tick jitter",
        "µs",
        vec![
            s(
                "solve time",
                "#1f5fbf",
                pairs(&t, &col(csv, Column::SolveUs), 1.0),
            ),
            s(
                "tick jitter",
                "#c33",
                pairs(&t, &col(csv, Column::JitterUs), 1.0),
            ),
        ],
    ));
    if csv.has(Column::PoseAgeMs) {
        charts.push(chart(
            "pose-age",
            "pose age at the tick",
            "ms",
            vec![s(
                "pose age",
                "#733",
                pairs(&t, &col(csv, Column::PoseAgeMs), 1.0),
            )],
        ));
    }
    let dist = [Column::DistX, Column::DistY, Column::DistZ].map(|c| col(csv, c));
    if dist.iter().any(|d| d.iter().any(|v| v.is_finite())) {
        charts.push(chart(
            "disturbance",
            "disturbance estimate (acceleration offset)",
            "m/s²",
            vec![
                s("d̂ x", "#1f5fbf", pairs(&t, &dist[0], 1.0)),
                s("d̂ y", "#c33", pairs(&t, &dist[1], 1.0)),
                s("d̂ z", "#2a7", pairs(&t, &dist[2], 1.0)),
            ],
        ));
    }
    let states = csv.texts(Column::State);
    let cmd: Vec<(f64, f64)> = col(csv, Column::Roll)
        .into_iter()
        .zip(col(csv, Column::Pitch))
        .collect();
    let phases = page::phase_stats(&t, &states, &err, &cmd, quantile);
    page(name, csv, log, &charts, header, &phases)
}

fn page(
    name: &Path,
    csv: &FlightCsv,
    log: Option<&FlightLog>,
    charts: &[Chart],
    header: &Header,
    phases: &[page::PhaseStats],
) -> String {
    let title = format!("dflat review — {}", name.display());
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{}</title>\
         <style>{}</style></head><body>\n<h1>{}</h1>\n",
        esc(&title),
        page::STYLE,
        esc(&title)
    );
    h.push_str(&page::header_html(header));
    h.push_str("<div class=\"grid\"><div><h2>summary</h2><table id=\"summary\">\n");
    for (key, label, value, unit) in summary(csv) {
        let shown = if value.is_finite() {
            if value.fract() == 0.0 && value.abs() < 1e9 {
                format!("{value:.0}")
            } else {
                format!("{value:.3}")
            }
        } else {
            "—".into()
        };
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td class=\"v\" data-key=\"{key}\" data-value=\"{value}\">{shown}</td><td>{unit}</td></tr>",
            esc(label)
        );
    }
    h.push_str("</table></div><div><h2>per phase</h2>\n");
    h.push_str(&page::phase_table(phases));
    h.push_str(
        "<p>Bands: the supervisor's states (FAILSAFE red); lines: state changes, \
         guard and fallback events in red (hover for the label).</p></div></div>\n",
    );
    h.push_str(
        "<div id=\"zoom-bar\"><button id=\"zoom-reset\" type=\"button\">reset zoom</button>\
         <span id=\"zoom-range\"></span> <span id=\"cursor-time\"></span> \
         <small>wheel or drag: zoom · shift+drag: pan · double-click: all</small></div>\n<div class=\"grid\">\n",
    );
    for c in charts {
        let _ = writeln!(h, "<figure>{}</figure>", c.to_svg());
    }
    h.push_str("</div>\n");
    if let Some(log) = log
        && !log.texts.is_empty()
    {
        h.push_str("<h2>STATUSTEXT</h2>\n<ul id=\"texts\">\n");
        for (t, text) in &log.texts {
            let _ = writeln!(h, "<li>{t:.2} s: {}</li>", esc(text));
        }
        h.push_str("</ul>\n");
    }
    let _ = writeln!(h, "<script>{}</script>", page::SCRIPT);
    h.push_str("</body></html>\n");
    h
}
