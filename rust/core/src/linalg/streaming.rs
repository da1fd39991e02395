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
use crate::guard;
use crate::linalg::lstsq::{solve_triangular, LeastSquares};

/// Rows folded per Householder sweep: the stacked [R_aug; block] (p+1 columns) stays in the
/// core's L2 cache. Measured on p = 11 at N = 1e5 (faer's unblocked QR): 256 to 4096 rows are
/// within 10 % of each other; larger blocks only cost memory.
pub const BLOCK_ROWS: usize = 1024;

/// Blocks per hand-over from a `fold_stream` producer to its folding thread: small enough
/// that the folding thread starts early on 1e5 rows, large enough to wake it rarely. One
/// output-error factor at N = 1e5 / 1e6 (2026-11-22, this 2-core machine), 2 / 4 / 16 blocks:
/// cascade 3.5 / 3.6 / 4.3 ms and 34 / 33 / 32 ms; sandwich 7.8 / 7.9 / 8.8 ms and 72 / 67 /
/// 66 ms.
const HANDOVER_BLOCKS: usize = 4;

/// Hand-over buffers (rows, targets) kept between `fold_stream_parts` calls on this thread, at
/// most `SPARE_BUFFERS` (about 2 MB): fresh ones of this size come from the OS page by page.
/// The cascade output-error factor at N = 1e5 on 2 threads (2026-11-22, this machine): 286
/// page faults and 41 ns per sample with fresh buffers, none and 33 ns with spares.
const SPARE_BUFFERS: usize = 8;

thread_local! {
    static SPARE: std::cell::RefCell<Vec<(Vec<f64>, Vec<f64>)>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// A hand-over buffer pair from this thread's spares, or new ones.
fn spare_buffers(rows: usize, values: usize) -> (Vec<f64>, Vec<f64>) {
    let (mut a, mut b) = SPARE
        .with(|s| s.borrow_mut().pop())
        .unwrap_or_else(|| (Vec::with_capacity(values), Vec::with_capacity(rows)));
    a.clear();
    b.clear();
    a.reserve(values);
    b.reserve(rows);
    (a, b)
}

/// Keep a buffer pair for the next call on this thread.
fn keep_spare(buffers: (Vec<f64>, Vec<f64>)) {
    SPARE.with(|s| {
        let mut s = s.borrow_mut();
        if s.len() < SPARE_BUFFERS {
            s.push(buffers);
        }
    });
}

/// Upper bound of `default_threads`.
pub const MAX_THREADS: usize = 8;

/// Rows per thread from which a parallel fold pays: below it, spawning a thread and merging
/// its factor cost more than the thread saves. The cascade regression (p = 12, 2026-11-22,
/// this 2-core machine) on 1 / 2 threads: 129 / 168 us at 5000 rows, 254 / 220 us at 1e4.
pub const ROWS_PER_THREAD: usize = 8192;

/// `default_threads()`, at most one per `ROWS_PER_THREAD` rows of a regression.
pub fn threads_for(rows: usize) -> usize {
    default_threads().min((rows / ROWS_PER_THREAD).max(1))
}

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

    /// The factor over p columns of the rows of several factors whose columns overlap:
    /// column k of `parts[i].0` is column `parts[i].1[k]` here (the target stays the target).
    /// Folding each part's R_aug rows, so that R_aug^T R_aug is the sum of the parts' Gram
    /// matrices; `extra_sum_squares` joins the residual corner (targets whose rows are
    /// accounted for elsewhere, e.g. `StreamedParts::dispersion`); `rows` is the row count
    /// the parts stand for.
    pub fn embed_sum(
        p: usize,
        parts: &[(&TriangularFactor, &[usize])],
        rows: usize,
        extra_sum_squares: f64,
    ) -> Result<Self> {
        let n = p + 1;
        let mut out = Self::new(p);
        for (part, map) in parts {
            let m = part.p + 1;
            if map.len() != part.p || map.iter().any(|&c| c >= p) {
                return Err(Error::Data(format!(
                    "streaming least squares: a column map {map:?} for a factor of {} columns \
                     into {p} (internal shape mismatch)",
                    part.p
                )));
            }
            out.fold_block(m, |col, j| {
                let source = if j == p {
                    Some(part.p)
                } else {
                    map.iter().position(|&c| c == j)
                };
                for (i, c) in col.iter_mut().enumerate() {
                    *c = source.map_or(0.0, |k| part.r[i * m + k]);
                }
            });
        }
        let corner = &mut out.r[n * n - 1];
        *corner = (*corner * *corner + extra_sum_squares).sqrt();
        out.rows = rows;
        Ok(out)
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

    /// A^T b of the rows folded so far, as R^T (Q^T b) (R_aug^T R_aug = [A | b]^T [A | b]):
    /// the output-error gradient J^T r of a factor of [J | r].
    pub fn gradient(&self) -> Vec<f64> {
        let (p, n) = (self.p, self.p + 1);
        (0..p)
            .map(|j| (0..=j).map(|i| self.r[i * n + j] * self.r[i * n + p]).sum())
            .collect()
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
            // interrupted: stop early (the caller discards the partial factor)
            if (t - lo) % guard::CHUNK == 0 && guard::interrupted() {
                break;
            }
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
    let stop = guard::scope();
    std::thread::scope(|scope| {
        let work = &work;
        let handles: Vec<_> = bounds[1..]
            .iter()
            .map(|&(lo, hi)| {
                let stop = stop.clone();
                scope.spawn(move || {
                    guard::adopt(stop); // the caller's interruption reaches this thread
                    work(lo, hi)
                })
            })
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
        for chunk in (lo..hi).step_by(guard::CHUNK) {
            // interrupted: stop early (the caller discards the partial factors)
            if guard::interrupted() {
                break;
            }
            for t in chunk..(chunk + guard::CHUNK).min(hi) {
                fill(t, &mut split);
            }
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

/// Where a `fold_stream` producer pushes rows: each row belongs to one part (a factor over
/// that part's columns); full batches are folded here (one thread) or handed to a folding
/// thread (two), always in the order produced. A run of identical rows (`repeat`) is folded
/// as one: k rows [a | b_1], .., [a | b_k] have the Gram matrix of the single row
/// [sqrt(k) a | sqrt(k) mean(b)] plus sum (b_i - mean(b))^2 in the target's corner alone.
pub struct RowSink {
    widths: Vec<usize>,
    /// Rows gathered per part before a fold (local) or a hand-over to the folding thread.
    batch: usize,
    a: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    /// The last pushed row, still open to `repeat`.
    run: Option<Run>,
    rows: usize,
    sum_squares: f64,
    /// Sum over closed runs of sum (b_i - mean(b))^2.
    dispersion: f64,
    target: SinkTarget,
}

/// A row pushed k times: its part, k, its first target b_1, and the sums of d_i = b_i - b_1
/// and d_i^2 (the shifted-data form: no division per row, and deviations from a target of
/// the same run keep the cancellation in sum (b_i - mean)^2 = sum d_i^2 - (sum d_i)^2 / k
/// small).
struct Run {
    part: usize,
    count: usize,
    first: f64,
    sum_d: f64,
    sum_d2: f64,
}

enum SinkTarget {
    Local(Vec<TriangularFactor>),
    Channel {
        full: std::sync::mpsc::SyncSender<(usize, Vec<f64>, Vec<f64>)>,
        empty: std::sync::mpsc::Receiver<(Vec<f64>, Vec<f64>)>,
        /// With `own_every` > 0, every `own_every`-th batch (counted over all parts in
        /// `handed`) is folded by the producer into `own`, the others by the folding thread
        /// (`fold_stream_shared`); a fixed pattern, so a fixed result.
        own: Vec<TriangularFactor>,
        own_every: usize,
        handed: usize,
    },
}

/// What `fold_stream_parts` folded: one factor per part, the number of rows pushed (runs
/// counted in full), the sum of their squared targets, and the within-run dispersion of the
/// targets that the merged runs leave out of the factors.
pub struct StreamedParts {
    pub factors: Vec<TriangularFactor>,
    pub rows: usize,
    pub sum_squares: f64,
    pub dispersion: f64,
}

impl RowSink {
    /// Append one row of part 0 (`widths[0]` values) with its target.
    #[inline]
    pub fn push(&mut self, row: &[f64], target: f64) -> Result<()> {
        self.push_part(0, &[row], target)
    }

    /// Append one row of `part`, its values given in pieces (concatenated in order, together
    /// `widths[part]` values), with its target.
    #[inline]
    pub fn push_part(&mut self, part: usize, pieces: &[&[f64]], target: f64) -> Result<()> {
        let width: usize = pieces.iter().map(|p| p.len()).sum();
        if self.widths.get(part) != Some(&width) {
            return Err(Error::Data(format!(
                "streaming least squares: a row of {width} values for part {part} of column \
                 widths {:?} (internal shape mismatch)",
                self.widths
            )));
        }
        self.close_run()?;
        for piece in pieces {
            self.a[part].extend_from_slice(piece);
        }
        self.b[part].push(target);
        self.run = Some(Run {
            part,
            count: 1,
            first: target,
            sum_d: 0.0,
            sum_d2: 0.0,
        });
        self.rows += 1;
        self.sum_squares += target * target;
        Ok(())
    }

    /// The last pushed row once more, with this target; false (nothing added) when no row
    /// was pushed yet.
    #[inline]
    pub fn repeat(&mut self, target: f64) -> bool {
        let Some(run) = self.run.as_mut() else {
            return false;
        };
        run.count += 1;
        let d = target - run.first;
        run.sum_d += d;
        run.sum_d2 += d * d;
        self.rows += 1;
        self.sum_squares += target * target;
        true
    }

    /// Put the open run's merged row in place and hand over a full batch.
    fn close_run(&mut self) -> Result<()> {
        let Some(run) = self.run.take() else {
            return Ok(());
        };
        let (part, w) = (run.part, self.widths[run.part]);
        if run.count > 1 {
            let k = run.count as f64;
            let mean_d = run.sum_d / k;
            let scale = k.sqrt();
            let a = &mut self.a[part];
            let at = a.len() - w;
            for v in &mut a[at..] {
                *v *= scale;
            }
            if let Some(b) = self.b[part].last_mut() {
                *b = (run.first + mean_d) * scale;
            }
            self.dispersion += (run.sum_d2 - run.sum_d * mean_d).max(0.0);
        }
        if self.b[part].len() >= self.batch {
            self.flush(part)?;
        }
        Ok(())
    }

    fn flush(&mut self, part: usize) -> Result<()> {
        if self.b[part].is_empty() {
            return Ok(());
        }
        guard::check()?; // a batch of rows between two interruption checks
        match &mut self.target {
            SinkTarget::Local(factors) => {
                factors[part].fold(&self.a[part], &self.b[part])?;
                self.a[part].clear();
                self.b[part].clear();
            }
            SinkTarget::Channel {
                full,
                empty,
                own,
                own_every,
                handed,
            } => {
                *handed += 1;
                if *own_every > 0 && *handed % *own_every == 0 {
                    own[part].fold(&self.a[part], &self.b[part])?;
                    self.a[part].clear();
                    self.b[part].clear();
                    return Ok(());
                }
                let most = self.widths.iter().max().copied().unwrap_or(0);
                let (mut a, mut b) = match empty.try_recv() {
                    Ok((mut a, mut b)) => {
                        a.clear();
                        b.clear();
                        (a, b)
                    }
                    Err(_) => spare_buffers(self.batch, self.batch * most),
                };
                std::mem::swap(&mut a, &mut self.a[part]);
                std::mem::swap(&mut b, &mut self.b[part]);
                if full.send((part, a, b)).is_err() {
                    return Err(Error::Data(
                        "streaming least squares: the folding thread stopped (internal error)"
                            .into(),
                    ));
                }
            }
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        self.close_run()?;
        (0..self.widths.len()).try_for_each(|k| self.flush(k))
    }
}

/// Fold the rows that `produce` pushes (one part of p columns, no repeats) into a factor;
/// returns it with the sum of the squared targets. See `fold_stream_parts`.
pub fn fold_stream(
    p: usize,
    threads: usize,
    produce: impl FnOnce(&mut RowSink) -> Result<()>,
) -> Result<(TriangularFactor, f64)> {
    let mut out = fold_stream_parts(&[p], threads, produce)?;
    let factor = out
        .factors
        .pop()
        .unwrap_or_else(|| TriangularFactor::new(p));
    Ok((factor, out.sum_squares))
}

/// Fold the rows that `produce` pushes, in order, into one factor per part (`widths[k]`
/// columns each). With `threads` >= 2 the folding runs on a second thread while `produce`
/// computes the next rows (a sequential recursion, e.g. sensitivities); the result is the
/// same bits either way.
pub fn fold_stream_parts(
    widths: &[usize],
    threads: usize,
    produce: impl FnOnce(&mut RowSink) -> Result<()>,
) -> Result<StreamedParts> {
    fold_stream_inner(widths, threads, 0, produce)
}

/// `fold_stream` for rows that are cheap to make against their fold (many columns): with
/// `threads` >= 2 the producer folds every `own_every`-th batch itself (into a factor merged
/// at the end) while the second thread folds the others, so both cores fold. The result
/// depends on `threads` and `own_every` only through rounding (a fixed pattern: the same
/// bits run to run). Wiener-Hammerstein at p = 41 (2026-11-24): the producer's rows cost
/// about a quarter of their fold.
pub fn fold_stream_shared(
    p: usize,
    threads: usize,
    own_every: usize,
    produce: impl FnOnce(&mut RowSink) -> Result<()>,
) -> Result<(TriangularFactor, f64)> {
    let mut out = fold_stream_inner(&[p], threads, own_every, produce)?;
    let factor = out
        .factors
        .pop()
        .unwrap_or_else(|| TriangularFactor::new(p));
    Ok((factor, out.sum_squares))
}

fn fold_stream_inner(
    widths: &[usize],
    threads: usize,
    own_every: usize,
    produce: impl FnOnce(&mut RowSink) -> Result<()>,
) -> Result<StreamedParts> {
    let new_factors = || {
        widths
            .iter()
            .map(|&w| TriangularFactor::new(w))
            .collect::<Vec<_>>()
    };
    let sink = |target, batch: usize| {
        let (a, b) = widths
            .iter()
            .map(|&w| spare_buffers(batch, batch * w))
            .unzip();
        RowSink {
            widths: widths.to_vec(),
            batch,
            a,
            b,
            run: None,
            rows: 0,
            sum_squares: 0.0,
            dispersion: 0.0,
            target,
        }
    };
    let done = |s: RowSink, factors| StreamedParts {
        factors,
        rows: s.rows,
        sum_squares: s.sum_squares,
        dispersion: s.dispersion,
    };
    if threads <= 1 {
        let mut s = sink(SinkTarget::Local(new_factors()), BLOCK_ROWS);
        produce(&mut s)?;
        s.finish()?;
        let factors = match std::mem::replace(&mut s.target, SinkTarget::Local(Vec::new())) {
            SinkTarget::Local(f) => f,
            SinkTarget::Channel { .. } => unreachable!("a local sink stays local"),
        };
        for (a, b) in s.a.drain(..).zip(s.b.drain(..)) {
            keep_spare((a, b));
        }
        return Ok(done(s, factors));
    }
    std::thread::scope(|scope| {
        let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<(usize, Vec<f64>, Vec<f64>)>(2);
        let (empty_tx, empty_rx) = std::sync::mpsc::channel();
        let folder = scope.spawn(move || {
            let mut factors = new_factors();
            let mut status = Ok(());
            for (part, a, b) in full_rx {
                if status.is_ok() {
                    status = factors[part].fold(&a, &b);
                }
                let _ = empty_tx.send((a, b)); // the producer may be gone
            }
            status.map(|_| factors)
        });
        // hand over several blocks at once: fewer wake-ups of the folding thread
        let mut s = sink(
            SinkTarget::Channel {
                full: full_tx,
                empty: empty_rx,
                own: new_factors(),
                own_every,
                handed: 0,
            },
            HANDOVER_BLOCKS * BLOCK_ROWS,
        );
        let produced = produce(&mut s).and_then(|_| s.finish());
        let SinkTarget::Channel {
            full, empty, own, ..
        } = std::mem::replace(&mut s.target, SinkTarget::Local(Vec::new()))
        else {
            unreachable!("the sink was made with a channel")
        };
        drop(full); // closes the channel: the folder finishes
        let folded = match folder.join() {
            Ok(f) => f,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        // the producer's own batches join the folder's factors (nothing to merge without)
        let folded = folded.and_then(|mut factors| {
            for (f, o) in factors.iter_mut().zip(&own) {
                if o.rows > 0 {
                    f.merge(o)?;
                }
            }
            Ok(factors)
        });
        // every buffer is back: the folder returned each one it took
        for buffers in empty.try_iter() {
            keep_spare(buffers);
        }
        for (a, b) in s.a.drain(..).zip(s.b.drain(..)) {
            keep_spare((a, b));
        }
        produced?;
        Ok(done(s, folded?))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::lstsq::solve;

    use crate::test_params::{lcg_unit, names};

    /// Uniform in (-1, 1) from the tests' generator.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            lcg_unit(&mut self.0) * 2.0 - 1.0
        }
    }

    #[test]
    fn the_factors_gradient_is_a_transpose_b() {
        let (rows, p) = (3000, 6);
        let (a, b) = problem(rows, p, 17);
        let mut factor = TriangularFactor::new(p);
        factor.fold(&a, &b).unwrap();
        let want: Vec<f64> = (0..p)
            .map(|j| (0..rows).map(|r| a[r * p + j] * b[r]).sum())
            .collect();
        for (g, w) in factor.gradient().iter().zip(&want) {
            assert!((g - w).abs() <= 1e-10 * w.abs().max(1.0), "{g} vs {w}");
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
            unscaled_covariance: crate::linalg::lstsq::inverse_gram(&rrow, &scale),
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
    fn parts_with_repeated_rows_give_the_factor_of_all_rows() {
        // Rows over 7 columns in two overlapping parts (0..5 and 0..3 + 5..7), each pushed
        // once and then repeated 0..4 times with new targets, against the plain fold of
        // every row written out in full.
        let (rows, p) = (6000, 7);
        let (a, b) = problem(rows, p, 17);
        let left: Vec<usize> = (0..5).collect();
        let right: Vec<usize> = (0..3).chain(5..7).collect();
        let mut g = Lcg(29);
        let plan: Vec<(usize, usize)> = (0..rows)
            .map(|t| (t % 2 + (t % 7 == 3) as usize) % 2)
            .map(|part| (part, ((g.next() + 1.0) * 2.5) as usize)) // (part, repeats 0..4)
            .collect();
        let mut full_a = Vec::new();
        let mut full_b = Vec::new();
        for (t, &(part, reps)) in plan.iter().enumerate() {
            let cols = if part == 0 { &left } else { &right };
            let mut row = vec![0.0; p];
            for &c in cols {
                row[c] = a[t * p + c];
            }
            for k in 0..=reps {
                full_a.extend_from_slice(&row);
                full_b.push(b[t] + 0.01 * k as f64 * g.next() + if k > 0 { 1e3 } else { 0.0 });
            }
        }
        let mut want = TriangularFactor::new(p);
        want.fold(&full_a, &full_b).unwrap();
        let produce = |sink: &mut RowSink| {
            let mut at = 0;
            for (t, &(part, reps)) in plan.iter().enumerate() {
                let cols = if part == 0 { &left } else { &right };
                let row: Vec<f64> = cols.iter().map(|&c| a[t * p + c]).collect();
                sink.push_part(part, &[&row[..2], &row[2..]], full_b[at])?;
                for k in 1..=reps {
                    assert!(sink.repeat(full_b[at + k]));
                }
                at += reps + 1;
            }
            Ok(())
        };
        let one = fold_stream_parts(&[5, 5], 1, produce).unwrap();
        let two = fold_stream_parts(&[5, 5], 2, produce).unwrap();
        assert_eq!((&one.factors, one.rows), (&two.factors, two.rows));
        assert_eq!(
            (one.sum_squares, one.dispersion),
            (two.sum_squares, two.dispersion)
        );
        assert_eq!(one.rows, full_b.len());
        let ss: f64 = full_b.iter().map(|v| v * v).sum();
        assert!(rel(one.sum_squares, ss) < 1e-13);
        let got = TriangularFactor::embed_sum(
            p,
            &[(&one.factors[0], &left), (&one.factors[1], &right)],
            one.rows,
            one.dispersion,
        )
        .unwrap();
        assert_eq!(got.rows(), want.rows());
        // the same Gram matrix, hence the same solution and residual (the repeated rows'
        // targets are 1e3 off, so the dispersion carries most of the residual)
        let n = p + 1;
        let (r, w) = (got.r_aug(), want.r_aug());
        for i in 0..n {
            for j in i..n {
                let g1: f64 = (0..n).map(|k| r[k * n + i] * r[k * n + j]).sum();
                let g2: f64 = (0..n).map(|k| w[k * n + i] * w[k * n + j]).sum();
                let size = (w[i * n + i] * w[j * n + j]).abs().max(1.0);
                assert!((g1 - g2).abs() < 1e-10 * size, "{i} {j}: {g1} {g2}");
            }
        }
        assert_same(
            &got.solve(&names(p)).unwrap(),
            &want.solve(&names(p)).unwrap(),
            1e-9,
        );
        // nothing to repeat before the first row; a row of the wrong width is an error
        let none = fold_stream_parts(&[5, 5], 1, |sink| {
            assert!(!sink.repeat(1.0));
            Ok(())
        })
        .unwrap();
        assert_eq!((none.rows, none.sum_squares), (0, 0.0));
        for threads in [1, 2] {
            let bad =
                fold_stream_parts(&[5, 5], threads, |sink| sink.push_part(1, &[&a[..4]], 1.0));
            assert!(matches!(bad, Err(Error::Data(_))));
        }
        let map = [0usize, 1, 9, 3, 4];
        let bad_map = TriangularFactor::embed_sum(p, &[(&one.factors[0], &map)], 1, 0.0);
        assert!(matches!(bad_map, Err(Error::Data(_))));
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
        // the hand-over buffers those calls left filled are this thread's spares now: reused,
        // they change nothing
        for threads in [2, 1, 2] {
            assert_eq!(
                fold_stream(p, threads, produce).unwrap(),
                (one.clone(), ss1)
            );
        }
    }

    #[test]
    fn shared_folding_agrees_with_one_folder_and_repeats_its_bits() {
        // rows over several hand-over batches: the producer folds every third batch, the
        // folding thread the rest, merged at the end
        let (rows, p) = (4 * HANDOVER_BLOCKS * BLOCK_ROWS + 321, 12);
        let (a, b) = problem(rows, p, 17);
        let produce = |sink: &mut RowSink| {
            for t in 0..rows {
                sink.push(&a[t * p..(t + 1) * p], b[t])?;
            }
            Ok(())
        };
        let (one, ss1) = fold_stream(p, 1, produce).unwrap();
        let (shared, ss2) = fold_stream_shared(p, 2, 3, produce).unwrap();
        assert_eq!(ss1, ss2);
        assert_eq!(shared.rows, rows);
        let names = names(p);
        let (x1, x2) = (one.solve(&names).unwrap(), shared.solve(&names).unwrap());
        for j in 0..p {
            assert!((x1.theta[j] - x2.theta[j]).abs() < 1e-12 * (1.0 + x1.theta[j].abs()));
        }
        // R^T R is the same to rounding (R itself only up to the signs of its rows)
        let n = p + 1;
        for i in 0..n {
            for j in 0..n {
                let gram = |r: &[f64]| (0..n).map(|k| r[k * n + i] * r[k * n + j]).sum::<f64>();
                let (g1, g2) = (gram(one.r_aug()), gram(shared.r_aug()));
                assert!(
                    (g1 - g2).abs() < 1e-11 * (1.0 + g1.abs()),
                    "{i} {j}: {g1} {g2}"
                );
            }
        }
        // a fixed pattern: the same bits on every run; one thread or own_every 0 is fold_stream
        for _ in 0..3 {
            assert_eq!(
                fold_stream_shared(p, 2, 3, produce).unwrap(),
                (shared.clone(), ss2)
            );
        }
        assert_eq!(
            fold_stream_shared(p, 1, 3, produce).unwrap(),
            (one.clone(), ss1)
        );
        assert_eq!(fold_stream_shared(p, 2, 0, produce).unwrap(), (one, ss1));
    }
}
