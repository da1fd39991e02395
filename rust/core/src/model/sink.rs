//! Where a free-run simulation's output goes, chunk by chunk: collected into a vector, or
//! folded straight into the output-error cost against a measured record, so that the cost of
//! a 1e8-sample record needs no 1e8-sample buffer.

/// Takes a simulation's output in order, one chunk at a time.
pub trait OutputSink {
    fn take(&mut self, values: impl Iterator<Item = f64>);
}

impl OutputSink for Vec<f64> {
    #[inline(always)]
    fn take(&mut self, values: impl Iterator<Item = f64>) {
        self.extend(values);
    }
}

/// sum (y(t) - y_sim(t))^2 over t >= `warmup`, summed in time order (the sum
/// `output_error_cost` forms from the collected output, bit for bit).
pub struct ErrorSum<'a> {
    y: &'a [f64],
    warmup: usize,
    t: usize,
    pub sum: f64,
}

impl<'a> ErrorSum<'a> {
    /// The measured record `y` (its length the simulation's) and its warm-up.
    pub fn new(y: &'a [f64], warmup: usize) -> Self {
        Self {
            y,
            warmup,
            t: 0,
            sum: -0.0,
        }
    }
}

impl OutputSink for ErrorSum<'_> {
    #[inline(always)]
    fn take(&mut self, values: impl Iterator<Item = f64>) {
        for v in values {
            if self.t >= self.warmup {
                let e = self.y[self.t] - v;
                self.sum += e * e;
            }
            self.t += 1;
        }
    }
}
