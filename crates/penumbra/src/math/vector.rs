//! Small vectors generic over the number type, for differentiable code.
//! Traversal and sampling use glam's f32 types; conversions are provided.

use crate::ad::{Float, Real, ScalarReal};
use glam::{Vec2, Vec3};
use std::ops::{Add, AddAssign, Div, Index, Mul, MulAssign, Neg, Sub, SubAssign};

/// A 3-vector (point, direction, normal, or RGB colour) of `R`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V3<R> {
    pub x: R,
    pub y: R,
    pub z: R,
}

/// A 2-vector of `R` (texture coordinates, sample positions).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V2<R> {
    pub x: R,
    pub y: R,
}

impl<R: Real> V3<R> {
    #[inline(always)]
    pub fn new(x: R, y: R, z: R) -> Self {
        V3 { x, y, z }
    }
    #[inline(always)]
    pub fn splat(v: R) -> Self {
        V3::new(v, v, v)
    }
    #[inline(always)]
    pub fn zero() -> Self {
        Self::splat(R::cst(0.0))
    }
    /// A constant vector from an f32 glam vector.
    #[inline(always)]
    pub fn cst(v: Vec3) -> Self {
        V3::new(R::cst(v.x), R::cst(v.y), R::cst(v.z))
    }
    /// A constant per lane (a detached sample).
    #[inline(always)]
    pub fn from_prim(v: V3<R::Prim>) -> Self {
        V3::new(R::from_prim(v.x), R::from_prim(v.y), R::from_prim(v.z))
    }
    /// The primal value.
    #[inline(always)]
    pub fn prim(self) -> V3<R::Prim> {
        V3::new(self.x.val(), self.y.val(), self.z.val())
    }
    /// `a` in the lanes where `m` holds, `b` elsewhere.
    #[inline(always)]
    pub fn select(m: R::Mask, a: Self, b: Self) -> Self {
        V3::new(
            R::select(m, a.x, b.x),
            R::select(m, a.y, b.y),
            R::select(m, a.z, b.z),
        )
    }
    /// Whether no component carries a derivative.
    #[inline(always)]
    pub fn is_const(self) -> bool {
        self.x.is_const() && self.y.is_const() && self.z.is_const()
    }
    #[inline(always)]
    pub fn dot(self, o: Self) -> R {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    #[inline(always)]
    pub fn length_squared(self) -> R {
        self.dot(self)
    }
    #[inline(always)]
    pub fn length(self) -> R {
        self.length_squared().sqrt()
    }
    #[inline(always)]
    pub fn normalize(self) -> Self {
        self * self.length().recip()
    }
    /// Component-wise product (colours).
    #[inline(always)]
    pub fn mul_elem(self, o: Self) -> Self {
        V3::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
    /// Component-wise quotient (colours); a zero divisor gives zero.
    #[inline(always)]
    pub fn div_elem(self, o: Self) -> Self {
        let d = |a: R, b: R| R::select(b.val().equals(0.0), R::cst(0.0), a / b);
        V3::new(d(self.x, o.x), d(self.y, o.y), d(self.z, o.z))
    }
    #[inline(always)]
    pub fn map(self, f: impl Fn(R) -> R) -> Self {
        V3::new(f(self.x), f(self.y), f(self.z))
    }
    #[inline(always)]
    pub fn max_elem(self) -> R {
        self.x.max(self.y).max(self.z)
    }
    /// Mean of the three components.
    #[inline(always)]
    pub fn mean(self) -> R {
        (self.x + self.y + self.z) * (1.0 / 3.0)
    }
    /// Linear-sRGB luminance (Rec. 709 weights).
    #[inline(always)]
    pub fn luminance(self) -> R {
        self.x * 0.212671 + self.y * 0.715160 + self.z * 0.072169
    }
    /// Where all three components are zero.
    #[inline(always)]
    pub fn is_zero(self) -> R::Mask {
        self.x.val().equals(0.0) & self.y.val().equals(0.0) & self.z.val().equals(0.0)
    }
    /// Scales by a constant (`v * s` with `s: R` is the operator form).
    #[inline(always)]
    pub fn scale(self, s: f32) -> Self {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
    #[inline(always)]
    pub fn add_f(self, v: Vec3) -> Self {
        V3::new(self.x + v.x, self.y + v.y, self.z + v.z)
    }
    #[inline(always)]
    pub fn mul_f(self, v: Vec3) -> Self {
        V3::new(self.x * v.x, self.y * v.y, self.z * v.z)
    }
}

impl<R: ScalarReal> V3<R> {
    /// The primal value as a glam vector.
    #[inline(always)]
    pub fn val(self) -> Vec3 {
        Vec3::new(self.x.val(), self.y.val(), self.z.val())
    }
    #[inline(always)]
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

impl<R: Real> V2<R> {
    #[inline(always)]
    pub fn new(x: R, y: R) -> Self {
        V2 { x, y }
    }
    #[inline(always)]
    pub fn cst(v: Vec2) -> Self {
        V2::new(R::cst(v.x), R::cst(v.y))
    }
    #[inline(always)]
    pub fn zero() -> Self {
        V2::new(R::cst(0.0), R::cst(0.0))
    }
    #[inline(always)]
    pub fn from_prim(v: V2<R::Prim>) -> Self {
        V2::new(R::from_prim(v.x), R::from_prim(v.y))
    }
}

impl<R: ScalarReal> V2<R> {
    #[inline(always)]
    pub fn val(self) -> Vec2 {
        Vec2::new(self.x.val(), self.y.val())
    }
}

impl<R: Real> Index<usize> for V3<R> {
    type Output = R;
    #[inline(always)]
    fn index(&self, i: usize) -> &R {
        match i {
            0 => &self.x,
            1 => &self.y,
            _ => &self.z,
        }
    }
}

macro_rules! v3_binop {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<R: Real> $tr for V3<R> {
            type Output = V3<R>;
            #[inline(always)]
            fn $f(self, o: V3<R>) -> V3<R> {
                V3::new(self.x $op o.x, self.y $op o.y, self.z $op o.z)
            }
        }
    };
}
v3_binop!(Add, add, +);
v3_binop!(Sub, sub, -);

macro_rules! v2_binop {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<R: Real> $tr for V2<R> {
            type Output = V2<R>;
            #[inline(always)]
            fn $f(self, o: V2<R>) -> V2<R> {
                V2::new(self.x $op o.x, self.y $op o.y)
            }
        }
    };
}
v2_binop!(Add, add, +);
v2_binop!(Sub, sub, -);

impl<R: Real> Mul<R> for V2<R> {
    type Output = V2<R>;
    #[inline(always)]
    fn mul(self, s: R) -> V2<R> {
        V2::new(self.x * s, self.y * s)
    }
}

impl<R: Real> Mul<R> for V3<R> {
    type Output = V3<R>;
    #[inline(always)]
    fn mul(self, s: R) -> V3<R> {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}
#[allow(clippy::suspicious_arithmetic_impl)] // one reciprocal, three products
impl<R: Real> Div<R> for V3<R> {
    type Output = V3<R>;
    #[inline(always)]
    fn div(self, s: R) -> V3<R> {
        self * s.recip()
    }
}
impl<R: Real> Neg for V3<R> {
    type Output = V3<R>;
    #[inline(always)]
    fn neg(self) -> V3<R> {
        V3::new(-self.x, -self.y, -self.z)
    }
}
impl<R: Real> AddAssign for V3<R> {
    #[inline(always)]
    fn add_assign(&mut self, o: V3<R>) {
        *self = *self + o;
    }
}
impl<R: Real> SubAssign for V3<R> {
    #[inline(always)]
    fn sub_assign(&mut self, o: V3<R>) {
        *self = *self - o;
    }
}
impl<R: Real> MulAssign<R> for V3<R> {
    #[inline(always)]
    fn mul_assign(&mut self, s: R) {
        *self = *self * s;
    }
}

impl From<Vec3> for V3<f32> {
    #[inline(always)]
    fn from(v: Vec3) -> Self {
        V3::new(v.x, v.y, v.z)
    }
}

impl From<V3<f32>> for Vec3 {
    #[inline(always)]
    fn from(v: V3<f32>) -> Self {
        Vec3::new(v.x, v.y, v.z)
    }
}

impl From<Vec2> for V2<f32> {
    #[inline(always)]
    fn from(v: Vec2) -> Self {
        V2::new(v.x, v.y)
    }
}

impl From<V2<f32>> for Vec2 {
    #[inline(always)]
    fn from(v: V2<f32>) -> Self {
        Vec2::new(v.x, v.y)
    }
}

/// RGB radiance, reflectance or importance, linear sRGB primaries.
pub type Spectrum<R> = V3<R>;
