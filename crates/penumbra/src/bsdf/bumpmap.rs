//! `bumpmap`: a nested BSDF seen through a shading frame tilted by the
//! gradient of a height texture (Mitsuba 3's `src/bsdfs/bumpmap.cpp`).

use super::normalmap::{write_perturbed, Perturbation};
use super::{nested_bsdfs, rekey, scalar_param, Bsdf, BsdfFlags, BsdfT, NodeContext};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{Class, LoadContext, Node};
use crate::texture::{Bitmap, Texture};

/// Bump mapping: the surface is displaced along the shading normal by
/// `scale` times the height texture (the one nested `<texture>`, of any
/// name: a bitmap, usually with `raw` set; its value is the luminance of
/// RGB data), and shaded with the normal of the displaced surface, where
/// the displacement's own effect on the normal is neglected (Mitsuba's
/// approach: only the height's uv gradient tilts the frame, so constant
/// offsets do nothing). Parameter keys as Mitsuba's:
/// `<key>.nested_texture.data` (texels), `<key>.scale` and
/// `<key>.nested_bsdf.*`, all differentiable here (Mitsuba flags `scale`
/// non-differentiable). `flip_invalid_normals` and
/// `use_shadowing_function` as `normalmap`'s.
#[derive(Clone, Debug)]
pub struct BumpMap {
    pub nested: Box<Bsdf>,
    pub height: Bitmap,
    pub scale: ParamId,
    pub options: Perturbation,
}

impl BumpMap {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<BumpMap> {
        let nested = nested_bsdfs(node, &["nested_bsdf"])?;
        let nested = Box::new(Bsdf::from_node(&nested[0], ctx)?);
        let textures = node.children(Class::Texture);
        let [texture] = textures.as_slice() else {
            return Err(node.error(format!(
                "expects one nested height texture, found {}",
                textures.len()
            )));
        };
        let rekeyed;
        let texture: &Node = if texture.id.is_some() {
            texture
        } else {
            rekeyed = rekey(texture, &format!("{}.nested_texture", node.key));
            &rekeyed
        };
        let height = match Texture::from_node(texture, Domain::Finite, ctx)? {
            Texture::Bitmap(b) => b,
            _ => {
                return Err(texture.error(format!(
                    "a '{}' texture cannot be a bump map: its uv gradient is only known for \
                     bitmaps",
                    texture.plugin
                )))
            }
        };
        let scale = node.float("scale", 1.0)?;
        if !scale.is_finite() {
            let p = node.prop("scale").expect("a non-default scale was given");
            return Err(node.prop_error(p, format!("must be finite, found {scale}")));
        }
        let scale = scalar_param(
            node,
            "scale",
            scale,
            ParamFlags::DIFFERENTIABLE,
            Domain::Finite,
            ctx,
        )?;
        let options = Perturbation::from_node(node)?;
        Ok(BumpMap {
            nested,
            height,
            scale,
            options,
        })
    }

    pub fn parameters_changed(&mut self, store: &ParamStore) {
        self.nested.parameters_changed(store);
    }
}

impl BsdfT for BumpMap {
    fn flags(&self) -> BsdfFlags {
        self.nested.flags()
    }

    fn context_len(&self) -> usize {
        1 + self.nested.context_len()
    }

    /// The normal of the displaced surface p + h n: its tangents are
    /// ∂p/∂u + (∂h/∂u) n and ∂p/∂v + (∂h/∂v) n with their components along
    /// the shading normal n replaced by the height gradient (as Mitsuba
    /// does), oriented to the geometric normal's side.
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let grad = self.height.eval_1_grad(store, si) * store.read::<R>(self.scale, 0);
        let ns = si.sh_frame.n;
        let dp_du = si.dp_du + ns * (grad.x - ns.dot(si.dp_du));
        let dp_dv = si.dp_dv + ns * (grad.y - ns.dot(si.dp_dv));
        let mut n = dp_du.cross(dp_dv);
        if si.n.dot(n).val() < 0.0 {
            n = -n;
        }
        write_perturbed(&self.nested, store, si, si.to_local(n), self.options, nodes)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfContextT};
    use crate::ad::Dual;
    use crate::image::{write_image, Image};
    use crate::math::V3;
    use crate::params::{ParamStore, Seeds};
    use crate::scene::description::{Class, LoadContext, Node, Prop, Value};
    use glam::Vec3;
    use std::rc::Rc;

    /// A bump map over a 4×4 monochrome EXR image of `texel(x, y)` with
    /// `scale`, around a roughplastic, with key "bm".
    fn bumpmap(texel: impl Fn(usize, usize) -> f32, scale: f64, name: &str) -> (Bsdf, ParamStore) {
        let mut img = Image::new(4, 4, 1);
        for y in 0..4 {
            for x in 0..4 {
                img.set(x, y, 0, texel(x, y));
            }
        }
        let dir = std::env::temp_dir().join(format!("penumbra-bumpmap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("{name}.exr"));
        write_image(&path, &img).unwrap();
        // unnamed, as a user's nested texture: keyed by its property name
        let mut texture = Node::new(Class::Texture, "bitmap", None, "bm.heights".into(), loc());
        texture.props.push(Prop::new(
            "filename",
            Value::Str(path.to_string_lossy().into()),
            loc(),
        ));
        let n = node_with_key(
            "bumpmap",
            "bm",
            &[
                ("scale", float(scale)),
                ("heights", Value::Node(Rc::new(texture))),
                ("bsdf", nested("bm", "bsdf", "roughplastic", &[])),
            ],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap_or_else(|e| panic!("{e}"));
        (b, ctx.store)
    }

    /// A constant height does not tilt the frame: the nested BSDF itself.
    #[test]
    fn a_constant_height_is_the_nested_bsdf() {
        let (b, store) = bumpmap(|_, _| 0.3, 5.0, "constant");
        assert!(
            store.id("bm.nested_texture.data").is_some()
                && store.id("bm.scale").is_some()
                && store.id("bm.nested_bsdf.alpha").is_some()
        );
        let (plain, plain_store) = build("roughplastic", &[]);
        for wi in [dir(0.8, 0.3), dir(0.2, 2.0)] {
            for wo in [dir(0.5, 1.0), dir(0.9, -2.0), dir(-0.3, 0.5)] {
                let f = eval_f32(&b, &store, wi, wo);
                let g = eval_f32(&plain, &plain_store, wi, wo);
                assert!((f - g).abs().max_element() < 1e-6, "{f} vs {g}");
            }
        }
    }

    /// A height ramp in u tilts the normal against +u by atan(scale · slope)
    /// (the test interaction has ∂p/∂u = x, ∂p/∂v = y at uv = (½, ½)), and
    /// the value is shadowed by Mitsuba's bump-terminator term;
    /// sampling agrees with eval and pdf; derivatives with respect to the
    /// scale match a finite difference.
    #[test]
    fn a_ramp_tilts_the_normal() {
        // heights x/4 in texel units: ∂h/∂u = 4 · ¼ = 1 between columns
        let ramp = |x: usize, _| x as f32 / 4.0;
        let (b, store) = bumpmap(ramp, 0.5, "ramp");
        let super::super::Bsdf::BumpMap(bm) = &b else {
            unreachable!()
        };
        let g = bm
            .height
            .eval_1_grad(&store.primal(), &si::<f32>(dir(0.8, 0.3)))
            .val();
        assert!((g - glam::Vec2::new(1.0, 0.0)).length() < 1e-5, "{g}");
        // the nested BSDF sees the incident direction in the tilted frame:
        // the tilted normal is (−0.5, 0, 1)/|·|, and roughplastic's value
        // along it is that of the nested BSDF at wi rotated
        let n = Vec3::new(-0.5, 0.0, 1.0).normalize();
        let wi = dir(0.8, 0.3);
        let (plain, plain_store) = build("roughplastic", &[]);
        let s = Vec3::new(n.z, 0.0, -n.x);
        let local = |v: Vec3| Vec3::new(v.dot(s), v.y, v.dot(n));
        // times the bump-terminator shadowing: α² = ⅛ tan² θn = 1/32
        let shadowing =
            |wo: Vec3| 2.0 / (1.0 + (1.0 + (1.0 - wo.z * wo.z) / (wo.z * wo.z) / 32.0).sqrt());
        for wo in [dir(0.5, 1.0), dir(0.9, -2.0)] {
            let f = eval_f32(&b, &store, wi, wo);
            let g = eval_f32(&plain, &plain_store, local(wi), local(wo)) * shadowing(wo);
            assert!((f - g).abs().max_element() < 1e-5, "{f} vs {g}");
        }
        check_smooth(&b, &store, &[wi, dir(0.3, 2.0)], 1);

        let wo = dir(0.6, 2.5);
        let seeds = Seeds::tangents(&store, &[("bm.scale", &[1.0])]).unwrap();
        let d = b
            .context(&store.view(&seeds), &si::<Dual>(wi))
            .eval(V3::cst(wo));
        let d = Vec3::new(d.x.d, d.y.d, d.z.d);
        let h = 1e-3;
        let at = |scale: f64| {
            let (b, s) = bumpmap(ramp, scale, "ramp");
            eval_f32(&b, &s, wi, wo)
        };
        let fd = (at(0.5 + h) - at(0.5 - h)) / (2.0 * h as f32);
        assert_derivative(d, fd, at(0.5), &|| "d eval / d scale".into());
    }
}
