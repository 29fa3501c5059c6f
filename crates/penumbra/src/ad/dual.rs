//! Forward-mode dual numbers: a value and its derivative along one tangent
//! direction of the parameter space.

use super::{weighted_sum, Real, ScalarReal};
use crate::params::{ParamId, ParamView};
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// `v + d·ε` with `ε² = 0`: `d` is the directional derivative of `v` along
/// the tangent set in the parameter store.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dual {
    pub v: f32,
    pub d: f32,
}

impl Dual {
    #[inline(always)]
    pub fn new(v: f32, d: f32) -> Self {
        Dual { v, d }
    }
    /// Applies a scalar function with value `f` and derivative `df` at `v`.
    #[inline(always)]
    fn chain(self, f: f32, df: f32) -> Self {
        Dual::new(f, df * self.d)
    }
}

impl ScalarReal for Dual {
    #[inline(always)]
    fn from_param(store: &ParamView, id: ParamId, index: usize) -> Self {
        Dual::new(store.value(id, index), store.tangent(id, index))
    }
    #[inline(always)]
    fn param_sum(store: &ParamView, id: ParamId, terms: &[(usize, f32)]) -> Self {
        // the sums a product and a sum per element would make, bit for bit
        let d = store.tangents(id).map_or(0.0, |t| weighted_sum(t, terms));
        Dual::new(weighted_sum(store.data(id), terms), d)
    }
}

impl Real for Dual {
    type Prim = f32;
    type Mask = bool;
    #[inline(always)]
    fn cst(v: f32) -> Self {
        Dual::new(v, 0.0)
    }
    #[inline(always)]
    fn from_prim(p: f32) -> Self {
        Self::cst(p)
    }
    #[inline(always)]
    fn val(self) -> f32 {
        self.v
    }
    #[inline(always)]
    fn select(m: bool, a: Self, b: Self) -> Self {
        if m {
            a
        } else {
            b
        }
    }
    fn tracks(store: &ParamView, id: ParamId) -> bool {
        store.has_tangent(id)
    }
    #[inline(always)]
    fn is_const(self) -> bool {
        self.d == 0.0
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, if s > 0.0 { 0.5 / s } else { 0.0 })
    }
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    fn ln(self) -> Self {
        self.chain(self.v.ln(), 1.0 / self.v)
    }
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    fn tan(self) -> Self {
        let t = self.v.tan();
        self.chain(t, 1.0 + t * t)
    }
    fn acos(self) -> Self {
        let x = self.v.clamp(-1.0, 1.0);
        let s = (1.0 - x * x).sqrt();
        self.chain(x.acos(), if s > 0.0 { -1.0 / s } else { 0.0 })
    }
    fn asin(self) -> Self {
        let x = self.v.clamp(-1.0, 1.0);
        let s = (1.0 - x * x).sqrt();
        self.chain(x.asin(), if s > 0.0 { 1.0 / s } else { 0.0 })
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = self.v * self.v + x.v * x.v;
        let d = if r2 > 0.0 {
            (x.v * self.d - self.v * x.d) / r2
        } else {
            0.0
        };
        Dual::new(self.v.atan2(x.v), d)
    }
    fn powf(self, e: f32) -> Self {
        let p = self.v.powf(e);
        let dp = if e == 0.0 {
            0.0
        } else {
            e * self.v.powf(e - 1.0)
        };
        self.chain(p, dp)
    }
    fn abs(self) -> Self {
        if self.v < 0.0 {
            -self
        } else {
            self
        }
    }
}

impl Add for Dual {
    type Output = Dual;
    #[inline(always)]
    fn add(self, o: Dual) -> Dual {
        Dual::new(self.v + o.v, self.d + o.d)
    }
}
impl Sub for Dual {
    type Output = Dual;
    #[inline(always)]
    fn sub(self, o: Dual) -> Dual {
        Dual::new(self.v - o.v, self.d - o.d)
    }
}
impl Mul for Dual {
    type Output = Dual;
    #[inline(always)]
    fn mul(self, o: Dual) -> Dual {
        Dual::new(self.v * o.v, self.d * o.v + self.v * o.d)
    }
}
impl Div for Dual {
    type Output = Dual;
    #[inline(always)]
    fn div(self, o: Dual) -> Dual {
        // primal by a true division, so that f32 and Dual primals agree
        let v = self.v / o.v;
        Dual::new(v, (self.d - v * o.d) / o.v)
    }
}
impl Neg for Dual {
    type Output = Dual;
    #[inline(always)]
    fn neg(self) -> Dual {
        Dual::new(-self.v, -self.d)
    }
}
impl Add<f32> for Dual {
    type Output = Dual;
    #[inline(always)]
    fn add(self, o: f32) -> Dual {
        Dual::new(self.v + o, self.d)
    }
}
impl Sub<f32> for Dual {
    type Output = Dual;
    #[inline(always)]
    fn sub(self, o: f32) -> Dual {
        Dual::new(self.v - o, self.d)
    }
}
impl Mul<f32> for Dual {
    type Output = Dual;
    #[inline(always)]
    fn mul(self, o: f32) -> Dual {
        Dual::new(self.v * o, self.d * o)
    }
}
impl Div<f32> for Dual {
    type Output = Dual;
    #[inline(always)]
    fn div(self, o: f32) -> Dual {
        Dual::new(self.v / o, self.d / o)
    }
}
impl AddAssign for Dual {
    #[inline(always)]
    fn add_assign(&mut self, o: Dual) {
        *self = *self + o;
    }
}
impl SubAssign for Dual {
    #[inline(always)]
    fn sub_assign(&mut self, o: Dual) {
        *self = *self - o;
    }
}
impl MulAssign for Dual {
    #[inline(always)]
    fn mul_assign(&mut self, o: Dual) {
        *self = *self * o;
    }
}
impl DivAssign for Dual {
    #[inline(always)]
    fn div_assign(&mut self, o: Dual) {
        *self = *self / o;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central finite difference of `f` at `x`, in f64 for accuracy.
    fn fd(f: impl Fn(f64) -> f64, x: f64) -> f64 {
        let h = 1e-5;
        (f(x + h) - f(x - h)) / (2.0 * h)
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let x = 0.37f32;
        let dx = Dual::new(x, 1.0);
        let cases: Vec<(Dual, f64)> = vec![
            (dx.sqrt(), fd(f64::sqrt, x as f64)),
            (dx.exp(), fd(f64::exp, x as f64)),
            (dx.ln(), fd(f64::ln, x as f64)),
            (dx.sin(), fd(f64::sin, x as f64)),
            (dx.cos(), fd(f64::cos, x as f64)),
            (dx.tan(), fd(f64::tan, x as f64)),
            (dx.acos(), fd(f64::acos, x as f64)),
            (dx.asin(), fd(f64::asin, x as f64)),
            (dx.powf(2.7), fd(|t| t.powf(2.7), x as f64)),
            (dx.atan2(Dual::cst(0.8)), fd(|t| t.atan2(0.8), x as f64)),
            (Dual::cst(0.8).atan2(dx), fd(|t| 0.8f64.atan2(t), x as f64)),
            (dx.pow(dx), fd(|t| t.powf(t), x as f64)),
            (
                (dx * dx + dx) / (dx - 2.0),
                fd(|t| (t * t + t) / (t - 2.0), x as f64),
            ),
        ];
        for (i, (d, want)) in cases.iter().enumerate() {
            assert!(
                (d.d as f64 - want).abs() <= 1e-4 * want.abs().max(1.0),
                "case {i}: dual {} vs fd {want}",
                d.d
            );
        }
    }
}
