//! The diagnosis catalogue's effects on the nominal chain, one module each: the cascade (eq 16
//! -> eq 1) or the sandwich (eq 16 -> eq 1 -> eq 29; the input backlash is the sandwich whose
//! input block is 1).
//!
//! Every effect is an [`Effect`]: its parameters (as the Python catalogue orders them), their
//! check, and the hooks by which it enters the fused one-pass simulation of
//! [`crate::augmented::simulate_augmented`]. Each gives exactly the nominal model at zero size.
//! The registry below is the one place that lists them: adding an effect is a new module here
//! and its name in the `registry!` list (and its Python module in
//! `backlashid.diagnosis.effects`).
//!
//! For the output-error refit (`crate::identify::augmented_problem`) every effect also has
//! its parameters' names, domain bounds and tangent hooks: each hook returns the value of
//! its value hook and carries d/dtheta of that value (a vector over theta, `p` wide) along,
//! with the one-sided derivative that the value takes at a non-smooth point (sign at 0, a
//! clip's edge, a play's corner). A parameter may be marked not differentiable (an integer
//! dead time, the quantiser's step): it is held in the refit and searched outside it.

use std::fmt::Debug;

use crate::error::{Error, Result};

/// Where an effect enters the sample-by-sample simulation, in the order of the pass. For a
/// cascade (no output block) Load and Output are the same place, Load first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// On x(t) itself, before the linear block's recursion stores it and the backlash sees
    /// it ([`Effect::state`]).
    State,
    /// On the drive input of the linear block, before x(t+1) sees it ([`Effect::drive`]).
    Drive,
    /// On the dead-band widths of the backlash ([`Effect::widths`]).
    Widths,
    /// On the backlash's output, the load it drives, before the sandwich's output block
    /// ([`Effect::output`] on f(t)).
    Load,
    /// On the measured output, the sensor's side: after the sandwich's output block (eq 29),
    /// after the load for a cascade ([`Effect::output`]).
    Output,
}

/// What an effect sees of sample t.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// Sample index within the record (0-based).
    pub t: usize,
    /// The record's input u.
    pub u: &'a [f64],
    /// u(t-1) (u(-1) of the state before the record: the linear block's latest past input).
    pub u_prev: f64,
    /// x(t), the linear block's output (after the State stage; its input there).
    pub x: f64,
    /// x(t-1) (x(0) of the state before the record).
    pub x_prev: f64,
    /// f(t), the backlash output (Load and Output stages only; 0 before).
    pub f: f64,
    /// (t0 + t) / time_scale, the time of the drifts.
    pub tau: f64,
    /// x(t+1) without the term of u_eff(t): the linear block's free response one step ahead
    /// (Drive stage of a pass with an effect that [`Effect::needs_free`]; 0 otherwise).
    pub x_free: f64,
    /// a_1, the weight of u_eff(t) in x(t+1) = a_1 u_eff(t) + x_free.
    pub gain: f64,
}

/// What a tangent hook sees of the derivatives at sample t, each d/dtheta over the refit's
/// parameter vector theta (`p` values).
#[derive(Debug, Clone, Copy)]
pub struct Tangent<'a> {
    /// d x(t) / d theta.
    pub dx: &'a [f64],
    /// d x(t-1) / d theta.
    pub dx_prev: &'a [f64],
    /// d f(t) / d theta, the backlash output's (Load and Output stages only; empty before).
    pub df: &'a [f64],
    /// d x_free / d theta (Drive stage of a pass with an effect that [`Effect::needs_free`];
    /// empty otherwise). The gain a_1 is column 0 of theta.
    pub dx_free: &'a [f64],
}

/// The columns in theta of an effect's parameters (in the catalogue's order); None for a
/// parameter held in the refit.
pub type Columns = [Option<usize>];

/// `d[col] += v` for a parameter in theta (nothing for a held one).
#[inline(always)]
pub(crate) fn add_at(d: &mut [f64], col: Option<usize>, v: f64) {
    if let Some(c) = col {
        d[c] += v;
    }
}

/// One effect of the catalogue.
pub trait Effect: Clone + Debug + Send + Sync {
    /// The effect's name, as in the Python catalogue.
    fn name(&self) -> &'static str;
    /// Its stage in the one-pass simulation.
    fn stage(&self) -> Stage;
    /// Its position in the one-pass simulation (effects apply in increasing order).
    fn order(&self) -> u32;
    /// Every parameter in its domain; the message says which one to fix.
    fn check(&self) -> Result<()>;
    /// A fresh copy for one simulation, its memory at rest on x(0) = `x0` and y(0) = `y0`.
    fn start(&self, _x0: f64, _y0: f64) -> Self {
        self.clone()
    }
    /// State stage: x(t) as the recursion stores it, given the value `x` so far.
    fn state(&mut self, x: f64, _s: &Sample) -> f64 {
        x
    }
    /// Drive stage: the linear block's input at t, given the value `v` so far.
    fn drive(&mut self, v: f64, _s: &Sample) -> f64 {
        v
    }
    /// Widths stage: (c_L(t), c_R(t)) from the nominal widths, or None where they are nominal.
    fn widths(&self, _c_left: f64, _c_right: f64, _s: &Sample) -> Option<(f64, f64)> {
        None
    }
    /// Load and Output stages: the output at t, given the value `out` so far.
    fn output(&mut self, out: f64, _s: &Sample) -> f64 {
        out
    }

    /// Whether its drive hook reads the free response `Sample::x_free` and gain (computed
    /// only for a pass with such an effect).
    fn needs_free(&self) -> bool {
        false
    }
    /// Its parameters, in the catalogue's order (what `from_parameters` takes).
    fn parameters(&self) -> Vec<f64>;
    /// Their names, as in the Python catalogue.
    fn parameter_names(&self) -> Vec<String>;
    /// Whether parameter `k` has a derivative (false: held in the refit, searched outside).
    fn differentiable(&self, _k: usize) -> bool {
        true
    }
    /// The box of parameter `k`'s domain, (lower, upper), +-inf where free.
    fn bounds(&self, _k: usize) -> (f64, f64) {
        (f64::NEG_INFINITY, f64::INFINITY)
    }
    /// Every parameter where the refit may take it: `check` and any stricter domain of the
    /// derivatives (an open interval where the box of `bounds` is closed).
    fn feasible(&self) -> bool {
        self.check().is_ok()
    }
    /// `start` for a simulation with tangents over `p = dx0.len()` parameters: the memory
    /// at rest on x(0) = `x0` (d x(0) / d theta = `dx0`) and y(0) = `y0` (a constant);
    /// `cols` are the columns of its own parameters.
    fn start_tangent(&self, x0: f64, y0: f64, _dx0: &[f64], _cols: &Columns) -> Self {
        self.start(x0, y0)
    }
    /// `state` with the tangent `dx` of x(t) carried along (the default leaves it: an effect
    /// of another stage). Only the columns of a, b and the State and Drive effects' own
    /// parameters may be non-zero in `dx`.
    fn state_tangent(&mut self, x: f64, _dx: &mut [f64], s: &Sample, _cols: &Columns) -> f64 {
        self.state(x, s)
    }
    /// `drive` with the tangent `dv` of the value carried along (the default leaves it: an
    /// effect of another stage).
    fn drive_tangent(
        &mut self,
        v: f64,
        _dv: &mut [f64],
        s: &Sample,
        _d: &Tangent,
        _cols: &Columns,
    ) -> f64 {
        self.drive(v, s)
    }
    /// `widths` with the tangents (d c_L(t), d c_R(t)) carried along; returns the widths
    /// (the nominal ones where the effect leaves them).
    fn widths_tangent(
        &self,
        c: (f64, f64),
        _dc: (&mut [f64], &mut [f64]),
        s: &Sample,
        _cols: &Columns,
    ) -> (f64, f64) {
        self.widths(c.0, c.1, s).unwrap_or(c)
    }
    /// `output` with the tangent `dout` of the value carried along (the default leaves it:
    /// an effect of another stage).
    fn output_tangent(
        &mut self,
        out: f64,
        _dout: &mut [f64],
        s: &Sample,
        _d: &Tangent,
        _cols: &Columns,
    ) -> f64 {
        self.output(out, s)
    }
}

/// The sign of a velocity with sign(0) = 0 (a standstill, not a crossing): friction's
/// direction and the Bouc-Wen state's |v| derivative.
#[inline(always)]
pub(crate) fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// phi(kappa) = (1 - e^-kappa) / kappa and phi'(kappa), the exact step of a first-order
/// linear law over one sample (phi(0) = 1, any sign of kappa), by their series near 0 (where
/// the closed forms cancel): dynamic friction's bristles and the Bouc-Wen state.
#[inline(always)]
pub(crate) fn phi(kappa: f64) -> (f64, f64) {
    if kappa.abs() < 1e-2 {
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

/// Bounds lo < hi of a clip (+-inf for none), or a ModelError naming `effect`.
pub(crate) fn check_clip(effect: &str, lo: f64, hi: f64) -> Result<()> {
    if lo.is_nan() || hi.is_nan() || lo >= hi {
        return Err(Error::Model(format!(
            "{effect} bounds lo = {lo}, hi = {hi}: give lo < hi (+-inf for no bound)"
        )));
    }
    Ok(())
}

/// v clipped to [lo, hi]: the value of every saturation (input, state, sensor).
#[inline(always)]
pub(crate) fn clip(v: f64, lo: f64, hi: f64) -> f64 {
    if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    }
}

/// [`clip`] with its tangent: clipped, the bound's column (`cols[0]` lo, `cols[1]` hi) and
/// nothing of v; at an edge the value is v's, so is the derivative.
#[inline(always)]
pub(crate) fn clip_tangent(v: f64, dv: &mut [f64], lo: f64, hi: f64, cols: &Columns) -> f64 {
    if v < lo {
        dv.fill(0.0);
        add_at(dv, cols[0], 1.0);
        lo
    } else if v > hi {
        dv.fill(0.0);
        add_at(dv, cols[1], 1.0);
        hi
    } else {
        v
    }
}

/// A finite parameter, or a ModelError saying `what` to give.
pub(crate) fn finite(name: &str, v: f64, what: &str) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::Model(format!("{name} = {v}: {what}")))
    }
}

/// The parameters of `effect`, exactly `n` of them named `names`.
pub(crate) fn arity(effect: &str, p: &[f64], names: &str, n: usize) -> Result<()> {
    if p.len() == n {
        Ok(())
    } else {
        Err(Error::Model(format!(
            "{effect} takes {n} parameter(s) ({names}), got {}",
            p.len()
        )))
    }
}

/// `name`, `stage` and `order` of an effect's `impl Effect`: its module's `NAME`, the stage
/// and its position in the pass.
macro_rules! place {
    ($stage:ident, $order:expr) => {
        fn name(&self) -> &'static str {
            NAME
        }
        fn stage(&self) -> Stage {
            Stage::$stage
        }
        fn order(&self) -> u32 {
            $order
        }
    };
}

macro_rules! registry {
    ($($m:ident :: $t:ident),* $(,)?) => {
        $(pub mod $m;)*

        /// The names of the effects that act on the simulation.
        pub const NAMES: &[&str] = &[$($m::NAME),*];

        /// Any effect of the registry: the simulation's loop dispatches on it statically.
        #[derive(Debug, Clone)]
        pub enum AnyEffect {
            $(
                #[allow(missing_docs)]
                $t($m::$t),
            )*
        }

        impl AnyEffect {
            /// [`Effect::name`].
            pub fn name(&self) -> &'static str {
                match self { $(AnyEffect::$t(e) => e.name()),* }
            }
            /// [`Effect::stage`].
            pub fn stage(&self) -> Stage {
                match self { $(AnyEffect::$t(e) => e.stage()),* }
            }
            /// [`Effect::order`].
            pub fn order(&self) -> u32 {
                match self { $(AnyEffect::$t(e) => e.order()),* }
            }
            /// [`Effect::check`].
            pub fn check(&self) -> Result<()> {
                match self { $(AnyEffect::$t(e) => e.check()),* }
            }
            /// [`Effect::start`].
            pub fn start(&self, x0: f64, y0: f64) -> AnyEffect {
                match self { $(AnyEffect::$t(e) => AnyEffect::$t(e.start(x0, y0))),* }
            }
            /// [`Effect::state`].
            #[inline(always)]
            pub fn state(&mut self, x: f64, s: &Sample) -> f64 {
                match self { $(AnyEffect::$t(e) => e.state(x, s)),* }
            }
            /// [`Effect::drive`].
            #[inline(always)]
            pub fn drive(&mut self, v: f64, s: &Sample) -> f64 {
                match self { $(AnyEffect::$t(e) => e.drive(v, s)),* }
            }
            /// [`Effect::widths`].
            #[inline(always)]
            pub fn widths(&self, c_left: f64, c_right: f64, s: &Sample) -> Option<(f64, f64)> {
                match self { $(AnyEffect::$t(e) => e.widths(c_left, c_right, s)),* }
            }
            /// [`Effect::output`].
            #[inline(always)]
            pub fn output(&mut self, out: f64, s: &Sample) -> f64 {
                match self { $(AnyEffect::$t(e) => e.output(out, s)),* }
            }
            /// [`Effect::needs_free`].
            pub fn needs_free(&self) -> bool {
                match self { $(AnyEffect::$t(e) => e.needs_free()),* }
            }
            /// [`Effect::parameters`].
            pub fn parameters(&self) -> Vec<f64> {
                match self { $(AnyEffect::$t(e) => e.parameters()),* }
            }
            /// [`Effect::parameter_names`].
            pub fn parameter_names(&self) -> Vec<String> {
                match self { $(AnyEffect::$t(e) => e.parameter_names()),* }
            }
            /// [`Effect::differentiable`].
            pub fn differentiable(&self, k: usize) -> bool {
                match self { $(AnyEffect::$t(e) => e.differentiable(k)),* }
            }
            /// [`Effect::bounds`].
            pub fn bounds(&self, k: usize) -> (f64, f64) {
                match self { $(AnyEffect::$t(e) => e.bounds(k)),* }
            }
            /// [`Effect::feasible`].
            pub fn feasible(&self) -> bool {
                match self { $(AnyEffect::$t(e) => e.feasible()),* }
            }
            /// [`Effect::start_tangent`].
            pub fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], cols: &Columns) -> AnyEffect {
                match self {
                    $(AnyEffect::$t(e) => AnyEffect::$t(e.start_tangent(x0, y0, dx0, cols))),*
                }
            }
            /// [`Effect::state_tangent`].
            #[inline(always)]
            pub fn state_tangent(
                &mut self, x: f64, dx: &mut [f64], s: &Sample, cols: &Columns,
            ) -> f64 {
                match self { $(AnyEffect::$t(e) => e.state_tangent(x, dx, s, cols)),* }
            }
            /// [`Effect::drive_tangent`].
            #[inline(always)]
            pub fn drive_tangent(
                &mut self, v: f64, dv: &mut [f64], s: &Sample, d: &Tangent, cols: &Columns,
            ) -> f64 {
                match self { $(AnyEffect::$t(e) => e.drive_tangent(v, dv, s, d, cols)),* }
            }
            /// [`Effect::widths_tangent`].
            #[inline(always)]
            pub fn widths_tangent(
                &self, c: (f64, f64), dc: (&mut [f64], &mut [f64]), s: &Sample, cols: &Columns,
            ) -> (f64, f64) {
                match self { $(AnyEffect::$t(e) => e.widths_tangent(c, dc, s, cols)),* }
            }
            /// [`Effect::output_tangent`].
            #[inline(always)]
            pub fn output_tangent(
                &mut self, out: f64, dout: &mut [f64], s: &Sample, d: &Tangent, cols: &Columns,
            ) -> f64 {
                match self { $(AnyEffect::$t(e) => e.output_tangent(out, dout, s, d, cols)),* }
            }
        }

        /// The effect `name` with its parameters `p` (in the Python catalogue's order).
        pub fn from_parameters(name: &str, p: &[f64]) -> Result<AnyEffect> {
            $(
                if name == $m::NAME {
                    let effect = $m::from_parameters(p)?;
                    effect.check()?;
                    return Ok(AnyEffect::$t(effect));
                }
            )*
            Err(Error::Model(format!(
                "unknown effect {name:?}: the simulation knows {}",
                NAMES.join(", ")
            )))
        }
    };
}

registry!(
    dead_time::DeadTime,
    saturation::Saturation,
    friction::Friction,
    stick_slip::StickSlip,
    width_drift::WidthDrift,
    compliance::Compliance,
    hysteresis_memory::HysteresisMemory,
    output_offset::OutputOffset,
    quantization::Quantization,
    dynamic_friction::DynamicFriction,
    feedback_hysteresis::FeedbackHysteresis,
    creep::Creep,
    state_saturation::StateSaturation,
    sensor_saturation::SensorSaturation,
);
