//! The window fit with the model's linear drag (module docs, *Drag*).
//!
//! With drag D \[1/s\] on an axis the model's velocity decays by
//! `β = 1 − D·δt` per tick: `v_{j+1} = β·v_j + δt·(a_j + δ)`. The measured
//! positions are then
//!
//! ```text
//! y^m_j = p_0 + v_0·δt·b_j + S_j + δ·δt²·c_j + n_j
//! b_j = Σ_{m<j} β^m,   c_j = Σ_{m<j} w_m,   w_{m+1} = β·w_m + 1,  w_0 = 0
//! ```
//!
//! with `S_j` the model accelerations double-integrated the same way. For
//! β = 1 the basis is the drag-free one, `b_j = j`, `c_j = j(j−1)/2`. The
//! fit of (p_0, v_0, δ) is again linear with a fixed design per axis, so
//! the weights h are precomputed per axis.

use nalgebra::Vector3;

/// The per-axis basis of the drag-aware fit, for a window of L ticks.
#[derive(Debug, Clone)]
pub(super) struct DragBasis {
    /// Velocity decay per tick `β = 1 − D·δt` per axis.
    pub decay: Vector3<f64>,
    /// `b_j` per axis (velocity regressor, ticks).
    pub b: [Vec<f64>; 3],
    /// `c_j` per axis (offset regressor, ticks²).
    pub c: [Vec<f64>; 3],
    /// Fit weights h_j per axis \[1/s²\]: `δ̂ = Σ_j h_j·r_j`.
    pub h: [Vec<f64>; 3],
}

/// `(b_j, c_j)`, j = 0..l−1, for the decay β.
fn basis(l: usize, beta: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut b, mut c) = (Vec::with_capacity(l), Vec::with_capacity(l));
    let (mut bj, mut cj, mut w, mut p) = (0.0, 0.0, 0.0, 1.0);
    for _ in 0..l {
        b.push(bj);
        c.push(cj);
        bj += p;
        p *= beta;
        cj += w;
        w = beta * w + 1.0;
    }
    (b, c)
}

impl DragBasis {
    /// The basis for drag `drag` \[1/s\] per axis at step `dt` \[s\], window
    /// `l`; `None` when the fit is singular (window too short).
    pub fn new(drag: Vector3<f64>, l: usize, dt: f64) -> Option<Self> {
        let decay = drag.map(|d| 1.0 - d * dt);
        let n = (l - 1) as f64;
        let mut out = Self {
            decay,
            b: Default::default(),
            c: Default::default(),
            h: Default::default(),
        };
        for axis in 0..3 {
            let (b, c) = basis(l, decay[axis]);
            let row = |j: usize| Vector3::new(1.0, b[j] / n, 2.0 * c[j] / (n * n));
            out.h[axis] = super::weights_of_rows(l, dt, row)?;
            out.b[axis] = b;
            out.c[axis] = c;
        }
        Some(out)
    }

    /// True when no axis has drag (then the drag-free fit is used as is).
    pub fn is_free(&self) -> bool {
        self.decay == Vector3::repeat(1.0)
    }

    /// `(b, c)` of `axis` at the fractional tick `tau ∈ [0, l−1]`,
    /// interpolated linearly between the ticks.
    pub fn at(&self, axis: usize, tau: f64) -> (f64, f64) {
        let b = &self.b[axis];
        let c = &self.c[axis];
        let l = b.len();
        let j = (tau.floor().max(0.0) as usize).min(l - 2);
        let a = tau - j as f64;
        (b[j] + a * (b[j + 1] - b[j]), c[j] + a * (c[j + 1] - c[j]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_drag_is_the_plain_basis() {
        let (b, c) = basis(6, 1.0);
        assert_eq!(b, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(c, vec![0.0, 0.0, 1.0, 3.0, 6.0, 10.0]);
    }

    /// The weights recover δ exactly from positions of the decaying model,
    /// whatever p_0 and v_0.
    #[test]
    fn weights_recover_the_offset_under_drag() {
        let (dt, l, drag) = (0.02, 50, 0.4);
        let basis = DragBasis::new(Vector3::new(drag, drag, 0.0), l, dt).unwrap();
        let (mut p, mut v, delta) = (3.0, -2.5, 0.7);
        let mut est = 0.0;
        for j in 0..l {
            est += basis.h[0][j] * p;
            p += dt * v;
            v += dt * (delta - drag * v);
        }
        assert!((est - delta).abs() < 1e-9, "{est} vs {delta}");
    }
}
