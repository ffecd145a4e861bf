//! The review page, parsed and checked part by part on a synthetic
//! 10-minute flight (no browser needed).

use std::path::Path;

use crate::flightlog::FlightCsv;

use crate::page::Header;
use crate::review::{quantile, render_with};

const COLUMNS: &[&str] = &[
    "tick",
    "t",
    "state",
    "x",
    "y",
    "z",
    "ref_x",
    "ref_y",
    "ref_z",
    "roll",
    "pitch",
    "yaw",
    "thrust",
    "solve_us",
    "jitter_us",
    "dist_x",
    "dist_y",
    "dist_z",
    "guard",
    "pose_age_ms",
];

/// A 10-minute flight at 50 Hz: HOLDING, TRACKING a circle, one FAILSAFE
/// span with a guard event, HOLDING again.
fn flight() -> (FlightCsv, Vec<f64>, Vec<String>) {
    let n = 30_000;
    let mut rows = Vec::with_capacity(n);
    let mut err = Vec::new();
    let mut states = Vec::new();
    for k in 0..n {
        let t = k as f64 * 0.02;
        let state = match k {
            0..500 => "HOLDING",
            500..20_000 => "TRACKING",
            20_000..20_100 => "FAILSAFE",
            _ => "HOLDING",
        };
        let (rx, ry) = if state == "TRACKING" {
            (10.0 * (0.1 * t).cos(), 10.0 * (0.1 * t).sin())
        } else {
            (10.0, 0.0)
        };
        let e = if state == "TRACKING" {
            0.05 + 0.02 * (3.0 * t).sin()
        } else {
            0.01
        };
        let (x, y) = (rx + e, ry);
        err.push(e);
        states.push(state.to_owned());
        let guard = if k == 20_000 { "pose lost" } else { "" };
        let row = [
            k.to_string(),
            format!("{t:.3}"),
            state.into(),
            format!("{x:.4}"),
            format!("{y:.4}"),
            "-10.0".into(),
            format!("{rx:.4}"),
            format!("{ry:.4}"),
            "-10.0".into(),
            format!("{:.4}", 0.1 * (0.5 * t).sin()),
            format!("{:.4}", 0.1 * (0.5 * t).cos()),
            "0".into(),
            "0.5".into(),
            "40".into(),
            "30".into(),
            "0.1".into(),
            "0".into(),
            "0".into(),
            guard.into(),
            "5".into(),
        ];
        rows.push(row.to_vec());
    }
    let csv = FlightCsv {
        header: COLUMNS.iter().map(|c| (*c).to_owned()).collect(),
        rows,
        torn_tail: None,
    };
    (csv, err, states)
}

fn attr<'a>(html: &'a str, at: usize, name: &str) -> &'a str {
    let key = format!("{name}=\"");
    let start = html[at..].find(&key).expect(name) + at + key.len();
    let end = html[start..].find('"').unwrap() + start;
    &html[start..end]
}

#[test]
fn the_page_has_its_parts_and_a_10_minute_flight_stays_under_2_mb() {
    let (csv, err, states) = flight();
    let header = Header {
        flight: "flight-test.csv".into(),
        date: Some("2026-11-25 12:00:00 UTC".into()),
        config: Some("config/px4.toml".into()),
        vehicle: Some("model = \"spatial\"\ndrag_h = 0.3\n".into()),
        kind: "sim (the configuration has a [sitl] table)".into(),
    };
    let html = render_with(Path::new("flight-test.csv"), &csv, None, None, &header);
    println!("10-minute flight: {} bytes", html.len());
    assert!(html.len() < 2_000_000, "{} bytes", html.len());

    // Offline: no external resource of any kind.
    assert!(html.contains("<meta name=\"viewport\""));
    for bad in [
        "src=",
        "href=\"http",
        "@import",
        "url(http",
        "fetch(",
        "XMLHttpRequest",
    ] {
        assert!(!html.contains(bad), "external reference {bad}");
    }
    assert_eq!(
        html.matches("http://").count(),
        html.matches("http://www.w3.org/2000/svg").count(),
        "only the SVG namespace may name a URL"
    );
    // Header.
    for part in [
        "flight-header",
        env!("CARGO_PKG_VERSION"),
        "2026-11-25 12:00:00 UTC",
        "config/px4.toml",
        "drag_h = 0.3",
        "sim (the configuration",
    ] {
        assert!(html.contains(part), "header lacks {part}");
    }
    // State bands, FAILSAFE red, labelled.
    let failsafe = html
        .find("class=\"band\" data-label=\"FAILSAFE\"")
        .expect("FAILSAFE band");
    assert_eq!(attr(&html, failsafe, "fill"), "#d22");
    assert!(html.contains("class=\"band\" data-label=\"TRACKING\""));
    assert!(html.contains("class=\"band-label\""));
    let guard = html
        .find("data-label=\"guard: pose lost\"")
        .expect("guard marker");
    assert_eq!(attr(&html, guard, "stroke"), "#d22");
    // Statistics per phase, TRACKING apart from HOLDING, against the data.
    for phase in ["TRACKING", "HOLDING", "FAILSAFE"] {
        let at = html
            .find(&format!("data-phase=\"{phase}\""))
            .unwrap_or_else(|| panic!("no {phase} row"));
        let e: Vec<f64> = (0..err.len())
            .filter(|&i| states[i] == phase)
            .map(|i| err[i])
            .collect();
        let row_end = html[at..].find("</tr>").unwrap() + at;
        let p95_at = html[at..row_end].find("data-key=\"p95\">").unwrap() + at + 15;
        let shown: f64 = html[p95_at..].split('<').next().unwrap().parse().unwrap();
        assert!(
            (shown - quantile(&e, 0.95)).abs() < 1.5e-3,
            "{phase}: p95 {shown} vs {}",
            quantile(&e, 0.95)
        );
    }
    // Position and velocity, setpoint vs measured, per axis.
    for axis in ["x", "y", "z"] {
        for kind in ["position", "velocity"] {
            assert!(
                html.contains(&format!("<svg id=\"{kind}-{axis}\"")),
                "{kind}-{axis}"
            );
        }
        assert!(html.contains(&format!("data-name=\"v{axis} measured\"")));
        assert!(html.contains(&format!("data-name=\"{axis} setpoint\"")));
    }
    // Zoom and cursor: the script, time charts with their mapping, the
    // vehicle's track on the map.
    assert!(html.contains("<script>") && html.contains("dflatZoom"));
    assert!(html.matches("class=\"chart time\"").count() >= 10);
    assert!(html.contains("class=\"plot\"") && html.contains("data-pw=\""));
    let track = html.find("class=\"vehicle\"").expect("vehicle marker");
    assert!(attr(&html, track, "data-track").len() > 1000);
    // Thinning keeps every series' extremes.
    let at = html.find("data-name=\"tracking error\"").unwrap();
    let points: usize = attr(&html, at, "data-points").parse().unwrap();
    let max: f64 = attr(&html, at, "data-max").parse().unwrap();
    assert!(points <= crate::svg::MAX_POINTS + 8, "{points}");
    let true_max = err.iter().copied().fold(0.0, f64::max);
    assert!((max - true_max).abs() < 2e-4, "{max} vs {true_max}");
}

#[test]
fn thinning_keeps_min_max_and_order() {
    let pts: Vec<(f64, f64)> = (0..10_000)
        .map(|i| (i as f64, ((i * 7919) % 1000) as f64))
        .collect();
    let thin = crate::svg::thin(&pts, 400);
    assert!(thin.len() <= 404, "{}", thin.len());
    assert!(thin.windows(2).all(|w| w[0].0 < w[1].0));
    assert_eq!(thin.iter().map(|p| p.1).fold(f64::MIN, f64::max), 999.0);
    assert_eq!(thin.iter().map(|p| p.1).fold(f64::MAX, f64::min), 0.0);
    let short = crate::svg::thin(&pts[..10], 400);
    assert_eq!(short, pts[..10].to_vec());
}

/// The page in a real browser (headless Chromium, when installed): it
/// loads with no console error, and the zoom changes every time chart's
/// mapping. Skipped, with the reason printed, when `/usr/bin/chromium` is
/// absent (Debian: `apt-get install -y chromium`; `.ci/run` installs it).
#[test]
fn the_page_runs_in_headless_chromium() {
    let chromium = Path::new("/usr/bin/chromium");
    if !chromium.exists() {
        println!("skipped: /usr/bin/chromium not installed (apt-get install -y chromium)");
        return;
    }
    let (csv, _, _) = flight();
    let html = render_with(
        Path::new("flight-test.csv"),
        &csv,
        None,
        None,
        &Header::default(),
    );
    let dir = std::env::temp_dir().join(format!("dflat-review-chromium-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let page = dir.join("review.html");
    std::fs::write(&page, &html).unwrap();
    let out = std::process::Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            // No background connections: the machine's network is closed.
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            &format!("--user-data-dir={}", dir.join("profile").display()),
            "--virtual-time-budget=5000",
            "--dump-dom",
            &format!("file://{}#selftest", page.display()),
        ])
        .output()
        .expect("run chromium");
    let dom = String::from_utf8_lossy(&out.stdout);
    let log = String::from_utf8_lossy(&out.stderr);
    let console: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("CONSOLE") || l.contains("Uncaught"))
        .collect();
    assert!(console.is_empty(), "console messages: {console:?}");
    let at = dom.find("data-selftest=\"zoomed ").unwrap_or_else(|| {
        panic!(
            "the page's script did not run its self-test; stderr:\n{}",
            log.lines().take(40).collect::<Vec<_>>().join("\n")
        )
    });
    let test = dom[at..].split('"').nth(1).unwrap();
    println!("chromium: {test}");
    // Zoomed 10× about the middle: scale ≈ 5 (a fifth of the span).
    let scale: f64 = test
        .split("scale(")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .expect("a scale in the transform");
    assert!((scale - 5.0).abs() < 0.5, "{test}");
    assert!(
        !test.ends_with("vehicle -20"),
        "the cursor did not move the vehicle: {test}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
