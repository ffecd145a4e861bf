//! The mismatch study's markdown tables.

use super::*;

impl MismatchResult {
    /// The summary row of (σ, scenario, controller).
    pub fn row(
        &self,
        sigma: f64,
        scenario: &str,
        controller: MismatchController,
    ) -> Option<&MismatchSummary> {
        self.summary.iter().find(|r| {
            r.sigma == sigma && r.scenario == scenario && r.controller == controller.name()
        })
    }

    /// Markdown tables: per σ the steady-state error per scenario and
    /// controller \[cm\] with the estimates; the noise check; the budgets.
    pub fn table(&self) -> String {
        let c = &self.config;
        let mut s = format!(
            "Steady-state error [cm]: mean over {} trials of the mean 3-D distance to the \
             setpoint in the last {} s of {} s (max over trials in brackets); spatial plant and \
             model, 10 m step north; DF-MPC N = {}, q = {}, r = {}; estimator {} Hz, {} ticks. \
             Multi-rate DF: N = {}, q = {}, r = {}, s = {:?}, plan tilt ≤ {}°, window M = {}. \
             κ̂, d̂: final estimates (mean) of DF multi-rate + estimator (else DF + \
             estimator).\n",
            c.trials,
            c.steady_window,
            c.duration,
            c.df_weights.0,
            c.df_weights.1,
            c.df_weights.2,
            c.estimator.bandwidth_hz,
            c.estimator.fit_span,
            c.df_multi_rate.horizon,
            c.df_multi_rate.q,
            c.df_multi_rate.r,
            c.df_multi_rate.smoothness,
            c.df_multi_rate.plan_tilt_deg,
            c.df_multi_rate.window.fit_span
        );
        for &sigma in &c.sigmas {
            s += &format!("\n**σ = {} mm**\n\n| scenario |", sigma * 1000.0);
            for k in &c.controllers {
                s += &format!(" {} |", k.label());
            }
            s += " κ̂ | d̂ [m/s²] |\n|---|";
            for _ in &c.controllers {
                s += "---:|";
            }
            s += "---:|---|\n";
            for sc in &c.scenarios {
                s += &format!("| {} |", sc.name);
                for &k in &c.controllers {
                    match self.row(sigma, &sc.name, k) {
                        Some(r) if r.diverged > 0 => {
                            s += &format!(" diverged ({}/{}) |", r.diverged, r.trials)
                        }
                        Some(r) => {
                            s += &format!(
                                " {:.1} ({:.1}) |",
                                100.0 * r.steady_error,
                                100.0 * r.steady_error_max
                            )
                        }
                        None => s += " - |",
                    }
                }
                let shown = [
                    MismatchController::DfMultiRateEstimator,
                    MismatchController::DfEstimator,
                ]
                .into_iter()
                .find_map(|k| self.row(sigma, &sc.name, k));
                match shown {
                    Some(r) if r.thrust_scale.is_finite() && r.diverged == 0 => {
                        s += &format!(
                            " {:.3} | ({:.2}, {:.2}) |\n",
                            r.thrust_scale, r.acceleration[0], r.acceleration[1]
                        )
                    }
                    _ => s += " - | - |\n",
                }
            }
        }
        s += "\nScenarios: ";
        s += &c
            .scenarios
            .iter()
            .map(|sc| format!("{}: {}", sc.name, sc.description))
            .collect::<Vec<_>>()
            .join("; ");
        s += ".\n";
        if let Some(n) = &self.noise_check {
            s += &format!(
                "\nNoise check (the noise sweep's set-up and seeds, {} trials per σ): DF-MPC \
                 N = 200, q = 1, r = 0.08 and the multi-rate DF (MR) with / without the \
                 estimator; mean output error over 0–10 s (the paper's metric) and after 5 s.\n\n\
                 | σ [m] | DF [m] | DF + est [m] | ratio | late ratio | MR [m] | MR + est [m] | \
                 MR ratio | MR late ratio |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
                n.sweep.trials
            );
            for r in &n.rows {
                s += &format!(
                    "| {:.0e} | {:.4} | {:.4} | {:.3} | {:.2} | {:.4} | {:.4} | {:.3} | {:.2} |\n",
                    r.sigma,
                    r.df_error,
                    r.df_est_error,
                    r.ratio,
                    r.ratio_late,
                    r.mr_error,
                    r.mr_est_error,
                    r.mr_ratio,
                    r.mr_ratio_late
                );
            }
        }
        let verdict = |p: bool| if p { "PASS" } else { "FAIL" };
        s += &format!(
            "\nBudget: steady-state error with the estimator ≤ {:.0} cm in every scenario:",
            100.0 * STEADY_BUDGET
        );
        for b in &self.budgets.steady {
            let w = if b.worst_steady_error.is_finite() {
                format!("{:.2} cm", 100.0 * b.worst_steady_error)
            } else if b.worst_steady_error == f64::NEG_INFINITY {
                "not flown".to_string()
            } else {
                "diverged".to_string()
            };
            s += &format!(
                " σ = {} mm, {}: worst {w} → {};",
                b.sigma * 1000.0,
                b.controller,
                verdict(b.pass)
            );
        }
        s.pop();
        s.push('\n');
        if let (Some(n), Some(p)) = (&self.noise_check, self.budgets.noise_pass) {
            s += &format!(
                "Budget: noise-sweep error of DF with the estimator / without ≤ \
                 {NOISE_RATIO_BUDGET:.2} at every σ: worst {:.3} (classic DF), {:.3} (multi-rate \
                 DF) → {}\n",
                n.worst_ratio,
                n.mr_worst_ratio,
                verdict(p)
            );
        }
        if let Some(a) = &self.airframe {
            s.push('\n');
            s += &a.table();
        }
        s
    }
}
