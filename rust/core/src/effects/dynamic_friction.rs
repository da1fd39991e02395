//! Dynamic friction on the output (Dahl / LuGre family): a friction force whose internal
//! (bristle) state follows the motion of x and relaxes when the motion stops, as in a friction
//! damper whose input is a displacement and whose measured output is a force.
//!
//! Continuous form, with w = z / z_s the bristle state normalised to its sliding value:
//!
//!   dw/dt = x'(t) / z_s - (|x'(t)| / z_s + lambda) w,   y += k_f w,
//!
//! the Dahl law dz/dx = 1 - sign(x') z / z_s (the friction force saturates at +-k_f after a
//! slide of a few z_s) plus a relaxation at rate lambda per sample (the force decays at
//! standstill). Between two samples x moves linearly, v(t) = x(t) - x(t-1) a sample, so the
//! law is a linear ODE of constant coefficients over the sample and its exact step is
//!
//!   kappa = |v| / z_s + lambda,   w(t) = e^-kappa w(t-1) + (v / z_s) phi(kappa),
//!   phi(kappa) = (1 - e^-kappa) / kappa (phi(0) = 1),
//!
//! so |w| <= 1 whenever it starts there (a convex combination of w(t-1) and sign(v) phi
//! kappa |v| / z_s <= 1), without a step-size limit. Parameters: k_f (the friction force at
//! full slip, output units; zero size 0), z_s (the presliding displacement, x units, > 0),
//! lambda (>= 0). At k_f = 0 it is the nominal model; w starts at rest (0).

use super::{add_at, arity, finite, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "dynamic_friction";

/// Dynamic friction (k_f, z_s, lambda) and its bristle state w.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicFriction {
    /// The friction force at full slip k_f.
    pub force: f64,
    /// The presliding displacement z_s.
    pub presliding: f64,
    /// The relaxation rate lambda per sample.
    pub relaxation: f64,
    w: f64,
    /// d w / d theta (tangent simulations only).
    dw: Vec<f64>,
}

/// From [k_f, z_s, lambda].
pub fn from_parameters(p: &[f64]) -> Result<DynamicFriction> {
    arity(NAME, p, "k_f, z_s, lambda", 3)?;
    Ok(DynamicFriction {
        force: p[0],
        presliding: p[1],
        relaxation: p[2],
        w: 0.0,
        dw: Vec::new(),
    })
}

/// phi(kappa) = (1 - e^-kappa) / kappa and phi'(kappa), by their series near 0 (where the
/// closed forms cancel).
#[inline(always)]
fn phi(kappa: f64) -> (f64, f64) {
    if kappa < 1e-2 {
        let k = kappa;
        (
            1.0 - k / 2.0 + k * k / 6.0 - k * k * k / 24.0 + k * k * k * k / 120.0,
            -0.5 + k / 3.0 - k * k / 8.0 + k * k * k / 30.0 - k * k * k * k / 144.0,
        )
    } else {
        let e = (-kappa).exp();
        let p = -(-kappa).exp_m1() / kappa;
        (p, (e - p) / kappa)
    }
}

impl DynamicFriction {
    /// The exact step for the velocity `v`: (w(t), e^-kappa, phi(kappa), phi'(kappa)).
    #[inline(always)]
    fn step(&self, v: f64) -> (f64, f64, f64, f64) {
        let kappa = v.abs() / self.presliding + self.relaxation;
        let e = (-kappa).exp();
        let (p, dp) = phi(kappa);
        (e * self.w + v / self.presliding * p, e, p, dp)
    }
}

impl Effect for DynamicFriction {
    // after compliance (which filters f itself), before the extra plays
    place!(Output, 5);
    fn check(&self) -> Result<()> {
        finite("k_f", self.force, "give a finite friction force (0 for none)")?;
        if !(self.presliding.is_finite() && self.presliding > 0.0) {
            return Err(Error::Model(format!(
                "z_s = {}: give a positive presliding displacement (in units of x)",
                self.presliding
            )));
        }
        if !(self.relaxation.is_finite() && self.relaxation >= 0.0) {
            return Err(Error::Model(format!(
                "lambda = {}: give a relaxation rate >= 0 per sample",
                self.relaxation
            )));
        }
        Ok(())
    }
    fn start(&self, _x0: f64, _y0: f64) -> Self {
        // the bristles at rest
        DynamicFriction {
            w: 0.0,
            dw: Vec::new(),
            ..self.clone()
        }
    }
    #[inline]
    fn output(&mut self, out: f64, s: &Sample) -> f64 {
        if self.force == 0.0 {
            return out;
        }
        self.w = self.step(s.x - s.x_prev).0;
        out + self.force * self.w
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.force, self.presliding, self.relaxation]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["k_f".into(), "z_s".into(), "lambda".into()]
    }
    /// k_f free (the force's sign is the sensor's), z_s >= 0 (`feasible`: > 0), lambda >= 0.
    fn bounds(&self, k: usize) -> (f64, f64) {
        match k {
            0 => (f64::NEG_INFINITY, f64::INFINITY),
            _ => (0.0, f64::INFINITY),
        }
    }
    fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], _cols: &Columns) -> Self {
        let mut e = self.start(x0, y0);
        e.dw = vec![0.0; dx0.len()];
        e
    }
    /// kappa = |v| / z_s + lambda: d kappa = sign(v) dv / z_s - |v| / z_s^2 dz_s + dlambda
    /// (sign(0) = 0, the one-sided derivative of |v| at rest); d w = e^-kappa dw(t-1) +
    /// (v / z_s phi' - e^-kappa w(t-1)) d kappa + phi (dv / z_s - v / z_s^2 dz_s);
    /// d out += k_f dw + w dk_f. The state runs at k_f = 0 too (w is the derivative in k_f).
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let (v, zs) = (s.x - s.x_prev, self.presliding);
        let (w, e, p, dp) = self.step(v);
        let sign = if v > 0.0 {
            1.0
        } else if v < 0.0 {
            -1.0
        } else {
            0.0
        };
        // w = e w1 + (v / z_s) phi: the coefficients of d kappa and of dv
        let c_kappa = v / zs * dp - e * self.w;
        let c_v = c_kappa * sign / zs + p / zs;
        for ((o, a), b) in self.dw.iter_mut().zip(d.dx).zip(d.dx_prev) {
            *o = e * *o + c_v * (a - b);
        }
        add_at(
            &mut self.dw,
            cols[1],
            -c_kappa * v.abs() / (zs * zs) - p * v / (zs * zs),
        );
        add_at(&mut self.dw, cols[2], c_kappa);
        self.w = w;
        for (o, dw) in dout.iter_mut().zip(&self.dw) {
            *o += self.force * dw;
        }
        add_at(dout, cols[0], w);
        if self.force == 0.0 {
            out
        } else {
            out + self.force * w
        }
    }
}
