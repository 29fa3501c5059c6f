//! Gradient checking: the derivative of a rendered image along a parameter
//! direction, three ways — central finite differences with identical random
//! numbers, forward mode, and reverse mode (path replay) — each over several
//! independent batches so that their agreement can be judged against their
//! Monte Carlo noise.

use super::{render_backward, render_forward};
use crate::error::{Error, Result};
use crate::integrator::{render, ProgressFn, RenderOptions, Rendered};
use crate::scene::Scene;
use std::sync::Arc;

/// A mean over batches with its standard error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    pub mean: f64,
    pub std_err: f64,
}

impl Estimate {
    fn of(samples: &[f64]) -> Estimate {
        let n = samples.len() as f64;
        let mean = samples.iter().sum::<f64>() / n;
        let var = if samples.len() > 1 {
            samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Estimate {
            mean,
            std_err: (var / n).sqrt(),
        }
    }

    /// |a − b| in units of the combined standard error.
    pub fn z_score(&self, other: &Estimate) -> f64 {
        let se = (self.std_err.powi(2) + other.std_err.powi(2)).sqrt();
        let d = (self.mean - other.mean).abs();
        if se > 0.0 {
            d / se
        } else if d == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    }
}

/// Settings of a gradient check.
#[derive(Clone)]
pub struct CheckOptions {
    /// Samples per pixel of each batch.
    pub spp: u32,
    /// Edge samples per pixel of the boundary term of primary visibility
    /// in the derivative passes ([`RenderOptions::sppp`]; default: the
    /// integrator's `sppp`, else `spp`).
    pub sppp: Option<u32>,
    /// Samples per pixel of the boundary term of the visibility seen from
    /// the first vertex ([`RenderOptions::sppi`]; default: the
    /// integrator's `sppi`, else `spp`).
    pub sppi: Option<u32>,
    /// Independent batches (different seeds) for the error bars.
    pub batches: u32,
    /// Relative step of the finite differences.
    pub eps: f32,
    pub threads: Option<usize>,
    /// Called after each batch with `(batches done, batches)`.
    pub progress: Option<Arc<ProgressFn>>,
    /// Passed on to [`RenderOptions::force`].
    pub force: bool,
    /// The direction of the derivative, as long as the parameter (default:
    /// the parameter's own value, see [`CheckReport::tangent`]). Geometry
    /// is checked along translations, rotations or perturbations of its
    /// vertices ([`translation_tangent`], [`perturbation_tangent`]).
    pub tangent: Option<Vec<f32>>,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            spp: 16,
            sppp: None,
            sppi: None,
            batches: 4,
            eps: 1e-2,
            threads: None,
            progress: None,
            force: false,
            tangent: None,
        }
    }
}

/// The derivative of `S(θ) = Σ_pixels I(θ)` along the tangent `t` of one
/// parameter, estimated three ways.
#[derive(Clone, Debug)]
pub struct CheckReport {
    pub key: String,
    /// The tangent direction (the parameter's own value, i.e. the
    /// derivative with respect to a relative scale `θ·(1+s)` at s = 0, or
    /// ones where the value is zero).
    pub tangent: Vec<f32>,
    pub finite_differences: Estimate,
    pub forward: Estimate,
    pub reverse: Estimate,
    /// Batch-averaged derivative images (crop height × width × 3).
    pub fd_image: Rendered,
    pub forward_image: Rendered,
}

/// A tangent that moves parameter `key` by the translation `t`: every
/// point of a `[n, 3]` array (vertex positions, a sphere's centre), or the
/// translation column of a `[4, 4]` row-major `to_world`.
pub fn translation_tangent(scene: &Scene, key: &str, t: [f32; 3]) -> Result<Vec<f32>> {
    let p = scene.params.get(scene.params.require(key)?);
    match p.shape.as_slice() {
        [4, 4] => {
            let mut v = vec![0.0; 16];
            (v[3], v[7], v[11]) = (t[0], t[1], t[2]);
            Ok(v)
        }
        [.., 3] => Ok((0..p.data.len()).map(|i| t[i % 3]).collect()),
        s => Err(Error::Param {
            key: key.into(),
            msg: format!(
                "a translation moves [n, 3] points or a [4, 4] to_world; this parameter has shape {s:?}"
            ),
        }),
    }
}

/// A random tangent with elements uniform in [−1, 1) (seeded), e.g. a
/// perturbation of every vertex.
pub fn perturbation_tangent(scene: &Scene, key: &str, seed: u64) -> Result<Vec<f32>> {
    let n = scene.params.data(scene.params.require(key)?).len();
    let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    Ok((0..n)
        .map(|_| {
            // xorshift64*
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            let r = s.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40;
            r as f32 / (1u64 << 23) as f32 - 1.0
        })
        .collect())
}

/// Checks the derivative with respect to parameter `key`.
pub fn check_gradient(scene: &mut Scene, key: &str, opts: &CheckOptions) -> Result<CheckReport> {
    if opts.batches == 0 || opts.spp == 0 {
        return Err(Error::Invalid(
            "check-grad needs at least one batch and one sample".into(),
        ));
    }
    let id = scene.params.require(key)?;
    let p = scene.params.get(id);
    if !p.flags.differentiable {
        return Err(Error::Param {
            key: key.into(),
            msg: "this parameter is not differentiable".into(),
        });
    }
    let theta: Vec<f32> = p.data.clone();
    let tangent: Vec<f32> = match &opts.tangent {
        Some(t) if t.len() != theta.len() => {
            return Err(Error::Param {
                key: key.into(),
                msg: format!(
                    "the tangent has {} values, the parameter {} (shape {:?})",
                    t.len(),
                    theta.len(),
                    p.shape
                ),
            })
        }
        Some(t) => t.clone(),
        None if theta.iter().all(|&v| v == 0.0) => vec![1.0; theta.len()],
        None => theta.clone(),
    };
    let (mut fd, mut fw, mut rv) = (Vec::new(), Vec::new(), Vec::new());
    let mut fd_sum: Option<Vec<f64>> = None;
    let mut fw_sum: Option<Vec<f64>> = None;
    let add = |acc: &mut Option<Vec<f64>>, img: &[f32]| match acc {
        Some(a) => a.iter_mut().zip(img).for_each(|(a, &v)| *a += v as f64),
        None => *acc = Some(img.iter().map(|&v| v as f64).collect()),
    };
    let shifted =
        |s: f32| -> Vec<f32> { theta.iter().zip(&tangent).map(|(v, t)| v + s * t).collect() };
    let mut last: Option<Rendered> = None;
    let result = (|| -> Result<()> {
        for b in 0..opts.batches {
            let ro = RenderOptions {
                spp: Some(opts.spp),
                sppp: opts.sppp,
                sppi: opts.sppi,
                seed: 1000 + b as u64,
                threads: opts.threads,
                force: opts.force,
                // all three on the scalar loop: its finite differences are
                // the derivatives of the estimate that forward mode
                // differentiates and reverse mode replays (the loop in
                // lanes estimates the image with other directions)
                lanes: Some(1),
                ..Default::default()
            };
            // finite differences with identical random numbers
            scene.params.set(key, &shifted(opts.eps))?;
            scene.update()?;
            let plus = render(scene, &ro)?;
            scene.params.set(key, &shifted(-opts.eps))?;
            scene.update()?;
            let minus = render(scene, &ro)?;
            scene.params.set(key, &theta)?;
            scene.update()?;
            let d: Vec<f32> = plus
                .data
                .iter()
                .zip(&minus.data)
                .map(|(a, b)| (a - b) / (2.0 * opts.eps))
                .collect();
            fd.push(d.iter().map(|&v| v as f64).sum());
            add(&mut fd_sum, &d);
            // forward mode
            let f = render_forward(scene, &[(key, &tangent)], &ro)?;
            fw.push(f.data.iter().map(|&v| v as f64).sum());
            add(&mut fw_sum, &f.data);
            // reverse mode: ∂S/∂I = 1 everywhere, then project on the tangent
            let ones = vec![1.0f32; f.data.len()];
            let g = render_backward(scene, &ones, Some(&[key]), &ro)?;
            let grad = g.get(key).expect("the requested key has a gradient");
            rv.push(
                grad.iter()
                    .zip(&tangent)
                    .map(|(&g, &t)| g as f64 * t as f64)
                    .sum(),
            );
            last = Some(f);
            if let Some(p) = &opts.progress {
                p(b as usize + 1, opts.batches as usize);
            }
        }
        Ok(())
    })();
    // leave the scene as it was, whatever happened
    scene.params.set(key, &theta)?;
    scene.update()?;
    result?;
    let shape = last.expect("at least one batch");
    let image = |acc: Option<Vec<f64>>| Rendered {
        data: acc
            .expect("at least one batch")
            .iter()
            .map(|v| (v / opts.batches as f64) as f32)
            .collect(),
        ..shape.clone()
    };
    Ok(CheckReport {
        key: key.into(),
        tangent,
        finite_differences: Estimate::of(&fd),
        forward: Estimate::of(&fw),
        reverse: Estimate::of(&rv),
        fd_image: image(fd_sum),
        forward_image: image(fw_sum),
    })
}
