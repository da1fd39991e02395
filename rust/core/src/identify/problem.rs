//! An identification problem compiled once: the structure (orders, degree, feedthroughs) and
//! the record (u, y, warm-up), checked on construction. It owns the layout of the physical
//! parameter vector theta and its names in the paper's order (eq 19 / eq 31):
//!   a_1..a_na (a_0..a_na with an input feedthrough), b_1..b_nb, c_L, m_L2..m_Ln, m_R1, c_R,
//!   m_R2..m_Rn, then for the sandwich r_2..r_nr (r_1..r_nr with an output feedthrough),
//!   s_1..s_ns; m_L1 = 1 and the first output coefficient = 1 are fixed.
//! A block with a feedthrough is the same block one sample later: the core sees coefficients
//! at lags 1.. and the caller hands in the measured output delayed accordingly.
//!
//! With `initial_state` (`Structure::with_initial_state`), theta ends with the initial state
//! of a record that does not start at rest: x0_1..x0_n (the input block's, n = max(na, nb)
//! of the core's block), y_prev (the backlash memory y(0)) and for the sandwich w0_1..w0_m
//! (the output block's); `identify::initial` documents the parametrisation.
//!
//! Several records of one system (`Problem::several`) share the model's parameters, each
//! record with its own initial-state block (`Problem` documents the layout and the sums).
//!
//! Every method unpacks theta once into the blocks and calls the existing numerics
//! (`CascadeRegression`, `SandwichRegression`, the output-error factors and gradients); the
//! record is not checked again.

use crate::error::{Error, Result};
use crate::guard;
use crate::identify::gradient::{
    cascade_oe_gradient_from, cascade_oe_gradient_motion_from, sandwich_oe_gradient_from,
};
use crate::identify::gradient::{Motion, OeGradient};
use crate::identify::initial::{self, InitialState, Start};
use crate::identify::regressor::solve_factor;
use crate::identify::samples::Samples;
use crate::identify::sensitivity::{
    cascade_oe_factor_motion_from, oe_threads, sandwich_oe_factor_from, XChunks,
};
use crate::identify::{finite_cost, output_error_cost};
use crate::identify::{CascadeRegression, SandwichRegression};
use crate::linalg::{LeastSquares, TriangularFactor};
use crate::model::backlash::{GeneralBacklash, Step};
use crate::model::cascade::CascadeModel;
use crate::model::linear::{blame_feeding_block, LinearBlock, MAX_ORDER};
use crate::model::sandwich::SandwichModel;
use crate::model::signal::{check_same_length, check_signal};
use crate::model::sink::ErrorSum;

/// The structure of an identification: the (input) linear block's orders, the branches'
/// degree, the sandwich's output block's orders (nr = 0 for a cascade) and the feedthroughs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Structure {
    pub na: usize,
    pub nb: usize,
    pub degree: usize,
    pub nr: usize,
    pub ns: usize,
    pub feedthrough: bool,
    pub output_feedthrough: bool,
    /// theta ends with the initial state (`identify::initial`); false: from rest.
    pub initial_state: bool,
}

/// The positions in theta of the input block's and the backlash's parameters (the
/// sensitivities' columns too): a (na of them, a_0.. with feedthrough), b, c_L, m_L2..m_Ln,
/// m_R1, c_R, m_R2..m_Rn; the sandwich's r and s follow.
pub(crate) struct Layout {
    pub(crate) na: usize,
    pub(crate) nb: usize,
    pub(crate) n: usize,
}

impl Layout {
    pub(crate) fn linear(&self) -> usize {
        self.na + self.nb
    }
    pub(crate) fn c_l(&self) -> usize {
        self.linear()
    }
    pub(crate) fn m_l(&self, i: usize) -> usize {
        self.c_l() + i - 1 // i = 2..n
    }
    pub(crate) fn m_r1(&self) -> usize {
        self.linear() + self.n
    }
    pub(crate) fn c_r(&self) -> usize {
        self.m_r1() + 1
    }
    pub(crate) fn m_r(&self, i: usize) -> usize {
        self.c_r() + i - 1 // i = 2..n
    }
    /// The first output-block coefficient, after m_Rn.
    pub(crate) fn r(&self) -> usize {
        self.m_r(self.n) + 1
    }
}

/// The blocks of a parameter vector: input block, backlash (as an estimate: no branch-shape
/// checks), and the sandwich's output block.
pub struct Blocks {
    pub linear: LinearBlock,
    pub backlash: GeneralBacklash,
    pub output: Option<LinearBlock>,
    /// The initial state's values (None: from rest).
    pub initial: Option<InitialState>,
}

fn whole(name: &str, value: usize, least: usize) -> Result<()> {
    if value < least {
        return Err(Error::Data(format!(
            "{name} = {value}: give a whole number >= {least}"
        )));
    }
    Ok(())
}

impl Structure {
    /// A cascade (nr = ns = 0) or sandwich structure; orders and degree checked.
    pub fn new(
        na: usize,
        nb: usize,
        degree: usize,
        nr: usize,
        ns: usize,
        feedthrough: bool,
        output_feedthrough: bool,
    ) -> Result<Self> {
        whole("na", na, 1)?;
        whole("degree", degree, 1)?;
        // before anything proportional to them (the names, the layout) is built
        for (name, value) in [
            ("na", na),
            ("nb", nb),
            ("degree", degree),
            ("nr", nr),
            ("ns", ns),
        ] {
            if value > MAX_ORDER {
                return Err(Error::Model(format!(
                    "{name} = {value}: orders and the degree are at most {MAX_ORDER} (a linear \
                     block's poles are the eigenvalues of its companion matrix, O(order^3), and \
                     no record identifies that many parameters)"
                )));
            }
        }
        if output_feedthrough && nr == 0 {
            return Err(Error::Data(
                "output_feedthrough is for the sandwich's output block: a cascade has none".into(),
            ));
        }
        Ok(Self {
            na,
            nb,
            degree,
            nr,
            ns,
            feedthrough,
            output_feedthrough,
            initial_state: false,
        })
    }

    /// The same structure with (true) or without the initial state at the end of theta.
    pub fn with_initial_state(self, initial_state: bool) -> Self {
        Self {
            initial_state,
            ..self
        }
    }

    /// True for a sandwich (nr > 0).
    pub fn is_sandwich(&self) -> bool {
        self.nr > 0
    }

    /// Input coefficients as the core sees them (a_0..a_na with feedthrough).
    pub fn n_a(&self) -> usize {
        self.na + usize::from(self.feedthrough)
    }

    /// Output-block coefficients as the core sees them, the fixed first one included.
    pub fn n_r(&self) -> usize {
        if self.is_sandwich() {
            self.nr + usize::from(self.output_feedthrough)
        } else {
            0
        }
    }

    /// The positions of the input block's and the backlash's parameters in theta.
    pub(crate) fn layout(&self) -> Layout {
        Layout {
            na: self.n_a(),
            nb: self.nb,
            n: self.degree,
        }
    }

    /// The number of parameters p.
    pub fn size(&self) -> usize {
        self.model_size() + self.initial_size()
    }

    /// The number of the model's parameters (theta without the initial state).
    pub fn model_size(&self) -> usize {
        self.layout().r()
            + if self.is_sandwich() {
                self.n_r() - 1 + self.ns
            } else {
                0
            }
    }

    /// The number of initial-state values x0 of the input block (0 from rest).
    pub fn n_x0(&self) -> usize {
        match self.initial_state {
            true => initial::order(self.n_a(), self.nb),
            false => 0,
        }
    }

    /// The number of initial-state values w0 of the sandwich's output block (0 from rest).
    pub fn n_w0(&self) -> usize {
        match self.initial_state && self.is_sandwich() {
            true => initial::order(self.n_r(), self.ns),
            false => 0,
        }
    }

    /// The number of initial-state values: x0, y_prev, w0 (0 from rest).
    pub fn initial_size(&self) -> usize {
        match self.initial_state {
            true => self.n_x0() + 1 + self.n_w0(),
            false => 0,
        }
    }

    /// The parameter names in the order of theta: the model's, then the initial state's
    /// (x0_1..x0_n, y_prev, w0_1..w0_m).
    pub fn names(&self) -> Vec<String> {
        let mut names = self.model_names();
        if self.initial_state {
            names.extend((1..=self.n_x0()).map(|k| format!("x0_{k}")));
            names.push("y_prev".into());
            names.extend((1..=self.n_w0()).map(|k| format!("w0_{k}")));
        }
        names
    }

    /// Where each block of parameters sits in theta, in theta's order: a, b, c_L, m_L (m_L2..),
    /// m_R1, c_R, m_R (m_R2..), r (the free ones), s, x0, y_prev, w0; a block the structure
    /// lacks is empty. The one layout `names` spells out.
    pub fn blocks(&self) -> Vec<(&'static str, std::ops::Range<usize>)> {
        let n = self.degree;
        let r_free = self.n_r().saturating_sub(1);
        let s = if self.is_sandwich() { self.ns } else { 0 };
        let y_prev = usize::from(self.initial_state);
        let sizes = [
            ("a", self.n_a()),
            ("b", self.nb),
            ("c_L", 1),
            ("m_L", n - 1),
            ("m_R1", 1),
            ("c_R", 1),
            ("m_R", n - 1),
            ("r", r_free),
            ("s", s),
            ("x0", self.n_x0()),
            ("y_prev", y_prev),
            ("w0", self.n_w0()),
        ];
        let mut at = 0;
        sizes
            .into_iter()
            .map(|(name, len)| {
                at += len;
                (name, at - len..at)
            })
            .collect()
    }

    /// The names of the model's parameters (no initial state).
    pub(crate) fn model_names(&self) -> Vec<String> {
        let first = usize::from(!self.feedthrough);
        let n = self.degree;
        let mut names: Vec<String> = (first..=self.na).map(|i| format!("a{i}")).collect();
        names.extend((1..=self.nb).map(|j| format!("b{j}")));
        names.push("c_L".into());
        names.extend((2..=n).map(|i| format!("m_L{i}")));
        names.push("m_R1".into());
        names.push("c_R".into());
        names.extend((2..=n).map(|i| format!("m_R{i}")));
        if self.is_sandwich() {
            let first = if self.output_feedthrough { 1 } else { 2 };
            names.extend((first..=self.nr).map(|i| format!("r{i}")));
            names.extend((1..=self.ns).map(|j| format!("s{j}")));
        }
        names
    }

    /// The names of the least-squares vector of eq (19) / (31): c_1 = c_L, c_2 = m_R1 c_R (the
    /// paper's iteration has no initial state).
    pub fn ls_names(&self) -> Vec<String> {
        self.model_names()
            .into_iter()
            .map(|k| match k.as_str() {
                "c_L" => "c_1".into(),
                "c_R" => "c_2".into(),
                _ => k,
            })
            .collect()
    }

    /// The blocks of a physical vector, with m_L1 = 1 (and r_1 = 1) put back.
    pub fn unpack(&self, theta: &[f64]) -> Result<Blocks> {
        if theta.len() != self.size() {
            return Err(Error::Data(format!(
                "theta has {} parameters but the structure has {}: give one value per name",
                theta.len(),
                self.size()
            )));
        }
        let n = self.degree;
        let lay = self.layout();
        let (c_l, m_r1, c_r, r) = (lay.c_l(), lay.m_r1(), lay.c_r(), lay.r());
        let linear = LinearBlock::new(
            theta[..self.n_a()].to_vec(),
            theta[self.n_a()..c_l].to_vec(),
        )?;
        let m_left: Vec<f64> = std::iter::once(1.0)
            .chain(theta[c_l + 1..c_l + n].iter().copied())
            .collect();
        let m_right: Vec<f64> = std::iter::once(theta[m_r1])
            .chain(theta[c_r + 1..r].iter().copied())
            .collect();
        let backlash = GeneralBacklash::from_estimate(theta[c_l], theta[c_r], m_left, m_right)?;
        let p0 = self.model_size();
        let output = if self.is_sandwich() {
            let s0 = r + self.n_r() - 1;
            let rs: Vec<f64> = std::iter::once(1.0)
                .chain(theta[r..s0].iter().copied())
                .collect();
            Some(LinearBlock::new(rs, theta[s0..p0].to_vec())?)
        } else {
            None
        };
        let initial = self.initial_state.then(|| {
            let y_at = p0 + self.n_x0();
            InitialState {
                x0: theta[p0..y_at].to_vec(),
                y_prev: theta[y_at],
                w0: theta[y_at + 1..].to_vec(),
            }
        });
        if let Some(k) = (p0..theta.len()).find(|&k| !theta[k].is_finite()) {
            return Err(Error::Model(format!(
                "the initial state's {} is {}: give finite values",
                self.names()[k],
                theta[k]
            )));
        }
        Ok(Blocks {
            linear,
            backlash,
            output,
            initial,
        })
    }
}

/// One iteration of the paper's algorithm at an estimate: the least-squares solution, the
/// fraction of samples that move the backlash, and (cascade) the estimate's own free-run
/// simulation RMSE.
pub struct Iteration {
    pub ls: LeastSquares,
    pub moving_fraction: f64,
    pub rmse: Option<f64>,
}

/// One record of an identification: input, measured output and its warm-up.
#[derive(Debug, Clone)]
pub struct Record {
    pub u: Samples,
    pub y: Samples,
    pub warmup: usize,
}

impl Record {
    /// Checks u and y (non-empty, finite, one length) and 0 <= warmup < len(u); `at` names
    /// the record in the messages of several (None: the one record, the plain messages).
    fn new(u: Samples, y: Samples, warmup: usize, at: Option<usize>) -> Result<Self> {
        let (u_name, y_name) = match at {
            Some(i) => (format!("u[{i}]"), format!("y[{i}]")),
            None => ("u".into(), "y".into()),
        };
        check_signal(&u_name, &u)?;
        check_signal(&y_name, &y)?;
        match at {
            Some(i) if u.len() != y.len() => {
                return Err(Error::Data(format!(
                    "record {i}: {u_name} has {} samples but {y_name} has {}: give input and \
                     output of the same record",
                    u.len(),
                    y.len()
                )))
            }
            Some(_) => {}
            None => check_same_length(&u, &y, &y_name)?,
        }
        if warmup >= u.len() {
            let of = at.map_or(String::new(), |i| format!(" of record {i}"));
            return Err(Error::Data(format!(
                "warmup = {warmup}: give a whole number of samples, 0 <= warmup < {} (the record \
                 length{of})",
                u.len()
            )));
        }
        Ok(Self { u, y, warmup })
    }
}

/// The structure and the record(s) of an identification, checked once.
///
/// Several records (`Problem::several`) share the model's parameters: theta is the model's
/// parameters followed, with an initial state, by one initial-state block per record (names
/// suffixed `@i`, record i counted from 1: x0_1@1, y_prev@1, x0_1@2, ...). Every criterion
/// sums over the records: the cost, the gradient, the output-error factor (each record's
/// rows folded into the one factor of the joint problem) and the paper's iteration (each
/// record's regression rows, its lags and backlash memory restarting at its own start).
/// `simulate` returns the records' outputs concatenated. One record is the plain problem,
/// bit for bit.
#[derive(Debug, Clone)]
pub struct Problem {
    structure: Structure,
    records: Vec<Record>,
    /// The `Motion` of the last gradient pass that had it, with its theta (`motion`).
    motion: MotionCache,
}

/// The last (theta, `Motion`) a gradient pass found: the fit asks for the motion at its end,
/// where its last gradient pass usually ran, and is spared a simulation of the record.
#[derive(Debug, Default)]
struct MotionCache(std::sync::Mutex<Option<(Vec<f64>, Motion)>>);

impl MotionCache {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<(Vec<f64>, Motion)>> {
        // a poisoned cache (a panic while it was held) is only a cache
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The motion found at exactly this theta (bit for bit), if any.
    fn at(&self, theta: &[f64]) -> Option<Motion> {
        match &*self.lock() {
            Some((t, m))
                if t.len() == theta.len()
                    && t.iter().zip(theta).all(|(a, b)| a.to_bits() == b.to_bits()) =>
            {
                Some(*m)
            }
            _ => None,
        }
    }
}

impl Clone for MotionCache {
    fn clone(&self) -> Self {
        Self(std::sync::Mutex::new(self.lock().clone()))
    }
}

/// Records longer than this take their gradient from the output-error factor: the cascade's
/// reverse pass keeps x, y and the case of every sample (17 bytes each: 71 MB here, 1.7 GB at
/// 1e8 samples), the factor's forward pass a few rows.
pub const BUFFERED_GRADIENT_SAMPLES: usize = 1 << 22;

/// Adds to `motion` the samples t >= warmup of the backlash driven by x (the record's samples
/// `from..from + x.len()`) from memory `y_prev`, which it leaves at the last output; an
/// overflowing output is the simulation's ModelError.
fn motion_along(
    step: impl Step,
    x: &[f64],
    from: usize,
    y_prev: &mut f64,
    warmup: usize,
    motion: &mut Motion,
) -> Result<()> {
    for (k, &xt) in x.iter().enumerate() {
        let (v, case) = step.step_case(xt, *y_prev);
        if !v.is_finite() {
            return Err(crate::model::backlash::output_overflow(from + k, xt));
        }
        if from + k >= warmup {
            motion.add(&[xt], &[case]);
        }
        *y_prev = v;
    }
    Ok(())
}

impl Problem {
    /// Checks u and y (non-empty, finite, one length) and 0 <= warmup < len(u).
    pub fn new(
        structure: Structure,
        u: impl Into<Samples>,
        y: impl Into<Samples>,
        warmup: usize,
    ) -> Result<Self> {
        Ok(Self {
            structure,
            records: vec![Record::new(u.into(), y.into(), warmup, None)?],
            motion: MotionCache::default(),
        })
    }

    /// Several records (u_i, y_i, warmup_i) of one system, each checked as `new` checks
    /// one (messages name the record, counted from 0); at least one.
    pub fn several<U: Into<Samples>, Y: Into<Samples>>(
        structure: Structure,
        records: Vec<(U, Y, usize)>,
    ) -> Result<Self> {
        if records.is_empty() {
            return Err(Error::Data(
                "no records: give at least one (u, y) pair".into(),
            ));
        }
        let records = records
            .into_iter()
            .enumerate()
            .map(|(i, (u, y, w))| Record::new(u.into(), y.into(), w, Some(i)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            structure,
            records,
            motion: MotionCache::default(),
        })
    }

    pub fn structure(&self) -> &Structure {
        &self.structure
    }

    /// The records (one for `new`).
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// The first record's input (the record of a one-record problem).
    pub fn u(&self) -> &[f64] {
        &self.records[0].u
    }

    /// The first record's output.
    pub fn y(&self) -> &[f64] {
        &self.records[0].y
    }

    /// The first record's warm-up.
    pub fn warmup(&self) -> usize {
        self.records[0].warmup
    }

    /// The samples of all records.
    pub fn samples(&self) -> usize {
        self.records.iter().map(|r| r.u.len()).sum()
    }

    /// The warm-up samples of all records (samples() - total_warmup() residuals).
    pub fn total_warmup(&self) -> usize {
        self.records.iter().map(|r| r.warmup).sum()
    }

    /// The number of parameters: the model's and one initial-state block per record.
    pub fn size(&self) -> usize {
        self.structure.model_size() + self.records.len() * self.structure.initial_size()
    }

    /// The parameter names in the order of theta (several records with an initial state:
    /// its names suffixed `@i` per record i = 1..).
    pub fn names(&self) -> Vec<String> {
        if self.records.len() == 1 {
            return self.structure.names();
        }
        let mut names = self.structure.model_names();
        let state = &self.structure.names()[names.len()..];
        for i in 1..=self.records.len() {
            names.extend(state.iter().map(|k| format!("{k}@{i}")));
        }
        names
    }

    fn check_len(&self, theta: &[f64]) -> Result<()> {
        if theta.len() != self.size() {
            return Err(Error::Data(format!(
                "theta has {} parameters but the problem has {}: give one value per name",
                theta.len(),
                self.size()
            )));
        }
        Ok(())
    }

    /// Record i's own parameter vector (the model's, then its initial state) and the
    /// positions of its columns in theta.
    fn own(&self, theta: &[f64], i: usize) -> (Vec<f64>, Vec<usize>) {
        let (p0, k) = (self.structure.model_size(), self.structure.initial_size());
        let at = p0 + i * k;
        let cols: Vec<usize> = (0..p0).chain(at..at + k).collect();
        (cols.iter().map(|&c| theta[c]).collect(), cols)
    }

    /// The blocks of every record (one record: theta itself).
    fn unpack_all(&self, theta: &[f64]) -> Result<Vec<(Blocks, Vec<usize>)>> {
        if self.records.len() == 1 {
            let cols = (0..theta.len()).collect();
            return Ok(vec![(self.structure.unpack(theta)?, cols)]);
        }
        self.check_len(theta)?;
        (0..self.records.len())
            .map(|i| {
                let (own, cols) = self.own(theta, i);
                Ok((self.structure.unpack(&own)?, cols))
            })
            .collect()
    }

    /// Free-run output of the estimate theta, from rest or from theta's initial state(s);
    /// several records' outputs concatenated in order.
    pub fn simulate(&self, theta: &[f64]) -> Result<Vec<f64>> {
        let mut out = guard::buffer(self.samples(), "the simulated output")?;
        for ((blocks, _), rec) in self.unpack_all(theta)?.into_iter().zip(&self.records) {
            out.extend(Self::simulate_blocks(blocks, &rec.u)?);
        }
        Ok(out)
    }

    fn simulate_blocks(blocks: Blocks, u: &[f64]) -> Result<Vec<f64>> {
        if let Some(init) = &blocks.initial {
            let x = initial::simulate_from(&blocks.linear, u, &init.x0)?;
            let y = (blocks.backlash.simulate(&x, init.y_prev))
                .map_err(|e| blame_feeding_block(e, &blocks.linear, "input"))?;
            return match &blocks.output {
                None => Ok(y),
                Some(out) => initial::simulate_named(out, &y, &init.w0, "w"),
            };
        }
        match blocks.output {
            None => {
                let m = CascadeModel::new(blocks.linear, blocks.backlash);
                m.simulate(u, &m.rest_state())
            }
            Some(out) => {
                let m = SandwichModel::new(blocks.linear, blocks.backlash, out);
                m.simulate(u, &m.rest_state())
            }
        }
    }

    /// The output-error cost at theta: sum (y - y_sim)^2 over t >= warmup (summed over the
    /// records), one simulation; a ModelError where the simulation diverges (a non-finite
    /// cost).
    pub fn cost(&self, theta: &[f64]) -> Result<f64> {
        let mut cost = 0.0;
        for ((blocks, _), rec) in self.unpack_all(theta)?.into_iter().zip(&self.records) {
            cost += Self::record_cost(blocks, rec)?;
        }
        Ok(cost)
    }

    /// One record's output-error cost: from rest folded as the simulation runs (no
    /// N-sample buffer), from an initial state on the simulated output.
    fn record_cost(blocks: Blocks, rec: &Record) -> Result<f64> {
        if blocks.initial.is_some() {
            let sim = Self::simulate_blocks(blocks, &rec.u)?;
            return output_error_cost(&rec.y, &sim, rec.warmup);
        }
        let mut sum = ErrorSum::new(&rec.y, rec.warmup);
        match blocks.output {
            None => {
                let m = CascadeModel::new(blocks.linear, blocks.backlash);
                m.simulate_into(&rec.u, &m.rest_state(), &mut sum)?;
            }
            Some(out) => {
                let m = SandwichModel::new(blocks.linear, blocks.backlash, out);
                m.simulate_into(&rec.u, &m.rest_state(), &mut sum)?;
            }
        }
        finite_cost(sum.sum)
    }

    /// The stability guard of the output-error search: every linear block of theta has its
    /// poles strictly inside the unit circle (eq 16, and eq 29 for the sandwich).
    pub fn feasible(&self, theta: &[f64]) -> Result<bool> {
        let blocks = self.unpack_all(theta)?;
        let b = &blocks[0].0;
        Ok(b.linear.is_stable() && b.output.as_ref().map_or(true, LinearBlock::is_stable))
    }

    /// The box of theta: the dead-band widths c_L and c_R at least 0 (eq 4-5: L meets zero at
    /// x = -c_L, R at x = c_R, so the band [-c_L, c_R] holds), every other parameter free.
    pub fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let p = self.size();
        let lay = self.structure.layout();
        let mut lower = vec![f64::NEG_INFINITY; p];
        lower[lay.c_l()] = 0.0;
        lower[lay.c_r()] = 0.0;
        (lower, vec![f64::INFINITY; p])
    }

    /// One iteration of the paper's algorithm at theta (cascade eq 18-28, sandwich eq 33-36),
    /// streamed into a triangular factor. The cascade's switching signal is the measured y,
    /// or with `simulated_switching` the estimate's own simulated output. It is a from-rest
    /// method: theta's initial state, if the structure has one, is ignored (the least-squares
    /// vector has the model's names), and theta may be given without it. Several records:
    /// their rows in one least-squares problem (each record's regression from its own
    /// start), the moving fraction and the RMSE over all their samples after the warm-ups.
    pub fn iteration(&self, theta: &[f64], simulated_switching: bool) -> Result<Iteration> {
        let names = self.structure.ls_names();
        let model = &theta[..self.structure.model_size().min(theta.len())];
        let from_rest = theta.len() == self.structure.model_size();
        if self.records.len() > 1 && !from_rest {
            self.check_len(theta)?;
        }
        let blocks = match from_rest || self.records.len() > 1 {
            true => self.structure.with_initial_state(false).unpack(model)?,
            false => self.structure.unpack(theta)?,
        };
        if let [rec] = &self.records[..] {
            let (factor, moving, rmse) = Self::record_iteration(&blocks, rec, simulated_switching)?;
            return Ok(Iteration {
                ls: solve_factor(&factor, &names, moving)?,
                moving_fraction: moving,
                rmse,
            });
        }
        let mut joint = TriangularFactor::new(names.len());
        let (mut moved, mut squares, mut count, mut cascade) = (0.0, 0.0, 0.0, false);
        for rec in &self.records {
            let (factor, moving, rmse) = Self::record_iteration(&blocks, rec, simulated_switching)?;
            joint.merge(&factor)?;
            let n = rec.u.len().saturating_sub(rec.warmup).max(1) as f64;
            moved += moving * n;
            count += n;
            if let Some(r) = rmse {
                (squares, cascade) = (squares + r * r * n, true);
            }
        }
        let moving = moved / count;
        let rmse = (squares / count).sqrt();
        Ok(Iteration {
            ls: solve_factor(&joint, &names, moving)?,
            moving_fraction: moving,
            rmse: cascade.then_some(if rmse.is_finite() {
                rmse
            } else {
                f64::INFINITY
            }),
        })
    }

    /// One record's factor, moving fraction and (cascade) simulation RMSE of the paper's step.
    fn record_iteration(
        blocks: &Blocks,
        rec: &Record,
        simulated_switching: bool,
    ) -> Result<(TriangularFactor, f64, Option<f64>)> {
        match &blocks.output {
            Some(out) => {
                let regression =
                    SandwichRegression::new(&blocks.linear, &blocks.backlash, out, &rec.u, &rec.y)?;
                let (factor, moving) = regression.factor(rec.warmup);
                Ok((factor, moving, None))
            }
            None => {
                let simulated;
                let y_switch: &[f64] = if simulated_switching {
                    let m = CascadeModel::new(blocks.linear.clone(), blocks.backlash.clone());
                    simulated = m.simulate(&rec.u, &m.rest_state())?;
                    &simulated
                } else {
                    &rec.y
                };
                let regression = CascadeRegression::new(
                    &blocks.linear,
                    &blocks.backlash,
                    &rec.u,
                    &rec.y,
                    y_switch,
                )?;
                let (factor, moving, rmse) = regression.iteration(rec.warmup);
                Ok((factor, moving, Some(rmse)))
            }
        }
    }

    /// The output-error problem at theta in factored form: R_aug of [J | y - y_sim] over
    /// t >= warmup and the cost sum (y - y_sim)^2, streamed (no N x p Jacobian).
    /// With an initial state, J has its columns too (theta's order). Several records: each
    /// record's rows (its Jacobian in the model's columns and its own initial state's) folded
    /// into one factor, R_aug^T R_aug the sum of the records' [J_i | r_i]^T [J_i | r_i].
    pub fn oe_factor(&self, theta: &[f64]) -> Result<(TriangularFactor, f64)> {
        let all = self.unpack_all(theta)?;
        let p0 = self.structure.model_size();
        if let ([(b, _)], [rec]) = (&all[..], &self.records[..]) {
            let (factor, cost, motion) = self.record_factor(b, rec, p0)?;
            if let Some(motion) = motion {
                // the cascade's walk has the motion too: kept for `motion` at this theta
                *self.motion.lock() = Some((theta.to_vec(), motion));
            }
            return Ok((factor, cost));
        }
        let mut parts = Vec::with_capacity(all.len());
        let (mut cost, mut rows) = (0.0, 0);
        for ((blocks, cols), rec) in all.iter().zip(&self.records) {
            let (factor, c, _) = self.record_factor(blocks, rec, p0)?;
            cost += c;
            rows += factor.rows();
            parts.push((factor, cols));
        }
        let maps: Vec<(&TriangularFactor, &[usize])> =
            parts.iter().map(|(f, c)| (f, c.as_slice())).collect();
        Ok((
            TriangularFactor::embed_sum(self.size(), &maps, rows, 0.0)?,
            cost,
        ))
    }

    /// One record's output-error factor over the model's columns and its initial state's, with
    /// the motion where the walk has it (the cascade's).
    fn record_factor(
        &self,
        b: &Blocks,
        rec: &Record,
        p0: usize,
    ) -> Result<(TriangularFactor, f64, Option<Motion>)> {
        let (u, y, threads) = (&rec.u[..], &rec.y[..], oe_threads(rec.u.len()));
        let start = Self::start(b, p0);
        let (lin, bl, w) = (&b.linear, &b.backlash, rec.warmup);
        Ok(match &b.output {
            None => {
                let (f, c, m) =
                    cascade_oe_factor_motion_from(lin, bl, start.as_ref(), u, y, w, threads)?;
                (f, c, Some(m))
            }
            Some(out) => {
                let (f, c) =
                    sandwich_oe_factor_from(lin, bl, out, start.as_ref(), u, y, w, threads)?;
                (f, c, None)
            }
        })
    }

    /// The initial state's values and columns (after the model's `p0` parameters).
    fn start(blocks: &Blocks, p0: usize) -> Option<Start<'_>> {
        blocks
            .initial
            .as_ref()
            .map(|state| Start { state, col: p0 })
    }

    /// g = J^T (y - y_sim) over t >= warmup and the cost, one pass without the factor
    /// (beyond `BUFFERED_GRADIENT_SAMPLES` samples in all: R^T Q^T r of the factor, in bounded
    /// memory); several records: the records' gradients summed into theta's columns.
    pub fn gradient(&self, theta: &[f64]) -> Result<OeGradient> {
        if self.samples() > BUFFERED_GRADIENT_SAMPLES {
            // g = R^T (Q^T r) of the output-error factor: bounded memory, about 1.5 gradient
            // passes of time
            let (factor, cost) = self.oe_factor(theta)?;
            return Ok(OeGradient {
                gradient: factor.gradient(),
                cost,
            });
        }
        let all = self.unpack_all(theta)?;
        let p0 = self.structure.model_size();
        if self.records.len() == 1 {
            let (b, rec) = (&all[0].0, &self.records[0]);
            if b.output.is_none() {
                let start = Self::start(b, p0);
                let (g, motion) = cascade_oe_gradient_motion_from(
                    &b.linear,
                    &b.backlash,
                    start.as_ref(),
                    &rec.u,
                    &rec.y,
                    rec.warmup,
                )?;
                if let Some(m) = motion {
                    *self.motion.lock() = Some((theta.to_vec(), m));
                }
                return Ok(g);
            }
            return Self::record_gradient(b, rec, p0);
        }
        let mut total = OeGradient {
            gradient: vec![0.0; self.size()],
            cost: 0.0,
        };
        for ((blocks, cols), rec) in all.iter().zip(&self.records) {
            let g = Self::record_gradient(blocks, rec, p0)?;
            for (&c, v) in cols.iter().zip(&g.gradient) {
                total.gradient[c] += v;
            }
            total.cost += g.cost;
        }
        Ok(total)
    }

    /// The `Motion` of the record at theta over t >= warmup (the samples that move the
    /// backlash and the range of x), on the simulation of `simulate` (from rest or from
    /// theta's initial state): the last gradient pass's (or motion's) if it ran at this very
    /// theta and had it, else one simulation of x and the backlash. One record only.
    pub fn motion(&self, theta: &[f64]) -> Result<Motion> {
        if self.records.len() != 1 {
            return Err(Error::Data(
                "motion: a problem of one record only (several: per record)".into(),
            ));
        }
        let b = self.structure.unpack(theta)?;
        if let Some(m) = self.motion.at(theta) {
            return Ok(m);
        }
        let rec = &self.records[0];
        let x0 = b.initial.as_ref().map(|init| &init.x0[..]);
        let mut y_prev = b.initial.as_ref().map_or(0.0, |init| init.y_prev);
        let mut motion = Motion::empty();
        // x a chunk at a time: bounded memory on any record length
        XChunks::new(&b.linear, &rec.u, x0)?.each(|from, x| {
            let (y, w, m) = (&mut y_prev, rec.warmup, &mut motion);
            match b.backlash.padded_step() {
                Some(padded) => motion_along(padded, x, from, y, w, m),
                None => motion_along(&b.backlash, x, from, y, w, m),
            }
            .map_err(|e| blame_feeding_block(e, &b.linear, "input"))
        })?;
        *self.motion.lock() = Some((theta.to_vec(), motion));
        Ok(motion)
    }

    fn record_gradient(b: &Blocks, rec: &Record, p0: usize) -> Result<OeGradient> {
        let start = Self::start(b, p0);
        let (lin, bl, u, y, w) = (&b.linear, &b.backlash, &rec.u, &rec.y, rec.warmup);
        match &b.output {
            None => cascade_oe_gradient_from(lin, bl, start.as_ref(), u, y, w),
            Some(out) => sandwich_oe_gradient_from(lin, bl, out, start.as_ref(), u, y, w),
        }
    }
}
