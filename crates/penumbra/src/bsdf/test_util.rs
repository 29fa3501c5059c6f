//! Shared helpers of the BSDF tests: building plugins from properties,
//! surface interactions with a given incident direction, the χ² and
//! consistency checks of sampling, Monte Carlo albedo estimates, and the
//! check of derivatives with respect to the directions.

use super::{Bsdf, BsdfContextT, BsdfFlags, BsdfT};
use crate::ad::{Dual, ScalarReal};
use crate::error::SrcLoc;
use crate::geometry::SurfaceInteraction;
use crate::math::warp::square_to_uniform_sphere;
use crate::math::{Frame, Spectrum, V2, V3};
use crate::params::ParamStore;
use crate::scene::description::{Class, LoadContext, Node, Prop, Value};
use crate::testing::{Chi2Test, Pcg32};
use glam::Vec3;
use std::rc::Rc;

pub fn loc() -> SrcLoc {
    SrcLoc {
        file: "test.xml".into(),
        line: 1,
    }
}

pub fn rgb(r: f32, g: f32, b: f32) -> Value {
    Value::Rgb(Vec3::new(r, g, b))
}
pub fn float(v: f64) -> Value {
    Value::Float(v)
}
pub fn string(s: &str) -> Value {
    Value::Str(s.into())
}
pub fn boolean(b: bool) -> Value {
    Value::Bool(b)
}

/// A `<bsdf type=plugin>` node with key `key` and the given properties.
pub fn node_with_key(plugin: &str, key: &str, props: &[(&str, Value)]) -> Node {
    let mut n = Node::new(Class::Bsdf, plugin, None, key.into(), loc());
    for (name, v) in props {
        n.props.push(Prop::new(*name, v.clone(), loc()));
    }
    n
}

/// A nested, unnamed bsdf property value (key `<parent>.bsdf`).
pub fn nested(parent_key: &str, name: &str, plugin: &str, props: &[(&str, Value)]) -> Value {
    Value::Node(Rc::new(node_with_key(
        plugin,
        &format!("{parent_key}.{name}"),
        props,
    )))
}

/// Builds plugin `plugin` with key "b".
pub fn build(plugin: &str, props: &[(&str, Value)]) -> (Bsdf, ParamStore) {
    let n = node_with_key(plugin, "b", props);
    let mut ctx = LoadContext::default();
    let b = Bsdf::from_node(&n, &mut ctx).unwrap_or_else(|e| panic!("{e}"));
    (b, ctx.store)
}

/// A direction with cos θ = `cos_theta` and azimuth `phi`.
pub fn dir(cos_theta: f32, phi: f32) -> Vec3 {
    let s = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(s * phi.cos(), s * phi.sin(), cos_theta)
}

/// A surface interaction at the origin with the standard frame and the
/// given local incident direction.
pub fn si<R: ScalarReal>(wi: Vec3) -> SurfaceInteraction<R> {
    SurfaceInteraction {
        t: R::cst(1.0),
        p: V3::zero(),
        n: V3::cst(Vec3::Z),
        sh_frame: Frame {
            s: V3::cst(Vec3::X),
            t: V3::cst(Vec3::Y),
            n: V3::cst(Vec3::Z),
        },
        uv: V2::new(R::cst(0.5), R::cst(0.5)),
        dp_du: V3::cst(glam::Vec3::X),
        dp_dv: V3::cst(glam::Vec3::Y),
        wi: V3::cst(wi),
        area_scale: R::cst(1.0),
        shape: 0,
        prim: 0,
        vertices: [0; 3],
        bary: V2::zero(),
    }
}

pub fn eval_f32(b: &Bsdf, store: &ParamStore, wi: Vec3, wo: Vec3) -> Vec3 {
    b.context(&store.primal(), &si::<f32>(wi))
        .eval(V3::cst(wo))
        .val()
}

pub fn pdf_f32(b: &Bsdf, store: &ParamStore, wi: Vec3, wo: Vec3) -> f32 {
    b.context(&store.primal(), &si::<f32>(wi)).pdf(wo)
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-6
}

/// For each incident direction: a χ² test of the smooth lobes' sampling
/// against `pdf` (threshold 1e-3 divided by the number of χ² tests,
/// `wis.len() × tests_in_fn`), ∫ pdf ≤ 1, and for sampled directions of
/// smooth lobes `pdf(wo)` = the sample's pdf and `eval(wo) / pdf(wo)` =
/// its weight. Also runs [`check_direction_derivatives`].
pub fn check_smooth(b: &Bsdf, store: &ParamStore, wis: &[Vec3], tests_in_fn: usize) {
    check_direction_derivatives(b, store, 7);
    let threshold = 1e-3 / (wis.len() * tests_in_fn) as f64;
    for (i, &wi) in wis.iter().enumerate() {
        let ctx = b.context(&store.primal(), &si::<f32>(wi));
        // default pdf integration (12² points per bin): lobes narrower than
        // ~0.1 rad at the pole need more (alpha ≥ 0.1 is tested)
        let t = Chi2Test {
            samples: 100_000,
            seed: 101 + i as u64,
            ..Chi2Test::default()
        };
        let mut checked = 0;
        let r = t.run(
            |rng: &mut Pcg32| {
                let u1 = rng.next_f32();
                let u2 = rng.next_2d();
                let bs = ctx.sample(u1, u2)?;
                assert!(bs.weight.is_finite() && bs.pdf > 0.0, "wi {wi:?}: {bs:?}");
                if bs.lobe.has(BsdfFlags::DELTA) {
                    return None;
                }
                if checked < 2000 {
                    checked += 1;
                    let p = ctx.pdf(bs.wo.val());
                    assert!(
                        close(p, bs.pdf, 2e-3),
                        "wi {wi:?} wo {:?}: pdf {p} vs sample pdf {}",
                        bs.wo,
                        bs.pdf
                    );
                    let f = ctx.eval(bs.wo).val() / p;
                    let w = bs.weight.val();
                    for c in 0..3 {
                        assert!(
                            close(f[c], w[c], 2e-3),
                            "wi {wi:?} wo {:?}: eval/pdf {f} vs weight {w}",
                            bs.wo
                        );
                    }
                }
                Some(bs.wo.val())
            },
            |wo| ctx.pdf(wo),
        );
        assert!(r.p_value > threshold, "{b:?} wi {wi:?}: χ² failed: {r:?}");
        assert!(
            r.pdf_integral <= 1.0 + 1e-2,
            "{b:?} wi {wi:?}: ∫pdf = {}",
            r.pdf_integral
        );
    }
}

/// Monte Carlo estimate of the directional albedo ∫ f |cos| dωo from
/// `sample` weights (transmitted weights times η², undoing the radiance
/// scaling of refraction, so that the result is the energy fraction):
/// returns (mean, standard error) per channel.
pub fn albedo_estimate(
    b: &Bsdf,
    store: &ParamStore,
    wi: Vec3,
    n: usize,
    seed: u64,
) -> (Vec3, Vec3) {
    let ctx = b.context(&store.primal(), &si::<f32>(wi));
    let mut rng = Pcg32::new(seed);
    let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
    for _ in 0..n {
        let u1 = rng.next_f32();
        let u2 = rng.next_2d();
        if let Some(bs) = ctx.sample(u1, u2) {
            let w: Spectrum<f32> = bs.weight.scale(bs.eta * bs.eta);
            for c in 0..3 {
                sum[c] += w[c] as f64;
                sum2[c] += (w[c] as f64).powi(2);
            }
        }
    }
    let mut mean = Vec3::ZERO;
    let mut se = Vec3::ZERO;
    for c in 0..3 {
        let m = sum[c] / n as f64;
        let var = (sum2[c] / n as f64 - m * m).max(0.0);
        mean[c] = m as f32;
        se[c] = (var / n as f64).sqrt() as f32;
    }
    (mean, se)
}

/// ∫ eval(wi, wo) dωo over the sphere by the midpoint rule in (θ, φ)
/// (`n` × 2`n` cells), transmitted values (other side than `wi`) times
/// `trans_scale` (η² to undo radiance scaling): the albedo, independent of
/// the sampling routines.
pub fn albedo_quadrature(
    b: &Bsdf,
    store: &ParamStore,
    wi: Vec3,
    n: usize,
    trans_scale: f32,
) -> Vec3 {
    let ctx = b.context(&store.primal(), &si::<f32>(wi));
    let (dt, dp) = (
        std::f64::consts::PI / n as f64,
        std::f64::consts::PI / n as f64,
    );
    let mut sum = [0.0f64; 3];
    for i in 0..n {
        let theta = (i as f64 + 0.5) * dt;
        let (st, ct) = theta.sin_cos();
        for j in 0..2 * n {
            let phi = (j as f64 + 0.5) * dp;
            let wo = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
            let mut f = ctx.eval(V3::cst(wo)).val();
            if wo.z * wi.z < 0.0 {
                f *= trans_scale;
            }
            for c in 0..3 {
                sum[c] += f[c] as f64 * st * dt * dp;
            }
        }
    }
    Vec3::new(sum[0] as f32, sum[1] as f32, sum[2] as f32)
}

/// Asserts that `hits` successes in `n` trials agree with probability `p`:
/// within 4 standard deviations of Binomial(n, p), plus 1 for rounding.
pub fn assert_binomial(hits: usize, n: usize, p: f32, what: &str) {
    let sd = (n as f32 * p * (1.0 - p)).sqrt();
    assert!(
        (hits as f32 - n as f32 * p).abs() <= 4.0 * sd + 1.0,
        "{what}{hits} vs {}",
        n as f32 * p
    );
}

/// Energy conservation at `wi`: the sampled albedo (20 000 samples from
/// `seed`) is at most 1 within 4 standard errors, the quadrature of `eval`
/// (200 cells; transmitted values times `trans_scale`) at most 1 + 5e-3,
/// and the two agree within 4 standard errors + 5e-3. Returns the sampled
/// albedo (first channel) and the message describing the case.
pub fn check_energy(
    b: &Bsdf,
    store: &ParamStore,
    wi: Vec3,
    seed: u64,
    trans_scale: f32,
    what: &str,
) -> (f32, String) {
    let (a, se) = albedo_estimate(b, store, wi, 20_000, seed);
    let q = albedo_quadrature(b, store, wi, 200, trans_scale);
    let msg = format!("{what} {wi:?}: MC {a} ± {se}, quadrature {q}");
    assert!(a.x <= 1.0 + 4.0 * se.x && q.x <= 1.0 + 5e-3, "{msg}");
    assert!((a.x - q.x).abs() <= 4.0 * se.x + 5e-3, "{msg}");
    (a.x, msg)
}

/// For each property set of `plugin`: [`check_smooth`] at `wis`, and the
/// sampled albedo (20 000 samples from `seed`) at each of `wis` at most 1
/// within 4 standard errors in every channel.
pub fn check_sampling_and_albedo(
    plugin: &str,
    cases: &[Vec<(&str, Value)>],
    wis: &[Vec3],
    seed: u64,
) {
    for c in cases {
        let (b, store) = build(plugin, c);
        check_smooth(&b, &store, wis, cases.len());
        for &wi in wis {
            let (a, se) = albedo_estimate(&b, &store, wi, 20_000, seed);
            assert!(
                a.max_element() <= 1.0 + 4.0 * se.max_element(),
                "{a} ± {se}"
            );
        }
    }
}

/// Angle step of the finite differences (radians along a great circle).
const FD_STEP: f32 = 1e-3;

/// `|d − fd| ≤ FD_REL |fd| + FD_FLOOR |value|` per channel. The floor
/// covers rounding: the f32 evaluations are accurate to a few ulps
/// (relative error ≲ 1e-6 after normalisations and Fresnel terms), which a
/// central difference with step h/2 = 5e-4 divides by 2·5e-4, i.e. noise ≲
/// 1e-3 |value|; 5e-3 leaves a margin. The relative part covers the
/// truncation error (h/2)² f‴/6, ≲ 1e-4 |fd| for lobes no narrower than
/// α = 0.1 (f varies on the scale α, so f‴ ~ f′/α²), with a wide margin.
/// A detached direction changes the derivative by O(|value|) (the
/// derivative of a cosine, or of D, along a unit tangent), far above both.
const FD_REL: f32 = 2e-2;
const FD_FLOOR: f32 = 5e-3;

/// Directions closer to the horizon than this are skipped (cosines and
/// Fresnel terms vary fastest there, and the side can switch within a step).
const MIN_COS: f32 = 0.15;

/// `w` turned by angle `h` towards the unit tangent `t ⊥ w`: a path on the
/// unit sphere whose derivative at `h = 0` is `t`.
fn turn(w: Vec3, t: Vec3, h: f32) -> Vec3 {
    w * h.cos() + t * h.sin()
}

/// A uniformly random unit tangent of the unit vector `w`.
fn random_tangent(rng: &mut Pcg32, w: Vec3) -> Vec3 {
    loop {
        let r = square_to_uniform_sphere(rng.next_2d());
        let t = r - w * w.dot(r);
        if t.length() > 0.1 {
            return t.normalize();
        }
    }
}

/// The direction `w` carrying the tangent `t` (forward mode).
fn dual_dir(w: Vec3, t: Vec3) -> V3<Dual> {
    V3::new(
        Dual::new(w.x, t.x),
        Dual::new(w.y, t.y),
        Dual::new(w.z, t.z),
    )
}

/// The tangent part of a forward-mode vector.
fn tangent_of(v: V3<Dual>) -> Vec3 {
    Vec3::new(v.x.d, v.y.d, v.z.d)
}

/// The central difference of `f` along `h` with step `FD_STEP / 2`, or
/// `None` where `f` is not smooth on [−FD_STEP, FD_STEP]: a branch switch
/// (`f` returns `None`, e.g. another lobe was chosen), a change of support
/// (a channel becomes zero), or a kink / singularity (the differences with
/// steps `FD_STEP` and `FD_STEP / 2` disagree by more than half the
/// tolerance; for a smooth `f` they differ by ~(3/4) h² f‴/6).
fn central_difference(f: impl Fn(f32) -> Option<Vec3>) -> Option<Vec3> {
    let h = FD_STEP;
    let v: Vec<Vec3> = [-h, -h / 2.0, 0.0, h / 2.0, h]
        .iter()
        .map(|&x| f(x))
        .collect::<Option<_>>()?;
    let zero = v[2].cmpeq(Vec3::ZERO);
    if v.iter().any(|w| w.cmpeq(Vec3::ZERO) != zero) {
        return None;
    }
    let fd_h = (v[4] - v[0]) / (2.0 * h);
    let fd = (v[3] - v[1]) / h;
    let tol = fd.abs() * FD_REL + v[2].abs() * FD_FLOOR;
    (fd_h - fd).abs().cmple(tol * 0.5).all().then_some(fd)
}

/// Asserts that the forward-mode derivative `d` matches the finite
/// difference `fd` of a quantity of value `value` (see [`FD_REL`]).
pub fn assert_derivative(d: Vec3, fd: Vec3, value: Vec3, what: &dyn Fn() -> String) {
    let tol = fd.abs() * FD_REL + value.abs() * FD_FLOOR;
    assert!(
        (d - fd).abs().cmple(tol).all(),
        "{}: derivative {d} vs finite difference {fd} (value {value})",
        what()
    );
}

/// Checks that `b` is differentiable in the directions (fixed seed): for
/// random `wi`, `wo` and unit tangents, the `Dual` derivative of `eval`
/// along a tangent of `si.wi` and along one of `wo` matches the central
/// difference of the f32 `eval` along the great circles they span; and
/// for samples of delta lobes, the derivatives of the sampled `wo` and of
/// the lobe's value `weight · pdf` (the weight divides by the primal,
/// detached pdf) along a tangent of `wi` match the differences of f32
/// `sample` calls with the same `u1`, `u2`. Samples of smooth lobes must
/// have constant directions. Points where a difference straddles a branch
/// or a kink are skipped (see [`central_difference`]); enough must remain.
pub fn check_direction_derivatives(b: &Bsdf, store: &ParamStore, seed: u64) {
    let mut rng = Pcg32::new(seed);
    let trials = 64;
    let (mut evals, mut deltas) = (0, 0);
    let with_wi = |wi: V3<Dual>| {
        let mut s = si::<Dual>(Vec3::Z);
        s.wi = wi;
        s
    };
    for k in 0..trials {
        let wi = square_to_uniform_sphere(rng.next_2d());
        let wo = square_to_uniform_sphere(rng.next_2d());
        let (ti, to) = (random_tangent(&mut rng, wi), random_tangent(&mut rng, wo));
        let (u1, u2) = (rng.next_f32(), rng.next_2d());
        if wi.z.abs() < MIN_COS {
            continue;
        }
        let what = |d: &'static str| move || format!("{b:?} #{k} wi {wi} wo {wo}: {d}");
        if wo.z.abs() >= MIN_COS {
            let value = eval_f32(b, store, wi, wo);
            let d_wi = b
                .context(&store.primal(), &with_wi(dual_dir(wi, ti)))
                .eval(V3::cst(wo));
            let d_wo = b
                .context(&store.primal(), &si::<Dual>(wi))
                .eval(dual_dir(wo, to));
            let fd_wi = central_difference(|h| Some(eval_f32(b, store, turn(wi, ti, h), wo)));
            let fd_wo = central_difference(|h| Some(eval_f32(b, store, wi, turn(wo, to, h))));
            if let (Some(fd_wi), Some(fd_wo)) = (fd_wi, fd_wo) {
                evals += 1;
                assert_derivative(tangent_of(d_wi), fd_wi, value, &what("eval along wi"));
                assert_derivative(tangent_of(d_wo), fd_wo, value, &what("eval along wo"));
            }
        }
        let Some(bs) = b
            .context(&store.primal(), &with_wi(dual_dir(wi, ti)))
            .sample(u1, u2)
        else {
            continue;
        };
        if !bs.lobe.has(BsdfFlags::DELTA) {
            assert_eq!(tangent_of(bs.wo), Vec3::ZERO, "{}", what("smooth sample")());
            continue;
        }
        let sample_at = |h: f32| {
            let s = b
                .context(&store.primal(), &si::<f32>(turn(wi, ti, h)))
                .sample(u1, u2)?;
            (s.lobe == bs.lobe).then_some(s)
        };
        let fd_wo = central_difference(|h| sample_at(h).map(|s| s.wo.val()));
        let fd_value = central_difference(|h| sample_at(h).map(|s| s.weight.val() * s.pdf));
        if let (Some(fd_wo), Some(fd_value)) = (fd_wo, fd_value) {
            deltas += 1;
            let (wo_s, value) = (bs.wo.val(), bs.weight.val() * bs.pdf);
            let d_value = tangent_of(bs.weight) * bs.pdf;
            assert_derivative(tangent_of(bs.wo), fd_wo, wo_s, &what("delta wo"));
            assert_derivative(d_value, fd_value, value, &what("delta weight · pdf"));
        }
    }
    if b.flags().has(BsdfFlags::SMOOTH) {
        assert!(evals >= trials / 4, "{b:?}: only {evals} evals checked");
    }
    if b.flags().has(BsdfFlags::DELTA) {
        assert!(deltas > 0, "{b:?}: no delta sample checked");
    }
}

/// A row of BSDF values computed by Mitsuba 3.9.1: the parameter case's
/// name, `wi`, `wo`, `eval` and `pdf`.
pub type MitsubaRow = (&'static str, [f32; 3], [f32; 3], [f32; 3], f32);

/// Checks `plugin`'s `eval` and `pdf` with the parameters `case(name)`
/// against Mitsuba's values in `rows` (relative 2e-5), and that the `Dual`
/// evaluation has the same primal values.
pub fn assert_matches_mitsuba(
    plugin: &str,
    rows: &[MitsubaRow],
    case: impl Fn(&str) -> Vec<(&'static str, Value)>,
) {
    for &(name, wi, wo, f_ref, p_ref) in rows {
        let (b, store) = build(plugin, &case(name));
        let (wi, wo) = (Vec3::from(wi), Vec3::from(wo));
        let f = eval_f32(&b, &store, wi, wo);
        let p = pdf_f32(&b, &store, wi, wo);
        for c in 0..3 {
            assert!(
                (f[c] - f_ref[c]).abs() <= 2e-5 * f_ref[c].abs() + 1e-7,
                "{plugin} {name} {wi:?} {wo:?}: {f} vs {f_ref:?}"
            );
        }
        assert!(
            (p - p_ref).abs() <= 2e-5 * p_ref + 1e-7,
            "{plugin} {name} {wi:?} {wo:?}: pdf {p} vs {p_ref}"
        );
        let d = b
            .context(&store.primal(), &si::<Dual>(wi))
            .eval(V3::cst(wo));
        assert_eq!([d.x.v, d.y.v, d.z.v], [f.x, f.y, f.z]);
    }
}
