//! Primal numbers in lanes: `N` paths' values of one quantity, computed
//! with one instruction per operation where the processor has vectors of
//! that width (docs/perf/lanes.md).
//!
//! [`Lanes`] stores plain arrays and writes every operation as a loop over
//! the lanes, which LLVM turns into vector instructions of the width the
//! enclosing function is compiled for: 16-lane AVX-512 or 8-lane AVX2 code
//! inside a `#[target_feature]` entry point chosen at run time
//! ([`widest_lanes`]), SSE2 or NEON elsewhere, with no intrinsics and the
//! same results lane for lane as `f32`. The rule that makes it fast: every
//! function between such an entry point and these operations must be
//! inlined into it (everything here is `#[inline(always)]`); a generic
//! function compiled out of line gets the baseline target and a call per
//! operation.
//!
//! Elementary functions (`exp`, `ln`, `sin`, …) call the scalar `f32`
//! function per lane: the same values as one path at a time, at scalar
//! speed. Code on the hot path uses polynomials written over [`Float`]
//! instead (as the warps' sine and cosine), which vectorise and give the
//! same values at every width.

use super::{Float, Mask, Real};
use crate::math::V3;
use glam::Vec3;
use std::fmt::{self, Debug};
use std::ops::{
    Add, AddAssign, BitAnd, BitAndAssign, BitOr, BitOrAssign, Div, DivAssign, Mul, MulAssign, Neg,
    Not, Sub, SubAssign,
};

/// `N` values of one primal quantity, one per path.
#[derive(Clone, Copy, PartialEq)]
pub struct Lanes<const N: usize>(pub [f32; N]);

/// Which of `N` lanes a condition holds in: all bits set (-1) where it
/// holds, 0 elsewhere, the form vector compares and blends use.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct LaneMask<const N: usize>(pub [i32; N]);

/// Eight lanes: one AVX2 register.
pub type F32x8 = Lanes<8>;
/// Sixteen lanes: one AVX-512 register.
pub type F32x16 = Lanes<16>;

/// The number of lanes whose operations this processor executes as one
/// vector instruction: 16 with AVX-512 (F, VL, DQ, BW), 8 with AVX2 and
/// FMA, 1 otherwise (and on other architectures, until they get entry
/// points of their own).
pub fn widest_lanes() -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx512vl")
            && is_x86_feature_detected!("avx512dq")
            && is_x86_feature_detected!("avx512bw")
        {
            return 16;
        }
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return 8;
        }
    }
    1
}

/// `[f(0), …, f(N − 1)]` as a plain loop: `std::array::from_fn` goes
/// through closures that LLVM left out of line, and code left out of line
/// is compiled without the target features of the entry point that runs
/// the lanes (docs/perf/lanes.md): every lane operation builds its array
/// here.
#[inline(always)]
pub fn each_lane<T: Copy + Default, const N: usize>(mut f: impl FnMut(usize) -> T) -> [T; N] {
    let mut out = [T::default(); N];
    for (i, o) in out.iter_mut().enumerate() {
        *o = f(i);
    }
    out
}

impl<const N: usize> Lanes<N> {
    #[inline(always)]
    pub fn splat(v: f32) -> Self {
        Lanes([v; N])
    }
    /// Lane `i`'s value from `f(i)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> f32) -> Self {
        Lanes(each_lane(f))
    }
    /// The largest integer not above each lane's value (one rounding
    /// instruction for all the lanes).
    #[inline(always)]
    pub fn floor(self) -> Self {
        self.map(f32::floor)
    }
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> Self {
        Lanes(each_lane(|i| f(self.0[i])))
    }
    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        Lanes(each_lane(|i| f(self.0[i], o.0[i])))
    }
    #[inline(always)]
    fn test(self, o: Self, f: impl Fn(f32, f32) -> bool) -> LaneMask<N> {
        LaneMask(each_lane(|i| -(f(self.0[i], o.0[i]) as i32)))
    }
}

impl<const N: usize> LaneMask<N> {
    /// Whether the condition holds in lane `i`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> bool {
        self.0[i] != 0
    }
    /// The mask from `f(i)` per lane.
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> bool) -> Self {
        LaneMask(each_lane(|i| -(f(i) as i32)))
    }
}

impl<const N: usize> Default for Lanes<N> {
    #[inline(always)]
    fn default() -> Self {
        Lanes::splat(0.0)
    }
}

impl<const N: usize> Debug for Lanes<N> {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.debug_list().entries(self.0.iter()).finish()
    }
}

impl<const N: usize> Debug for LaneMask<N> {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.debug_list()
            .entries(self.0.iter().map(|&m| m != 0))
            .finish()
    }
}

impl<const N: usize> From<f32> for Lanes<N> {
    #[inline(always)]
    fn from(v: f32) -> Self {
        Lanes::splat(v)
    }
}

macro_rules! lanes_binop {
    ($tr:ident, $f:ident, $tra:ident, $fa:ident, $op:tt) => {
        impl<const N: usize> $tr for Lanes<N> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                self.zip(o, |a, b| a $op b)
            }
        }
        impl<const N: usize> $tr<f32> for Lanes<N> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: f32) -> Self {
                self.map(|a| a $op o)
            }
        }
        impl<const N: usize> $tra for Lanes<N> {
            #[inline(always)]
            fn $fa(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
}
lanes_binop!(Add, add, AddAssign, add_assign, +);
lanes_binop!(Sub, sub, SubAssign, sub_assign, -);
lanes_binop!(Mul, mul, MulAssign, mul_assign, *);
lanes_binop!(Div, div, DivAssign, div_assign, /);

impl<const N: usize> Neg for Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|a| -a)
    }
}

macro_rules! mask_binop {
    ($tr:ident, $f:ident, $tra:ident, $fa:ident, $op:tt) => {
        impl<const N: usize> $tr for LaneMask<N> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                LaneMask(each_lane(|i| self.0[i] $op o.0[i]))
            }
        }
        impl<const N: usize> $tra for LaneMask<N> {
            #[inline(always)]
            fn $fa(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
}
mask_binop!(BitAnd, bitand, BitAndAssign, bitand_assign, &);
mask_binop!(BitOr, bitor, BitOrAssign, bitor_assign, |);

impl<const N: usize> Not for LaneMask<N> {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        LaneMask(self.0.map(|m| !m))
    }
}

impl<const N: usize> Mask for LaneMask<N> {
    #[inline(always)]
    fn splat(b: bool) -> Self {
        LaneMask([-(b as i32); N])
    }
    // folds rather than short-circuiting iterators, which would not
    // vectorise
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().fold(0, |a, &m| a | m) != 0
    }
    #[inline(always)]
    fn all(self) -> bool {
        self.0.iter().fold(-1, |a, &m| a & m) != 0
    }
}

impl<const N: usize> Real for Lanes<N> {
    const DIFFERENTIABLE: bool = false;
    type Prim = Self;
    type Mask = LaneMask<N>;
    #[inline(always)]
    fn cst(v: f32) -> Self {
        Lanes::splat(v)
    }
    #[inline(always)]
    fn from_prim(p: Self) -> Self {
        p
    }
    #[inline(always)]
    fn val(self) -> Self {
        self
    }
    #[inline(always)]
    fn select(m: LaneMask<N>, a: Self, b: Self) -> Self {
        Lanes(each_lane(|i| if m.0[i] != 0 { a.0[i] } else { b.0[i] }))
    }
    // each lane as `f32`'s implementation of `Real` computes it
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        self.map(f32::exp)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        self.map(f32::ln)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        self.map(f32::sin)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        self.map(f32::cos)
    }
    #[inline(always)]
    fn tan(self) -> Self {
        self.map(f32::tan)
    }
    #[inline(always)]
    fn acos(self) -> Self {
        self.map(<f32 as Real>::acos)
    }
    #[inline(always)]
    fn asin(self) -> Self {
        self.map(<f32 as Real>::asin)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        self.zip(x, f32::atan2)
    }
    #[inline(always)]
    fn powf(self, e: f32) -> Self {
        self.map(|a| a.powf(e))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self.map(f32::abs)
    }
    #[inline(always)]
    fn pow(self, e: Self) -> Self {
        self.zip(e, f32::powf)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.zip(o, f32::min)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.zip(o, f32::max)
    }
    #[inline(always)]
    fn clamp(self, lo: f32, hi: f32) -> Self {
        self.map(|a| a.clamp(lo, hi))
    }
}

impl<const N: usize> Float for Lanes<N> {
    #[inline(always)]
    fn lt(self, o: impl Into<Self>) -> LaneMask<N> {
        self.test(o.into(), |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, o: impl Into<Self>) -> LaneMask<N> {
        self.test(o.into(), |a, b| a <= b)
    }
    #[inline(always)]
    fn gt(self, o: impl Into<Self>) -> LaneMask<N> {
        self.test(o.into(), |a, b| a > b)
    }
    #[inline(always)]
    fn ge(self, o: impl Into<Self>) -> LaneMask<N> {
        self.test(o.into(), |a, b| a >= b)
    }
    #[inline(always)]
    fn equals(self, o: impl Into<Self>) -> LaneMask<N> {
        self.test(o.into(), |a, b| a == b)
    }
    #[inline(always)]
    fn finite(self) -> LaneMask<N> {
        self.test(self, |a, _| a.is_finite())
    }
}

/// The lanes of a vector whose value in lane `k` is `f(k)`.
#[inline(always)]
pub(crate) fn lanes3<const N: usize>(mut f: impl FnMut(usize) -> Vec3) -> V3<Lanes<N>> {
    let v: [Vec3; N] = each_lane(&mut f);
    V3::new(
        Lanes::<N>::from_fn(|k| v[k].x),
        Lanes::<N>::from_fn(|k| v[k].y),
        Lanes::<N>::from_fn(|k| v[k].z),
    )
}

/// Lane `k` of a vector.
#[inline(always)]
pub(crate) fn lane3<const N: usize>(v: V3<Lanes<N>>, k: usize) -> Vec3 {
    Vec3::new(v.x.0[k], v.y.0[k], v.z.0[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values that exercise every branch of the operations: signed zeros,
    /// tiny and huge magnitudes, the boundaries of acos' domain, ±∞, NaN.
    fn values() -> Vec<f32> {
        let mut v = vec![0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 1e-30, -1e-30, 3e30, -3e30];
        v.extend([1.0 + f32::EPSILON, -1.0 - f32::EPSILON, 7.25, -123.5]);
        v.extend([f32::INFINITY, f32::NEG_INFINITY, f32::NAN]);
        v.extend((0..40).map(|k| (k as f32 * 0.731).sin() * 4.0));
        v
    }

    fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// `N` lanes from `xs` starting at `k` (wrapping round), so that every
    /// value meets every other in some lane.
    fn lanes<const N: usize>(xs: &[f32], k: usize) -> Lanes<N> {
        Lanes::from_fn(|i| xs[(k + i * 7) % xs.len()])
    }

    type Unary<const N: usize> = (fn(Lanes<N>) -> Lanes<N>, fn(f32) -> f32, &'static str);
    type Binary<const N: usize> = (
        fn(Lanes<N>, Lanes<N>) -> Lanes<N>,
        fn(f32, f32) -> f32,
        &'static str,
    );
    type Test<const N: usize> = (LaneMask<N>, fn(f32, f32) -> bool, &'static str);

    fn check_width<const N: usize>() {
        let xs = values();
        for k in 0..xs.len() {
            let (a, b) = (lanes::<N>(&xs, k), lanes::<N>(&xs, k + 3));
            let unary: [Unary<N>; 13] = [
                (|x| x.sqrt(), |x| x.sqrt(), "sqrt"),
                (|x| x.exp(), |x| x.exp(), "exp"),
                (|x| x.ln(), |x| x.ln(), "ln"),
                (|x| x.sin(), |x| x.sin(), "sin"),
                (|x| x.cos(), |x| x.cos(), "cos"),
                (|x| Real::acos(x), |x| Real::acos(x), "acos"),
                (|x| Real::abs(x), |x| Real::abs(x), "abs"),
                (|x| x.safe_sqrt(), |x| x.safe_sqrt(), "safe_sqrt"),
                (
                    |x| Real::clamp(x, -0.5, 2.0),
                    |x| Real::clamp(x, -0.5, 2.0),
                    "clamp",
                ),
                (|x| x.recip(), |x| x.recip(), "recip"),
                (|x| -x, |x| -x, "neg"),
                (|x| x.powf(1.5), |x| x.powf(1.5), "powf"),
                (|x| x * 3.0 - 0.25, |x| x * 3.0 - 0.25, "affine"),
            ];
            for (fl, fs, name) in unary {
                let r = fl(a);
                for i in 0..N {
                    assert!(same(r.0[i], fs(a.0[i])), "{name}({}) at width {N}", a.0[i]);
                }
            }
            let binary: [Binary<N>; 7] = [
                (|x, y| x + y, |x, y| x + y, "+"),
                (|x, y| x - y, |x, y| x - y, "-"),
                (|x, y| x * y, |x, y| x * y, "*"),
                (|x, y| x / y, |x, y| x / y, "/"),
                (|x, y| Real::min(x, y), |x, y| Real::min(x, y), "min"),
                (|x, y| Real::max(x, y), |x, y| Real::max(x, y), "max"),
                (|x, y| x.atan2(y), |x, y| x.atan2(y), "atan2"),
            ];
            for (fl, fs, name) in binary {
                let r = fl(a, b);
                for i in 0..N {
                    let e = fs(a.0[i], b.0[i]);
                    assert!(same(r.0[i], e), "{} {name} {} at width {N}", a.0[i], b.0[i]);
                }
            }
            let tests: [Test<N>; 6] = [
                (a.lt(b), |x, y| x < y, "<"),
                (a.le(b), |x, y| x <= y, "<="),
                (a.gt(b), |x, y| x > y, ">"),
                (a.ge(b), |x, y| x >= y, ">="),
                (a.equals(b), |x, y| x == y, "=="),
                (a.finite(), |x, _| x.is_finite(), "finite"),
            ];
            for (m, fs, name) in tests {
                for i in 0..N {
                    assert_eq!(
                        m.lane(i),
                        fs(a.0[i], b.0[i]),
                        "{} {name} {}",
                        a.0[i],
                        b.0[i]
                    );
                }
                let s = Lanes::select(m, a, b);
                for i in 0..N {
                    let e = if m.lane(i) { a.0[i] } else { b.0[i] };
                    assert!(same(s.0[i], e));
                }
                let n = !m;
                assert_eq!(m.any(), (0..N).any(|i| m.lane(i)));
                assert_eq!(m.all(), (0..N).all(|i| m.lane(i)));
                assert!((m & n).none());
                assert!((m | n).all());
            }
        }
        assert!(LaneMask::<N>::splat(true).all() && LaneMask::<N>::splat(false).none());
        let one = LaneMask::<N>::from_fn(|i| i == N - 1);
        assert!(one.any() && (N == 1 || !one.all()));
    }

    #[test]
    fn lanes_compute_what_f32_computes_lane_for_lane() {
        check_width::<1>();
        check_width::<8>();
        check_width::<16>();
    }

    #[test]
    fn the_widest_lanes_are_a_supported_width() {
        assert!([1, 8, 16].contains(&widest_lanes()));
    }
}
