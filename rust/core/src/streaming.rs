//! Streaming least squares: the upper-triangular factor of a tall-skinny QR, updated block by
//! block, so that a regression over N = 1e8 samples never holds an N x p matrix.
//!
//! For rows [A | b] folded so far, `TriangularFactor` keeps R_aug ((p+1) x (p+1), upper
//! triangular) with R_aug^T R_aug = [A | b]^T [A | b]: its leading p x p block is the R of
//! A = QR, its last column above the diagonal is Q^T b, and R_aug[p][p]^2 is the residual sum
//! of squares. Each block of rows is folded by Householder reflections of the stacked
//! [R_aug; block], which touch only the diagonal of R_aug and the block (the structured TSQR
//! step); two partial factors merge by folding the rows of one into the other.

use crate::error::{Error, Result};
use crate::lstsq::{solve_triangular, LeastSquares};

/// Rows folded per Householder sweep: the stacked [R_aug; block] (p+1 columns) stays in the
/// core's L2 cache. Measured on p = 11 at N = 1e5 (faer's unblocked QR): 256 to 4096 rows are
/// within 10 % of each other; larger blocks only cost memory.
pub const BLOCK_ROWS: usize = 1024;

/// Blocks per hand-over from a `fold_stream` producer to its folding thread.
const HANDOVER_BLOCKS: usize = 16;

/// Upper bound of `default_threads`.
pub const MAX_THREADS: usize = 8;

/// The threads a streaming regression uses: the machine's available parallelism, 1 to
/// `MAX_THREADS`. Results depend on it only through rounding (`fold_parallel`).
pub fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, MAX_THREADS)
}

/// The R factor of [A | b] for the rows folded so far. Equality and `Debug` look at p, the
/// row count and R_aug (not at the scratch space).
pub struct TriangularFactor {
    p: usize,
    rows: usize,
    /// R_aug, row-major (p+1) x (p+1); zero below the diagonal.
    r: Vec<f64>,
    /// Workspace of the Householder sweeps, made on the first fold and reused.
    sweep: Option<Box<Sweep>>,
}

impl Clone for TriangularFactor {
    fn clone(&self) -> Self {
        Self {
            p: self.p,
            rows: self.rows,
            r: self.r.clone(),
            sweep: None,
        }
    }
}

impl PartialEq for TriangularFactor {
    fn eq(&self, other: &Self) -> bool {
        self.p == other.p && self.rows == other.rows && self.r == other.r
    }
}

impl std::fmt::Debug for TriangularFactor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangularFactor")
            .field("p", &self.p)
            .field("rows", &self.rows)
            .field("r_aug", &self.r)
            .finish()
    }
}

impl TriangularFactor {
    /// The factor of no rows (R_aug = 0) for p regressors.
    pub fn new(p: usize) -> Self {
        Self {
            p,
            rows: 0,
            r: vec![0.0; (p + 1) * (p + 1)],
            sweep: None,
        }
    }

    /// The factor of several factors over disjoint sets of columns, plus rows in which every
    /// regressor is zero: `parts[k]` covers the next `parts[k].cols()` columns (in order) and
    /// the common target, `zero_rows` rows contribute only `zero_sum_squares` = sum b^2.
    /// Since no row touches two parts, A^T A is block diagonal and R_aug is
    /// [[R_1, 0, q_1], [0, R_2, q_2], ..., [0, 0, rho]] with rho^2 the sum of the parts'
    /// residuals and `zero_sum_squares` (exact, no rounding beyond that sum).
    pub fn direct_sum(parts: &[TriangularFactor], zero_rows: usize, zero_sum_squares: f64) -> Self {
        let p: usize = parts.iter().map(|f| f.p).sum();
        let n = p + 1;
        let mut out = Self::new(p);
        let (mut at, mut rho2) = (0, zero_sum_squares);
        for part in parts {
            let (q, m) = (part.p, part.p + 1);
            for i in 0..q {
                for j in i..q {
                    out.r[(at + i) * n + at + j] = part.r[i * m + j];
                }
                out.r[(at + i) * n + p] = part.r[i * m + q];
            }
            rho2 += part.r[m * m - 1] * part.r[m * m - 1];
            out.rows += part.rows;
            at += q;
        }
        out.r[n * n - 1] = rho2.sqrt();
        out.rows += zero_rows;
        out
    }

    /// Number of regressors p (R_aug is (p+1) x (p+1)).
    pub fn cols(&self) -> usize {
        self.p
    }

    /// Number of rows folded so far.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// R_aug row-major, (p+1) x (p+1).
    pub fn r_aug(&self) -> &[f64] {
        &self.r
    }

    /// Fold k rows of A (row-major, `a.len()` = k p) with their targets b (`b.len()` = k).
    pub fn fold(&mut self, a: &[f64], b: &[f64]) -> Result<()> {
        let (p, k) = (self.p, b.len());
        if a.len() != k * p {
            return Err(Error::Data(format!(
                "streaming least squares: a block of {k} targets needs {} regressor values \
                 ({p} per row), got {} (internal shape mismatch)",
                k * p,
                a.len()
            )));
        }
        let mut start = 0;
        while start < k {
            let m = (k - start).min(BLOCK_ROWS);
            self.fold_block(m, |col, j| {
                if j < p {
                    for (i, c) in col.iter_mut().enumerate() {
                        *c = a[(start + i) * p + j];
                    }
                } else {
                    col.copy_from_slice(&b[start..start + m]);
                }
            });
            start += m;
        }
        self.rows += k;
        Ok(())
    }

    /// Combine with the factor of other rows: the result is the factor of both row sets
    /// (the QR of [R1; R2]). Merging in a fixed order gives a fixed result.
    pub fn merge(&mut self, other: &TriangularFactor) -> Result<()> {
        if other.p != self.p {
            return Err(Error::Data(format!(
                "streaming least squares: cannot merge a factor of {} columns into one of {} \
                 (internal shape mismatch)",
                other.p, self.p
            )));
        }
        let n = self.p + 1;
        // The rows of R2 below its diagonal are zero, so only the first min(rows, n) can be
        // non-zero; folding all n keeps the arithmetic independent of the row count.
        self.fold_block(n, |col, j| {
            for (i, c) in col.iter_mut().enumerate() {
                *c = other.r[i * n + j];
            }
        });
        self.rows += other.rows;
        Ok(())
    }

    /// The least-squares solution min ||A theta - b|| of the rows folded so far, with the
    /// checks and statistics of `lstsq::solve`.
    pub fn solve(&self, names: &[String]) -> Result<LeastSquares> {
        let n = self.p + 1;
        solve_triangular(&self.r, n, self.p, self.rows, names)
    }

    /// Fold m <= max(BLOCK_ROWS, p + 1) rows whose column j (of m values; j = p the target)
    /// `fill(column, j)` writes.
    fn fold_block(&mut self, m: usize, mut fill: impl FnMut(&mut [f64], usize)) {
        let n = self.p + 1;
        let mut sweep = self
            .sweep
            .take()
            .unwrap_or_else(|| Box::new(Sweep::new(n, BLOCK_ROWS.max(n))));
        for j in 0..n {
            let col = sweep.stacked.col_as_slice_mut(j);
            for (i, c) in col[..n].iter_mut().enumerate() {
                *c = self.r[i * n + j];
            }
            fill(&mut col[n..n + m], j);
        }
        sweep.triangularise(n + m);
        for i in 0..n {
            for j in i..n {
                self.r[i * n + j] = sweep.stacked[(i, j)];
            }
        }
        self.sweep = Some(sweep);
    }
}

/// The stacked [R_aug; block] (column-major, n columns, room for `n + rows` rows) and faer's
/// QR workspace.
struct Sweep {
    stacked: faer::Mat<f64>,
    householder: faer::Mat<f64>,
    buffer: faer::dyn_stack::MemBuffer,
}

/// faer's QR block size for the sweep: 1 (unblocked Householder). On these narrow stacks the
/// blocked (WY) form does more work than it saves: at p = 11, block size 1 folds 1e5 rows in
/// 3.4 ms, 4 in 5.4 ms, 12 in 5.4 ms (2026-11-22, this 2-core machine).
const QR_BLOCK: usize = 1;

impl Sweep {
    fn new(n: usize, rows: usize) -> Self {
        use faer::linalg::qr::no_pivoting::factor::qr_in_place_scratch;
        Self {
            stacked: faer::Mat::zeros(n + rows, n),
            householder: faer::Mat::zeros(QR_BLOCK, n),
            buffer: faer::dyn_stack::MemBuffer::new(qr_in_place_scratch::<f64>(
                n + rows,
                n,
                QR_BLOCK,
                faer::Par::Seq,
                Default::default(),
            )),
        }
    }

    /// Triangularise the first `rows` rows of `stacked` in place by faer's Householder QR: its
    /// upper n x n triangle is then the R factor of those rows (unique up to the signs of its
    /// rows, which no solution or statistic depends on).
    fn triangularise(&mut self, rows: usize) {
        use faer::linalg::qr::no_pivoting::factor::qr_in_place;
        qr_in_place(
            self.stacked.as_mut().subrows_mut(0, rows),
            self.householder.as_mut(),
            faer::Par::Seq,
            faer::dyn_stack::MemStack::new(&mut self.buffer),
            Default::default(),
        );
    }
}

/// Fold `rows` rows, row t written by `fill(t, row)` (which returns the target), on `threads`
/// scoped threads: contiguous chunks, one factor per chunk, merged in chunk order, so the
/// result depends on `threads` (through rounding) but never on timing.
pub fn fold_parallel(
    rows: usize,
    p: usize,
    threads: usize,
    fill: impl Fn(usize, &mut [f64]) -> f64 + Sync,
) -> TriangularFactor {
    let threads = threads.clamp(1, rows.div_ceil(BLOCK_ROWS).max(1));
    let fold_range = |lo: usize, hi: usize| {
        let mut factor = TriangularFactor::new(p);
        let mut a = vec![0.0; BLOCK_ROWS * p];
        let mut b = vec![0.0; BLOCK_ROWS];
        let mut t = lo;
        while t < hi {
            let k = (hi - t).min(BLOCK_ROWS);
            for i in 0..k {
                b[i] = fill(t + i, &mut a[i * p..(i + 1) * p]);
            }
            // shapes agree by construction
            let _ = factor.fold(&a[..k * p], &b[..k]);
            t += k;
        }
        factor
    };
    let mut iter = in_chunks(rows, threads, fold_range).into_iter();
    let mut out = iter.next().unwrap_or_else(|| TriangularFactor::new(p));
    for part in iter {
        let _ = out.merge(&part); // same p by construction
    }
    out
}

/// `work(lo, hi)` on `threads` contiguous chunks of 0..rows (the first on this thread, the
/// others on scoped threads), the results in chunk order.
fn in_chunks<T: Send>(
    rows: usize,
    threads: usize,
    work: impl Fn(usize, usize) -> T + Sync,
) -> Vec<T> {
    if threads <= 1 {
        return vec![work(0, rows)];
    }
    let bounds: Vec<(usize, usize)> = (0..threads)
        .map(|c| (rows * c / threads, rows * (c + 1) / threads))
        .collect();
    std::thread::scope(|scope| {
        let work = &work;
        let handles: Vec<_> = bounds[1..]
            .iter()
            .map(|&(lo, hi)| scope.spawn(move || work(lo, hi)))
            .collect();
        let mut parts = vec![work(bounds[0].0, bounds[0].1)];
        for h in handles {
            match h.join() {
                Ok(part) => parts.push(part),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
        parts
    })
}

/// The rows of one `fold_parallel_split` chunk, gathered per part and folded block by block.
/// A producer writes a candidate row into `slot(k)` and then says with `keep(k, target,
/// taken)` whether it belongs to part k: writing every candidate and keeping by a flag avoids
/// a data-dependent branch per row (the switching of eq 25-26 is as good as random).
pub struct SplitRows {
    widths: Vec<usize>,
    /// Per part: `BLOCK_ROWS` rows, row-major, the first `len[k]` in use.
    a: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    len: Vec<usize>,
    factors: Vec<TriangularFactor>,
    zero_rows: usize,
    zero_sum_squares: f64,
}

impl SplitRows {
    fn new(widths: &[usize]) -> Self {
        Self {
            widths: widths.to_vec(),
            a: widths.iter().map(|&w| vec![0.0; BLOCK_ROWS * w]).collect(),
            b: widths.iter().map(|_| vec![0.0; BLOCK_ROWS]).collect(),
            len: vec![0; widths.len()],
            factors: widths.iter().map(|&w| TriangularFactor::new(w)).collect(),
            zero_rows: 0,
            zero_sum_squares: 0.0,
        }
    }

    /// Where the next row of part k goes (`widths[k]` values).
    #[inline]
    pub fn slot(&mut self, k: usize) -> &mut [f64] {
        let (w, at) = (self.widths[k], self.len[k]);
        &mut self.a[k][at * w..(at + 1) * w]
    }

    /// The row in `slot(k)`, with its target, joins part k if `taken`.
    #[inline]
    pub fn keep(&mut self, k: usize, target: f64, taken: bool) {
        let at = self.len[k];
        self.b[k][at] = target;
        self.len[k] = at + taken as usize;
        if self.len[k] == BLOCK_ROWS {
            self.flush(k);
        }
    }

    /// A row whose regressors are all zero, if `taken`: only its target's square counts.
    #[inline]
    pub fn keep_zero(&mut self, target: f64, taken: bool) {
        self.zero_rows += taken as usize;
        self.zero_sum_squares += target * target * (taken as u8 as f64);
    }

    fn flush(&mut self, k: usize) {
        let (w, m) = (self.widths[k], self.len[k]);
        // shapes agree by construction
        let _ = self.factors[k].fold(&self.a[k][..m * w], &self.b[k][..m]);
        self.len[k] = 0;
    }

    fn finish(mut self) -> (Vec<TriangularFactor>, usize, f64) {
        for k in 0..self.widths.len() {
            self.flush(k);
        }
        (self.factors, self.zero_rows, self.zero_sum_squares)
    }
}

/// `fold_parallel` for regressions whose rows each touch one of several disjoint column
/// sets (`widths[k]` columns each, in order), or none: `fill(t, rows)` hands row t to
/// `rows` (`SplitRows::slot`, `keep`, `keep_zero`) with its values in its part's columns
/// only. Each part folds only its own columns and `TriangularFactor::direct_sum` joins
/// them: the factor of the full rows (to rounding) for sum_k w_k^2 instead of (sum_k w_k)^2
/// work per row. Contiguous chunks per thread, merged in chunk order (deterministic).
/// Returns the factor and the number of all-zero rows.
pub fn fold_parallel_split(
    rows: usize,
    widths: &[usize],
    threads: usize,
    fill: impl Fn(usize, &mut SplitRows) + Sync,
) -> (TriangularFactor, usize) {
    let threads = threads.clamp(1, rows.div_ceil(BLOCK_ROWS).max(1));
    let fold_range = |lo: usize, hi: usize| {
        let mut split = SplitRows::new(widths);
        for t in lo..hi {
            fill(t, &mut split);
        }
        split.finish()
    };
    let mut iter = in_chunks(rows, threads, fold_range).into_iter();
    let (mut factors, mut zero_rows, mut zero_ss) = iter.next().unwrap_or_else(|| {
        (
            widths.iter().map(|&w| TriangularFactor::new(w)).collect(),
            0,
            0.0,
        )
    });
    for (more, z, ss) in iter {
        for (f, g) in factors.iter_mut().zip(&more) {
            let _ = f.merge(g); // same widths by construction
        }
        zero_rows += z;
        zero_ss += ss;
    }
    (
        TriangularFactor::direct_sum(&factors, zero_rows, zero_ss),
        zero_rows,
    )
}

/// Where `fold_stream`'s producer pushes rows: full blocks are folded here (one thread) or
/// handed to a folding thread (two), always in the order produced.
pub struct RowSink {
    p: usize,
    /// Rows gathered before a fold (local) or a hand-over to the folding thread.
    batch: usize,
    a: Vec<f64>,
    b: Vec<f64>,
    sum_squares: f64,
    target: SinkTarget,
}

enum SinkTarget {
    Local(TriangularFactor),
    Channel {
        full: std::sync::mpsc::SyncSender<(Vec<f64>, Vec<f64>)>,
        empty: std::sync::mpsc::Receiver<(Vec<f64>, Vec<f64>)>,
    },
}

impl RowSink {
    /// Append one row (p values) with its target.
    #[inline]
    pub fn push(&mut self, row: &[f64], target: f64) -> Result<()> {
        if row.len() != self.p {
            return Err(Error::Data(format!(
                "streaming least squares: a row of {} values for {} columns (internal shape \
                 mismatch)",
                row.len(),
                self.p
            )));
        }
        self.a.extend_from_slice(row);
        self.b.push(target);
        self.sum_squares += target * target;
        if self.b.len() >= self.batch {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        if self.b.is_empty() {
            return Ok(());
        }
        match &mut self.target {
            SinkTarget::Local(factor) => {
                factor.fold(&self.a, &self.b)?;
                self.a.clear();
                self.b.clear();
            }
            SinkTarget::Channel { full, empty } => {
                let (mut a, mut b) = empty.try_recv().unwrap_or_else(|_| {
                    (
                        Vec::with_capacity(self.batch * self.p),
                        Vec::with_capacity(self.batch),
                    )
                });
                a.clear();
                b.clear();
                std::mem::swap(&mut a, &mut self.a);
                std::mem::swap(&mut b, &mut self.b);
                if full.send((a, b)).is_err() {
                    return Err(Error::Data(
                        "streaming least squares: the folding thread stopped (internal error)"
                            .into(),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Fold the rows that `produce` pushes, in order, into a factor of p columns; returns it with
/// the sum of the squared targets. With `threads` >= 2 the folding runs on a second thread
/// while `produce` computes the next rows (a sequential recursion, e.g. sensitivities); the
/// result is the same bits either way.
pub fn fold_stream(
    p: usize,
    threads: usize,
    produce: impl FnOnce(&mut RowSink) -> Result<()>,
) -> Result<(TriangularFactor, f64)> {
    let sink = |target, batch| RowSink {
        p,
        batch,
        a: Vec::with_capacity(batch * p),
        b: Vec::with_capacity(batch),
        sum_squares: 0.0,
        target,
    };
    if threads <= 1 {
        let mut s = sink(SinkTarget::Local(TriangularFactor::new(p)), BLOCK_ROWS);
        produce(&mut s)?;
        s.flush()?;
        return match s.target {
            SinkTarget::Local(f) => Ok((f, s.sum_squares)),
            SinkTarget::Channel { .. } => unreachable!("a local sink stays local"),
        };
    }
    std::thread::scope(|scope| {
        let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<(Vec<f64>, Vec<f64>)>(2);
        let (empty_tx, empty_rx) = std::sync::mpsc::channel();
        let folder = scope.spawn(move || {
            let mut factor = TriangularFactor::new(p);
            let mut status = Ok(());
            for (a, b) in full_rx {
                if status.is_ok() {
                    status = factor.fold(&a, &b);
                }
                let _ = empty_tx.send((a, b)); // the producer may be gone
            }
            status.map(|_| factor)
        });
        // hand over several blocks at once: fewer wake-ups of the folding thread
        let mut s = sink(
            SinkTarget::Channel {
                full: full_tx,
                empty: empty_rx,
            },
            HANDOVER_BLOCKS * BLOCK_ROWS,
        );
        let produced = produce(&mut s).and_then(|_| s.flush());
        let sum_squares = s.sum_squares;
        drop(s); // closes the channel: the folder finishes
        let folded = match folder.join() {
            Ok(f) => f,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        produced?;
        Ok((folded?, sum_squares))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lstsq::solve;

    fn names(p: usize) -> Vec<String> {
        (0..p).map(|j| format!("p{j}")).collect()
    }

    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
    }

    /// A random problem with badly scaled columns (like powers of xi) and noise.
    fn problem(rows: usize, p: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut g = Lcg(seed);
        let mut a = vec![0.0; rows * p];
        let mut b = vec![0.0; rows];
        for r in 0..rows {
            let mut fit = 0.0;
            for j in 0..p {
                let v = g.next() * 10f64.powi(j as i32 % 5 - 2);
                a[r * p + j] = v;
                fit += v * (j as f64 + 1.0);
            }
            b[r] = fit + 0.1 * g.next();
        }
        (a, b)
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs().max(1e-300)
    }

    fn assert_same(got: &LeastSquares, want: &LeastSquares, tol: f64) {
        for (g, w) in got.theta.iter().zip(&want.theta) {
            assert!(rel(*g, *w) < tol, "theta {g} vs {w}");
        }
        assert!(rel(got.rss, want.rss) < tol, "rss {} {}", got.rss, want.rss);
        let big = want
            .unscaled_covariance
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for (g, w) in got
            .unscaled_covariance
            .iter()
            .zip(&want.unscaled_covariance)
        {
            assert!((g - w).abs() < tol * big.max(w.abs()), "cov {g} vs {w}");
        }
        assert!(rel(got.rcond, want.rcond) < 1e-8);
    }

    /// The dense reference: faer's QR of the whole scaled matrix, explicit residual.
    fn dense(a: &[f64], rows: usize, p: usize, b: &[f64]) -> LeastSquares {
        use faer::linalg::solvers::SolveLstsq;
        let mut scale = vec![0.0; p];
        for r in 0..rows {
            for j in 0..p {
                scale[j] += a[r * p + j] * a[r * p + j];
            }
        }
        let scale: Vec<f64> = scale.iter().map(|s| s.sqrt()).collect();
        let m = faer::Mat::<f64>::from_fn(rows, p, |r, j| a[r * p + j] / scale[j]);
        let rhs = faer::Mat::<f64>::from_fn(rows, 1, |r, _| b[r]);
        let qr = m.qr();
        let sol = qr.solve_lstsq(rhs.as_ref());
        let theta: Vec<f64> = (0..p).map(|j| sol[(j, 0)] / scale[j]).collect();
        let rss = (0..rows)
            .map(|r| (b[r] - (0..p).map(|j| a[r * p + j] * theta[j]).sum::<f64>()).powi(2))
            .sum();
        let rf = qr.thin_R();
        let rrow: Vec<f64> = (0..p)
            .flat_map(|i| (0..p).map(move |j| (i, j)))
            .map(|(i, j)| rf[(i, j)])
            .collect();
        let diag: Vec<f64> = (0..p).map(|j| rf[(j, j)].abs()).collect();
        let max = diag.iter().cloned().fold(0.0, f64::max);
        let min = diag.iter().cloned().fold(f64::INFINITY, f64::min);
        LeastSquares {
            theta,
            rss,
            unscaled_covariance: crate::lstsq::inverse_gram(&rrow, &scale),
            rcond: min / max,
        }
    }

    #[test]
    fn streamed_solution_equals_the_dense_one() {
        for (rows, p, seed) in [(2000, 11, 1u64), (777, 14, 2), (40, 5, 3), (3000, 3, 4)] {
            let (a, b) = problem(rows, p, seed);
            let want = dense(&a, rows, p, &b);
            assert_same(&solve(&a, rows, p, &b, &names(p)).unwrap(), &want, 1e-10);
            for block in [1, 2, p - 1, p + 1, 64, 513, rows] {
                let mut f = TriangularFactor::new(p);
                let mut start = 0;
                while start < rows {
                    let end = (start + block).min(rows);
                    f.fold(&a[start * p..end * p], &b[start..end]).unwrap();
                    start = end;
                }
                assert_eq!(f.rows(), rows);
                assert_eq!(f.cols(), p);
                assert_same(&f.solve(&names(p)).unwrap(), &want, 1e-10);
            }
        }
    }

    #[test]
    fn merges_in_any_grouping_give_the_same_solution() {
        let (rows, p) = (1500, 9);
        let (a, b) = problem(rows, p, 7);
        let want = dense(&a, rows, p, &b);
        let part = |lo: usize, hi: usize| {
            let mut f = TriangularFactor::new(p);
            f.fold(&a[lo * p..hi * p], &b[lo..hi]).unwrap();
            f
        };
        let cuts = [0, 3, 400, 401, 1100, 1500];
        let parts: Vec<_> = cuts.windows(2).map(|w| part(w[0], w[1])).collect();
        // ((((0 1) 2) 3) 4)
        let mut left = parts[0].clone();
        for q in &parts[1..] {
            left.merge(q).unwrap();
        }
        // (0 (1 (2 (3 4))))
        let mut right = parts[4].clone();
        for q in parts[..4].iter().rev() {
            let mut q = q.clone();
            q.merge(&right).unwrap();
            right = q;
        }
        // ((0 1) (2 (3 4)))
        let mut x = parts[0].clone();
        x.merge(&parts[1]).unwrap();
        let mut y = parts[3].clone();
        y.merge(&parts[4]).unwrap();
        let mut z = parts[2].clone();
        z.merge(&y).unwrap();
        x.merge(&z).unwrap();
        for f in [&left, &right, &x] {
            assert_eq!(f.rows(), rows);
            assert_same(&f.solve(&names(p)).unwrap(), &want, 1e-10);
        }
        // an empty factor is neutral
        let mut e = TriangularFactor::new(p);
        e.merge(&left).unwrap();
        assert_same(&e.solve(&names(p)).unwrap(), &want, 1e-10);
    }

    #[test]
    fn r_aug_is_the_gram_factor_and_its_corner_the_residual() {
        let (rows, p) = (300, 6);
        let (a, b) = problem(rows, p, 11);
        let mut f = TriangularFactor::new(p);
        f.fold(&a, &b).unwrap();
        let n = p + 1;
        let r = f.r_aug();
        let aug = |row: usize, j: usize| if j < p { a[row * p + j] } else { b[row] };
        for i in 0..n {
            for j in 0..n {
                if i > j {
                    assert_eq!(r[i * n + j], 0.0);
                }
                let rtr: f64 = (0..n).map(|k| r[k * n + i] * r[k * n + j]).sum();
                let gram: f64 = (0..rows).map(|t| aug(t, i) * aug(t, j)).sum();
                assert!((rtr - gram).abs() < 1e-11 * gram.abs().max(1.0), "{i} {j}");
            }
        }
        let ls = f.solve(&names(p)).unwrap();
        assert!(rel(ls.rss, r[n * n - 1].powi(2)) < 1e-15);
    }

    #[test]
    fn parallel_fold_is_deterministic_and_thread_count_changes_only_rounding() {
        let (rows, p) = (20_000, 11);
        let (a, b) = problem(rows, p, 5);
        let fill = |t: usize, row: &mut [f64]| {
            row.copy_from_slice(&a[t * p..(t + 1) * p]);
            b[t]
        };
        let one = fold_parallel(rows, p, 1, fill);
        let two = fold_parallel(rows, p, 2, fill);
        let three = fold_parallel(rows, p, 3, fill);
        for _ in 0..5 {
            assert_eq!(fold_parallel(rows, p, 2, fill), two);
            assert_eq!(fold_parallel(rows, p, 3, fill), three);
        }
        let mut sequential = TriangularFactor::new(p);
        sequential.fold(&a, &b).unwrap();
        assert_eq!(one, sequential);
        let want = one.solve(&names(p)).unwrap();
        for f in [&two, &three] {
            assert_eq!(f.rows(), rows);
            assert_same(&f.solve(&names(p)).unwrap(), &want, 1e-11);
        }
        // more threads than blocks, and no rows at all
        let small = fold_parallel(10, p, 8, fill);
        assert_eq!(small.rows(), 10);
        assert_eq!(fold_parallel(0, p, 4, fill).rows(), 0);
    }

    #[test]
    fn dead_and_dependent_columns_are_named() {
        let (rows, p) = (200, 4);
        let (mut a, b) = problem(rows, p, 9);
        for t in 0..rows {
            a[t * p + 2] = 0.0;
        }
        let mut f = TriangularFactor::new(p);
        f.fold(&a, &b).unwrap();
        match f.solve(&names(p)) {
            Err(Error::NotIdentifiable(m)) => {
                assert!(m.contains("p2") && m.contains("zero"), "{m}")
            }
            other => panic!("{other:?}"),
        }
        for t in 0..rows {
            a[t * p + 2] = 3.0 * a[t * p] - a[t * p + 1];
        }
        let mut f = TriangularFactor::new(p);
        f.fold(&a, &b).unwrap();
        match f.solve(&names(p)) {
            Err(Error::NotIdentifiable(m)) => {
                assert!(m.contains("p2") && m.contains("rank deficient"), "{m}")
            }
            other => panic!("{other:?}"),
        }
        // a non-finite value is reported, not a panic
        a[5 * p + 1] = f64::INFINITY;
        let mut f = TriangularFactor::new(p);
        f.fold(&a, &b).unwrap();
        match f.solve(&names(p)) {
            Err(Error::NotIdentifiable(m)) => assert!(m.contains("non-finite"), "{m}"),
            other => panic!("{other:?}"),
        }
        // too few rows, bad shapes, no rows
        let mut f = TriangularFactor::new(p);
        f.fold(&a[..2 * p], &b[..2]).unwrap();
        assert!(matches!(f.solve(&names(p)), Err(Error::NotIdentifiable(_))));
        assert!(matches!(f.fold(&a[..3], &b[..2]), Err(Error::Data(_))));
        assert!(matches!(
            f.merge(&TriangularFactor::new(p + 1)),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            TriangularFactor::new(p).solve(&names(p)),
            Err(Error::NotIdentifiable(_))
        ));
    }

    #[test]
    fn split_fold_equals_the_fold_of_the_full_rows() {
        // rows touching columns 0..4 or 4..7 only, or none (zero rows), as eq (18) does
        let (rows, widths, p) = (9000, [4usize, 3], 7);
        let (a, b) = problem(rows, p, 17);
        let part = |t: usize| match t % 5 {
            0 | 2 => Some(0),
            1 | 4 => Some(1),
            _ => None,
        };
        let mut full = vec![0.0; rows * p];
        for t in 0..rows {
            match part(t) {
                Some(0) => full[t * p..t * p + 4].copy_from_slice(&a[t * p..t * p + 4]),
                Some(_) => full[t * p + 4..t * p + 7].copy_from_slice(&a[t * p + 4..t * p + 7]),
                None => {}
            }
        }
        let want = dense(&full, rows, p, &b);
        // every candidate row is written, as the cascade's producer does
        let (a, b) = (&a, &b);
        let fill_with = |drop_right: bool| {
            move |t: usize, split: &mut SplitRows| {
                let k = part(t).filter(|&k| !(drop_right && k == 1));
                split.slot(0).copy_from_slice(&a[t * p..t * p + 4]);
                split.keep(0, b[t], k == Some(0));
                split.slot(1).copy_from_slice(&a[t * p + 4..t * p + 7]);
                split.keep(1, b[t], k == Some(1));
                split.keep_zero(b[t], k.is_none());
            }
        };
        for threads in [1, 2, 3] {
            let (f, zero_rows) = fold_parallel_split(rows, &widths, threads, fill_with(false));
            assert_eq!(zero_rows, (0..rows).filter(|t| part(*t).is_none()).count());
            assert_eq!(f.rows(), rows);
            assert_eq!(f.cols(), p);
            assert_same(&f.solve(&names(p)).unwrap(), &want, 1e-10);
            assert_eq!(
                fold_parallel_split(rows, &widths, threads, fill_with(false)).0,
                f
            );
        }
        // a part without rows is a zero column, reported by name like any other
        let (none, _) = fold_parallel_split(rows, &widths, 2, fill_with(true));
        match none.solve(&names(p)) {
            Err(Error::NotIdentifiable(m)) => {
                assert!(m.contains("p4") && m.contains("zero"), "{m}")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn fold_stream_gives_the_same_bits_on_one_and_two_threads() {
        let (rows, p) = (5000, 8);
        let (a, b) = problem(rows, p, 13);
        let produce = |sink: &mut RowSink| {
            for t in 0..rows {
                sink.push(&a[t * p..(t + 1) * p], b[t])?;
            }
            Ok(())
        };
        let (one, ss1) = fold_stream(p, 1, produce).unwrap();
        let (two, ss2) = fold_stream(p, 2, produce).unwrap();
        assert_eq!((&one, ss1), (&two, ss2));
        let mut sequential = TriangularFactor::new(p);
        sequential.fold(&a, &b).unwrap();
        assert_eq!(one, sequential);
        let want: f64 = b.iter().map(|v| v * v).sum();
        assert!((ss1 - want).abs() < 1e-12 * want);
        // a producer's error comes back; a bad row is an error
        for threads in [1, 2] {
            let failed = fold_stream(p, threads, |sink| {
                for t in 0..1000 {
                    sink.push(&a[t * p..(t + 1) * p], b[t])?;
                }
                Err(Error::Model("stop".into()))
            });
            assert_eq!(failed, Err(Error::Model("stop".into())));
            let bad = fold_stream(p, threads, |sink| sink.push(&a[..p - 1], 1.0));
            assert!(matches!(bad, Err(Error::Data(_))));
        }
    }
}
