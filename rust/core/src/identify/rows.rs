//! The rows of the paper's regressions, built on demand from the internal signals of an
//! estimate: the backlash columns the cascade (eq 18) and the sandwich (eq 33) share, each
//! model's row source with the constructor of its public regression type (`regressor`), and
//! folding the rows into a dense matrix or a triangular factor. Private to `identify`.

use super::regressor::{
    moving_fraction, CascadeRegression, Regression, RowRegression, SandwichRegression,
};
use crate::error::{Error, Result};
use crate::linalg::streaming::{fold_parallel, fold_parallel_split, SplitRows, TriangularFactor};
use crate::model::backlash::{GeneralBacklash, Step};
use crate::model::linear::LinearBlock;
use crate::model::signal::{check_same_length, check_signal};
use crate::model::switching::switching;

/// Degree n of an estimate (both branches have n coefficients in the regressions).
pub fn degree(backlash: &GeneralBacklash) -> Result<usize> {
    let (nl, nr) = (
        backlash.left().coefficients().len(),
        backlash.right().coefficients().len(),
    );
    if nl != nr {
        return Err(Error::Model(format!(
            "the estimate's branches have degrees {nl} and {nr}: identification uses one degree n"
        )));
    }
    Ok(nl)
}

/// What the cascade's and the sandwich's rows share: the estimate's backlash, the input u,
/// x by eq (22) and the switching functions f1, f2 (eq 25-26) for every sample, and the
/// orders na, nb and degree n of the columns [a, b, c_1, m_L2..m_Ln, m_R1, c_2, m_R2..m_Rn]
/// (eq 19).
pub struct BacklashColumns<'a> {
    pub backlash: &'a GeneralBacklash,
    pub u: &'a [f64],
    pub x: Vec<f64>,
    pub f1: Vec<bool>,
    pub f2: Vec<bool>,
    na: usize,
    nb: usize,
    n: usize,
}

impl<'a> BacklashColumns<'a> {
    /// Checks the estimate's degree and simulates x by eq (22) from rest (the caller has
    /// checked u and evaluates the switching).
    fn new(linear: &LinearBlock, backlash: &'a GeneralBacklash, u: &'a [f64]) -> Result<Self> {
        let n = degree(backlash)?;
        Ok(Self {
            backlash,
            u,
            x: linear.simulate(u, &linear.rest_state())?, // eq (22)
            f1: Vec::new(),
            f2: Vec::new(),
            na: linear.na(),
            nb: linear.nb(),
            n,
        })
    }

    /// na + nb + 2n + 1 columns.
    fn cols(&self) -> usize {
        self.na + self.nb + 2 * self.n + 1
    }

    /// The backlash part of eq (18) at sample `tau` (the whole phi(tau) of the cascade),
    /// written to the start of `row`: [u(tau-i) f1, -x(tau-j) f1, f1, xi1^i f1 (i>=2), x f2,
    /// -f2, xi2^i f2 (i>=2)]. Returns the number of values written (`cols`).
    fn fill(&self, row: &mut [f64], tau: usize, f1: bool, f2: bool) -> usize {
        let (na, nb, n, u, x) = (self.na, self.nb, self.n, self.u, &self.x);
        let lag = |s: &[f64], k: usize| if k <= tau { s[tau - k] } else { 0.0 };
        let (g1, g2) = (f1 as u8 as f64, f2 as u8 as f64);
        let xi1 = x[tau] + self.backlash.c_left(); // eq (23)
        let xi2 = x[tau] - self.backlash.c_right(); // eq (24)
        let mut k = 0;
        let mut put = |v: f64| {
            row[k] = v;
            k += 1;
        };
        (1..=na).for_each(|i| put(lag(u, i) * g1));
        (1..=nb).for_each(|j| put(-lag(x, j) * g1));
        put(g1);
        (2..=n).for_each(|i| put(xi1.powi(i as i32) * g1));
        put(x[tau] * g2);
        put(-g2);
        (2..=n).for_each(|i| put(xi2.powi(i as i32) * g2));
        k
    }
}

/// A regression whose rows are built on demand from the internal signals of an estimate
/// (eq 18 for the cascade, eq 33 for the sandwich).
pub trait RowSource<'a>: Sync {
    /// The backlash columns, with x and f1, f2 of every sample.
    fn part(&self) -> &BacklashColumns<'a>;
    fn into_part(self) -> BacklashColumns<'a>;
    fn cols(&self) -> usize;
    /// The first usable row for a warm-up of `warmup` samples.
    fn first_row(&self, warmup: usize) -> usize;
    /// The row of sample t into `row`; returns its target.
    fn fill(&self, t: usize, row: &mut [f64]) -> f64;

    fn len(&self) -> usize {
        self.part().u.len()
    }

    /// With f1, f2 of every sample evaluated (the dense regression reports them).
    fn with_flags(self) -> Self
    where
        Self: Sized,
    {
        self
    }

    /// All rows from `warmup` on folded into a triangular factor on `threads` threads, with
    /// the moving fraction.
    fn factor(&self, warmup: usize, threads: usize) -> (TriangularFactor, f64)
    where
        Self: Sized,
    {
        factor(self, warmup, threads)
    }
}

/// All rows from `warmup` on as a dense row-major matrix.
pub fn dense<'a, R: RowSource<'a>>(rows: R, warmup: usize) -> Regression {
    let (cols, start) = (rows.cols(), rows.first_row(warmup).min(rows.len()));
    let mut phi = vec![0.0; (rows.len() - start) * cols];
    let target: Vec<f64> = (start..rows.len())
        .map(|t| rows.fill(t, &mut phi[(t - start) * cols..(t - start + 1) * cols]))
        .collect();
    let part = rows.into_part();
    Regression {
        rows: target.len(),
        cols,
        phi,
        target,
        x: part.x,
        f1: part.f1,
        f2: part.f2,
    }
}

/// All rows from `warmup` on folded into a triangular factor on `threads` threads, with the
/// moving fraction.
pub fn factor<'a, R: RowSource<'a>>(
    rows: &R,
    warmup: usize,
    threads: usize,
) -> (TriangularFactor, f64) {
    let start = rows.first_row(warmup).min(rows.len());
    let factor = fold_parallel(rows.len() - start, rows.cols(), threads, |i, row| {
        rows.fill(start + i, row)
    });
    let part = rows.part();
    (factor, moving_fraction(&part.f1, &part.f2, warmup))
}

/// The cascade's regression at an estimate: x by eq (22) and f1, f2 by eq (25)-(26) for
/// every sample; rows are built from them on demand.
pub struct CascadeRows<'a> {
    pub part: BacklashColumns<'a>,
    pub y: &'a [f64],
    y_switch: &'a [f64],
}

impl<'a> CascadeRegression<'a> {
    /// Checks the record and simulates x by eq (22); f1 and f2 are evaluated when the rows
    /// are (by the folding threads, or for `dense`).
    pub fn new(
        linear: &LinearBlock,
        backlash: &'a GeneralBacklash,
        u: &'a [f64],
        y: &'a [f64],
        y_switch: &'a [f64],
    ) -> Result<Self> {
        check_signal("u", u)?;
        check_signal("y", y)?;
        check_same_length(u, y, "y")?;
        check_same_length(u, y_switch, "y_switch")?;
        Ok(RowRegression(CascadeRows {
            part: BacklashColumns::new(linear, backlash, u)?,
            y,
            y_switch,
        }))
    }
}

impl CascadeRows<'_> {
    /// With f1, f2 of eq (25)-(26) for every sample.
    pub fn with_switching(mut self) -> Self {
        let (part, y_switch) = (&self.part, self.y_switch);
        (self.part.f1, self.part.f2) = (0..part.u.len())
            .map(|t| {
                let ys_prev = if t > 0 { y_switch[t - 1] } else { 0.0 };
                switching(part.backlash, part.x[t], ys_prev) // eq (25)-(26)
            })
            .unzip();
        self
    }

    /// phi(t) of eq (18) restricted to the columns its switching selects: the left part
    /// [u(t-i), -x(t-j), 1, xi1^i (i>=2)] kept if f1, the right part [x, -1, xi2^i (i>=2)]
    /// kept if f2, else an all-zero row; the target is eq (21). Both parts are written
    /// every time (`SplitRows::keep`).
    #[inline]
    fn fill_parts(&self, t: usize, f1: bool, f2: bool, split: &mut SplitRows) {
        let part = &self.part;
        let (x, u, backlash) = (&part.x, part.u, part.backlash);
        let (na, nb, n) = (part.na, part.nb, part.n);
        let left = split.slot(0);
        for i in 1..=na {
            left[i - 1] = if i <= t { u[t - i] } else { 0.0 };
        }
        for j in 1..=nb {
            left[na + j - 1] = if j <= t { -x[t - j] } else { 0.0 };
        }
        left[na + nb] = 1.0;
        let xi1 = x[t] + backlash.c_left(); // eq (23)
        let mut power = xi1;
        for v in &mut left[na + nb + 1..na + nb + n] {
            power *= xi1;
            *v = power;
        }
        split.keep(0, self.y[t], f1);
        let right = split.slot(1);
        right[0] = x[t];
        right[1] = -1.0;
        let xi2 = x[t] - backlash.c_right(); // eq (24)
        let mut power = xi2;
        for v in &mut right[2..=n] {
            power *= xi2;
            *v = power;
        }
        split.keep(1, self.y[t], f2);
        let y_prev = if t > 0 { self.y[t - 1] } else { 0.0 };
        split.keep_zero(self.y[t] - y_prev, !f1 && !f2);
    }
}

impl<'a> RowSource<'a> for CascadeRows<'a> {
    fn part(&self) -> &BacklashColumns<'a> {
        &self.part
    }

    fn into_part(self) -> BacklashColumns<'a> {
        self.part
    }

    fn cols(&self) -> usize {
        self.part.cols()
    }

    fn first_row(&self, warmup: usize) -> usize {
        warmup
    }

    fn with_flags(self) -> Self {
        self.with_switching()
    }

    /// Folded split by branch, with f1, f2 evaluated by the folding threads.
    fn factor(&self, warmup: usize, threads: usize) -> (TriangularFactor, f64) {
        cascade_rows_factor(self, warmup, threads)
    }

    /// phi(t) of eq (18) into `row`; returns the target y(t) - y(t-1)[1 - f1][1 - f2] (21).
    fn fill(&self, t: usize, row: &mut [f64]) -> f64 {
        let (f1, f2) = (self.part.f1[t], self.part.f2[t]);
        self.part.fill(row, t, f1, f2);
        let y_prev = if t > 0 { self.y[t - 1] } else { 0.0 };
        let hold = if f1 || f2 { 0.0 } else { y_prev };
        self.y[t] - hold // eq (21)
    }
}

/// RMS of y(t) - y_sim(t) over t >= warmup, y_sim the backlash output for x from y(0) = 0.
pub fn simulation_rmse(x: &[f64], y: &[f64], warmup: usize, step: impl Step) -> f64 {
    let (mut y_prev, mut sse) = (0.0, 0.0);
    for (t, (&xt, &yt)) in x.iter().zip(y).enumerate() {
        y_prev = step.step(xt, y_prev);
        if t >= warmup {
            let e = yt - y_prev;
            sse += e * e;
        }
    }
    let rmse = (sse / x.len().saturating_sub(warmup).max(1) as f64).sqrt();
    if rmse.is_finite() {
        rmse
    } else {
        f64::INFINITY
    }
}

/// The factor of eq (18) for `rows` from `warmup` on, split by branch, and the moving fraction.
pub fn cascade_rows_factor(
    rows: &CascadeRows,
    warmup: usize,
    threads: usize,
) -> (TriangularFactor, f64) {
    // Eq (18): a row has f1 times the left-branch columns or f2 times the right-branch ones
    // (f1 f2 = 0), never both, so A^T A is block diagonal and each branch folds on its own.
    // f1, f2 (eq 25-26) depend on x(t) and y_switch(t-1) only: the folding threads evaluate
    // them for their own rows.
    let (start, backlash) = (warmup.min(rows.len()), rows.part.backlash);
    let (factor, zero_rows) = match backlash.padded_step() {
        Some(padded) => fold_cascade_rows(rows, start, threads, |x, y_prev| {
            padded.switching(x, y_prev)
        }),
        None => fold_cascade_rows(rows, start, threads, |x, y_prev| {
            switching(backlash, x, y_prev)
        }),
    };
    let used = rows.len() - start;
    let moving = if used == 0 {
        0.0
    } else {
        (used - zero_rows) as f64 / used as f64
    };
    (factor, moving)
}

/// The rows of eq (18) from `start` on, split by branch (`fold_parallel_split`), with f1, f2
/// of eq (25)-(26) by `cases(x(t), y_switch(t-1))`.
fn fold_cascade_rows(
    rows: &CascadeRows,
    start: usize,
    threads: usize,
    cases: impl Fn(f64, f64) -> (bool, bool) + Sync,
) -> (TriangularFactor, usize) {
    let (part, y_switch) = (&rows.part, rows.y_switch);
    let (left, right) = (part.na + part.nb + part.n, part.n + 1);
    fold_parallel_split(rows.len() - start, &[left, right], threads, |i, split| {
        let t = start + i;
        let ys_prev = if t > 0 { y_switch[t - 1] } else { 0.0 };
        let (f1, f2) = cases(part.x[t], ys_prev);
        rows.fill_parts(t, f1, f2, split);
    })
}

/// The sandwich's regression at an estimate: x by eq (22), the backlash output y by eq (35)
/// and its f1, f2 for every sample; rows are built from them on demand.
pub struct SandwichRows<'a> {
    part: BacklashColumns<'a>,
    w: &'a [f64],
    nr: usize,
    ns: usize,
    y: Vec<f64>,
}

impl<'a> SandwichRegression<'a> {
    /// Checks the record and simulates x by eq (22), the backlash output y by eq (35) and
    /// its f1, f2.
    pub fn new(
        input_linear: &LinearBlock,
        backlash: &'a GeneralBacklash,
        output_linear: &LinearBlock,
        u: &'a [f64],
        w: &'a [f64],
    ) -> Result<Self> {
        check_signal("u", u)?;
        check_signal("w", w)?;
        check_same_length(u, w, "w")?;
        let mut part = BacklashColumns::new(input_linear, backlash, u)?;
        let y = backlash.simulate(&part.x, 0.0)?; // eq (35)
        (part.f1, part.f2) = crate::model::cascade::switching_flags(backlash, &part.x, &y, 0.0)?;
        Ok(RowRegression(SandwichRows {
            part,
            w,
            nr: output_linear.na(),
            ns: output_linear.nb(),
            y,
        }))
    }
}

impl<'a> RowSource<'a> for SandwichRows<'a> {
    fn part(&self) -> &BacklashColumns<'a> {
        &self.part
    }

    fn into_part(self) -> BacklashColumns<'a> {
        self.part
    }

    fn cols(&self) -> usize {
        self.part.cols() + self.nr.saturating_sub(1) + self.ns
    }

    fn first_row(&self, warmup: usize) -> usize {
        warmup.max(1) // eq (33) starts from the backlash at t - 1
    }

    /// Phi(t) of eq (33) into `row` (t >= 1); returns the target of eq (34).
    fn fill(&self, t: usize, row: &mut [f64]) -> f64 {
        let tau = t - 1;
        let (f1, f2) = (self.part.f1[tau], self.part.f2[tau]);
        let lag = |s: &[f64], k: usize| if k <= t { s[t - k] } else { 0.0 };
        let mut k = self.part.fill(row, tau, f1, f2);
        for i in 2..=self.nr {
            row[k] = lag(&self.y, i);
            k += 1;
        }
        for j in 1..=self.ns {
            row[k] = -lag(self.w, j);
            k += 1;
        }
        let hold = if f1 || f2 { 0.0 } else { lag(&self.y, 2) };
        self.w[t] - hold // eq (34)
    }
}
