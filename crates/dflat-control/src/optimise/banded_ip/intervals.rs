//! Interval rows `lo ≤ g·x ≤ hi` of the banded interior point, hard or
//! soft ([`Intervals`]; the maths in [`super`]).

use super::{Centring, Constraints, TOLERANCE, limit, norm};
use crate::optimise::banded::SymBand;
use crate::optimise::bounds::Row;

/// One side `h·x − σ + s = b` of a row (σ = 0, w unused when hard).
#[derive(Debug, Clone, Copy, Default)]
struct Side {
    s: f64,
    z: f64,
    sig: f64,
    w: f64,
    /// Primal residual `h·x − σ + s − b`.
    r: f64,
    ds: f64,
    dz: f64,
    dsig: f64,
    dw: f64,
    /// Newton elimination: `Δz = k0 + d·hΔx`, `Δσ = (e0 + d1·hΔx)/S`.
    k0: f64,
    e0: f64,
}

/// Interval rows `lo ≤ g·x ≤ hi`, hard or soft (module docs).
#[derive(Debug, Clone)]
pub struct Intervals {
    rows: Vec<Row>,
    /// `[upper, lower]` per row; upper `g·x ≤ hi`, lower `−g·x ≤ −lo`.
    sides: Vec<[Side; 2]>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// `1 + max |bound|`.
    b_scale: f64,
    /// The exact penalty ρ of soft rows (`None`: hard).
    soft: Option<f64>,
}

impl Intervals {
    /// The rows, soft with penalty ρ when `penalty` is finite.
    pub(in crate::optimise) fn new(rows: Vec<Row>, penalty: Option<f64>) -> Self {
        let m = rows.len();
        Self {
            rows,
            sides: vec![[Side::default(); 2]; m],
            lo: vec![0.0; m],
            hi: vec![0.0; m],
            b_scale: 1.0,
            soft: penalty.filter(|p| p.is_finite()),
        }
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// The largest span of a row (the band it needs).
    pub fn span(&self) -> usize {
        self.rows.iter().map(Row::span).max().unwrap_or(0)
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Sets the rows' bounds (checked by the caller).
    pub fn set_bounds(&mut self, lo: &[f64], hi: &[f64]) {
        self.lo.copy_from_slice(lo);
        self.hi.copy_from_slice(hi);
        self.b_scale = 1.0 + norm(lo).max(norm(hi));
    }

    /// The rows' multipliers `[upper, lower]` (≥ 0; the Lagrangian's
    /// `z_u·(g·x − hi) + z_l·(lo − g·x)`), in row order.
    pub fn duals(&self, out: &mut [[f64; 2]]) {
        for (o, [up, low]) in out.iter_mut().zip(&self.sides) {
            *o = [up.z, low.z];
        }
    }

    /// The weight `d` a side adds to `hhᵀ` in the KKT matrix.
    fn weight(&self, sd: &Side) -> f64 {
        if self.soft.is_some() {
            // z/s in series with w/σ, in the form that stays finite when
            // either ratio is huge.
            1.0 / (sd.s / sd.z + sd.sig / sd.w)
        } else {
            sd.z / sd.s
        }
    }
}

impl Constraints for Intervals {
    fn pairs(&self) -> usize {
        self.rows.len() * if self.soft.is_some() { 4 } else { 2 }
    }

    fn start(&mut self, v: &[f64]) {
        for (k, (row, side)) in self.rows.iter().zip(self.sides.iter_mut()).enumerate() {
            let g = row.dot(v);
            let floor = (0.1 * (self.hi[k] - self.lo[k])).max(1e-3 * self.b_scale);
            for (j, sd) in side.iter_mut().enumerate() {
                // Distance to the bound along this side's direction.
                let room = if j == 0 {
                    self.hi[k] - g
                } else {
                    g - self.lo[k]
                };
                *sd = Side {
                    s: room.max(floor),
                    z: 1.0,
                    ..Side::default()
                };
                if let Some(rho) = self.soft {
                    sd.w = (rho - 1.0).max(1.0);
                    sd.sig = (-room).max(0.0) + floor / sd.w;
                }
            }
        }
    }

    fn residuals(&mut self, v: &[f64], r: &mut [f64], gap: &mut f64) -> f64 {
        let mut rp: f64 = 0.0;
        let mut rsig: f64 = 0.0;
        for (k, (row, side)) in self.rows.iter().zip(self.sides.iter_mut()).enumerate() {
            let g = row.dot(v);
            let [up, low] = side;
            row.axpy(up.z - low.z, r);
            up.r = g - up.sig + up.s - self.hi[k];
            low.r = -g - low.sig + low.s + self.lo[k];
            rp = rp.max(up.r.abs()).max(low.r.abs());
            *gap += up.s * up.z + low.s * low.z;
            if let Some(rho) = self.soft {
                *gap += up.sig * up.w + low.sig * low.w;
                rsig = rsig
                    .max((rho - up.z - up.w).abs())
                    .max((rho - low.z - low.w).abs());
            }
        }
        let sig_tolerance = 1e-8 * (1.0 + self.soft.unwrap_or(0.0));
        (rp / (TOLERANCE * self.b_scale)).max(rsig / sig_tolerance)
    }

    fn assemble(&self, kkt: &mut SymBand) {
        for (row, side) in self.rows.iter().zip(&self.sides) {
            let d: f64 = side.iter().map(|sd| self.weight(sd)).sum();
            for a in 0..row.len {
                for b in 0..=a {
                    kkt.add(row.idx[a], row.idx[b], d * row.coef[a] * row.coef[b]);
                }
            }
        }
    }

    fn eliminate(&mut self, rc: Centring, rhs: &mut [f64]) {
        // Δz = k0 + d·hΔx, rhs −= hᵀk0 (h = ±g).
        for (row, side) in self.rows.iter().zip(self.sides.iter_mut()) {
            for sd in side.iter_mut() {
                let rcs = rc.rc(sd.s, sd.z, sd.ds * sd.dz);
                sd.k0 = if let Some(rho) = self.soft {
                    let rcw = rc.rc(sd.sig, sd.w, sd.dsig * sd.dw);
                    let (d1, d2) = (sd.z / sd.s, sd.w / sd.sig);
                    let rs = rho - sd.z - sd.w;
                    sd.e0 = -rs - rcs / sd.s - rcw / sd.sig + d1 * sd.r;
                    -rcs / sd.s + d1 * sd.r - d1 * sd.e0 / (d1 + d2)
                } else {
                    (sd.z * sd.r - rcs) / sd.s
                };
            }
            row.axpy(-(side[0].k0 - side[1].k0), rhs);
        }
    }

    fn recover(&mut self, dv: &[f64], rc: Centring) {
        for (row, side) in self.rows.iter().zip(self.sides.iter_mut()) {
            let gdx = row.dot(dv);
            for (j, sd) in side.iter_mut().enumerate() {
                let hdx = if j == 0 { gdx } else { -gdx };
                let rcs = rc.rc(sd.s, sd.z, sd.ds * sd.dz);
                if self.soft.is_some() {
                    let rcw = rc.rc(sd.sig, sd.w, sd.dsig * sd.dw);
                    let (d1, d2) = (sd.z / sd.s, sd.w / sd.sig);
                    let dsig = (sd.e0 + d1 * hdx) / (d1 + d2);
                    sd.ds = -sd.r - hdx + dsig;
                    sd.dz = -(rcs + sd.z * sd.ds) / sd.s;
                    sd.dw = -(rcw + sd.w * dsig) / sd.sig;
                    sd.dsig = dsig;
                } else {
                    sd.ds = -sd.r - hdx;
                    sd.dz = -(rcs + sd.z * sd.ds) / sd.s;
                }
            }
        }
    }

    fn limit(&self, alpha: &mut f64) {
        for sd in self.sides.iter().flatten() {
            limit(alpha, sd.s, sd.ds);
            limit(alpha, sd.z, sd.dz);
            limit(alpha, sd.sig, sd.dsig);
            limit(alpha, sd.w, sd.dw);
        }
    }

    fn gap_after(&self, alpha: f64, gap: &mut f64) {
        let soft = self.soft.is_some();
        let after = |sd: &Side| {
            let hard = (sd.s + alpha * sd.ds) * (sd.z + alpha * sd.dz);
            if soft {
                hard + (sd.sig + alpha * sd.dsig) * (sd.w + alpha * sd.dw)
            } else {
                hard
            }
        };
        for [up, low] in &self.sides {
            *gap += after(up) + after(low);
        }
    }

    fn step(&mut self, alpha: f64) {
        let soft = self.soft.is_some();
        for sd in self.sides.iter_mut().flatten() {
            sd.s += alpha * sd.ds;
            sd.z += alpha * sd.dz;
            if soft {
                sd.sig += alpha * sd.dsig;
                sd.w += alpha * sd.dw;
            }
        }
    }
}
