//! The switching-function form of the general backlash, eq (9)-(15), from which the
//! identification regressors (18) and (33) are built.
//!
//! With h(s) = 1 for s <= 0 (eq 11):
//!   f1(t) = h[ L(x(t)) - y(t-1) ]   (eq 12),   f2(t) = h[ y(t-1) - R(x(t)) ]   (eq 13),
//! and eq (15) gives y(t). Eq (14) lets f1 = f2 = 1 when the branches cross; we keep the case
//! order of eq (1): f1 wins, so f2 := f2 and not f1 (NOTES.md, item 2).

use crate::error::Result;
use crate::guard;
use crate::model::backlash::{check_memory, GeneralBacklash};
use crate::model::signal::check_signal;

/// Internal signals of eq (9)-(15) for one record.
#[derive(Debug, Clone, PartialEq)]
pub struct SwitchingSignals {
    /// xi_1(t) = x(t) + c_L (eq 9)
    pub xi1: Vec<f64>,
    /// xi_2(t) = x(t) - c_R (eq 10)
    pub xi2: Vec<f64>,
    pub f1: Vec<bool>,
    pub f2: Vec<bool>,
    /// y(t) by eq (15)
    pub y: Vec<f64>,
}

/// sum_{i=k}^n m_i xi^i, by explicit powers (the separated terms of eq 15).
fn power_sum(m: &[f64], xi: f64, from: usize) -> f64 {
    let mut p = xi.powi(from as i32);
    let mut acc = 0.0;
    for mi in &m[from - 1..] {
        acc += mi * p;
        p *= xi;
    }
    acc
}

/// Eq (12)-(13) with the case order of eq (1): (f1, f2) for x(t) given y(t-1). L(x) and
/// R(x), the branch sums of xi_1 = x + c_L and xi_2 = x - c_R (eq 9-10), are evaluated by
/// Horner's rule as the simulation's step evaluates them, so f1, f2 name exactly the case
/// the simulation takes.
#[inline]
pub fn switching(backlash: &GeneralBacklash, x: f64, y_prev: f64) -> (bool, bool) {
    let f1 = backlash.left().value(x) - y_prev <= 0.0; // eq (12)
    let f2 = y_prev - backlash.right().value(x) <= 0.0; // eq (13)
    (f1, f2 && !f1)
}

/// The backlash output by eq (12)-(15), with every internal signal, from memory y(0) = y0.
pub fn switching_form(backlash: &GeneralBacklash, x: &[f64], y0: f64) -> Result<SwitchingSignals> {
    check_signal("x", x)?;
    check_memory(y0)?;
    let (c_l, c_r) = (backlash.c_left(), backlash.c_right());
    let (m_l, m_r) = (
        backlash.left().coefficients(),
        backlash.right().coefficients(),
    );
    let n = x.len();
    let mut out = SwitchingSignals {
        xi1: guard::buffer(n, "xi1")?,
        xi2: guard::buffer(n, "xi2")?,
        f1: guard::buffer(n, "f1")?,
        f2: guard::buffer(n, "f2")?,
        y: guard::buffer(n, "y")?,
    };
    let mut y_prev = y0;
    for (t, &xt) in x.iter().enumerate() {
        if t % guard::CHUNK == 0 {
            guard::check()?;
        }
        let (f1, f2) = switching(backlash, xt, y_prev);
        let (xi1, xi2) = (xt + c_l, xt - c_r);
        let (g1, g2) = (f1 as u8 as f64, f2 as u8 as f64);
        // eq (15): the first terms separated so that x, c_L and c_R appear linearly
        let y = m_l[0] * xt * g1
            + m_l[0] * c_l * g1
            + if m_l.len() > 1 {
                power_sum(m_l, xi1, 2) * g1
            } else {
                0.0
            }
            + m_r[0] * xt * g2
            - m_r[0] * c_r * g2
            + if m_r.len() > 1 {
                power_sum(m_r, xi2, 2) * g2
            } else {
                0.0
            }
            + y_prev * (1.0 - g1) * (1.0 - g2);
        out.xi1.push(xi1);
        out.xi2.push(xi2);
        out.f1.push(f1);
        out.f2.push(f2);
        out.y.push(y);
        y_prev = y;
    }
    Ok(out)
}
