//! `conductor`: a smooth metal (perfect specular reflection with the
//! conductor Fresnel term).

use super::fresnel::{fresnel_conductor, lookup_conductor, CONDUCTOR_TABLE};
use super::{default_albedo, BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NodeContext};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Complex index of refraction `eta + i k` of a conductor, from
/// `material` (a name from Mitsuba's table, or "none" = perfect mirror,
/// the default) or from `eta` / `k` (float, rgb or texture). Both become
/// parameters `<key>.eta.value` and `<key>.k.value`, as in Mitsuba.
#[derive(Clone, Debug)]
pub struct ConductorIor {
    pub eta: Texture,
    pub k: Texture,
}

impl ConductorIor {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<ConductorIor> {
        let material = node.string("material", "none")?;
        let (eta_default, k_default) = if material == "none" {
            // eta = 0, k = 1: the Fresnel term is 1 at all angles
            (Vec3::ZERO, Vec3::ONE)
        } else {
            if node.has("eta") || node.has("k") {
                return Err(node.error(format!(
                    "give either 'material' or 'eta' and 'k', not both (material is '{material}')"
                )));
            }
            lookup_conductor(&material).ok_or_else(|| {
                let names: Vec<&str> = CONDUCTOR_TABLE.iter().map(|e| e.0).collect();
                node.error(format!(
                    "unknown conductor material '{material}'; known: none, {}",
                    names.join(", ")
                ))
            })?
        };
        let tex = |name: &str, v: Vec3, ctx: &mut LoadContext| -> Result<Texture> {
            if node.has(name) || v.x == v.y && v.y == v.z {
                Texture::from_prop(
                    node,
                    name,
                    Some(v.x),
                    Channels::Rgb,
                    Domain::NonNegative,
                    ctx,
                )
            } else {
                // a named material: an RGB uniform value
                crate::texture::Uniform::new(
                    &format!("{}.{}", node.key, name),
                    Channels::Rgb,
                    v,
                    Domain::NonNegative,
                    ctx,
                )
                .map(Texture::Uniform)
            }
        };
        let eta = tex("eta", eta_default, ctx)?;
        let k = tex("k", k_default, ctx)?;
        Ok(ConductorIor { eta, k })
    }

    /// The index at `si`.
    pub fn eval<R: ScalarReal>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
    ) -> ConductorIorValue<R> {
        ConductorIorValue {
            eta: self.eta.eval(store, si),
            k: self.k.eval(store, si),
        }
    }
}

/// A [`ConductorIor`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct ConductorIorValue<R: ScalarReal> {
    eta: Spectrum<R>,
    k: Spectrum<R>,
}

impl<R: ScalarReal> ConductorIorValue<R> {
    /// Fresnel reflectance for incident cosine `cos_i`.
    pub fn fresnel(&self, cos_i: R) -> Spectrum<R> {
        fresnel_conductor(cos_i, self.eta, self.k)
    }
}

/// Smooth conductor: delta reflection weighted by the conductor Fresnel
/// term times `specular_reflectance` (default 1). Parameters: `material`,
/// `eta`, `k`, `specular_reflectance`.
#[derive(Clone, Debug)]
pub struct Conductor {
    pub ior: ConductorIor,
    pub specular_reflectance: Texture,
}

impl Conductor {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Conductor> {
        let ior = ConductorIor::from_node(node, ctx)?;
        let specular_reflectance = Texture::from_prop(
            node,
            "specular_reflectance",
            Some(1.0),
            Channels::Rgb,
            Domain::UnitInterval,
            ctx,
        )?;
        Ok(Conductor {
            ior,
            specular_reflectance,
        })
    }
}

impl BsdfT for Conductor {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::DELTA_REFLECTION
    }
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::Conductor(ConductorContext {
            wi: si.wi,
            ior: self.ior.eval(store, si),
            specular_reflectance: self.specular_reflectance.eval(store, si),
        }));
        1
    }
}

/// [`Conductor`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct ConductorContext<R: ScalarReal> {
    wi: V3<R>,
    ior: ConductorIorValue<R>,
    specular_reflectance: Spectrum<R>,
}

impl<R: ScalarReal> BsdfContextT<R> for ConductorContext<R> {
    fn eval(&self, _: V3<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn pdf(&self, _: Vec3) -> f32 {
        0.0
    }
    fn sample(&self, _u1: f32, _u2: Vec2) -> Option<BsdfSample<R>> {
        if !(self.wi.z.val() > 0.0) {
            return None;
        }
        let f = self.ior.fresnel(self.wi.z);
        let weight = f.mul_elem(self.specular_reflectance);
        Some(BsdfSample::specular_reflection(self.wi, 1.0, weight))
    }
    fn albedo(&self) -> Spectrum<R> {
        default_albedo(self)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::BsdfContextT;
    use crate::bsdf::fresnel::fresnel_conductor_1;

    #[test]
    fn mirror_by_default_and_named_materials() {
        let (b, store) = build("conductor", &[]);
        check_direction_derivatives(&b, &store, 3);
        for k in ["b.eta.value", "b.k.value", "b.specular_reflectance.value"] {
            assert!(store.id(k).is_some(), "{k}");
        }
        let wi = dir(0.3, 1.0);
        let bs = b
            .context(&store.primal(), &si::<f32>(wi))
            .sample(0.5, glam::Vec2::splat(0.5))
            .unwrap();
        assert!((bs.wo.val() - glam::Vec3::new(-wi.x, -wi.y, wi.z)).length() < 1e-6);
        assert!((bs.weight.val() - glam::Vec3::ONE).abs().max_element() < 1e-6);
        assert!(eval_f32(&b, &store, wi, bs.wo.val()) == glam::Vec3::ZERO);
        assert!(b
            .context(&store.primal(), &si::<f32>(-wi))
            .sample(0.5, glam::Vec2::splat(0.5))
            .is_none());

        let (b, store) = build(
            "conductor",
            &[
                ("material", string("Au")),
                ("specular_reflectance", float(0.5)),
            ],
        );
        check_direction_derivatives(&b, &store, 3);
        let bs = b
            .context(&store.primal(), &si::<f32>(wi))
            .sample(0.1, glam::Vec2::ZERO)
            .unwrap();
        let want = 0.5 * fresnel_conductor_1(wi.z, 0.143036, 3.983);
        assert!((bs.weight.x - want).abs() < 1e-5, "{bs:?} {want}");
        assert!(
            bs.weight.x > bs.weight.z,
            "gold reflects red more than blue"
        );

        let n = node_with_key("conductor", "b", &[("material", string("Gold"))]);
        let e = crate::bsdf::Bsdf::from_node(&n, &mut Default::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown conductor material 'Gold'") && e.contains("Au"),
            "{e}"
        );
    }
}
