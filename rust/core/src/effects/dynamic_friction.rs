//! Dynamic friction on the load (Dahl / LuGre family): a friction force whose internal
//! (bristle) state follows a motion q and relaxes when the motion stops, as in a friction
//! damper whose input is a displacement and whose measured output is a force. The motion is
//! the linear block's output x (source 0: the friction sits behind the drive's dynamics), the
//! measured input u itself (source 1: an imposed displacement) or the backlash's output f
//! (source 2: the load's own motion, which stops while the play is crossed).
//!
//! Continuous form, with w = z / z_s the bristle state normalised to its sliding value:
//!
//!   dw/dt = q'(t) / z_s - (|q'(t)| / z_s + lambda) w,   f += k_f w,
//!
//! the friction force added to the load f(t), before the sandwich's output block (eq 29), which
//! filters both (in a cascade, on the output y).
//!
//! the Dahl law dz/dx = 1 - sign(x') z / z_s (the friction force saturates at +-k_f after a
//! slide of a few z_s) plus a relaxation at rate lambda per sample (the force decays at
//! standstill). Between two samples q moves linearly, v(t) = q(t) - q(t-1) a sample, so the
//! law is a linear ODE of constant coefficients over the sample and its exact step is
//!
//!   kappa = |v| / z_s + lambda,   w(t) = e^-kappa w(t-1) + (v / z_s) phi(kappa),
//!   phi(kappa) = (1 - e^-kappa) / kappa (phi(0) = 1),
//!
//! so |w| <= 1 whenever it starts there (a convex combination of w(t-1) and sign(v) phi
//! kappa |v| / z_s <= 1), without a step-size limit. Parameters: k_f (the friction force at
//! full slip, output units; zero size 0), z_s (the presliding displacement, units of q, > 0),
//! lambda (>= 0), source (0: q = x, 1: q = u, 2: q = f; held in the refit, each searched).
//! At k_f = 0 it is the nominal model; w starts at rest (0); before the record q is x(0) of
//! the state, the linear block's latest past input (rest: 0, held: u(0)) or the backlash's
//! memory y(0).

use super::{add_at, arity, finite, phi, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "dynamic_friction";

/// Dynamic friction (k_f, z_s, lambda, source) and its bristle state w.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicFriction {
    /// The friction force at full slip k_f.
    pub force: f64,
    /// The presliding displacement z_s.
    pub presliding: f64,
    /// The relaxation rate lambda per sample.
    pub relaxation: f64,
    /// The motion the bristles follow.
    pub source: Source,
    w: f64,
    /// f(t-1), the backlash's output a sample before (source 2).
    f_prev: f64,
    /// d w / d theta and d f(t-1) / d theta (tangent simulations only).
    dw: Vec<f64>,
    df_prev: Vec<f64>,
}

/// The motion q of the friction's bristles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// x, the linear block's output (source 0).
    Drive,
    /// u, the measured input (source 1).
    Input,
    /// f, the backlash's output, the load's motion (source 2).
    Load,
}

/// From [k_f, z_s, lambda, source] (source 0: driven by x, 1: by u, 2: by f; [k_f, z_s,
/// lambda]: by x).
pub fn from_parameters(p: &[f64]) -> Result<DynamicFriction> {
    if p.len() != 3 {
        arity(NAME, p, "k_f, z_s, lambda, source", 4)?;
    }
    let code = p.get(3).copied().unwrap_or(0.0);
    let source = if code == 0.0 {
        Source::Drive
    } else if code == 1.0 {
        Source::Input
    } else if code == 2.0 {
        Source::Load
    } else {
        return Err(Error::Model(format!(
            "source = {code}: give 0 (friction driven by the linear block's output x), 1 (by the input u) \
             or 2 (by the backlash's output f)"
        )));
    };
    Ok(DynamicFriction {
        force: p[0],
        presliding: p[1],
        relaxation: p[2],
        source,
        w: 0.0,
        f_prev: 0.0,
        dw: Vec::new(),
        df_prev: Vec::new(),
    })
}

impl DynamicFriction {
    /// The motion over sample t, v = q(t) - q(t-1).
    #[inline(always)]
    fn velocity(&self, s: &Sample) -> f64 {
        match self.source {
            Source::Drive => s.x - s.x_prev,
            Source::Input => s.u[s.t] - s.u_prev,
            Source::Load => s.f - self.f_prev,
        }
    }

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
    // on the load, before the sandwich's output block filters it with the backlash's output
    // (a cascade: on the output); after compliance and the extra plays
    place!(Load, 6);
    fn check(&self) -> Result<()> {
        finite("k_f", self.force, "give a finite friction force (0 for none)")?;
        if !(self.presliding.is_finite() && self.presliding > 0.0) {
            return Err(Error::Model(format!(
                "z_s = {}: give a positive presliding displacement (in units of the motion it follows)",
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
    fn start(&self, _x0: f64, y0: f64) -> Self {
        // the bristles at rest, the load at the backlash's memory
        DynamicFriction {
            w: 0.0,
            f_prev: y0,
            dw: Vec::new(),
            df_prev: Vec::new(),
            ..self.clone()
        }
    }
    #[inline]
    fn output(&mut self, out: f64, s: &Sample) -> f64 {
        if self.force == 0.0 {
            return out;
        }
        self.w = self.step(self.velocity(s)).0;
        self.f_prev = s.f;
        out + self.force * self.w
    }
    fn parameters(&self) -> Vec<f64> {
        vec![
            self.force,
            self.presliding,
            self.relaxation,
            match self.source {
                Source::Drive => 0.0,
                Source::Input => 1.0,
                Source::Load => 2.0,
            },
        ]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["k_f".into(), "z_s".into(), "lambda".into(), "source".into()]
    }
    /// The source is a choice: searched outside the refit.
    fn differentiable(&self, k: usize) -> bool {
        k < 3
    }
    /// k_f free (the force's sign is the sensor's), z_s >= 0 (`feasible`: > 0), lambda >= 0,
    /// source in {0, 1, 2}.
    fn bounds(&self, k: usize) -> (f64, f64) {
        match k {
            0 => (f64::NEG_INFINITY, f64::INFINITY),
            3 => (0.0, 2.0),
            _ => (0.0, f64::INFINITY),
        }
    }
    fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], _cols: &Columns) -> Self {
        let mut e = self.start(x0, y0);
        e.dw = vec![0.0; dx0.len()];
        e.df_prev = vec![0.0; dx0.len()]; // y(0) of the state is a constant
        e
    }
    /// kappa = |v| / z_s + lambda: d kappa = sign(v) dv / z_s - |v| / z_s^2 dz_s + dlambda
    /// (sign(0) = 0, the one-sided derivative of |v| at rest); d w = e^-kappa dw(t-1) +
    /// (v / z_s phi' - e^-kappa w(t-1)) d kappa + phi (dv / z_s - v / z_s^2 dz_s);
    /// d out += k_f dw + w dk_f. The state runs at k_f = 0 too (w is the derivative in k_f).
    /// Driven by x, dv = dx(t) - dx(t-1); by u, dv = 0 (the measured input has no
    /// parameter); by f, dv = df(t) - df(t-1).
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let (v, zs) = (self.velocity(s), self.presliding);
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
        match self.source {
            Source::Drive => {
                for ((o, a), b) in self.dw.iter_mut().zip(d.dx).zip(d.dx_prev) {
                    *o = e * *o + c_v * (a - b);
                }
            }
            Source::Input => self.dw.iter_mut().for_each(|o| *o *= e),
            Source::Load => {
                for ((o, a), b) in self.dw.iter_mut().zip(d.df).zip(&self.df_prev) {
                    *o = e * *o + c_v * (a - b);
                }
                self.df_prev.copy_from_slice(d.df);
            }
        }
        self.f_prev = s.f;
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
