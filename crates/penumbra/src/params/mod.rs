//! The parameter store: every differentiable quantity of a scene lives in a
//! flat, named f32 buffer, keyed like Mitsuba's `traverse()` keys
//! (`"red.reflectance.value"`, `"plane.bsdf.reflectance.data"`,
//! `"obj.vertex_positions"`). Components keep [`ParamId`]s and read values
//! as `R: Real` through [`ParamStore::read`], so that forward-mode seeding
//! and reverse-mode tagging happen in one place.

use crate::ad::Real;
use crate::error::Error;
use crate::math::V3;
use std::collections::HashMap;

/// Index of a parameter in its [`ParamStore`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ParamId(pub u32);

/// What may be done with a parameter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParamFlags {
    /// Derivatives with respect to it are computed.
    pub differentiable: bool,
    /// Changing it moves visibility discontinuities (geometry): its
    /// derivatives need boundary terms.
    pub discontinuous: bool,
    /// Cannot be changed after loading (e.g. mesh topology).
    pub read_only: bool,
}

impl ParamFlags {
    pub const DIFFERENTIABLE: ParamFlags = ParamFlags {
        differentiable: true,
        discontinuous: false,
        read_only: false,
    };
    pub const GEOMETRY: ParamFlags = ParamFlags {
        differentiable: true,
        discontinuous: true,
        read_only: false,
    };
    pub const NON_DIFFERENTIABLE: ParamFlags = ParamFlags {
        differentiable: false,
        discontinuous: false,
        read_only: false,
    };
    pub const READ_ONLY: ParamFlags = ParamFlags {
        differentiable: false,
        discontinuous: false,
        read_only: true,
    };
}

/// The valid range of a parameter's values, checked on update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Domain {
    /// Any finite value.
    Finite,
    /// Finite and ≥ 0 (radiance, extinction).
    NonNegative,
    /// Finite and > 0 (roughness, index of refraction).
    Positive,
    /// In [0, 1] (reflectance, albedo, blend weights).
    UnitInterval,
}

impl Domain {
    /// Whether `v` lies in the domain.
    pub fn admits(self, v: f32) -> bool {
        v.is_finite()
            && match self {
                Domain::Finite => true,
                Domain::NonNegative => v >= 0.0,
                Domain::Positive => v > 0.0,
                Domain::UnitInterval => (0.0..=1.0).contains(&v),
            }
    }
    /// The domain in words ("in [0, 1]"), for messages.
    pub fn describe(self) -> &'static str {
        match self {
            Domain::Finite => "finite",
            Domain::NonNegative => "finite and >= 0",
            Domain::Positive => "finite and > 0",
            Domain::UnitInterval => "in [0, 1]",
        }
    }
}

/// One named parameter buffer.
#[derive(Clone, Debug)]
pub struct Param {
    pub key: String,
    pub data: Vec<f32>,
    /// Logical shape, row-major (`[3]` for an RGB value, `[h, w, c]` for a
    /// texture, `[n, 3]` for vertex positions).
    pub shape: Vec<usize>,
    pub flags: ParamFlags,
    pub domain: Domain,
    /// Tangent (forward-mode direction), same length as `data`, if set.
    pub tangent: Option<Vec<f32>>,
    /// Set by [`ParamStore::set`]; cleared when dependants were updated.
    pub dirty: bool,
    /// Reverse mode records reads of this parameter (set by
    /// `render_backward` for the parameters whose gradients it returns).
    pub grad_enabled: bool,
}

/// All parameters of a scene.
#[derive(Clone, Debug, Default)]
pub struct ParamStore {
    params: Vec<Param>,
    by_key: HashMap<String, ParamId>,
}

impl ParamStore {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a parameter. Keys must be unique; values must be in `domain`.
    pub fn add(
        &mut self,
        key: impl Into<String>,
        data: Vec<f32>,
        shape: Vec<usize>,
        flags: ParamFlags,
        domain: Domain,
    ) -> Result<ParamId, Error> {
        let key = key.into();
        if self.by_key.contains_key(&key) {
            return Err(Error::Param {
                key,
                msg: "a parameter with this key exists already (two objects with the same id?)"
                    .into(),
            });
        }
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        check_domain(&key, &data, domain)?;
        let id = ParamId(self.params.len() as u32);
        self.by_key.insert(key.clone(), id);
        self.params.push(Param {
            key,
            data,
            shape,
            flags,
            domain,
            tangent: None,
            dirty: false,
            grad_enabled: false,
        });
        Ok(id)
    }

    #[inline(always)]
    pub fn value(&self, id: ParamId, i: usize) -> f32 {
        self.params[id.0 as usize].data[i]
    }

    #[inline(always)]
    pub fn tangent(&self, id: ParamId, i: usize) -> f32 {
        match &self.params[id.0 as usize].tangent {
            Some(t) => t[i],
            None => 0.0,
        }
    }

    /// Element `i` of parameter `id` as `R` (seeded or tagged for
    /// differentiation according to `R`).
    #[inline(always)]
    pub fn read<R: Real>(&self, id: ParamId, i: usize) -> R {
        R::from_param(self, id, i)
    }

    /// Elements `3i, 3i+1, 3i+2` as a vector (RGB values, positions).
    #[inline(always)]
    pub fn read3<R: Real>(&self, id: ParamId, i: usize) -> V3<R> {
        V3::new(
            self.read(id, 3 * i),
            self.read(id, 3 * i + 1),
            self.read(id, 3 * i + 2),
        )
    }

    pub fn id(&self, key: &str) -> Option<ParamId> {
        self.by_key.get(key).copied()
    }

    /// The id of `key`, or an error that lists close matches.
    pub fn require(&self, key: &str) -> Result<ParamId, Error> {
        self.id(key).ok_or_else(|| {
            let mut near: Vec<&str> = self
                .by_key
                .keys()
                .filter(|k| {
                    let last = key.rsplit('.').next().unwrap_or(key);
                    k.contains(last) || key.contains(k.split('.').next().unwrap_or(""))
                })
                .map(|s| s.as_str())
                .collect();
            near.sort();
            near.truncate(8);
            Error::Param {
                key: key.to_string(),
                msg: if near.is_empty() {
                    "no such parameter (list them with traverse / `penumbra params`)".into()
                } else {
                    format!(
                        "no such parameter; did you mean one of: {}",
                        near.join(", ")
                    )
                },
            }
        })
    }

    pub fn get(&self, id: ParamId) -> &Param {
        &self.params[id.0 as usize]
    }

    pub fn data(&self, id: ParamId) -> &[f32] {
        &self.params[id.0 as usize].data
    }

    pub fn len(&self) -> usize {
        self.params.len()
    }
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// All parameters, in insertion order.
    pub fn iter(&self) -> impl Iterator<Item = (ParamId, &Param)> {
        self.params
            .iter()
            .enumerate()
            .map(|(i, p)| (ParamId(i as u32), p))
    }

    /// Replaces the values of `key`; checks length, finiteness and domain.
    /// Marks it dirty so that the scene refreshes what depends on it.
    pub fn set(&mut self, key: &str, data: &[f32]) -> Result<(), Error> {
        let id = self.require(key)?;
        let p = &mut self.params[id.0 as usize];
        if p.flags.read_only {
            return Err(Error::Param {
                key: key.into(),
                msg: "this parameter is read-only".into(),
            });
        }
        if data.len() != p.data.len() {
            return Err(Error::Param {
                key: key.into(),
                msg: format!(
                    "expected {} values (shape {:?}), got {}",
                    p.data.len(),
                    p.shape,
                    data.len()
                ),
            });
        }
        check_domain(key, data, p.domain)?;
        p.data.copy_from_slice(data);
        p.dirty = true;
        Ok(())
    }

    /// Sets the forward-mode tangent of `key` (same length as its data).
    pub fn set_tangent(&mut self, key: &str, tangent: &[f32]) -> Result<(), Error> {
        let id = self.require(key)?;
        let p = &mut self.params[id.0 as usize];
        if !p.flags.differentiable {
            return Err(Error::Param {
                key: key.into(),
                msg: "this parameter is not differentiable".into(),
            });
        }
        if tangent.len() != p.data.len() {
            return Err(Error::Param {
                key: key.into(),
                msg: format!(
                    "tangent needs {} values (shape {:?}), got {}",
                    p.data.len(),
                    p.shape,
                    tangent.len()
                ),
            });
        }
        if let Some(i) = tangent.iter().position(|v| !v.is_finite()) {
            return Err(Error::Param {
                key: key.into(),
                msg: format!("tangent element {i} is not finite"),
            });
        }
        p.tangent = Some(tangent.to_vec());
        Ok(())
    }

    /// Enables reverse-mode recording for exactly the parameters in `ids`.
    pub fn set_grad_enabled(&mut self, ids: &[ParamId]) {
        for p in &mut self.params {
            p.grad_enabled = false;
        }
        for id in ids {
            self.params[id.0 as usize].grad_enabled = true;
        }
    }

    pub fn clear_tangents(&mut self) {
        for p in &mut self.params {
            p.tangent = None;
        }
    }

    /// Keys of the parameters marked dirty since the last call; clears them.
    pub fn take_dirty(&mut self) -> Vec<ParamId> {
        let mut out = Vec::new();
        for (i, p) in self.params.iter_mut().enumerate() {
            if p.dirty {
                p.dirty = false;
                out.push(ParamId(i as u32));
            }
        }
        out
    }
}

fn check_domain(key: &str, data: &[f32], domain: Domain) -> Result<(), Error> {
    if let Some(i) = data.iter().position(|&v| !domain.admits(v)) {
        return Err(Error::Param {
            key: key.into(),
            msg: format!(
                "element {i} is {}, but values must be {}",
                data[i],
                domain.describe()
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;

    #[test]
    fn read_seeds_tangents_only_for_dual() {
        let mut s = ParamStore::new();
        let id = s
            .add(
                "red.reflectance.value",
                vec![0.5, 0.1, 0.1],
                vec![3],
                ParamFlags::DIFFERENTIABLE,
                Domain::UnitInterval,
            )
            .unwrap();
        s.set_tangent("red.reflectance.value", &[1.0, 0.0, 2.0])
            .unwrap();
        assert_eq!(s.read::<f32>(id, 2), 0.1);
        assert_eq!(s.read::<Dual>(id, 2), Dual::new(0.1, 2.0));
        s.clear_tangents();
        assert_eq!(s.read::<Dual>(id, 2), Dual::new(0.1, 0.0));
    }

    #[test]
    fn set_checks_shape_domain_and_key() {
        let mut s = ParamStore::new();
        s.add(
            "a.alpha.value",
            vec![0.2],
            vec![1],
            ParamFlags::DIFFERENTIABLE,
            Domain::Positive,
        )
        .unwrap();
        let e = s.set("a.alpha.value", &[0.0]).unwrap_err().to_string();
        assert!(e.contains("a.alpha.value") && e.contains("> 0"), "{e}");
        let e = s.set("a.alpha.value", &[f32::NAN]).unwrap_err().to_string();
        assert!(e.contains("NaN"), "{e}");
        let e = s.set("a.alpha.value", &[0.1, 0.2]).unwrap_err().to_string();
        assert!(e.contains("expected 1 values"), "{e}");
        let e = s.set("a.alpha", &[0.1]).unwrap_err().to_string();
        assert!(
            e.contains("did you mean") && e.contains("a.alpha.value"),
            "{e}"
        );
        s.set("a.alpha.value", &[0.3]).unwrap();
        assert_eq!(s.take_dirty().len(), 1);
        assert!(s.take_dirty().is_empty());
    }
}
