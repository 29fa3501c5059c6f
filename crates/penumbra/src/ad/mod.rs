//! Automatic differentiation: the [`Real`] number trait that all
//! differentiable code is generic over.
//!
//! Rendering code (BSDFs, textures, emitters, hit re-evaluation,
//! integrators) is written once, generic over `R: Real`:
//! - `f32` renders the primal image;
//! - [`Dual`] carries one tangent direction (forward mode);
//! - a local reverse-mode variable (path replay) records only the terms
//!   of one path vertex.
//!
//! Parameters enter through [`Real::from_param`], so that seeding a tangent
//! (forward mode) or tagging a leaf for scattering (reverse mode) happens in
//! one place: the parameter store's `read`.

mod dual;
mod float;
pub mod lanes;
pub mod reverse;

pub use dual::Dual;
pub use float::{Float, Mask};
pub use reverse::Var;

use crate::params::{ParamId, ParamView};
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real number that rendering code computes with, for one path or for
/// several paths in lanes.
///
/// Comparisons and branch decisions are made on the primal value
/// ([`Real::val`], a [`Float`]): derivatives never change which branch a
/// sample takes. Code generic over `R: Real` decides with masks and
/// [`Real::select`], so that it runs in lanes too; code written for one
/// path at a time is generic over [`ScalarReal`], whose primal value is an
/// `f32` and whose decisions are `bool`s.
pub trait Real:
    Copy
    + Debug
    + Default
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f32, Output = Self>
    + Sub<f32, Output = Self>
    + Mul<f32, Output = Self>
    + Div<f32, Output = Self>
    + Add<<Self as Real>::Prim, Output = Self>
    + Sub<<Self as Real>::Prim, Output = Self>
    + Mul<<Self as Real>::Prim, Output = Self>
    + Div<<Self as Real>::Prim, Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
{
    /// Whether the type carries derivatives (false for `f32`): code that
    /// only exists to give derivatives (re-evaluations whose primal value
    /// is known) is skipped for the primal image.
    const DIFFERENTIABLE: bool = true;
    /// The primal number: `f32`, or one `f32` per lane.
    type Prim: Float<Mask = Self::Mask>;
    /// A decision per lane: `bool` for one path.
    type Mask: Mask;
    /// A constant (in every lane): its derivative is zero.
    fn cst(v: f32) -> Self;
    /// A constant per lane (a detached sample): its derivative is zero.
    fn from_prim(p: Self::Prim) -> Self;
    /// The primal value, detached from any derivative.
    fn val(self) -> Self::Prim;
    /// `a` in the lanes where `m` holds, `b` elsewhere, each with its
    /// derivative.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Whether reads of parameter `id` carry derivatives (a tangent is set
    /// in forward mode, its gradient is requested in reverse mode): lets
    /// code that only exists for such derivatives be skipped.
    fn tracks(_store: &ParamView, _id: ParamId) -> bool {
        false
    }
    /// Whether this value carries no derivative (always for `f32`): a
    /// computation from constants only can then run on f32 and be lifted.
    fn is_const(self) -> bool {
        true
    }

    fn sqrt(self) -> Self;
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
    fn tan(self) -> Self;
    fn acos(self) -> Self;
    fn asin(self) -> Self;
    fn atan2(self, x: Self) -> Self;
    /// `self^e` for a constant exponent.
    fn powf(self, e: f32) -> Self;
    fn abs(self) -> Self;
    fn recip(self) -> Self {
        Self::cst(1.0) / self
    }
    /// `sqrt(max(self, 0))`: the safe square root of quantities that are
    /// non-negative up to rounding.
    fn safe_sqrt(self) -> Self {
        Self::select(self.val().gt(0.0), self.sqrt(), Self::cst(0.0))
    }
    /// `self^e` for a differentiable exponent (self > 0).
    fn pow(self, e: Self) -> Self {
        (self.ln() * e).exp()
    }
    fn sqr(self) -> Self {
        self * self
    }
    /// The smaller of the two; its derivative is the chosen operand's.
    fn min(self, o: Self) -> Self {
        Self::select(o.val().lt(self.val()), o, self)
    }
    /// The larger of the two; its derivative is the chosen operand's.
    fn max(self, o: Self) -> Self {
        Self::select(o.val().gt(self.val()), o, self)
    }
    fn clamp(self, lo: f32, hi: f32) -> Self {
        let v = self.val();
        let inside = Self::select(v.gt(hi), Self::cst(hi), self);
        Self::select(v.lt(lo), Self::cst(lo), inside)
    }
}

/// A [`Real`] for one path at a time: its primal value is an `f32` and its
/// decisions are `bool`s. Code not yet written with masks is generic over
/// this trait; parameter reads are defined for it.
pub trait ScalarReal: Real<Prim = f32, Mask = bool> {
    /// Element `index` of parameter `id`, read from `store`: the one place
    /// where derivatives are seeded (forward) or tagged (reverse).
    fn from_param(store: &ParamView, id: ParamId, index: usize) -> Self;
    /// Σ_k w_k · (element i_k of parameter `id`) over `terms` = (i_k, w_k),
    /// terms of weight 0 left out: a filtered read (a grid's trilinear
    /// interpolation) in one step. Its primal is [`weighted_sum`] in every
    /// number type; `f32` reads the values directly, and reverse mode
    /// records one tape node for the whole sum instead of a product and a
    /// sum per element.
    #[inline(always)]
    fn param_sum(store: &ParamView, id: ParamId, terms: &[(usize, f32)]) -> Self {
        let mut v = Self::cst(0.0);
        for &(i, w) in terms {
            if w != 0.0 {
                v += Self::from_param(store, id, i) * w;
            }
        }
        v
    }
    fn is_finite(self) -> bool {
        self.val().is_finite()
    }
}

/// Σ_k w_k · data[i_k], in the order of `terms`, terms of weight 0 left
/// out: the primal of [`Real::param_sum`].
#[inline(always)]
pub fn weighted_sum(data: &[f32], terms: &[(usize, f32)]) -> f32 {
    let mut v = 0.0;
    for &(i, w) in terms {
        if w != 0.0 {
            v += data[i] * w;
        }
    }
    v
}

impl ScalarReal for f32 {
    #[inline(always)]
    fn from_param(store: &ParamView, id: ParamId, index: usize) -> Self {
        store.value(id, index)
    }
    #[inline(always)]
    fn param_sum(store: &ParamView, id: ParamId, terms: &[(usize, f32)]) -> Self {
        weighted_sum(store.data(id), terms)
    }
}

impl Real for f32 {
    const DIFFERENTIABLE: bool = false;
    type Prim = f32;
    type Mask = bool;
    #[inline(always)]
    fn cst(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn from_prim(p: f32) -> Self {
        p
    }
    #[inline(always)]
    fn val(self) -> f32 {
        self
    }
    #[inline(always)]
    fn select(m: bool, a: f32, b: f32) -> f32 {
        if m {
            a
        } else {
            b
        }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        f32::exp(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        f32::ln(self)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        f32::sin(self)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        f32::cos(self)
    }
    #[inline(always)]
    fn tan(self) -> Self {
        f32::tan(self)
    }
    #[inline(always)]
    fn acos(self) -> Self {
        f32::acos(self.clamp(-1.0, 1.0))
    }
    #[inline(always)]
    fn asin(self) -> Self {
        f32::asin(self.clamp(-1.0, 1.0))
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        f32::atan2(self, x)
    }
    #[inline(always)]
    fn powf(self, e: f32) -> Self {
        f32::powf(self, e)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f32::abs(self)
    }
    #[inline(always)]
    fn pow(self, e: Self) -> Self {
        f32::powf(self, e)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        f32::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32::max(self, o)
    }
    #[inline(always)]
    fn clamp(self, lo: f32, hi: f32) -> Self {
        f32::clamp(self, lo, hi)
    }
}
