//! Gradient-descent optimisers over parameters of the store, with
//! per-parameter learning rates; updated values are projected back into
//! each parameter's valid domain (reflectance in [0, 1], roughness > 0, …).

use crate::diff::Gradients;
use crate::error::{Error, Result};
use crate::params::{Domain, ParamStore};
use std::collections::HashMap;

/// The smallest value kept for parameters that must stay positive
/// (roughness, index of refraction).
const MIN_POSITIVE: f32 = 1e-3;

/// The largest |g| kept for phase-function anisotropies (the phase
/// function becomes a delta at 1).
const MAX_ANISOTROPY: f32 = 0.999;

/// Clamps `v` into `domain`.
pub fn project(v: f32, domain: Domain) -> f32 {
    match domain {
        Domain::Finite => v,
        Domain::NonNegative => v.max(0.0),
        Domain::Positive => v.max(MIN_POSITIVE),
        Domain::UnitInterval => v.clamp(0.0, 1.0),
        Domain::OpenSignedUnit => v.clamp(-MAX_ANISOTROPY, MAX_ANISOTROPY),
    }
}

/// Which update rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Plain gradient descent with optional momentum.
    Sgd { momentum: f32 },
    /// Adam (Kingma & Ba 2015).
    Adam {
        beta1: f32,
        beta2: f32,
        epsilon: f32,
    },
}

/// An optimiser over named parameters.
#[derive(Clone, Debug)]
pub struct Optimizer {
    pub method: Method,
    /// Learning rate per parameter key.
    pub learning_rates: Vec<(String, f32)>,
    /// First and second moments per key (Adam), or velocity (SGD).
    state: HashMap<String, (Vec<f32>, Vec<f32>)>,
    step: u32,
}

impl Optimizer {
    pub fn new(method: Method, learning_rates: Vec<(String, f32)>) -> Result<Optimizer> {
        for (k, lr) in &learning_rates {
            if !(*lr > 0.0) || !lr.is_finite() {
                return Err(Error::Param {
                    key: k.clone(),
                    msg: format!("learning rate must be > 0, found {lr}"),
                });
            }
        }
        Ok(Optimizer {
            method,
            learning_rates,
            state: HashMap::new(),
            step: 0,
        })
    }

    pub fn adam(learning_rates: Vec<(String, f32)>) -> Result<Optimizer> {
        Optimizer::new(
            Method::Adam {
                beta1: 0.9,
                beta2: 0.999,
                epsilon: 1e-8,
            },
            learning_rates,
        )
    }

    /// Keys of the optimised parameters.
    pub fn keys(&self) -> Vec<&str> {
        self.learning_rates
            .iter()
            .map(|(k, _)| k.as_str())
            .collect()
    }

    /// One descent step on `store` from `grads` (∂loss/∂θ); values are
    /// projected into their domains. Call `Scene::update` afterwards.
    pub fn step(&mut self, store: &mut ParamStore, grads: &Gradients) -> Result<()> {
        self.step += 1;
        let t = self.step as i32;
        for (key, lr) in &self.learning_rates {
            let g = grads.get(key).ok_or_else(|| Error::Param {
                key: key.clone(),
                msg: "no gradient was computed for this parameter".into(),
            })?;
            let id = store.require(key)?;
            let p = store.get(id);
            let domain = p.domain;
            let mut values = p.data.clone();
            let (m, v) = self
                .state
                .entry(key.clone())
                .or_insert_with(|| (vec![0.0; g.len()], vec![0.0; g.len()]));
            for i in 0..values.len() {
                let gi = g[i];
                let delta = match self.method {
                    Method::Sgd { momentum } => {
                        m[i] = momentum * m[i] + gi;
                        lr * m[i]
                    }
                    Method::Adam {
                        beta1,
                        beta2,
                        epsilon,
                    } => {
                        m[i] = beta1 * m[i] + (1.0 - beta1) * gi;
                        v[i] = beta2 * v[i] + (1.0 - beta2) * gi * gi;
                        let mh = m[i] / (1.0 - beta1.powi(t));
                        let vh = v[i] / (1.0 - beta2.powi(t));
                        lr * mh / (vh.sqrt() + epsilon)
                    }
                };
                values[i] = project(values[i] - delta, domain);
            }
            store.set(key, &values)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diff::GradEntry;
    use crate::params::ParamFlags;

    /// Both methods minimise a quadratic and respect the domain.
    #[test]
    fn descends_a_quadratic_within_the_domain() {
        for method in [
            Method::Sgd { momentum: 0.5 },
            Method::Adam {
                beta1: 0.9,
                beta2: 0.999,
                epsilon: 1e-8,
            },
        ] {
            let mut s = ParamStore::new();
            s.add(
                "r.value",
                vec![0.9, 0.1],
                vec![2],
                ParamFlags::DIFFERENTIABLE,
                Domain::UnitInterval,
            )
            .unwrap();
            let target = [0.3f32, 1.4]; // the second lies outside [0, 1]
            let mut opt = Optimizer::new(method, vec![("r.value".into(), 0.05)]).unwrap();
            for _ in 0..300 {
                let x = s.data(s.id("r.value").unwrap()).to_vec();
                let g = Gradients {
                    entries: vec![GradEntry {
                        key: "r.value".into(),
                        shape: vec![2],
                        data: x.iter().zip(&target).map(|(x, t)| 2.0 * (x - t)).collect(),
                    }],
                    ..Default::default()
                };
                opt.step(&mut s, &g).unwrap();
            }
            let x = s.data(s.id("r.value").unwrap());
            assert!((x[0] - 0.3).abs() < 0.02, "{method:?}: {x:?}");
            assert_eq!(x[1], 1.0, "{method:?}: clamped to the domain");
        }
    }
}
