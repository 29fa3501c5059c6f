//! The parameter store: every differentiable quantity of a scene lives in a
//! flat, named f32 buffer, keyed like Mitsuba's `traverse()` keys
//! (`"red.reflectance.value"`, `"plane.bsdf.reflectance.data"`,
//! `"obj.vertex_positions"`). Components keep [`ParamId`]s and read values
//! as `R: ScalarReal` through a [`ParamView`]: the scene's values together with
//! the [`Seeds`] of one derivative call (tangents in forward mode, the
//! recorded parameters in reverse mode), so that seeding and tagging happen
//! in one place and the derivative state never lives in the scene.

use crate::ad::ScalarReal;
use crate::error::Error;
use crate::geometry::mesh::AttributeParam;
use crate::math::{V2, V3};
use std::collections::HashMap;
use std::fmt;

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
    /// Changing it moves surface points or shading frames (positions,
    /// normals, the camera): paths are then differentiated in a
    /// parameterisation that moves with it (`integrator::scatter`).
    pub moves_frames: bool,
    /// Cannot be changed after loading (e.g. mesh topology).
    pub read_only: bool,
}

impl ParamFlags {
    pub const DIFFERENTIABLE: ParamFlags = ParamFlags {
        differentiable: true,
        discontinuous: false,
        moves_frames: false,
        read_only: false,
    };
    pub const GEOMETRY: ParamFlags = ParamFlags {
        differentiable: true,
        discontinuous: true,
        moves_frames: true,
        read_only: false,
    };
    /// Shading normals: they turn shading frames without moving any edge.
    pub const SHADING_FRAME: ParamFlags = ParamFlags {
        differentiable: true,
        discontinuous: false,
        moves_frames: true,
        read_only: false,
    };
    pub const NON_DIFFERENTIABLE: ParamFlags = ParamFlags {
        differentiable: false,
        discontinuous: false,
        moves_frames: false,
        read_only: false,
    };
    pub const READ_ONLY: ParamFlags = ParamFlags {
        differentiable: false,
        discontinuous: false,
        moves_frames: false,
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
    /// In (-1, 1): the mean cosine of a phase function (Henyey-Greenstein
    /// `g`; ±1 would be a delta).
    OpenSignedUnit,
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
                Domain::OpenSignedUnit => v > -1.0 && v < 1.0,
            }
    }
    /// The domain in words ("in [0, 1]"), for messages.
    pub fn describe(self) -> &'static str {
        match self {
            Domain::Finite => "finite",
            Domain::NonNegative => "finite and >= 0",
            Domain::Positive => "finite and > 0",
            Domain::UnitInterval => "in [0, 1]",
            Domain::OpenSignedUnit => "in (-1, 1)",
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
    /// Set by [`ParamStore::set`]; cleared when dependants were updated.
    pub dirty: bool,
}

/// All parameters of a scene.
#[derive(Clone, Debug, Default)]
pub struct ParamStore {
    params: Vec<Param>,
    by_key: HashMap<String, ParamId>,
    /// The mesh attributes of each shape (by shape index): where the
    /// `mesh_attribute` texture finds the values of the shape it is
    /// evaluated on.
    shape_attributes: Vec<Vec<AttributeParam>>,
}

impl ParamStore {
    pub fn new() -> Self {
        Self::default()
    }

    /// Records the mesh attributes of shape `shape`.
    pub fn set_shape_attributes(&mut self, shape: u32, attributes: Vec<AttributeParam>) {
        let i = shape as usize;
        if self.shape_attributes.len() <= i {
            self.shape_attributes.resize(i + 1, Vec::new());
        }
        self.shape_attributes[i] = attributes;
    }

    /// Attribute `name` of shape `shape`, if it has one.
    #[inline]
    pub fn shape_attribute(&self, shape: u32, name: &str) -> Option<&AttributeParam> {
        self.shape_attributes
            .get(shape as usize)?
            .iter()
            .find(|a| a.name == name)
    }

    /// The mesh attributes of all shapes.
    pub fn shape_attributes(&self) -> impl Iterator<Item = &AttributeParam> {
        self.shape_attributes.iter().flatten()
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
            dirty: false,
        });
        Ok(id)
    }

    #[inline(always)]
    pub fn value(&self, id: ParamId, i: usize) -> f32 {
        self.params[id.0 as usize].data[i]
    }

    /// A view of the values without derivatives (primal renders, and
    /// reads outside of a derivative call).
    pub fn primal(&self) -> ParamView<'_> {
        self.view(&NO_SEEDS)
    }

    /// A view of the values with the derivative state `seeds`.
    pub fn view<'a>(&'a self, seeds: &'a Seeds) -> ParamView<'a> {
        ParamView { store: self, seeds }
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
                msg: format!(
                    "no such parameter{}; `penumbra params SCENE` (or `print(pn.traverse(scene))` \
                     in Python) lists every key",
                    if near.is_empty() {
                        String::new()
                    } else {
                        format!("; did you mean one of: {}", near.join(", "))
                    }
                ),
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

    /// A table of the parameters `ids`: key, shape, flags, domain and a
    /// summary of the current value (the values themselves up to 4
    /// elements, else min / mean / max). `penumbra params` and Python's
    /// `traverse` print it; [`fmt::Display`] shows every parameter.
    pub fn table(&self, ids: &[ParamId]) -> String {
        let rows: Vec<[String; 5]> = ids
            .iter()
            .map(|&id| {
                let p = self.get(id);
                let shape: Vec<String> = p.shape.iter().map(usize::to_string).collect();
                [
                    p.key.clone(),
                    format!("[{}]", shape.join(", ")),
                    p.flags.to_string(),
                    p.domain.describe().to_string(),
                    summarize(&p.data),
                ]
            })
            .collect();
        let head = ["key", "shape", "flags", "domain", "value"].map(String::from);
        let mut widths = [0usize; 4];
        for r in std::iter::once(&head).chain(&rows) {
            for (w, cell) in widths.iter_mut().zip(r) {
                *w = (*w).max(cell.chars().count());
            }
        }
        let mut out = String::new();
        for r in std::iter::once(&head).chain(&rows) {
            for (w, cell) in widths.iter().zip(r) {
                out += &format!("{cell:<w$}  ");
            }
            out += &r[4];
            out.push('\n');
        }
        out
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

/// The derivative state of one derivative call: per parameter, its
/// forward-mode tangent, or whether reverse mode records its reads. The
/// call owns it (`render_forward`, `render_backward`), so a scene is shared
/// read-only by renders and derivative calls alike.
#[derive(Clone, Debug, Default)]
pub struct Seeds {
    /// Indexed by [`ParamId`]; `None` is a zero tangent.
    tangents: Vec<Option<Vec<f32>>>,
    /// Indexed by [`ParamId`].
    recorded: Vec<bool>,
    /// A seeded parameter moves geometry or the camera.
    moves_geometry: bool,
}

static NO_SEEDS: Seeds = Seeds {
    tangents: Vec::new(),
    recorded: Vec::new(),
    moves_geometry: false,
};

impl Seeds {
    /// Forward mode along `tangents` (key, one value per element of the
    /// parameter); parameters not listed have zero tangent. Checks keys,
    /// lengths, finiteness and that each parameter is differentiable.
    pub fn tangents(store: &ParamStore, tangents: &[(&str, &[f32])]) -> Result<Seeds, Error> {
        let mut seeds = Seeds::default();
        seeds.tangents.resize(store.len(), None);
        for (key, t) in tangents {
            let id = store.require(key)?;
            let p = store.get(id);
            require_differentiable(key, p)?;
            if t.len() != p.data.len() {
                return Err(Error::Param {
                    key: key.to_string(),
                    msg: format!(
                        "tangent needs {} values (shape {:?}), got {}",
                        p.data.len(),
                        p.shape,
                        t.len()
                    ),
                });
            }
            if let Some(i) = t.iter().position(|v| !v.is_finite()) {
                return Err(Error::Param {
                    key: key.to_string(),
                    msg: format!("tangent element {i} is not finite"),
                });
            }
            seeds.tangents[id.0 as usize] = Some(t.to_vec());
            seeds.moves_geometry |= p.flags.moves_frames;
        }
        Ok(seeds)
    }

    /// Reverse mode records the reads of exactly the parameters `ids`
    /// (each must be differentiable).
    pub fn recorded(store: &ParamStore, ids: &[ParamId]) -> Result<Seeds, Error> {
        let mut seeds = Seeds::default();
        seeds.recorded.resize(store.len(), false);
        for &id in ids {
            let p = store.get(id);
            require_differentiable(&p.key, p)?;
            seeds.recorded[id.0 as usize] = true;
            seeds.moves_geometry |= p.flags.moves_frames;
        }
        Ok(seeds)
    }

    /// Whether reverse mode records reads of `id`.
    pub fn is_recorded(&self, id: ParamId) -> bool {
        self.recorded.get(id.0 as usize).copied().unwrap_or(false)
    }

    /// Whether a seeded parameter moves surface points or shading frames
    /// (flag `moves_frames`: geometry, shading normals, the camera): paths
    /// are then re-evaluated in the parameterisation of
    /// `integrator::scatter`.
    pub fn moves_geometry(&self) -> bool {
        self.moves_geometry
    }
}

fn require_differentiable(key: &str, p: &Param) -> Result<(), Error> {
    if p.flags.differentiable {
        Ok(())
    } else {
        Err(Error::Param {
            key: key.into(),
            msg: "this parameter is not differentiable".into(),
        })
    }
}

/// What rendering code reads parameters through: the scene's values and
/// the [`Seeds`] of the call. Dereferences to the store for everything
/// else (`data`, `get`, `value`).
#[derive(Clone, Copy, Debug)]
pub struct ParamView<'a> {
    store: &'a ParamStore,
    seeds: &'a Seeds,
}

impl<'a> ParamView<'a> {
    /// The forward-mode tangent of element `i` of `id` (0 if none is set).
    #[inline(always)]
    pub fn tangent(&self, id: ParamId, i: usize) -> f32 {
        match self.seeds.tangents.get(id.0 as usize) {
            Some(Some(t)) => t[i],
            _ => 0.0,
        }
    }

    /// The forward-mode tangent of `id`, if one is set.
    #[inline(always)]
    pub fn tangents(&self, id: ParamId) -> Option<&[f32]> {
        match self.seeds.tangents.get(id.0 as usize) {
            Some(Some(t)) => Some(t),
            _ => None,
        }
    }

    /// Whether a tangent is set for `id`.
    pub fn has_tangent(&self, id: ParamId) -> bool {
        matches!(self.seeds.tangents.get(id.0 as usize), Some(Some(_)))
    }

    /// Whether reverse mode records reads of `id`.
    pub fn is_recorded(&self, id: ParamId) -> bool {
        self.seeds.is_recorded(id)
    }

    /// See [`Seeds::moves_geometry`].
    pub fn moves_geometry(&self) -> bool {
        self.seeds.moves_geometry
    }

    /// Element `i` of parameter `id` as `R` (seeded or tagged for
    /// differentiation according to `R`).
    #[inline(always)]
    pub fn read<R: ScalarReal>(&self, id: ParamId, i: usize) -> R {
        R::from_param(self, id, i)
    }

    /// Elements `3i, 3i+1, 3i+2` as a vector (RGB values, positions).
    #[inline(always)]
    pub fn read3<R: ScalarReal>(&self, id: ParamId, i: usize) -> V3<R> {
        if !R::DIFFERENTIABLE {
            // one look-up of the parameter and one bounds check, not three
            let v = &self.store.data(id)[3 * i..3 * i + 3];
            return V3::new(R::cst(v[0]), R::cst(v[1]), R::cst(v[2]));
        }
        V3::new(
            self.read(id, 3 * i),
            self.read(id, 3 * i + 1),
            self.read(id, 3 * i + 2),
        )
    }

    /// Elements `2i, 2i+1` as a vector (texture coordinates).
    #[inline(always)]
    pub fn read2<R: ScalarReal>(&self, id: ParamId, i: usize) -> V2<R> {
        if !R::DIFFERENTIABLE {
            let v = &self.store.data(id)[2 * i..2 * i + 2];
            return V2::new(R::cst(v[0]), R::cst(v[1]));
        }
        V2::new(self.read(id, 2 * i), self.read(id, 2 * i + 1))
    }
}

impl std::ops::Deref for ParamView<'_> {
    type Target = ParamStore;
    fn deref(&self) -> &ParamStore {
        self.store
    }
}

impl fmt::Display for ParamStore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ids: Vec<ParamId> = self.iter().map(|(id, _)| id).collect();
        f.write_str(&self.table(&ids))
    }
}

impl fmt::Display for ParamFlags {
    /// `differentiable`, `differentiable, discontinuous`, `read-only`, or
    /// `-` for none.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<&str> = [
            (self.differentiable, "differentiable"),
            (self.discontinuous, "discontinuous"),
            (self.read_only, "read-only"),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .map(|(_, name)| *name)
        .collect();
        if names.is_empty() {
            f.write_str("-")
        } else {
            f.write_str(&names.join(", "))
        }
    }
}

/// The values themselves up to 4 elements, else their min / mean / max.
fn summarize(data: &[f32]) -> String {
    let num = |v: f64| format!("{v:.4}");
    if data.len() <= 4 {
        let v: Vec<String> = data.iter().map(|&v| num(v as f64)).collect();
        return format!("[{}]", v.join(", "));
    }
    let (lo, hi) = data
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let mean = data.iter().map(|&v| v as f64).sum::<f64>() / data.len() as f64;
    format!(
        "min {}, mean {}, max {}",
        num(lo as f64),
        num(mean),
        num(hi as f64)
    )
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
        let seeds = Seeds::tangents(&s, &[("red.reflectance.value", &[1.0, 0.0, 2.0])]).unwrap();
        let view = s.view(&seeds);
        assert_eq!(view.read::<f32>(id, 2), 0.1);
        assert_eq!(view.read::<Dual>(id, 2), Dual::new(0.1, 2.0));
        assert_eq!(s.primal().read::<Dual>(id, 2), Dual::new(0.1, 0.0));
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

    #[test]
    fn table_lists_shape_flags_and_a_value_summary() {
        let mut s = ParamStore::new();
        s.add(
            "red.reflectance.value",
            vec![0.5, 0.25, 0.125],
            vec![3],
            ParamFlags::DIFFERENTIABLE,
            Domain::UnitInterval,
        )
        .unwrap();
        s.add(
            "mesh.vertex_positions",
            vec![-1.0, 0.0, 1.0, 2.0, 3.0, 5.0],
            vec![2, 3],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )
        .unwrap();
        s.add(
            "mesh.faces",
            vec![0.0; 3],
            vec![1, 3],
            ParamFlags::READ_ONLY,
            Domain::Finite,
        )
        .unwrap();
        let t = s.to_string();
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 4, "{t}");
        let words = |l: &str| l.split_whitespace().collect::<Vec<_>>().join(" ");
        assert_eq!(words(lines[0]), "key shape flags domain value");
        assert_eq!(
            words(lines[1]),
            "red.reflectance.value [3] differentiable in [0, 1] [0.5000, 0.2500, 0.1250]"
        );
        assert_eq!(
            words(lines[2]),
            "mesh.vertex_positions [2, 3] differentiable, discontinuous finite \
             min -1.0000, mean 1.6667, max 5.0000"
        );
        assert_eq!(
            words(lines[3]),
            "mesh.faces [1, 3] read-only finite [0.0000, 0.0000, 0.0000]"
        );
        // the columns line up
        let col = lines[0].find("shape").unwrap();
        assert!(lines[1..].iter().all(|l| l.as_bytes()[col - 1] == b' '));
        assert_eq!(lines[1].find("[3]"), Some(col));
        // a subset
        let only = s.table(&[s.id("mesh.faces").unwrap()]);
        assert_eq!(only.lines().count(), 2);
    }

    #[test]
    fn unknown_keys_point_to_the_listing_commands() {
        let mut s = ParamStore::new();
        s.add(
            "red.reflectance.value",
            vec![0.5; 3],
            vec![3],
            ParamFlags::DIFFERENTIABLE,
            Domain::UnitInterval,
        )
        .unwrap();
        for key in ["red.reflectance.valeu", "nothing"] {
            let e = s.require(key).unwrap_err().to_string();
            assert!(e.contains("`penumbra params SCENE`"), "{e}");
            assert!(e.contains("pn.traverse(scene)"), "{e}");
        }
        let e = s.require("red.reflectance.valeu").unwrap_err().to_string();
        assert!(
            e.contains("did you mean one of: red.reflectance.value"),
            "{e}"
        );
    }
}
