//! Plot helpers write valid SVG and PNG files with the vendored font.

use std::path::PathBuf;

use dflat_lab::plot::{
    BoxPlot, BoxSeries, BoxStats, DF_RED, FMPC_BLUE, LinePlot, PD_GREEN, PathPlot, Series,
    controller_color, north_up, write_box_plot, write_line_plot, write_path_plot,
};
use nalgebra::Vector3;

fn out_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("dflat-sim-plots")
}

fn check(paths: &[PathBuf; 2], title: &str) {
    let svg = std::fs::read_to_string(&paths[0]).expect("svg written");
    assert!(svg.starts_with("<svg") || svg.contains("<svg"), "svg");
    assert!(svg.contains(title), "title in svg");
    let png = std::fs::read(&paths[1]).expect("png written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert!(png.len() > 5_000, "png has content");
}

#[test]
fn line_plot_with_log_x() {
    let sigmas = [0.0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2];
    let mut plot = LinePlot::new(
        "Output error vs noise",
        "output noise σ [m]",
        "mean output error [m]",
    );
    plot.log_x = true;
    plot.series.push(Series {
        markers: true,
        ..Series::new(
            "Discrete-Flatness",
            DF_RED,
            sigmas.iter().map(|s| (*s, 2.0 + 10.0 * s)).collect(),
        )
    });
    plot.series.push(Series::new(
        "Flatness MPC",
        FMPC_BLUE,
        sigmas.iter().map(|s| (*s, 2.0 + 300.0 * s)).collect(),
    ));
    let paths = write_line_plot(&out_dir().join("line"), &plot).expect("drawn");
    check(&paths, "Output error vs noise");
}

#[test]
fn path_plot_with_black_reference() {
    let reference = vec![
        Vector3::new(-30.0, -20.0, 0.0),
        Vector3::new(0.0, -20.0, 0.0),
        Vector3::new(0.0, 0.0, 0.0),
    ];
    let flown: Vec<Vector3<f64>> = (0..=100)
        .map(|i| {
            let s = i as f64 / 100.0;
            if s < 0.6 {
                Vector3::new(-30.0 + 50.0 * s, -20.0 + 0.5 * (s * 20.0).sin(), 0.0)
            } else {
                Vector3::new(-1.0, -20.0 + 50.0 * (s - 0.6), 0.0)
            }
        })
        .collect();
    let mut plot = PathPlot::new("L-path at 7 m/s", "east [m]", "north [m]");
    plot.reference = north_up(&reference);
    plot.series
        .push(Series::new("PD", PD_GREEN, north_up(&flown)));
    let paths = write_path_plot(&out_dir().join("path"), &plot).expect("drawn");
    check(&paths, "L-path at 7 m/s");
}

#[test]
fn grouped_box_plot() {
    let mut plot = BoxPlot::new(
        "Path error per speed",
        "desired speed [m/s]",
        "path error [m]",
    );
    plot.categories = ["3", "5", "7", "9"].iter().map(|s| s.to_string()).collect();
    for (i, (name, color)) in [
        ("PD", PD_GREEN),
        ("Flatness MPC", FMPC_BLUE),
        ("Discrete-Flatness", DF_RED),
    ]
    .into_iter()
    .enumerate()
    {
        let values = (0..4)
            .map(|g| {
                (0..60)
                    .map(|k| 0.1 * (1 + g + i) as f64 * (1.0 + ((k * 37 % 17) as f64) / 10.0))
                    .chain([3.0 * (g + 1) as f64])
                    .collect()
            })
            .collect();
        plot.series.push(BoxSeries {
            name: name.to_string(),
            color,
            values,
        });
    }
    let paths = write_box_plot(&out_dir().join("box"), &plot).expect("drawn");
    check(&paths, "Path error per speed");
}

#[test]
fn box_stats_and_colors() {
    let (b, outliers) = BoxStats::from_values(&[1.0, 2.0, 3.0, 4.0, 5.0, 100.0]).expect("stats");
    assert_eq!(b.median, 3.5);
    assert_eq!(b.whisker_hi, 5.0);
    assert_eq!(outliers, vec![100.0]);
    assert!(BoxStats::from_values(&[f64::NAN]).is_none());
    assert_eq!(controller_color("df-mpc", 0), DF_RED);
    assert_eq!(controller_color("fmpc", 0), FMPC_BLUE);
    assert_eq!(controller_color("pd", 0), PD_GREEN);
}
