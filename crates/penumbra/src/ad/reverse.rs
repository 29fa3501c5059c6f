//! A local reverse-mode variable for path replay (Nimier-David et al. 2020,
//! "Radiative Backpropagation"; Vicini et al. 2021, "Path Replay
//! Backpropagation").
//!
//! Operations on [`Var`] record onto a small thread-local tape. Reverse
//! mode (`diff/prb.rs`) records the computation of ONE path (the operations
//! on values that depend on the differentiated parameters: BSDF values,
//! emitted radiance, texture and volume lookups), propagates its adjoint
//! radiance through them with [`backward`], scatters the result into
//! parameter gradients, and clears the tape: memory stays independent of
//! the sample count, and holds one path's dependent operations.

use super::{weighted_sum, Real, ScalarReal};
use crate::params::{ParamId, ParamView};
use std::cell::RefCell;
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// Index of "no tape node": a constant.
const CONST: u32 = u32::MAX;

/// A key no pushed node has (two constant operands).
const NO_KEY: u128 = u128::MAX;

/// One recorded operation: up to two operands with their partial
/// derivatives.
#[derive(Clone, Copy)]
struct TapeNode {
    args: [u32; 2],
    partials: [f32; 2],
}

struct Tape {
    nodes: Vec<TapeNode>,
    /// Leaves read from the parameter store: (parameter, element, node,
    /// weight): the node's value holds weight × the element (a node may
    /// sum several elements: [`Real::param_sum`]).
    leaves: Vec<(ParamId, u32, u32, f32)>,
    /// Adjoint scratch space, reused between calls.
    adjoints: Vec<f32>,
    /// The operands and partials of the last node, packed, if [`push`]
    /// recorded it; [`NO_KEY`] after a leaf or a clear.
    last_key: u128,
}

thread_local! {
    // const-initialised: no lazy-initialisation check per operation
    static TAPE: RefCell<Tape> = const {
        RefCell::new(Tape {
            nodes: Vec::new(),
            leaves: Vec::new(),
            adjoints: Vec::new(),
            last_key: NO_KEY,
        })
    };
}

/// A real number that records how it was computed, for reverse mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Var {
    v: f32,
    node: u32,
}

impl Default for Var {
    fn default() -> Self {
        Var::cst(0.0)
    }
}

/// Records one operation on the tape; kept out of line so that operations
/// on constants (most of a path: geometry, sampling) inline to plain f32
/// arithmetic and a test.
#[inline(never)]
fn push(args: [u32; 2], partials: [f32; 2]) -> u32 {
    let key = (args[0] as u128)
        | (args[1] as u128) << 32
        | (partials[0].to_bits() as u128) << 64
        | (partials[1].to_bits() as u128) << 96;
    TAPE.with_borrow_mut(|t| {
        let i = t.nodes.len() as u32;
        if t.last_key == key {
            return i - 1;
        }
        t.last_key = key;
        t.nodes.push(TapeNode { args, partials });
        i
    })
}

impl Var {
    /// A tape node of value `v` whose leaves are the elements `terms`
    /// (index, weight) of recorded parameter `id`.
    fn param_leaf(v: f32, id: ParamId, terms: &[(usize, f32)]) -> Var {
        TAPE.with(|t| {
            let mut t = t.borrow_mut();
            let node = t.nodes.len() as u32;
            t.last_key = NO_KEY;
            t.nodes.push(TapeNode {
                args: [CONST, CONST],
                partials: [0.0, 0.0],
            });
            // zero weights too (a slice's map extends in one step): their
            // adjoints are zero, which `backward` does not hand over
            t.leaves
                .extend(terms.iter().map(|&(i, w)| (id, i as u32, node, w)));
            Var { v, node }
        })
    }

    /// Result of a unary operation with derivative `d`.
    #[inline(always)]
    fn unary(self, v: f32, d: f32) -> Var {
        if self.node == CONST {
            return Var { v, node: CONST };
        }
        Var {
            v,
            node: push([self.node, CONST], [d, 0.0]),
        }
    }

    /// Result of a binary operation with partials `da`, `db`.
    #[inline(always)]
    fn binary(a: Var, b: Var, v: f32, da: f32, db: f32) -> Var {
        match (a.node == CONST, b.node == CONST) {
            (true, true) => Var { v, node: CONST },
            (false, true) => Var {
                v,
                node: push([a.node, CONST], [da, 0.0]),
            },
            (true, false) => Var {
                v,
                node: push([b.node, CONST], [db, 0.0]),
            },
            (false, false) => Var {
                v,
                node: push([a.node, b.node], [da, db]),
            },
        }
    }

    /// True if this value depends on a parameter.
    pub fn is_attached(self) -> bool {
        self.node != CONST
    }
}

/// Clears the current thread's tape (call before recording a vertex).
pub fn clear_tape() {
    TAPE.with(|t| {
        let mut t = t.borrow_mut();
        t.nodes.clear();
        t.leaves.clear();
        t.last_key = NO_KEY;
    });
}

/// Propagates adjoints `(output, ∂loss/∂output)` back through the tape and
/// calls `scatter(param, element, ∂loss/∂param[element])` for every
/// parameter element read while recording whose adjoint is finite and not
/// zero (a NaN or infinite one is left out). Clears the tape.
pub fn backward(outputs: &[(Var, f32)], mut scatter: impl FnMut(ParamId, usize, f32)) {
    TAPE.with(|t| {
        let mut guard = t.borrow_mut();
        let t = &mut *guard;
        let n = t.nodes.len();
        t.adjoints.clear();
        t.adjoints.resize(n, 0.0);
        let mut any = false;
        for &(o, a) in outputs {
            if o.node != CONST && a != 0.0 {
                t.adjoints[o.node as usize] += a;
                any = true;
            }
        }
        if any {
            for i in (0..n).rev() {
                let a = t.adjoints[i];
                if a == 0.0 {
                    continue;
                }
                let node = t.nodes[i];
                for k in 0..2 {
                    let arg = node.args[k];
                    if arg != CONST {
                        t.adjoints[arg as usize] += a * node.partials[k];
                    }
                }
            }
            for &(id, index, node, w) in &t.leaves {
                let a = t.adjoints[node as usize] * w;
                if a != 0.0 && a.is_finite() {
                    scatter(id, index as usize, a);
                }
            }
        }
        t.nodes.clear();
        t.leaves.clear();
        t.last_key = NO_KEY;
    });
}

impl ScalarReal for Var {
    fn from_param(store: &ParamView, id: ParamId, index: usize) -> Self {
        let v = store.value(id, index);
        if !store.is_recorded(id) {
            return Var::cst(v);
        }
        Var::param_leaf(v, id, &[(index, 1.0)])
    }
    /// One node whose leaves are the summed elements, with their weights.
    fn param_sum(store: &ParamView, id: ParamId, terms: &[(usize, f32)]) -> Self {
        let v = weighted_sum(store.data(id), terms);
        if !store.is_recorded(id) {
            return Var::cst(v);
        }
        Var::param_leaf(v, id, terms)
    }
}

impl Real for Var {
    type Prim = f32;
    type Mask = bool;
    #[inline(always)]
    fn cst(v: f32) -> Self {
        Var { v, node: CONST }
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
        store.is_recorded(id)
    }
    #[inline(always)]
    fn is_const(self) -> bool {
        self.node == CONST
    }
    /// A branch rather than the default's select: the square root of a
    /// negative value would record a tape node nothing reads.
    fn safe_sqrt(self) -> Self {
        if self.v > 0.0 {
            self.sqrt()
        } else {
            Var::cst(0.0)
        }
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.unary(s, if s > 0.0 { 0.5 / s } else { 0.0 })
    }
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.unary(e, e)
    }
    fn ln(self) -> Self {
        self.unary(self.v.ln(), 1.0 / self.v)
    }
    fn sin(self) -> Self {
        self.unary(self.v.sin(), self.v.cos())
    }
    fn cos(self) -> Self {
        self.unary(self.v.cos(), -self.v.sin())
    }
    fn tan(self) -> Self {
        let t = self.v.tan();
        self.unary(t, 1.0 + t * t)
    }
    fn acos(self) -> Self {
        let x = self.v.clamp(-1.0, 1.0);
        let s = (1.0 - x * x).sqrt();
        self.unary(x.acos(), if s > 0.0 { -1.0 / s } else { 0.0 })
    }
    fn asin(self) -> Self {
        let x = self.v.clamp(-1.0, 1.0);
        let s = (1.0 - x * x).sqrt();
        self.unary(x.asin(), if s > 0.0 { 1.0 / s } else { 0.0 })
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = self.v * self.v + x.v * x.v;
        let (dy, dx) = if r2 > 0.0 {
            (x.v / r2, -self.v / r2)
        } else {
            (0.0, 0.0)
        };
        Var::binary(self, x, self.v.atan2(x.v), dy, dx)
    }
    fn powf(self, e: f32) -> Self {
        let d = if e == 0.0 {
            0.0
        } else {
            e * self.v.powf(e - 1.0)
        };
        self.unary(self.v.powf(e), d)
    }
    fn abs(self) -> Self {
        if self.v < 0.0 {
            -self
        } else {
            self
        }
    }
}

impl Add for Var {
    type Output = Var;
    #[inline(always)]
    fn add(self, o: Var) -> Var {
        Var::binary(self, o, self.v + o.v, 1.0, 1.0)
    }
}
impl Sub for Var {
    type Output = Var;
    #[inline(always)]
    fn sub(self, o: Var) -> Var {
        Var::binary(self, o, self.v - o.v, 1.0, -1.0)
    }
}
impl Mul for Var {
    type Output = Var;
    #[inline(always)]
    fn mul(self, o: Var) -> Var {
        Var::binary(self, o, self.v * o.v, o.v, self.v)
    }
}
impl Div for Var {
    type Output = Var;
    #[inline(always)]
    fn div(self, o: Var) -> Var {
        // primal by a true division, so that f32, Dual and Var primals
        // agree (the boundary term selects and samples edges from them)
        let v = self.v / o.v;
        if self.node == CONST && o.node == CONST {
            return Var { v, node: CONST };
        }
        let inv = 1.0 / o.v;
        Var::binary(self, o, v, inv, -v * inv)
    }
}
impl Neg for Var {
    type Output = Var;
    #[inline(always)]
    fn neg(self) -> Var {
        self.unary(-self.v, -1.0)
    }
}
impl Add<f32> for Var {
    type Output = Var;
    #[inline(always)]
    fn add(self, o: f32) -> Var {
        self.unary(self.v + o, 1.0)
    }
}
impl Sub<f32> for Var {
    type Output = Var;
    #[inline(always)]
    fn sub(self, o: f32) -> Var {
        self.unary(self.v - o, 1.0)
    }
}
impl Mul<f32> for Var {
    type Output = Var;
    #[inline(always)]
    fn mul(self, o: f32) -> Var {
        self.unary(self.v * o, o)
    }
}
impl Div<f32> for Var {
    type Output = Var;
    #[inline(always)]
    fn div(self, o: f32) -> Var {
        if self.node == CONST {
            return Var::cst(self.v / o);
        }
        self.unary(self.v / o, 1.0 / o)
    }
}
impl AddAssign for Var {
    #[inline(always)]
    fn add_assign(&mut self, o: Var) {
        *self = *self + o;
    }
}
impl SubAssign for Var {
    #[inline(always)]
    fn sub_assign(&mut self, o: Var) {
        *self = *self - o;
    }
}
impl MulAssign for Var {
    #[inline(always)]
    fn mul_assign(&mut self, o: Var) {
        *self = *self * o;
    }
}
impl DivAssign for Var {
    #[inline(always)]
    fn div_assign(&mut self, o: Var) {
        *self = *self / o;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::params::{Domain, ParamFlags, ParamStore, Seeds};

    /// The same generic function differentiated in forward mode (per input)
    /// and reverse mode (all inputs at once) gives the same gradient.
    #[test]
    fn reverse_gradient_equals_forward_derivatives() {
        fn f<R: ScalarReal>(s: &ParamView, id: ParamId) -> R {
            let (a, b, c): (R, R, R) = (s.read(id, 0), s.read(id, 1), s.read(id, 2));
            ((a * b).sin() + c.sqrt() * a.exp() - b / (c + 1.0)).powf(1.5) + a.atan2(c) * b.acos()
        }
        let mut s = ParamStore::new();
        let id = s
            .add(
                "x.value",
                vec![0.3, 0.4, 0.7],
                vec![3],
                ParamFlags::DIFFERENTIABLE,
                Domain::Finite,
            )
            .unwrap();
        let recorded = Seeds::recorded(&s, &[id]).unwrap();
        clear_tape();
        let out: Var = f(&s.view(&recorded), id);
        let mut grad = [0.0f32; 3];
        backward(&[(out, 2.0)], |pid, i, g| {
            assert_eq!(pid, id);
            grad[i] += g;
        });
        for k in 0..3 {
            let mut t = [0.0; 3];
            t[k] = 1.0;
            let seeds = Seeds::tangents(&s, &[("x.value", &t)]).unwrap();
            let d: Dual = f(&s.view(&seeds), id);
            assert!(
                (grad[k] - 2.0 * d.d).abs() < 1e-5 * d.d.abs().max(1.0),
                "{k}: {} vs {}",
                grad[k],
                2.0 * d.d
            );
            assert_eq!(out.v, d.v);
        }
    }

    /// Forward and reverse mode take the same boundary samples only if
    /// their primals agree bit for bit: a quotient is the true quotient
    /// (not the product with the reciprocal, an ulp off for these).
    #[test]
    fn quotients_are_those_of_f32() {
        for (a, b) in [(0.1f32, 0.3f32), (0.2, 1.1), (0.3, 3.7), (-0.1, 3.7)] {
            assert_eq!((Var::cst(a) / Var::cst(b)).val(), a / b);
            assert_eq!((Dual::cst(a) / Dual::cst(b)).val(), a / b);
        }
    }

    /// An operation repeated on the same operands with the same partials
    /// (the channels of a grey spectrum) is recorded once, whatever the
    /// values (`a + 1` and `a + 2` share a node), and the gradient is
    /// unchanged.
    #[test]
    fn repeated_operations_are_recorded_once() {
        let mut s = ParamStore::new();
        let id = s
            .add(
                "x.value",
                vec![0.5, 2.0],
                vec![2],
                ParamFlags::DIFFERENTIABLE,
                Domain::Finite,
            )
            .unwrap();
        let recorded = Seeds::recorded(&s, &[id]).unwrap();
        let view = s.view(&recorded);
        clear_tape();
        let (a, b): (Var, Var) = (view.read(id, 0), view.read(id, 1));
        let (p, q, r) = (a * b, a * b, a * b);
        let (u, w) = (a + 1.0, a + 2.0);
        TAPE.with(|t| assert_eq!(t.borrow().nodes.len(), 4));
        assert_eq!((u.v, w.v), (1.5, 2.5));
        let out = p + q * 2.0 + r * 3.0 + u * w;
        let mut grad = [0.0f32; 2];
        backward(&[(out, 1.0)], |_, i, g| grad[i] += g);
        // d/da = 6b + (a + 2) + (a + 1), d/db = 6a
        assert_eq!(grad, [6.0 * 2.0 + 2.5 + 1.5, 6.0 * 0.5]);
    }

    #[test]
    fn constants_and_non_differentiable_parameters_record_nothing() {
        let mut s = ParamStore::new();
        let id = s
            .add(
                "faces",
                vec![1.0],
                vec![1],
                ParamFlags::READ_ONLY,
                Domain::Finite,
            )
            .unwrap();
        clear_tape();
        let v: Var = s.primal().read(id, 0);
        let w = (v * 3.0 + Var::cst(2.0)).sqrt();
        assert!(!w.is_attached());
        TAPE.with(|t| assert!(t.borrow().nodes.is_empty()));
    }

    /// A weighted sum of parameter elements read in one step has the value
    /// and derivatives of the sum of products in every number type, and
    /// reverse mode records one node for it.
    #[test]
    fn param_sums_match_sums_of_reads() {
        let mut s = ParamStore::new();
        let data = vec![0.3, 1.7, 0.0, 2.25, 0.9];
        let id = s
            .add(
                "g.data",
                data,
                vec![5],
                ParamFlags::DIFFERENTIABLE,
                Domain::Finite,
            )
            .unwrap();
        let terms = [(1, 0.25), (3, 0.0), (4, 0.6), (0, 0.15), (1, 0.3)];
        fn generic<R: ScalarReal>(s: &ParamView, id: ParamId, terms: &[(usize, f32)]) -> R {
            let mut v = R::cst(0.0);
            for &(i, w) in terms {
                if w != 0.0 {
                    v += s.read::<R>(id, i) * w;
                }
            }
            v
        }
        let primal = s.primal();
        let v = f32::param_sum(&primal, id, &terms);
        assert_eq!(v, generic::<f32>(&primal, id, &terms));
        let tangent = [0.5, -1.0, 2.0, 3.0, 0.25];
        let seeds = Seeds::tangents(&s, &[("g.data", &tangent)]).unwrap();
        let d = Dual::param_sum(&s.view(&seeds), id, &terms);
        assert_eq!(d, generic::<Dual>(&s.view(&seeds), id, &terms));
        assert_eq!(d.v, v);
        let recorded = Seeds::recorded(&s, &[id]).unwrap();
        clear_tape();
        let out = Var::param_sum(&s.view(&recorded), id, &terms);
        assert_eq!(out.v, v);
        TAPE.with(|t| assert_eq!(t.borrow().nodes.len(), 1));
        let mut grad = [0.0f32; 5];
        backward(&[(out * 2.0, 1.0)], |_, i, g| grad[i] += g);
        for (g, want) in grad.iter().zip([0.3, 1.1, 0.0, 0.0, 1.2]) {
            assert!((g - want).abs() < 1e-6, "{grad:?}");
        }
    }
}
