//! The study's tables in text (`dflat experiment learned` prints them).

use super::LearnedResult;

fn fmt_ratio(a: f64, b: f64) -> String {
    if a.is_finite() && b > 0.0 {
        format!("{:5.2}×", a / b)
    } else {
        "    –".into()
    }
}

impl LearnedResult {
    /// The tables: cells (p95 \[m\] and learned / matched), the models, the
    /// seconds study.
    pub fn table(&self) -> String {
        let mut t = String::new();
        if self.config.exact_scale != 1.0 {
            t.push_str(&format!(
                "exact: the plants' aerodynamics × {} in the residual (--exact-scale)\n",
                self.config.exact_scale
            ));
        }
        t.push_str(
            "plant    vision  shape        speed   matched     stock  identify   learned  learned(r)     exact  learned/matched  r/matched  exact/matched\n",
        );
        for r in &self.rows {
            t += &format!(
                "{:8} {:4.0} Hz {:12} {:4.1}  {:8.4}  {:8.4}  {:8.4}  {:8.4}  {:10.4}  {:8.4}  {:>15}  {:>9}  {:>13}\n",
                r.plant,
                r.vision_hz,
                r.shape,
                r.speed,
                r.matched.p95,
                r.stock.p95,
                r.identified.p95,
                r.learned.p95,
                r.learned_window.p95,
                r.exact.p95,
                fmt_ratio(r.learned.p95, r.matched.p95),
                fmt_ratio(r.learned_window.p95, r.matched.p95),
                fmt_ratio(r.exact.p95, r.matched.p95),
            );
        }
        for g in &self.models {
            t += &format!(
                "\n{} at {:.0} Hz: identify: {}\n",
                g.plant,
                g.vision_hz,
                if g.identify_changes.is_empty() {
                    "nothing changed".to_owned()
                } else {
                    g.identify_changes.join("; ")
                }
            );
            for (label, m, truth) in [
                ("window 3", &g.learned, g.learned_truth_m),
                (
                    "window from data",
                    &g.learned_window,
                    g.learned_window_truth_m,
                ),
            ] {
                if let Some(m) = m {
                    let v = &m.validation;
                    let names: Vec<&str> = m.features.iter().map(|f| f.name()).collect();
                    t += &format!(
                        "  learned ({label}): r = {}, [{}], {:.0} s; held-out 0.5 s error {:.4} → {:.4} m ({:.2}×; from {:.1} s → {:.1} s of poses), one step {:.5} → {:.5} m\n",
                        m.window,
                        names.join(", "),
                        m.seconds,
                        v.horizon_parametric_m,
                        v.horizon_learned_m,
                        v.horizon_learned_m / v.horizon_parametric_m,
                        v.start_parametric_s,
                        v.start_learned_s,
                        v.one_step_parametric_m,
                        v.one_step_learned_m,
                    );
                    if let Some([p, l]) = truth {
                        t += &format!(
                            "    against the true positions (no pose noise at the horizon): {p:.4} → {l:.4} m ({:.2}×)\n",
                            l / p
                        );
                    }
                }
            }
            for why in &g.refusals {
                t += &format!("  not learned: {why}\n");
            }
            for why in &g.unexcited {
                t += &format!("  unexcited: {why}\n");
            }
        }
        if !self.seconds.is_empty() {
            t += "\nseconds of records → held-out 0.5 s error (parametric → learned), learned p95 / matched over the cells (worst, mean)\n";
            for s in &self.seconds {
                t += &match &s.refused {
                    None => format!(
                        "  {:5.0} s   {:.4} → {:.4} m   worst {:.2}×, mean {:.2}×\n",
                        s.seconds,
                        s.horizon_parametric_m,
                        s.horizon_learned_m,
                        s.worst_ratio,
                        s.mean_ratio
                    ),
                    Some(why) => format!(
                        "  {:5.0} s   nothing learned, the identified flights kept (worst {:.2}×, mean {:.2}×): {why}\n",
                        s.seconds, s.worst_ratio, s.mean_ratio
                    ),
                };
            }
        }
        t
    }
}
