//! Primal numbers and their masks: what a branch of rendering code looks
//! at.
//!
//! Rendering code decides on primal values (a derivative never changes
//! the branch a sample takes). For one path at a time the primal value is
//! an `f32` and a decision a `bool`; for several paths in lanes
//! ([`super::lanes`]) it is one `f32` per lane and a decision a lane mask.
//! Code written against [`Float`] and [`Mask`] compares with
//! [`Float::lt`] and friends, combines masks with `&`, `|` and `!`, and
//! merges the two sides of a decision with [`super::Real::select`]; for
//! `f32` this compiles to the branch it replaces.

use super::Real;
use std::fmt::Debug;
use std::ops::{BitAnd, BitAndAssign, BitOr, BitOrAssign, Not};

/// Which lanes a condition holds in (`bool` for one lane).
pub trait Mask:
    Copy
    + Debug
    + Send
    + Sync
    + 'static
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + Not<Output = Self>
    + BitAndAssign
    + BitOrAssign
{
    /// The same decision in every lane.
    fn splat(b: bool) -> Self;
    /// Whether the condition holds in at least one lane.
    fn any(self) -> bool;
    /// Whether the condition holds in every lane.
    fn all(self) -> bool;
    /// Whether the condition holds in no lane.
    #[inline(always)]
    fn none(self) -> bool {
        !self.any()
    }
}

impl Mask for bool {
    #[inline(always)]
    fn splat(b: bool) -> Self {
        b
    }
    #[inline(always)]
    fn any(self) -> bool {
        self
    }
    #[inline(always)]
    fn all(self) -> bool {
        self
    }
}

/// A primal number: `f32`, or `f32` in lanes. It is a [`Real`] without
/// derivatives whose primal value is itself, so that code generic over
/// `R: Real` runs on it unchanged; comparisons give masks.
pub trait Float: Real<Prim = Self> + From<f32> {
    fn lt(self, o: impl Into<Self>) -> Self::Mask;
    fn le(self, o: impl Into<Self>) -> Self::Mask;
    fn gt(self, o: impl Into<Self>) -> Self::Mask;
    fn ge(self, o: impl Into<Self>) -> Self::Mask;
    fn equals(self, o: impl Into<Self>) -> Self::Mask;
    /// False for NaN and ±∞.
    fn finite(self) -> Self::Mask;
}

impl Float for f32 {
    #[inline(always)]
    fn lt(self, o: impl Into<Self>) -> bool {
        self < o.into()
    }
    #[inline(always)]
    fn le(self, o: impl Into<Self>) -> bool {
        self <= o.into()
    }
    #[inline(always)]
    fn gt(self, o: impl Into<Self>) -> bool {
        self > o.into()
    }
    #[inline(always)]
    fn ge(self, o: impl Into<Self>) -> bool {
        self >= o.into()
    }
    #[inline(always)]
    fn equals(self, o: impl Into<Self>) -> bool {
        self == o.into()
    }
    #[inline(always)]
    fn finite(self) -> bool {
        self.is_finite()
    }
}
