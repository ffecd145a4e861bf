//! Figure helpers shared by the studies: a speed colour scale for flown
//! paths.

use crate::plot::{RGBColor, Series};

/// Anchors of a rainbow colour scale with good contrast between
/// neighbouring bins (turbo-like: dark blue → cyan → green → orange → dark
/// red), evenly spaced over [0, 1].
const SCALE: [RGBColor; 7] = [
    RGBColor(48, 18, 59),
    RGBColor(70, 134, 251),
    RGBColor(27, 208, 213),
    RGBColor(98, 252, 108),
    RGBColor(210, 233, 53),
    RGBColor(254, 155, 45),
    RGBColor(180, 30, 5),
];

/// The scale's colour at `u` ∈ [0, 1] (clamped; NaN → the low end).
pub(crate) fn scale_color(u: f64) -> RGBColor {
    let u = if u.is_finite() {
        u.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = u * (SCALE.len() - 1) as f64;
    let i = (x.floor() as usize).min(SCALE.len() - 2);
    let f = x - i as f64;
    let lerp = |a: u8, b: u8| (a as f64 + f * (b as f64 - a as f64)).round() as u8;
    let (a, b) = (SCALE[i], SCALE[i + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// Series drawing a path coloured by speed in bins of `bin` \[m/s\] from 0 to
/// `max_speed`: consecutive points in the same bin form one series (joined
/// to the next run, so the line is continuous). The first run of each bin
/// carries its legend entry ("4–6 m/s") when `legend`; the legend lists
/// bins in order of first appearance.
pub(crate) fn speed_series(
    points: &[(f64, f64)],
    speeds: &[f64],
    bin: f64,
    max_speed: f64,
    legend: bool,
    named: &mut Vec<usize>,
) -> Vec<Series> {
    let n_bins = ((max_speed / bin).ceil() as usize).max(1);
    let bin_of = |v: f64| -> usize {
        if v.is_finite() && v > 0.0 {
            ((v / bin).floor() as usize).min(n_bins - 1)
        } else {
            0
        }
    };
    let color_of = |b: usize| scale_color((b as f64 + 0.5) / n_bins as f64);
    let mut out = Vec::new();
    let mut start = 0;
    let n = points.len().min(speeds.len());
    while start + 1 < n {
        let b = bin_of(speeds[start]);
        let mut end = start + 1;
        while end + 1 < n && bin_of(speeds[end]) == b {
            end += 1;
        }
        let name = if legend && !named.contains(&b) {
            named.push(b);
            let lo = b as f64 * bin;
            if b + 1 == n_bins {
                format!("≥ {lo:.0} m/s")
            } else {
                format!("{lo:.0}–{:.0} m/s", lo + bin)
            }
        } else {
            String::new()
        };
        out.push(Series::new(name, color_of(b), points[start..=end].to_vec()));
        start = end;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_ends_and_runs() {
        assert_eq!(scale_color(0.0), SCALE[0]);
        assert_eq!(scale_color(1.0), SCALE[SCALE.len() - 1]);
        assert_eq!(scale_color(f64::NAN), SCALE[0]);
        let pts: Vec<(f64, f64)> = (0..6).map(|i| (i as f64, 0.0)).collect();
        let v = [1.0, 1.0, 5.0, 5.0, 5.0, 1.0];
        let mut named = Vec::new();
        let s = speed_series(&pts, &v, 2.0, 10.0, true, &mut named);
        // The last point joins the run before it.
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].points.len(), 3); // 0, 1 and the joint 2
        assert_eq!(s[1].points.len(), 4); // 2..=5
        assert_eq!(s[0].name, "0–2 m/s");
        assert_eq!(s[1].name, "4–6 m/s");
        let again = speed_series(&pts, &v, 2.0, 10.0, true, &mut named);
        assert!(again.iter().all(|s| s.name.is_empty()));
    }
}
