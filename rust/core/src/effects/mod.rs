//! The diagnosis catalogue's effects on the nominal cascade (eq 16 -> eq 1), one module each.
//!
//! Every effect is an [`Effect`]: its parameters (as the Python catalogue orders them), their
//! check, and the hooks by which it enters the fused one-pass simulation of
//! [`crate::augmented::simulate_augmented`]. Each gives exactly the nominal model at zero size.
//! The registry below is the one place that lists them: adding an effect is a new module here
//! and its name in the `registry!` list (and its Python module in
//! `backlashid.diagnosis.effects`).

use std::fmt::Debug;

use crate::error::{Error, Result};

/// Where an effect enters the sample-by-sample simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// On the drive input of the linear block, before x(t+1) sees it ([`Effect::drive`]).
    Drive,
    /// On the dead-band widths of the backlash ([`Effect::widths`]).
    Widths,
    /// On the output after the backlash ([`Effect::output`]).
    Output,
}

/// What an effect sees of sample t.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// Sample index within the record (0-based).
    pub t: usize,
    /// The record's input u.
    pub u: &'a [f64],
    /// x(t), the linear block's output.
    pub x: f64,
    /// x(t-1) (x(0) of the state before the record).
    pub x_prev: f64,
    /// f(t), the backlash output (Output stage only; 0 before).
    pub f: f64,
    /// (t0 + t) / time_scale, the time of the drifts.
    pub tau: f64,
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
    /// Drive stage: the linear block's input at t, given the value `v` so far.
    fn drive(&mut self, v: f64, _s: &Sample) -> f64 {
        v
    }
    /// Widths stage: (c_L(t), c_R(t)) from the nominal widths, or None where they are nominal.
    fn widths(&self, _c_left: f64, _c_right: f64, _s: &Sample) -> Option<(f64, f64)> {
        None
    }
    /// Output stage: the output at t, given the value `out` so far.
    fn output(&mut self, out: f64, _s: &Sample) -> f64 {
        out
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
    width_drift::WidthDrift,
    compliance::Compliance,
    hysteresis_memory::HysteresisMemory,
    output_offset::OutputOffset,
    quantization::Quantization,
);
