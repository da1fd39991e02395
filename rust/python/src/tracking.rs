//! The online identification of `backlashid._core` (rust/core/src/tracking): the recursive
//! estimator of a cascade or sandwich with its change detector. A block's trajectory crosses as two
//! (rows, p) arrays, the alarms as tuples; the state as a flat list of numbers (`save`).

use backlashid_core::guard;
use backlashid_core::tracking::{
    DetectorOptions, Method, MonitorOptions, Options, Orders, Sink, Tracker, MAX_MONITOR_DEGREES,
};
use numpy::PyArrayMethods;
use pyo3::prelude::*;

use crate::convert::{matrix, signal, vec_f64, MatrixOut, SignalIn, SignalOut};
use crate::errors::{run, CoreError, DataError};

/// (sample, direction, width, reference, statistic).
type AlarmOut = (u64, i8, f64, f64, f64);
/// (spacing, reference, slack, threshold, holdoff).
type DetectorIn = (u64, u32, f64, f64, u32);
/// (window, lags, thresholds for 1, 2, .. degrees of freedom, confirm, clear, whiteness).
type MonitorIn = (u64, usize, Vec<f64>, u32, u32, bool);
/// A monitor window: (last sample, Q, its degrees of freedom, mismatch verdict after it, Q_psi,
/// its degrees of freedom, "unsettled" verdict after it).
type WindowOut = (u64, f64, usize, bool, f64, usize, bool);

#[pyclass(module = "backlashid._core", name = "Tracker")]
pub(crate) struct PyTracker(Tracker);

#[pymethods]
impl PyTracker {
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (na, nb, degree, theta0, covariance, noise_var, noise_count, method, forgetting, drift, noise_memory, detector, nr=0, ns=0, monitor=None, innovation_bound=f64::INFINITY))]
    fn new(
        na: usize,
        nb: usize,
        degree: usize,
        theta0: Vec<f64>,
        covariance: SignalIn<'_>,
        noise_var: f64,
        noise_count: f64,
        method: &str,
        forgetting: f64,
        drift: Vec<f64>,
        noise_memory: f64,
        detector: Option<DetectorIn>,
        nr: usize,
        ns: usize,
        monitor: Option<MonitorIn>,
        innovation_bound: f64,
    ) -> PyResult<Self> {
        let method = match method {
            "regression" => Method::Regression,
            "prediction_error" => Method::PredictionError,
            other => {
                return Err(DataError::new_err(format!(
                    "method = {other:?}: give \"prediction_error\" or \"regression\""
                )))
            }
        };
        let (cov, rows, cols) = matrix("covariance", &covariance)?;
        if rows != cols {
            return Err(DataError::new_err("the covariance must be a square matrix"));
        }
        let options = Options {
            method,
            forgetting,
            drift,
            noise_memory,
            innovation_bound,
        };
        let detector =
            detector.map(
                |(spacing, reference, slack, threshold, holdoff)| DetectorOptions {
                    spacing,
                    reference,
                    slack,
                    threshold,
                    holdoff,
                },
            );
        let orders = Orders {
            na,
            nb,
            degree,
            nr,
            ns,
        };
        let monitor = monitor
            .map(|(window, lags, given, confirm, clear, whiteness)| {
                if given.len() > MAX_MONITOR_DEGREES {
                    return Err(DataError::new_err(format!(
                        "{} monitor thresholds: give at most {MAX_MONITOR_DEGREES}",
                        given.len()
                    )));
                }
                // a degree without a threshold stays 0: MonitorOptions::check refuses it
                let mut thresholds = [0.0; MAX_MONITOR_DEGREES];
                thresholds[..given.len()].copy_from_slice(&given);
                Ok(MonitorOptions {
                    window,
                    lags,
                    thresholds,
                    confirm,
                    clear,
                    whiteness,
                })
            })
            .transpose()?;
        let tracker = Tracker::new(
            orders,
            &theta0,
            &cov,
            noise_var,
            noise_count,
            &options,
            detector,
            monitor,
        )
        .map_err(CoreError)?;
        Ok(Self(tracker))
    }

    /// The number of parameters p.
    #[getter]
    fn size(&self) -> usize {
        self.0.size()
    }

    /// Samples tracked so far.
    #[getter]
    fn samples(&self) -> u64 {
        self.0.samples()
    }

    /// Updates the stability guard rejected.
    #[getter]
    fn rejected(&self) -> u64 {
        self.0.rejected()
    }

    /// Updates the innovation bound refused.
    #[getter]
    fn refused(&self) -> u64 {
        self.0.refused()
    }

    /// The running noise-variance estimate.
    #[getter]
    fn noise_variance(&self) -> f64 {
        self.0.noise_variance()
    }

    /// The detector's CUSUM statistics (S+, S-) and whether it is armed; None without one.
    fn detector_state(&self) -> Option<(f64, f64, bool)> {
        self.0.detector().map(|d| {
            let (pos, neg) = d.statistics();
            (pos, neg, d.armed())
        })
    }

    /// Whether the mismatch monitor's verdict holds; None without a monitor.
    fn mismatch(&self) -> Option<bool> {
        self.0.monitor().map(|m| m.mismatch())
    }

    /// Whether the monitor's "unsettled" verdict holds; None without a monitor.
    fn unsettled(&self) -> Option<bool> {
        self.0.monitor().map(|m| m.unsettled())
    }

    /// The current physical estimate and its covariance.
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<(SignalOut<'py>, MatrixOut<'py>)> {
        let p = self.0.size();
        let (theta, cov) = self.0.estimate();
        Ok((vec_f64(py, theta), vec_f64(py, cov).reshape([p, p])?))
    }

    /// Track a block: (theta, standard errors) of every `every`-th sample as (rows, p)
    /// arrays, the alarms raised and the monitor's windows closed.
    #[allow(clippy::type_complexity)]
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        u: SignalIn<'py>,
        y: SignalIn<'py>,
        every: u64,
    ) -> PyResult<(
        MatrixOut<'py>,
        MatrixOut<'py>,
        Vec<AlarmOut>,
        Vec<WindowOut>,
    )> {
        let (u, y) = (signal("u", &u)?, signal("y", &y)?);
        if every == 0 {
            return Err(DataError::new_err("every must be a whole number >= 1"));
        }
        let p = self.0.size();
        let rows = self.0.recorded(u.len(), every);
        let tracker = &mut self.0;
        let (theta, se, alarms, windows) = run(py, || {
            let mut theta = guard::filled(rows * p, 0.0, "the tracked parameters")?;
            let mut se = guard::filled(rows * p, 0.0, "the standard errors")?;
            let (mut alarms, mut windows) = (Vec::new(), Vec::new());
            let mut sink = Sink {
                theta: &mut theta,
                se: &mut se,
                every,
                alarms: &mut alarms,
                windows: &mut windows,
            };
            tracker.update(&u, &y, &mut sink)?;
            Ok((theta, se, alarms, windows))
        })?;
        let alarms = alarms
            .into_iter()
            .map(|a| (a.sample, a.direction, a.width, a.reference, a.statistic))
            .collect();
        let windows = windows
            .into_iter()
            .map(|w| {
                (
                    w.sample,
                    w.statistic,
                    w.degrees,
                    w.mismatch,
                    w.parameter_statistic,
                    w.parameter_degrees,
                    w.unsettled,
                )
            })
            .collect();
        Ok((
            vec_f64(py, theta).reshape([rows, p])?,
            vec_f64(py, se).reshape([rows, p])?,
            alarms,
            windows,
        ))
    }

    /// Every number that changes while tracking.
    fn save(&self) -> Vec<f64> {
        self.0.save()
    }

    /// Restore `save`'s numbers (a tracker built with the same arguments).
    fn load(&mut self, state: Vec<f64>) -> PyResult<()> {
        Ok(self.0.load(&state).map_err(CoreError)?)
    }
}
