//! The diagnosis's refit compiled once: the nominal chain's structure (a cascade, or a
//! sandwich: the input backlash is the sandwich with na = 1, nb = 0), effects of the
//! catalogue ([`crate::effects`]) with the names of their parameters that the refit frees,
//! and the record (u, y, warm-up, its time t0 and time scale, the start: rest, the input
//! held at u(0), or an explicit physical state; and the backlash memory y(0)), checked on
//! construction. theta is the chain's parameter vector (`Structure`'s layout and names: the
//! sandwich's with r_1 = 1 fixed, as `fit_sandwich`'s refinement) followed by the free effect
//! parameters in the order given; the other effect parameters (an integer dead time, a
//! quantiser's step, any not freed) keep their given values. The output-error factor and
//! gradient carry the exact sensitivities of `augmented_sensitivity`.

use crate::augmented::{check_time, simulate_augmented_chain, AugmentedChain, AugmentedState};
use crate::effects::{from_parameters, AnyEffect};
use crate::error::{Error, Result};
use crate::identify::augmented_sensitivity::{
    augmented_oe_factor, augmented_oe_gradient, augmented_sensitivity, Start,
};
use crate::identify::gradient::OeGradient;
use crate::identify::output_error_cost;
use crate::identify::problem::Structure;
use crate::identify::samples::Samples;
use crate::identify::sensitivity::{check_pair, oe_threads, Sensitivity};
use crate::linalg::TriangularFactor;
use crate::model::backlash::check_memory;
use crate::model::cascade::{CascadeModel, CascadeState};
use crate::model::linear::{LinearBlock, LinearState};

/// An explicit physical state before the record, each past most recent first: the input
/// block's past inputs u_past (na) and outputs x_past (nb), and for the sandwich its output
/// block's past inputs y_past (nr; y_past[0] is the backlash memory y(0)) and outputs w_past
/// (ns). The sensitivities take it as a constant.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Past {
    pub u_past: Vec<f64>,
    pub x_past: Vec<f64>,
    pub y_past: Vec<f64>,
    pub w_past: Vec<f64>,
}

/// Where the record starts.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordStart {
    /// The linear block at its equilibrium with u(0) (the input held before the record)
    /// instead of at rest; a sandwich's output block at its equilibrium with y(0) held.
    pub held: bool,
    /// The explicit state (None: rest or held); not with `held`.
    pub past: Option<Past>,
    /// The backlash memory y(0).
    pub y_prev: f64,
    /// The time of u(0) in the continuous record, in samples (drifts only).
    pub t0: f64,
    /// Samples per time unit of the drifts.
    pub time_scale: f64,
}

/// A refit of the nominal cascade with effects, compiled once.
#[derive(Debug, Clone)]
pub struct AugmentedProblem {
    structure: Structure,
    /// The effects with their given parameters (the held ones' values).
    effects: Vec<AnyEffect>,
    /// (effect, parameter) of each free name, in theta's order after the nominal part.
    free: Vec<(usize, usize)>,
    names: Vec<String>,
    u: Samples,
    y: Samples,
    warmup: usize,
    start: RecordStart,
}

/// The model, effects and their columns of one theta.
struct At {
    model: AugmentedChain,
    effects: Vec<(AnyEffect, Vec<Option<usize>>)>,
}

impl AugmentedProblem {
    /// `structure` a cascade or sandwich without feedthroughs or initial state; `effects`
    /// (name, parameters) pairs of the catalogue, each name at most once; `free` names of
    /// their parameters, each once and differentiable; u, y non-empty, finite, one length;
    /// 0 <= warmup < len(u); an explicit start's pasts of the structure's orders.
    pub fn new(
        structure: Structure,
        effects: &[(String, Vec<f64>)],
        free: &[String],
        u: impl Into<Samples>,
        y: impl Into<Samples>,
        warmup: usize,
        start: RecordStart,
    ) -> Result<Self> {
        let (u, y): (Samples, Samples) = (u.into(), y.into());
        if structure.feedthrough || structure.output_feedthrough || structure.initial_state {
            return Err(Error::Data(
                "the augmented chain takes a cascade or sandwich structure without feedthrough \
                 (the diagnosis delays the record instead) nor initial state (give the start)"
                    .into(),
            ));
        }
        check_pair(&u, &y, "y")?;
        if warmup >= u.len() {
            return Err(Error::Data(format!(
                "warmup = {warmup}: give a whole number of samples, 0 <= warmup < {} (the record \
                 length)",
                u.len()
            )));
        }
        check_time(start.t0, start.time_scale)?;
        check_memory(start.y_prev)?;
        if let Some(past) = &start.past {
            check_past(&structure, past, start.y_prev, start.held)?;
        }
        let mut built: Vec<AnyEffect> = Vec::with_capacity(effects.len());
        for (name, p) in effects {
            let e = from_parameters(name, p)?;
            if built.iter().any(|b| b.name() == e.name()) {
                return Err(Error::Model(format!(
                    "effect {name:?} given twice: give each effect once"
                )));
            }
            built.push(e);
        }
        let mut names = structure.names();
        let mut cols = Vec::with_capacity(free.len());
        for want in free {
            let hits: Vec<(usize, usize)> = built
                .iter()
                .enumerate()
                .flat_map(|(i, e)| {
                    e.parameter_names()
                        .into_iter()
                        .enumerate()
                        .filter(|(_, n)| n == want)
                        .map(move |(k, _)| (i, k))
                })
                .collect();
            let Some(&(i, k)) = hits.first() else {
                let known: Vec<String> = built.iter().flat_map(|e| e.parameter_names()).collect();
                return Err(Error::Model(format!(
                    "free parameter {want:?} is not a parameter of the effects given (they have \
                     {})",
                    known.join(", ")
                )));
            };
            if cols.contains(&(i, k)) {
                return Err(Error::Model(format!(
                    "free parameter {want:?} given twice: name each once"
                )));
            }
            if !built[i].differentiable(k) {
                return Err(Error::Model(format!(
                    "{}'s {want} has no derivative (a whole number of samples or a quantiser's \
                     step): hold it and search it outside the refit, one problem per value",
                    built[i].name()
                )));
            }
            cols.push((i, k));
            names.push(want.clone());
        }
        Ok(Self {
            structure,
            effects: built,
            free: cols,
            names,
            u,
            y,
            warmup,
            start,
        })
    }

    pub fn structure(&self) -> &Structure {
        &self.structure
    }

    /// The parameter names: the cascade's, then the free effect parameters'.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    pub fn u(&self) -> &[f64] {
        &self.u
    }

    pub fn y(&self) -> &[f64] {
        &self.y
    }

    pub fn warmup(&self) -> usize {
        self.warmup
    }

    pub fn start(&self) -> &RecordStart {
        &self.start
    }

    fn wrong_length(&self, theta: &[f64]) -> Error {
        Error::Data(format!(
            "theta has {} parameters but the problem has {}: give one value per name",
            theta.len(),
            self.names.len()
        ))
    }

    /// The cascade and the effects at theta (each effect checked in its domain).
    fn at(&self, theta: &[f64]) -> Result<At> {
        let p0 = self.structure.size();
        if theta.len() != self.names.len() {
            return Err(self.wrong_length(theta));
        }
        let blocks = self.structure.unpack(&theta[..p0])?;
        let mut params: Vec<Vec<f64>> = self.effects.iter().map(|e| e.parameters()).collect();
        let mut cols: Vec<Vec<Option<usize>>> =
            params.iter().map(|p| vec![None; p.len()]).collect();
        for (m, &(i, k)) in self.free.iter().enumerate() {
            params[i][k] = theta[p0 + m];
            cols[i][k] = Some(p0 + m);
        }
        let effects = self
            .effects
            .iter()
            .zip(params)
            .zip(cols)
            .map(|((e, p), c)| Ok((from_parameters(e.name(), &p)?, c)))
            .collect::<Result<_>>()?;
        Ok(At {
            model: AugmentedChain {
                cascade: CascadeModel::new(blocks.linear, blocks.backlash),
                output: blocks.output,
            },
            effects,
        })
    }

    /// The state before the record, d x_past / d theta (nb rows of p) and d w_past / d theta
    /// (ns rows, or empty for zeros): the explicit start (constants); rest (a sandwich's
    /// y_past = [y(0), 0, ..]); or the input held at u(0) with x at its equilibrium
    /// sum a / (1 + sum b) u(0), and a sandwich's output block at its equilibrium with y(0)
    /// held, w = sum r / (1 + sum s) y(0).
    fn state(&self, chain: &AugmentedChain) -> Result<(AugmentedState, Vec<f64>, Vec<f64>)> {
        let linear = &chain.cascade.linear;
        let (na, nb, p) = (linear.na(), linear.nb(), self.names.len());
        let y0 = self.start.y_prev;
        let mut dx_past = vec![0.0; nb * p];
        let mut dw_past = Vec::new();
        if let Some(past) = &self.start.past {
            let state = AugmentedState {
                cascade: CascadeState {
                    linear: LinearState {
                        u_past: past.u_past.clone(),
                        x_past: past.x_past.clone(),
                    },
                    y_prev: y0,
                },
                output: chain.output.as_ref().map(|_| LinearState {
                    u_past: past.y_past.clone(),
                    x_past: past.w_past.clone(),
                }),
            };
            return Ok((state, dx_past, dw_past));
        }
        let linear_state = if self.start.held {
            let u0 = self.u[0];
            let (x_eq, den) = equilibrium(linear, u0)?;
            for row in dx_past.chunks_exact_mut(p) {
                for v in &mut row[..na] {
                    *v = u0 / den;
                }
                for v in &mut row[na..na + nb] {
                    *v = -x_eq / den;
                }
            }
            LinearState {
                u_past: vec![u0; na],
                x_past: vec![x_eq; nb],
            }
        } else {
            linear.rest_state()
        };
        let output = match &chain.output {
            None => None,
            Some(block) if self.start.held => {
                // r_1 = 1 fixed: d w_eq / d r_i = y0 / den (i >= 2), d / d s_j = -w_eq / den
                let (nr, ns) = (block.na(), block.nb());
                let (w_eq, den) = equilibrium(block, y0)?;
                let (col_r, col_s) = (
                    self.structure.layout().r(),
                    self.structure.layout().r() + nr - 1,
                );
                dw_past = vec![0.0; ns * p];
                for row in dw_past.chunks_exact_mut(p) {
                    row[col_r..col_s].fill(y0 / den);
                    row[col_s..col_s + ns].fill(-w_eq / den);
                }
                Some(LinearState {
                    u_past: vec![y0; nr],
                    x_past: vec![w_eq; ns],
                })
            }
            Some(block) => {
                let mut rest = block.rest_state();
                rest.u_past[0] = y0;
                Some(rest)
            }
        };
        Ok((
            AugmentedState {
                cascade: CascadeState {
                    linear: linear_state,
                    y_prev: y0,
                },
                output,
            },
            dx_past,
            dw_past,
        ))
    }

    /// `pass` on theta's model and effects from the record's start state and its derivatives
    /// (rest, held at u[0], or explicit): what every sensitivity pass begins with.
    fn with_start<T>(
        &self,
        theta: &[f64],
        pass: impl FnOnce(&At, &Start) -> Result<T>,
    ) -> Result<T> {
        let at = self.at(theta)?;
        let (state, dx_past, dw_past) = self.state(&at.model)?;
        let start = Start {
            state: &state,
            dx_past: &dx_past,
            dw_past: &dw_past,
        };
        pass(&at, &start)
    }

    /// The free-run output at theta (`simulate_augmented_chain`).
    pub fn simulate(&self, theta: &[f64]) -> Result<Vec<f64>> {
        let at = self.at(theta)?;
        let (state, _, _) = self.state(&at.model)?;
        let effects: Vec<AnyEffect> = at.effects.into_iter().map(|(e, _)| e).collect();
        let s = &self.start;
        simulate_augmented_chain(&at.model, &effects, &self.u, s.t0, s.time_scale, &state)
    }

    /// sum (y - y_sim)^2 over t >= warmup.
    pub fn cost(&self, theta: &[f64]) -> Result<f64> {
        output_error_cost(&self.y, &self.simulate(theta)?, self.warmup)
    }

    /// The output and its dense Jacobian d y_sim / d theta (N x p; tests and small records).
    pub fn sensitivity(&self, theta: &[f64]) -> Result<Sensitivity> {
        self.with_start(theta, |at, start| {
            let s = &self.start;
            augmented_sensitivity(
                &at.model,
                &at.effects,
                &self.u,
                s.t0,
                s.time_scale,
                start,
                self.names.len(),
            )
        })
    }

    /// R_aug of [J | y - y_sim] over t >= warmup and the cost, streamed.
    pub fn oe_factor(&self, theta: &[f64]) -> Result<(TriangularFactor, f64)> {
        self.oe_factor_threads(theta, oe_threads(self.u.len()))
    }

    /// `oe_factor` with the folding on a second thread when `threads` >= 2 (the same bits).
    pub fn oe_factor_threads(
        &self,
        theta: &[f64],
        threads: usize,
    ) -> Result<(TriangularFactor, f64)> {
        self.with_start(theta, |at, start| {
            let s = &self.start;
            let (u, y, p) = (&self.u[..], &self.y[..], self.names.len());
            augmented_oe_factor(
                &at.model,
                &at.effects,
                u,
                y,
                self.warmup,
                s.t0,
                s.time_scale,
                start,
                p,
                threads,
            )
        })
    }

    /// g = J^T (y - y_sim) over t >= warmup and the cost, one pass without the factor.
    pub fn gradient(&self, theta: &[f64]) -> Result<OeGradient> {
        self.with_start(theta, |at, start| {
            let s = &self.start;
            let (u, y, p) = (&self.u[..], &self.y[..], self.names.len());
            augmented_oe_gradient(
                &at.model,
                &at.effects,
                u,
                y,
                self.warmup,
                s.t0,
                s.time_scale,
                start,
                p,
            )
        })
    }

    /// The refit's guard: the linear blocks stable and every effect with a free parameter
    /// inside its domain (`Effect::feasible`); an error only for a theta of the wrong length.
    pub fn feasible(&self, theta: &[f64]) -> Result<bool> {
        if theta.len() != self.names.len() {
            return Err(self.wrong_length(theta));
        }
        Ok(match self.at(theta) {
            Ok(at) => {
                at.model.cascade.linear.is_stable()
                    && at
                        .model
                        .output
                        .as_ref()
                        .map_or(true, LinearBlock::is_stable)
                    && at
                        .effects
                        .iter()
                        .all(|(e, c)| c.iter().all(Option::is_none) || e.feasible())
            }
            Err(_) => false,
        })
    }

    /// (lower, upper) per parameter: the cascade's as `Problem::bounds` (c_L, c_R >= 0, the
    /// others free), the effects' domain boxes (`Effect::bounds`) for the free ones.
    pub fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let p0 = self.structure.size();
        let lay = self.structure.layout();
        let mut lower = vec![f64::NEG_INFINITY; p0];
        lower[lay.c_l()] = 0.0;
        lower[lay.c_r()] = 0.0;
        let mut upper = vec![f64::INFINITY; p0];
        for &(i, k) in &self.free {
            let (lo, hi) = self.effects[i].bounds(k);
            lower.push(lo);
            upper.push(hi);
        }
        (lower, upper)
    }
}

/// x_eq = sum a / (1 + sum b) v of `block` held at the input v, and 1 + sum b.
fn equilibrium(block: &LinearBlock, v: f64) -> Result<(f64, f64)> {
    let den = 1.0 + block.b().iter().sum::<f64>();
    if den == 0.0 {
        return Err(Error::Model(format!(
            "the linear block {:?}, {:?} has a pole at z = 1, so no equilibrium holds it at a \
             constant input: start from rest (initial_state='rest') or give the state",
            block.a(),
            block.b()
        )));
    }
    Ok((block.a().iter().sum::<f64>() / den * v, den))
}

/// An explicit start's pasts of the structure's orders (the core's block: u_past na, x_past
/// nb, a sandwich's y_past nr with y_past[0] = y(0) and w_past ns; a cascade's empty), finite,
/// and not with a held start.
fn check_past(structure: &Structure, past: &Past, y_prev: f64, held: bool) -> Result<()> {
    if held {
        return Err(Error::Data(
            "held=True and an explicit start (u_past, x_past, y_past, w_past) both given: give \
             one of them"
                .into(),
        ));
    }
    let sandwich = structure.is_sandwich();
    let want = [
        ("u_past", &past.u_past, structure.n_a(), "na"),
        ("x_past", &past.x_past, structure.nb, "nb"),
        ("y_past", &past.y_past, structure.n_r(), "nr"),
        (
            "w_past",
            &past.w_past,
            if sandwich { structure.ns } else { 0 },
            "ns",
        ),
    ];
    for (name, v, n, order) in want {
        if v.len() != n {
            let what = if n == 0 && !sandwich {
                "none for a cascade".to_string()
            } else {
                format!("{order} = {n} of them, most recent first")
            };
            return Err(Error::Data(format!(
                "{name} has {} values: give {what}",
                v.len()
            )));
        }
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            return Err(Error::Data(format!(
                "{name} holds {x}: give finite past values"
            )));
        }
    }
    if sandwich && past.y_past[0] != y_prev {
        return Err(Error::Data(format!(
            "y_past[0] = {} but y_prev = {y_prev}: the output block's newest past input is the \
             backlash memory y(0); give the same value",
            past.y_past[0]
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::sensitivity::{cascade_sensitivity, sandwich_sensitivity};
    use crate::model::sandwich::{SandwichModel, SandwichState};
    use crate::test_params::{input, lcg_unit, noisy, perturbed, smooth_input, EXAMPLE2_THETA};

    /// Example 1's orders (na = nb = 2, cubic branches) at an estimate off the true values.
    const THETA: [f64; 11] = [
        0.65, 0.55, -0.15, 0.3, 0.55, -0.25, 0.28, 1.45, 0.45, 0.35, 0.25,
    ];

    fn structure() -> Structure {
        Structure::new(2, 2, 3, 0, 0, false, false).unwrap()
    }

    /// A slow triangle of `period` samples between -a and a.
    fn triangle(n: usize, period: usize, a: f64) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let ph = (k % period) as f64 / period as f64;
                a * (if ph < 0.5 {
                    4.0 * ph - 1.0
                } else {
                    3.0 - 4.0 * ph
                })
            })
            .collect()
    }

    /// The test records: a rich random input, a smooth two-tone one, slow triangles.
    fn inputs(n: usize) -> Vec<(&'static str, Vec<f64>)> {
        vec![
            ("random", input(n).iter().map(|v| 1.5 * v).collect()),
            ("smooth", smooth_input(n).iter().map(|v| 1.4 * v).collect()),
            ("triangle", triangle(n, 173, 1.6)),
            ("slow triangle + noise", noisy(&triangle(n, 401, 1.3), 9)),
        ]
    }

    fn start(held: bool) -> RecordStart {
        RecordStart {
            held,
            past: None,
            y_prev: if held { 0.3 } else { 0.0 },
            t0: if held { 700.0 } else { 0.0 },
            time_scale: 250.0,
        }
    }

    /// The problem of `effects` with `free` parameters on `u` (y: noise). A held start
    /// keeps x(0) = x(1) = x_eq (x sees u_eff up to t-1 only), so a backlash that moves at
    /// t = 0 meets L(x(1)) = y(0) at t = 1, a tie of eq (1) where the one-sided derivatives
    /// differ and differences straddle it: held, y(0) is taken inside the dead band at
    /// x_eq. Held with friction, u(0) = 0: x(0) = sum a u(0) - sum b x_eq equals x_eq only
    /// to rounding, and sign(x(0) - x_eq) of that residue jumps between +-1 with the last
    /// bit of theta (a discontinuity of the simulation itself); at u(0) = 0 both are 0.
    fn problem(
        effects: &[(&str, &[f64])],
        free: &[&str],
        u: &[f64],
        mut s: RecordStart,
    ) -> AugmentedProblem {
        let mut u = u.to_vec();
        if s.held && effects.iter().any(|(n, _)| *n == "friction") {
            u[0] = 0.0;
        }
        if s.held {
            let b = structure().unpack(&THETA).unwrap();
            let (a_sum, b_sum): (f64, f64) = (b.linear.a().iter().sum(), b.linear.b().iter().sum());
            let x_eq = a_sum / (1.0 + b_sum) * u[0];
            s.y_prev = 0.5 * (b.backlash.left().value(x_eq) + b.backlash.right().value(x_eq));
        }
        let effects: Vec<(String, Vec<f64>)> = effects
            .iter()
            .map(|(n, p)| (n.to_string(), p.to_vec()))
            .collect();
        let free: Vec<String> = free.iter().map(|n| n.to_string()).collect();
        let y = noisy(&vec![0.0; u.len()], 4);
        AugmentedProblem::new(structure(), &effects, &free, u, y, 5, s).unwrap()
    }

    /// theta of a problem: THETA then the free parameters' given values.
    fn theta(p: &AugmentedProblem) -> Vec<f64> {
        let mut th = THETA.to_vec();
        for &(i, k) in &p.free {
            th.push(p.effects[i].parameters()[k]);
        }
        th
    }

    /// Central differences of `simulate` against the exact Jacobian, column by column:
    /// the error's norm below `tol` times the column's (or the differences' scale). A
    /// switch of the backlash (or a clip, a play) that falls within +-h of a sample bends
    /// the differences there, so a column passes at the first of three step sizes that
    /// agrees (an error in the Jacobian fails at all three). Returns the worst relative
    /// error.
    fn check_jacobian(p: &AugmentedProblem, th: &[f64], tol: f64, what: &str) -> f64 {
        let sens = p.sensitivity(th).unwrap();
        let sim = p.simulate(th).unwrap();
        assert_eq!(
            sens.output, sim,
            "{what}: the tangent pass's values are the simulation's"
        );
        let cols = sens.cols;
        let n = sim.len();
        let mut worst: f64 = 0.0;
        for j in 0..cols {
            let exact: Vec<f64> = (0..n).map(|t| sens.jacobian[t * cols + j]).collect();
            let norm = exact.iter().map(|v| v * v).sum::<f64>().sqrt();
            let mut tries = Vec::new();
            for scale in [1.0, 1.0 / 7.0, 3.1] {
                let h = scale * 1e-6 * th[j].abs().max(0.1);
                let (mut plus, mut minus) = (th.to_vec(), th.to_vec());
                plus[j] += h;
                minus[j] -= h;
                let (sp, sm) = (p.simulate(&plus).unwrap(), p.simulate(&minus).unwrap());
                let fd: Vec<f64> = (0..n).map(|t| (sp[t] - sm[t]) / (2.0 * h)).collect();
                let fd_norm = fd.iter().map(|v| v * v).sum::<f64>().sqrt();
                let err = exact
                    .iter()
                    .zip(&fd)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f64>()
                    .sqrt();
                let rel = err / norm.max(fd_norm).max(1e-3);
                tries.push((rel, err, fd_norm));
                if rel < tol {
                    break;
                }
            }
            let (rel, err, fd_norm) = *tries.last().unwrap();
            assert!(
                rel < tol,
                "{what}: column {} ({}): |J - FD| = {err:e}, |J| = {norm:e}, |FD| = {fd_norm:e} \
                 ({tries:?})",
                j,
                p.names()[j]
            );
            worst = worst.max(rel);
        }
        worst
    }

    /// Every effect at non-zero sizes and at its zero size, alone and all together, on
    /// every input, from rest and held: the exact Jacobian is the differences'.
    #[test]
    fn sensitivities_are_central_differences_for_every_effect() {
        type Case<'a> = (&'a [(&'a str, &'a [f64])], &'a [&'a str]);
        let cases: &[Case] = &[
            (&[], &[]),
            (&[("saturation", &[-0.9, 1.0])], &["lo", "hi"]),
            (&[("friction", &[0.05, 0.1])], &["F_c", "F_v"]),
            (&[("friction", &[0.0, 0.0])], &["F_c", "F_v"]),
            (&[("width_drift", &[0.3, -0.2])], &["dc_L", "dc_R"]),
            (&[("width_drift", &[0.0, 0.0])], &["dc_L", "dc_R"]),
            (
                &[("compliance", &[0.4, 0.6, 0.15])],
                &["k", "omega", "zeta"],
            ),
            (&[("compliance", &[0.0, 0.5, 0.1])], &["k", "omega", "zeta"]),
            (
                &[("hysteresis_memory", &[0.2, 0.3, 0.5, -0.2])],
                &["r_1", "w_1", "r_2", "w_2"],
            ),
            (&[("hysteresis_memory", &[0.1, 0.0])], &["r_1", "w_1"]),
            (&[("output_offset", &[0.1, 0.3])], &["o_0", "o_1"]),
            (
                &[("dynamic_friction", &[0.2, 0.05, 0.01])],
                &["k_f", "z_s", "lambda"],
            ),
            (
                &[("dynamic_friction", &[0.0, 0.05, 0.01])],
                &["k_f", "z_s", "lambda"],
            ),
            (
                &[("dynamic_friction", &[0.2, 0.05, 0.01, 1.0])],
                &["k_f", "z_s", "lambda"],
            ),
            (
                &[("dynamic_friction", &[0.0, 0.05, 0.01, 1.0])],
                &["k_f", "z_s", "lambda"],
            ),
            (
                &[("dynamic_friction", &[0.2, 0.05, 0.01, 2.0])],
                &["k_f", "z_s", "lambda"],
            ),
            (
                &[("dynamic_friction", &[0.0, 0.05, 0.01, 2.0])],
                &["k_f", "z_s", "lambda"],
            ),
            (
                &[
                    ("compliance", &[0.3, 0.9, 0.2]),
                    ("dynamic_friction", &[-0.15, 0.08, 0.02, 2.0]),
                    ("hysteresis_memory", &[0.25, 0.2]),
                ],
                &["k", "omega", "zeta", "k_f", "z_s", "lambda", "r_1", "w_1"],
            ),
            (
                &[("feedback_hysteresis", &[0.3, 0.5, 0.2, 0.05])],
                &["alpha", "beta", "gamma", "k_3"],
            ),
            // at alpha = 0 and gamma != 0, z = alpha zeta is not linear in alpha (|z|), so
            // central differences straddle a kink: there the one-sided derivative is checked
            // (`feedback_hysteresis_at_zero_size_has_the_one_sided_derivative`)
            (
                &[("feedback_hysteresis", &[0.0, 0.5, 0.0, 0.0])],
                &["alpha", "beta", "gamma", "k_3"],
            ),
            (
                &[("creep", &[0.15, 3.4, -0.05, 5.7])],
                &["g_1", "l_1", "g_2", "l_2"],
            ),
            (&[("creep", &[0.0, 3.0])], &["g_1", "l_1"]),
            (&[("dead_time", &[2.0])], &[]),
            (
                &[
                    ("dead_time", &[1.0]),
                    ("saturation", &[-1.1, 0.95]),
                    ("friction", &[0.04, 0.15]),
                    ("width_drift", &[0.2, 0.1]),
                    ("compliance", &[0.3, 0.9, 0.2]),
                    ("hysteresis_memory", &[0.25, 0.2]),
                    ("output_offset", &[-0.1, 0.2]),
                ],
                &[
                    "lo", "hi", "F_c", "F_v", "dc_L", "dc_R", "k", "omega", "zeta", "r_1", "w_1",
                    "o_0", "o_1",
                ],
            ),
            (
                &[
                    ("friction", &[0.04, 0.15]),
                    ("feedback_hysteresis", &[0.2, 0.4, -0.1, 0.03]),
                    ("compliance", &[0.3, 0.9, 0.2]),
                    ("dynamic_friction", &[-0.1, 0.08, 0.02]),
                    ("hysteresis_memory", &[0.25, 0.2]),
                    ("creep", &[0.1, 3.0]),
                    ("output_offset", &[-0.1, 0.2]),
                ],
                &[
                    "F_c", "F_v", "alpha", "beta", "gamma", "k_3", "k", "omega", "zeta", "k_f",
                    "z_s", "lambda", "r_1", "w_1", "g_1", "l_1", "o_0", "o_1",
                ],
            ),
        ];
        let mut worst: f64 = 0.0;
        for (effects, free) in cases {
            for (name, u) in inputs(600) {
                for held in [false, true] {
                    let p = problem(effects, free, &u, start(held));
                    let what = format!("{effects:?} on {name}, held {held}");
                    worst = worst.max(check_jacobian(&p, &theta(&p), 1e-6, &what));
                }
            }
        }
        eprintln!("worst relative error {worst:e}");
    }

    /// Random non-zero sizes of every effect: the exact Jacobian is the differences'.
    #[test]
    fn sensitivities_at_random_sizes() {
        let mut g = 77u64;
        let mut r = |lo: f64, hi: f64| lo + (hi - lo) * lcg_unit(&mut g);
        for round in 0..4 {
            let sat = [r(-1.2, -0.6), r(0.6, 1.2)];
            let fr = [r(0.01, 0.1), r(0.0, 0.3)];
            let wd = [r(-0.4, 0.4), r(-0.4, 0.4)];
            let co = [r(0.1, 1.0), r(0.1, 2.5), r(0.05, 0.8)];
            let hy = [r(0.0, 0.5), r(-0.5, 0.5), r(0.0, 0.8), r(-0.5, 0.5)];
            let oo = [r(-1.0, 1.0), r(-1.0, 1.0)];
            let df = [r(-0.5, 0.5), r(0.01, 0.5), r(0.0, 0.1)];
            let fh = [r(0.0, 0.5), r(0.0, 0.5), r(-0.3, 0.3), r(-0.1, 0.1)];
            let cr = [r(-0.3, 0.3), r(2.4, 11.5), r(-0.3, 0.3), r(2.4, 11.5)];
            let each: [(&str, &[f64], &[&str]); 9] = [
                ("dynamic_friction", &df, &["k_f", "z_s", "lambda"]),
                (
                    "feedback_hysteresis",
                    &fh,
                    &["alpha", "beta", "gamma", "k_3"],
                ),
                ("creep", &cr, &["g_1", "l_1", "g_2", "l_2"]),
                ("saturation", &sat, &["lo", "hi"]),
                ("friction", &fr, &["F_c", "F_v"]),
                ("width_drift", &wd, &["dc_L", "dc_R"]),
                ("compliance", &co, &["k", "omega", "zeta"]),
                ("hysteresis_memory", &hy, &["r_1", "w_1", "r_2", "w_2"]),
                ("output_offset", &oo, &["o_0", "o_1"]),
            ];
            for (name, params, free) in each {
                for (input_name, u) in inputs(500) {
                    let p = problem(&[(name, params)], free, &u, start(round % 2 == 1));
                    let what = format!("{name} {params:?} on {input_name}");
                    check_jacobian(&p, &theta(&p), 1e-6, &what);
                }
            }
        }
    }

    /// Dynamic friction, feedback hysteresis and creep at zero size (k_f = 0; alpha = k_3 =
    /// 0; g_k = 0) with any other parameters: the nominal model bit for bit, from rest and
    /// held, and their tangent passes' values too.
    #[test]
    fn zero_size_dynamic_friction_feedback_hysteresis_and_creep_are_the_nominal_model() {
        let zero: &[(&str, &[f64])] = &[
            ("dynamic_friction", &[0.0, 0.03, 0.2]),
            ("feedback_hysteresis", &[0.0, 0.7, -0.4, 0.0]),
            ("creep", &[0.0, 2.5, 0.0, 9.0]),
        ];
        for (name, u) in inputs(700) {
            for held in [false, true] {
                let nominal = problem(&[], &[], &u, start(held));
                let want = nominal.simulate(&THETA).unwrap();
                let by_u: (&str, &[f64]) = ("dynamic_friction", &[0.0, 0.03, 0.2, 1.0]);
                let by_f: (&str, &[f64]) = ("dynamic_friction", &[0.0, 0.03, 0.2, 2.0]);
                for e in zero.iter().chain([&by_u, &by_f]) {
                    let p = problem(&[*e], &[], &u, start(held));
                    assert_eq!(p.simulate(&THETA).unwrap(), want, "{e:?} on {name}");
                    assert_eq!(p.sensitivity(&THETA).unwrap().output, want);
                }
                let all = problem(zero, &[], &u, start(held));
                assert_eq!(all.simulate(&THETA).unwrap(), want, "all on {name}");
            }
        }
    }

    /// Parameters outside the domains of the three, and a feedback whose state runs away,
    /// are ModelErrors naming what to give, not panics or non-finite outputs.
    #[test]
    fn dynamic_friction_feedback_hysteresis_and_creep_refuse_bad_parameters() {
        use crate::effects::from_parameters;
        let bad: &[(&str, &[f64])] = &[
            ("dynamic_friction", &[0.1, 0.0, 0.0]),
            ("dynamic_friction", &[0.1, 0.1, -0.1]),
            ("dynamic_friction", &[f64::NAN, 0.1, 0.0]),
            ("dynamic_friction", &[0.1, 0.1]),
            ("dynamic_friction", &[0.1, 0.1, 0.0, 0.5]),
            ("dynamic_friction", &[0.1, 0.1, 0.0, 3.0]),
            ("dynamic_friction", &[0.1, 0.1, 0.0, 1.0, 0.0]),
            ("feedback_hysteresis", &[0.1, 0.1, 0.1]),
            ("feedback_hysteresis", &[0.1, f64::INFINITY, 0.1, 0.0]),
            ("creep", &[0.1, 1.0]),
            ("creep", &[0.1, 12.0]),
            ("creep", &[0.1]),
            ("creep", &[f64::NAN, 3.0]),
        ];
        for (name, p) in bad {
            assert!(
                matches!(from_parameters(name, p), Err(Error::Model(_))),
                "{name} {p:?}"
            );
        }
        // a softening cubic stiffness and a Bouc-Wen loop of negative damping run away
        let u = smooth_input(3000);
        for params in [[0.0, 0.0, 0.0, -20.0], [1.0, 0.0, -5.0, 0.0]] {
            let p = problem(&[("feedback_hysteresis", &params)], &[], &u, start(false));
            let err = p.simulate(&THETA).unwrap_err();
            assert!(
                matches!(&err, Error::Model(m) if m.contains("diverged")),
                "{err:?}"
            );
        }
    }

    /// At alpha = 0 (the edge of its domain) with gamma != 0 the output is homogeneous, not
    /// linear, in alpha: the Jacobian's column is the derivative as alpha grows, a forward
    /// difference (its error O(h)).
    #[test]
    fn feedback_hysteresis_at_zero_size_has_the_one_sided_derivative() {
        for (name, u) in inputs(600) {
            let p = problem(
                &[("feedback_hysteresis", &[0.0, 0.5, 0.3, 0.0])],
                &["alpha"],
                &u,
                start(false),
            );
            let mut th = THETA.to_vec();
            th.push(0.0);
            let sens = p.sensitivity(&th).unwrap();
            let y0 = p.simulate(&th).unwrap();
            let h = 1e-7;
            th[11] = h;
            let yh = p.simulate(&th).unwrap();
            let (mut err, mut norm) = (0.0f64, 0.0f64);
            for (t, (a, b)) in yh.iter().zip(&y0).enumerate() {
                let j = sens.jacobian[t * sens.cols + 11];
                err = err.max((j - (a - b) / h).abs());
                norm = norm.max(j.abs());
            }
            assert!(
                norm > 0.1 && err < 1e-5 * norm,
                "{name}: {err:e} of {norm:e}"
            );
        }
    }

    #[test]
    fn without_effects_the_jacobian_is_the_cascades() {
        let u = smooth_input(800);
        let p = problem(&[], &[], &u, start(false));
        let got = p.sensitivity(&THETA).unwrap();
        let b = structure().unpack(&THETA).unwrap();
        let want = cascade_sensitivity(&b.linear, &b.backlash, &u).unwrap();
        assert_eq!(got.cols, want.cols);
        assert_eq!(got.output, want.output);
        for (a, b) in got.jacobian.iter().zip(&want.jacobian) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} {b}");
        }
    }

    /// Quantised output: flat in every parameter (J = 0); the differences are 0 but where
    /// a level changes within the step.
    #[test]
    fn a_quantiser_flattens_the_jacobian() {
        let u = smooth_input(600);
        let p = problem(
            &[("quantization", &[0.05]), ("output_offset", &[0.01, 0.0])],
            &["o_0"],
            &u,
            start(false),
        );
        let th = theta(&p);
        let sens = p.sensitivity(&th).unwrap();
        assert!(sens.jacobian.iter().all(|v| *v == 0.0));
        let mut plus = th.clone();
        plus[0] += 1e-9;
        let (a, b) = (p.simulate(&th).unwrap(), p.simulate(&plus).unwrap());
        let moved = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(moved < 6, "{moved}");
        // and the step itself is refused as a free parameter
        let e = vec![("quantization".to_string(), vec![0.05])];
        let err = AugmentedProblem::new(
            structure(),
            &e,
            &["q".into()],
            u.clone(),
            u.clone(),
            0,
            start(false),
        );
        assert!(matches!(err, Err(Error::Model(m)) if m.contains("outside the refit")));
    }

    /// R_aug^T R_aug = [J r]^T [J r] of the dense Jacobian, the gradient J^T r, the cost;
    /// one and two folding threads give the same bits.
    #[test]
    fn factor_and_gradient_are_those_of_the_dense_jacobian() {
        let u = noisy(&triangle(3000, 331, 1.4), 2);
        for (effects, free) in [
            (vec![("friction", vec![0.03, 0.1])], vec!["F_c", "F_v"]),
            (vec![("width_drift", vec![0.0, 0.0])], vec!["dc_L", "dc_R"]),
            (
                vec![("compliance", vec![0.3, 0.7, 0.2])],
                vec!["k", "omega", "zeta"],
            ),
            (vec![], vec![]),
        ] {
            let effects: Vec<(String, Vec<f64>)> = effects
                .into_iter()
                .map(|(n, p)| (n.to_string(), p))
                .collect();
            let free: Vec<String> = free.into_iter().map(String::from).collect();
            let clean = {
                let p = AugmentedProblem::new(
                    structure(),
                    &effects,
                    &free,
                    u.clone(),
                    u.clone(),
                    0,
                    start(true),
                )
                .unwrap();
                let mut th = THETA.to_vec();
                th.extend(p.bounds().0[11..].iter().map(|_| 0.0));
                for (m, &(i, k)) in p.free.iter().enumerate() {
                    th[11 + m] = p.effects[i].parameters()[k];
                }
                (p.simulate(&th).unwrap(), th)
            };
            let (y_true, th) = clean;
            let y = noisy(&y_true, 11);
            let warmup = 40;
            let p = AugmentedProblem::new(
                structure(),
                &effects,
                &free,
                u.clone(),
                y.clone(),
                warmup,
                start(true),
            )
            .unwrap();
            let mut est = th.clone();
            for (k, v) in est.iter_mut().enumerate() {
                *v *= 1.0 + 0.02 * ((k % 3) as f64 - 1.0);
            }
            let sens = p.sensitivity(&est).unwrap();
            let cols = sens.cols;
            let aug = |t: usize, j: usize| {
                if j < cols {
                    sens.jacobian[t * cols + j]
                } else {
                    y[t] - sens.output[t]
                }
            };
            let (f, cost) = p.oe_factor(&est).unwrap();
            assert_eq!(p.oe_factor_threads(&est, 2).unwrap(), (f.clone(), cost));
            let n = cols + 1;
            let r = f.r_aug();
            let size = (0..n)
                .map(|k| (warmup..y.len()).map(|t| aug(t, k).powi(2)).sum::<f64>())
                .fold(0.0f64, f64::max);
            for i in 0..n {
                for j in 0..n {
                    let rtr: f64 = (0..n).map(|k| r[k * n + i] * r[k * n + j]).sum();
                    let gram: f64 = (warmup..y.len()).map(|t| aug(t, i) * aug(t, j)).sum();
                    assert!(
                        (rtr - gram).abs() < 1e-11 * size,
                        "{effects:?} {i} {j}: {rtr} {gram}"
                    );
                }
            }
            let want_cost: f64 = (warmup..y.len()).map(|t| aug(t, cols).powi(2)).sum();
            assert!((cost - want_cost).abs() <= 1e-12 * want_cost);
            assert!((p.cost(&est).unwrap() - want_cost).abs() <= 1e-12 * want_cost);
            let g = p.gradient(&est).unwrap();
            assert!((g.cost - want_cost).abs() <= 1e-12 * want_cost);
            for j in 0..cols {
                let want: f64 = (warmup..y.len()).map(|t| aug(t, j) * aug(t, cols)).sum();
                assert!(
                    (g.gradient[j] - want).abs() <= 1e-10 * (1.0 + want.abs()),
                    "{j}"
                );
            }
        }
    }

    #[test]
    fn names_bounds_feasibility_and_refusals() {
        let u = smooth_input(100);
        let p = problem(
            &[
                ("compliance", &[0.2, 0.5, 0.1]),
                ("friction", &[0.0, 0.0]),
                ("dead_time", &[3.0]),
            ],
            &["zeta", "F_c", "k"],
            &u,
            start(false),
        );
        let mut names = structure().names();
        names.extend(["zeta", "F_c", "k"].map(String::from));
        assert_eq!(p.names(), &names[..]);
        let (lo, hi) = p.bounds();
        assert_eq!(&lo[11..], &[0.0, 0.0, 0.0]);
        assert_eq!(&hi[11..], &[1.0, f64::INFINITY, f64::INFINITY]);
        let mut nominal = [f64::NEG_INFINITY; 11];
        (nominal[4], nominal[8]) = (0.0, 0.0); // c_L, c_R as Problem::bounds
        assert_eq!(&lo[..11], &nominal[..]);
        let mut th = THETA.to_vec();
        th.extend([0.1, 0.0, 0.2]);
        assert!(p.feasible(&th).unwrap());
        th[11] = 1.0; // zeta = 1: outside the open interval
        assert!(!p.feasible(&th).unwrap());
        th[11] = 0.1;
        th[2] = -2.5; // an unstable linear block
        assert!(!p.feasible(&th).unwrap());
        assert!(matches!(p.feasible(&THETA), Err(Error::Data(_))));
        // the dead time stays as given: u delayed by 3
        let mut th = THETA.to_vec();
        th.extend([0.1, 0.0, 0.0]);
        let y = p.simulate(&th).unwrap();
        let plain = problem(&[], &[], &u, start(false))
            .simulate(&THETA)
            .unwrap();
        let mut shifted = vec![0.0; 3];
        shifted.extend_from_slice(&u[..97]);
        let delayed = problem(&[], &[], &shifted, start(false))
            .simulate(&THETA)
            .unwrap();
        assert_eq!(y, delayed);
        assert_ne!(y, plain);
        let e = |list: &[(&str, &[f64])]| -> Vec<(String, Vec<f64>)> {
            list.iter()
                .map(|(n, p)| (n.to_string(), p.to_vec()))
                .collect()
        };
        let make = |effects: Vec<(String, Vec<f64>)>, free: &[&str], warmup: usize| {
            let free: Vec<String> = free.iter().map(|s| s.to_string()).collect();
            AugmentedProblem::new(
                structure(),
                &effects,
                &free,
                u.clone(),
                u.clone(),
                warmup,
                start(false),
            )
        };
        assert!(
            matches!(make(e(&[("friction", &[0.0, 0.0])]), &["F_x"], 0), Err(Error::Model(m)) if m.contains("F_c, F_v"))
        );
        assert!(matches!(
            make(e(&[("friction", &[0.0, 0.0])]), &["F_c", "F_c"], 0),
            Err(Error::Model(_))
        ));
        assert!(matches!(
            make(e(&[("dead_time", &[1.0])]), &["d"], 0),
            Err(Error::Model(_))
        ));
        assert!(matches!(
            make(
                e(&[("friction", &[0.0, 0.0]), ("friction", &[0.1, 0.0])]),
                &[],
                0
            ),
            Err(Error::Model(_))
        ));
        assert!(matches!(make(e(&[]), &[], 100), Err(Error::Data(_))));
        assert!(matches!(p.simulate(&THETA), Err(Error::Data(_))));
        // a wild friction feedback diverges: a ModelError, not a panic
        let wild = problem(
            &[("friction", &[0.0, -50.0])],
            &["F_v"],
            &input(2000),
            start(false),
        );
        let mut th = THETA.to_vec();
        th.push(-50.0);
        assert!(matches!(wild.cost(&th), Err(Error::Model(_))));
        assert!(matches!(wild.oe_factor(&th), Err(Error::Model(_))));
        assert!(matches!(wild.gradient(&th), Err(Error::Model(_))));
    }

    /// The chains of the tests: (name, structure, theta off the true values): Example 1's
    /// cascade, Example 2's sandwich and the input backlash (Hammerstein: na = 1, nb = 0)
    /// with Example 2's backlash and output block.
    fn chains() -> Vec<(&'static str, Structure, Vec<f64>)> {
        let ex2 = perturbed(EXAMPLE2_THETA).to_vec();
        let mut hammerstein = vec![1.0];
        hammerstein.extend_from_slice(&ex2[4..]);
        vec![
            ("cascade", structure(), THETA.to_vec()),
            (
                "sandwich",
                Structure::new(2, 2, 3, 2, 2, false, false).unwrap(),
                ex2,
            ),
            (
                "hammerstein",
                Structure::new(1, 0, 3, 2, 2, false, false).unwrap(),
                hammerstein,
            ),
        ]
    }

    /// The nominal chain of a structure's theta.
    fn nominal(s: &Structure, th: &[f64]) -> AugmentedChain {
        let b = s.unpack(th).unwrap();
        AugmentedChain {
            cascade: CascadeModel::new(b.linear, b.backlash),
            output: b.output,
        }
    }

    /// How a test record starts.
    #[derive(Clone, Copy, Debug)]
    enum From {
        Rest,
        Held,
        /// The state the nominal chain left after 250 samples of the input (explicit).
        Busy,
    }

    /// The problem of `effects` with `free` parameters on `u` (y: noise) for a chain; the
    /// held start takes y(0) inside the dead band at x_eq and u(0) = 0 with friction (see
    /// `problem`).
    fn chain_problem(
        s: Structure,
        th: &[f64],
        effects: &[(&str, &[f64])],
        free: &[&str],
        u: &[f64],
        from: From,
    ) -> AugmentedProblem {
        let mut u = u.to_vec();
        let chain = nominal(&s, th);
        let mut start = RecordStart {
            held: false,
            past: None,
            y_prev: 0.0,
            t0: 300.0,
            time_scale: 250.0,
        };
        match from {
            From::Rest => {}
            From::Held => {
                start.held = true;
                if effects.iter().any(|(n, _)| *n == "friction") {
                    u[0] = 0.0;
                }
                let (x_eq, _) = equilibrium(&chain.cascade.linear, u[0]).unwrap();
                let bl = &chain.cascade.backlash;
                start.y_prev = 0.5 * (bl.left().value(x_eq) + bl.right().value(x_eq));
            }
            From::Busy => {
                let pre: Vec<f64> = smooth_input(250).iter().map(|v| 1.3 * v).collect();
                let (past, y_prev) = match &chain.output {
                    None => {
                        let m = &chain.cascade;
                        let st = m.simulate_internals(&pre, &m.rest_state()).unwrap();
                        let st = st.final_state;
                        let past = Past {
                            u_past: st.linear.u_past,
                            x_past: st.linear.x_past,
                            ..Past::default()
                        };
                        (past, st.y_prev)
                    }
                    Some(out) => {
                        let m = SandwichModel::new(
                            chain.cascade.linear.clone(),
                            chain.cascade.backlash.clone(),
                            out.clone(),
                        );
                        let st = m.simulate_internals(&pre, &m.rest_state()).unwrap();
                        let st = st.final_state;
                        let y_prev = st.output.u_past[0];
                        let past = Past {
                            u_past: st.input.u_past,
                            x_past: st.input.x_past,
                            y_past: st.output.u_past,
                            w_past: st.output.x_past,
                        };
                        (past, y_prev)
                    }
                };
                start.past = Some(past);
                start.y_prev = y_prev;
            }
        }
        let effects: Vec<(String, Vec<f64>)> = effects
            .iter()
            .map(|(n, p)| (n.to_string(), p.to_vec()))
            .collect();
        let free: Vec<String> = free.iter().map(|n| n.to_string()).collect();
        let y = noisy(&vec![0.0; u.len()], 4);
        AugmentedProblem::new(s, &effects, &free, u, y, 5, start).unwrap()
    }

    /// theta of a chain's problem: the chain's, then the free parameters' given values.
    fn chain_theta(p: &AugmentedProblem, th: &[f64]) -> Vec<f64> {
        let mut th = th.to_vec();
        for &(i, k) in &p.free {
            th.push(p.effects[i].parameters()[k]);
        }
        th
    }

    /// Every effect (existing and new) alone, and a mix of all stages, on the cascade, the
    /// sandwich and the input backlash, on every input, from rest, held and from a busy
    /// explicit start: the exact Jacobian is the central differences'.
    #[test]
    fn chain_sensitivities_are_central_differences_for_every_effect_and_start() {
        type Case<'a> = (&'a str, Vec<f64>, &'a [&'a str]);
        let mut worst: f64 = 0.0;
        for (chain_name, s, th) in chains() {
            for (input_name, u) in inputs(500) {
                // the sensor's clip at 70 % of the nominal output's range
                let y0 = chain_problem(s, &th, &[], &[], &u, From::Rest)
                    .simulate(&th)
                    .unwrap();
                let (lo, hi) = y0
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
                let cases: Vec<Case> = vec![
                    ("saturation", vec![-0.9, 1.0], &["lo", "hi"]),
                    ("state_saturation", vec![-0.7, 0.8], &["lo", "hi"]),
                    ("friction", vec![0.05, 0.1], &["F_c", "F_v"]),
                    (
                        "stick_slip",
                        vec![0.03, 0.1, 0.02, 0.1],
                        &["F_c", "F_v", "F_s", "v_s"],
                    ),
                    ("width_drift", vec![0.3, -0.2], &["dc_L", "dc_R"]),
                    ("compliance", vec![0.4, 0.6, 0.15], &["k", "omega", "zeta"]),
                    (
                        "hysteresis_memory",
                        vec![0.2, 0.3, 0.5, -0.2],
                        &["r_1", "w_1", "r_2", "w_2"],
                    ),
                    ("output_offset", vec![0.1, 0.3], &["o_0", "o_1"]),
                    ("sensor_saturation", vec![0.7 * lo, 0.7 * hi], &["lo", "hi"]),
                    ("dead_time", vec![2.0], &[]),
                    ("quantization", vec![0.0], &[]),
                    // the three motions a dynamic friction may follow: x, u and f
                    (
                        "dynamic_friction",
                        vec![0.2, 0.05, 0.01, 0.0],
                        &["k_f", "z_s", "lambda"],
                    ),
                    (
                        "dynamic_friction",
                        vec![-0.15, 0.08, 0.02, 1.0],
                        &["k_f", "z_s", "lambda"],
                    ),
                    (
                        "dynamic_friction",
                        vec![0.25, 0.04, 0.01, 2.0],
                        &["k_f", "z_s", "lambda"],
                    ),
                ];
                for (name, params, free) in &cases {
                    for from in [From::Rest, From::Held, From::Busy] {
                        let p = chain_problem(s, &th, &[(name, params)], free, &u, from);
                        let what =
                            format!("{chain_name}: {name} {params:?} on {input_name}, {from:?}");
                        let th = chain_theta(&p, &th);
                        worst = worst.max(check_jacobian(&p, &th, 1e-6, &what));
                    }
                }
                let mix: &[(&str, &[f64])] = &[
                    ("state_saturation", &[-0.75, 0.85]),
                    ("dead_time", &[1.0]),
                    ("friction", &[0.04, 0.15]),
                    ("width_drift", &[0.2, 0.1]),
                    ("compliance", &[0.3, 0.9, 0.2]),
                    ("hysteresis_memory", &[0.25, 0.2]),
                    ("output_offset", &[-0.1, 0.2]),
                    ("sensor_saturation", &[0.8 * lo, 0.8 * hi]),
                ];
                let free = [
                    "lo", "F_c", "F_v", "dc_L", "dc_R", "k", "omega", "zeta", "r_1", "w_1", "o_0",
                    "o_1",
                ];
                for from in [From::Rest, From::Held, From::Busy] {
                    let p = chain_problem(s, &th, mix, &free, &u, from);
                    let what = format!("{chain_name}: all stages on {input_name}, {from:?}");
                    let th = chain_theta(&p, &th);
                    worst = worst.max(check_jacobian(&p, &th, 1e-6, &what));
                }
            }
        }
        eprintln!("worst relative error {worst:e}");
    }

    /// Without effects the sandwich's (and the input backlash's) Jacobian is the sandwich
    /// refinement's (`identify::sensitivity`), and its output `SandwichModel`'s.
    #[test]
    fn without_effects_the_jacobian_is_the_sandwichs() {
        let u = smooth_input(800);
        for (name, s, th) in chains().into_iter().skip(1) {
            let p = chain_problem(s, &th, &[], &[], &u, From::Rest);
            let got = p.sensitivity(&th).unwrap();
            let b = s.unpack(&th).unwrap();
            let out = b.output.unwrap();
            let want = sandwich_sensitivity(&b.linear, &b.backlash, &out, &u).unwrap();
            assert_eq!(got.cols, want.cols, "{name}");
            assert_eq!(got.output, want.output, "{name}");
            let m = SandwichModel::new(b.linear, b.backlash, out);
            assert_eq!(got.output, m.simulate(&u, &m.rest_state()).unwrap());
            let scale = want.jacobian.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            let mut worst: f64 = 0.0;
            for (k, (a, b)) in got.jacobian.iter().zip(&want.jacobian).enumerate() {
                worst = worst.max((a - b).abs() / scale);
                assert!(
                    (a - b).abs() <= 1e-10 * scale,
                    "{name} row {} col {}: {a} {b}",
                    k / got.cols,
                    k % got.cols
                );
            }
            eprintln!("{name}: max |J - J_sandwich| / max |J| = {worst:e}");
            // the cost of the factor and of the gradient pass agree
            let (_, cost) = p.oe_factor(&th).unwrap();
            let g = p.gradient(&th).unwrap();
            assert!((g.cost - cost).abs() <= 1e-12 * cost);
        }
    }

    /// An explicit start's pasts are checked on construction: lengths of the structure's
    /// orders, finite, y_past[0] the memory, not with held; feedthroughs are refused.
    #[test]
    fn explicit_starts_and_sandwich_structures_are_checked() {
        let u = smooth_input(50);
        let sandwich = Structure::new(2, 2, 3, 2, 2, false, false).unwrap();
        let make = |s: Structure, past: Past, y_prev: f64, held: bool| {
            let start = RecordStart {
                held,
                past: Some(past),
                y_prev,
                t0: 0.0,
                time_scale: 1000.0,
            };
            AugmentedProblem::new(s, &[], &[], u.clone(), u.clone(), 0, start)
        };
        let good = Past {
            u_past: vec![0.1, 0.2],
            x_past: vec![0.3, 0.4],
            y_past: vec![0.5, 0.6],
            w_past: vec![0.7, 0.8],
        };
        assert!(make(sandwich, good.clone(), 0.5, false).is_ok());
        let data = |r: Result<AugmentedProblem>, word: &str| {
            assert!(
                matches!(&r, Err(Error::Data(m)) if m.contains(word)),
                "{word}: {r:?}"
            )
        };
        data(make(sandwich, good.clone(), 0.4, false), "y_past[0]");
        data(make(sandwich, good.clone(), 0.5, true), "held");
        let names = ["u_past", "x_past", "y_past", "w_past"];
        for (field, name) in names.iter().enumerate() {
            fn pick(p: &mut Past, field: usize) -> &mut Vec<f64> {
                match field {
                    0 => &mut p.u_past,
                    1 => &mut p.x_past,
                    2 => &mut p.y_past,
                    _ => &mut p.w_past,
                }
            }
            let mut bad = good.clone();
            pick(&mut bad, field).push(0.0);
            data(make(sandwich, bad, 0.5, false), name);
            let mut bad = good.clone();
            pick(&mut bad, field)[1] = f64::INFINITY;
            data(make(sandwich, bad, 0.5, false), name);
        }
        // a cascade has no output block's past
        let cascade_past = Past {
            y_past: vec![0.5],
            w_past: vec![],
            ..good.clone()
        };
        data(make(structure(), cascade_past, 0.5, false), "y_past");
        // feedthroughs and an initial state in theta are refused
        for s in [
            Structure::new(2, 2, 3, 2, 2, true, false).unwrap(),
            Structure::new(2, 2, 3, 2, 2, false, true).unwrap(),
            sandwich.with_initial_state(true),
        ] {
            let r = AugmentedProblem::new(s, &[], &[], u.clone(), u.clone(), 0, start(false));
            assert!(matches!(r, Err(Error::Data(_))), "{s:?}");
        }
        // the explicit start is used as given: the plain sandwich from that state
        let p = make(sandwich, good.clone(), 0.5, false).unwrap();
        let th = perturbed(EXAMPLE2_THETA);
        let (lin, bl, out) = crate::test_params::sandwich_from(&th);
        let m = SandwichModel::new(lin, bl, out);
        let state = SandwichState {
            input: LinearState {
                u_past: good.u_past.clone(),
                x_past: good.x_past.clone(),
            },
            output: LinearState {
                u_past: good.y_past.clone(),
                x_past: good.w_past.clone(),
            },
        };
        assert_eq!(p.simulate(&th).unwrap(), m.simulate(&u, &state).unwrap());
        // an unstable output block is infeasible
        let mut wild = th;
        wild[13] = 1.5;
        assert!(!p.feasible(&wild).unwrap());
        assert!(p.feasible(&th).unwrap());
    }
}
