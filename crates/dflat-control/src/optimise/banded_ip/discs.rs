//! The per-stage discs of the banded interior point ([`Discs`]; the
//! maths in [`super`]).

use super::{Centring, Constraints, Stages, TOLERANCE, limit};
use crate::ControlError;
use crate::optimise::banded::SymBand;

/// One stage's disc: slack, multiplier, residual `c + s`, steps, and
/// `u = ã + a_0` at the current iterate.
#[derive(Debug, Clone, Copy, Default)]
struct Disc {
    s: f64,
    z: f64,
    r: f64,
    ds: f64,
    dz: f64,
    u: [f64; 2],
}

/// The per-stage discs `½(‖ã_f + a_0‖² − A_f²) ≤ 0` on the first two
/// axes' accelerations (module docs).
#[derive(Debug, Clone)]
pub struct Discs {
    stages: Stages,
    /// Radius per stage A_f [m/s²] (empty: no discs).
    radius: Vec<f64>,
    discs: Vec<Disc>,
    /// The fixed accelerations a_0 [m/s²] (u = ã + a_0).
    a0: [f64; 2],
    /// `1 + max A_f²`.
    scale: f64,
}

impl Discs {
    /// Discs of radius `limit` [m/s²] on the first two axes of n stages.
    pub fn new(stages: Stages, n: usize, limit: f64) -> Self {
        Self {
            stages,
            radius: vec![limit; n],
            discs: vec![Disc::default(); n],
            a0: [0.0; 2],
            scale: 1.0,
        }
    }

    /// No discs.
    pub fn none() -> Self {
        Self::new(Stages { axes: 2 }, 0, 0.0)
    }

    /// Sets the radius per stage A_f [m/s²] (n entries, finite and > 0).
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        crate::optimise::cone::check_radius(radius, self.radius.len())?;
        self.radius.copy_from_slice(radius);
        Ok(())
    }

    /// Sets the fixed accelerations a_0 [m/s²] of the next solves.
    pub fn set_origin(&mut self, a0: [f64; 2]) {
        self.a0 = a0;
    }

    /// The KKT indices of stage f's (ã_x, ã_y).
    fn at(&self, f: usize) -> (usize, usize) {
        (self.stages.accel(0, f), self.stages.accel(1, f))
    }
}

impl Constraints for Discs {
    fn pairs(&self) -> usize {
        self.discs.len()
    }

    fn start(&mut self, _v: &[f64]) {
        for (c, r) in self.discs.iter_mut().zip(&self.radius) {
            let a2 = 0.5 * r * r;
            c.s = a2;
            c.z = 1.0 / a2;
        }
        self.scale = 1.0 + self.radius.iter().fold(0.0f64, |a, r| a.max(r * r));
    }

    fn residuals(&mut self, v: &[f64], r: &mut [f64], gap: &mut f64) -> f64 {
        let mut rp: f64 = 0.0;
        for f in 0..self.discs.len() {
            let (ix, iy) = self.at(f);
            let cs = &mut self.discs[f];
            cs.u = [v[ix] + self.a0[0], v[iy] + self.a0[1]];
            let a2 = self.radius[f] * self.radius[f];
            let cf = 0.5 * (cs.u[0] * cs.u[0] + cs.u[1] * cs.u[1] - a2);
            cs.r = cf + cs.s;
            rp = rp.max(cs.r.abs());
            r[ix] += cs.z * cs.u[0];
            r[iy] += cs.z * cs.u[1];
            *gap += cs.s * cs.z;
        }
        rp / (TOLERANCE * self.scale)
    }

    fn assemble(&self, kkt: &mut SymBand) {
        for (f, cs) in self.discs.iter().enumerate() {
            let d = cs.z / cs.s;
            let [ux, uy] = cs.u;
            let (ix, iy) = self.at(f);
            kkt.add(ix, ix, cs.z + d * ux * ux);
            kkt.add(iy, iy, cs.z + d * uy * uy);
            kkt.add(iy, ix, d * ux * uy);
        }
    }

    fn eliminate(&mut self, rc: Centring, rhs: &mut [f64]) {
        // rhs −= u·(z·r − rc)/s on (ã_x, ã_y).
        for (f, cs) in self.discs.iter().enumerate() {
            let (ix, iy) = self.at(f);
            let e = (cs.z * cs.r - rc.rc(cs.s, cs.z, cs.ds * cs.dz)) / cs.s;
            rhs[ix] -= cs.u[0] * e;
            rhs[iy] -= cs.u[1] * e;
        }
    }

    fn recover(&mut self, dv: &[f64], rc: Centring) {
        for f in 0..self.discs.len() {
            let (ix, iy) = self.at(f);
            let cs = &mut self.discs[f];
            let du = cs.u[0] * dv[ix] + cs.u[1] * dv[iy];
            let rcs = rc.rc(cs.s, cs.z, cs.ds * cs.dz);
            cs.ds = -cs.r - du;
            cs.dz = -(rcs + cs.z * cs.ds) / cs.s;
        }
    }

    fn limit(&self, alpha: &mut f64) {
        for cs in &self.discs {
            limit(alpha, cs.s, cs.ds);
            limit(alpha, cs.z, cs.dz);
        }
    }

    fn gap_after(&self, alpha: f64, gap: &mut f64) {
        for cs in &self.discs {
            *gap += (cs.s + alpha * cs.ds) * (cs.z + alpha * cs.dz);
        }
    }

    fn step(&mut self, alpha: f64) {
        for cs in &mut self.discs {
            cs.s += alpha * cs.ds;
            cs.z += alpha * cs.dz;
        }
    }
}
