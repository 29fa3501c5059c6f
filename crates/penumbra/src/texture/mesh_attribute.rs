//! Mitsuba's `mesh_attribute` texture: a per-vertex or per-face attribute
//! of the mesh that was hit (read from its PLY file, e.g. `vertex_color`),
//! times `scale`.

use super::TextureT;
use crate::ad::ScalarReal;
use crate::error::{Error, Result, SrcLoc};
use crate::geometry::mesh::AttributeParam;
use crate::geometry::{Shape, SurfaceInteraction};
use crate::math::{Spectrum, V3};
use crate::params::{ParamStore, ParamView};
use crate::scene::description::Node;

/// Parameters: `name` (`vertex_...` or `face_...`), `scale` (1). Vertex
/// attributes are interpolated with the hit's barycentrics, face
/// attributes are constant over a triangle. The values are the mesh's
/// parameter `<shape key>.<name>`, so derivatives flow to them.
#[derive(Clone, Debug)]
pub struct MeshAttribute {
    pub name: String,
    pub scale: f32,
    /// Where the texture was declared, for the errors of
    /// [`MeshAttribute::check_shape`] (made once the shapes using it are
    /// known).
    loc: SrcLoc,
    node: String,
}

impl MeshAttribute {
    pub fn from_node(node: &Node) -> Result<MeshAttribute> {
        let p = node
            .prop("name")
            .ok_or_else(|| node.error("missing required parameter 'name'"))?;
        let name = node.string("name", "")?;
        if !(name.starts_with("vertex_") || name.starts_with("face_")) {
            return Err(node.prop_error(
                p,
                format!("'{name}' must start with 'vertex_' or 'face_' (as in 'vertex_color')"),
            ));
        }
        Ok(MeshAttribute {
            name,
            scale: node.float("scale", 1.0)?,
            loc: node.loc.clone(),
            node: node.to_string(),
        })
    }

    fn error(&self, msg: impl std::fmt::Display) -> Error {
        Error::scene(&self.loc, format!("{}: {msg}", self.node))
    }

    /// Checks that `shape` (keyed `key`), on which the texture is used,
    /// is a mesh with the attribute, of 1 or 3 channels.
    pub fn check_shape(&self, shape: &Shape, key: &str) -> Result<()> {
        let Some(mesh) = shape.as_mesh() else {
            return Err(self.error(format!(
                "used on shape '{key}', which is not a mesh (attributes come from PLY files)"
            )));
        };
        let Some(a) = mesh.attributes.iter().find(|a| a.name == self.name) else {
            let names: Vec<&str> = mesh.attributes.iter().map(|a| a.name.as_str()).collect();
            return Err(self.error(format!(
                "shape '{key}' has no attribute '{}' (it has: {})",
                self.name,
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(", ")
                }
            )));
        };
        if a.channels != 1 && a.channels != 3 {
            return Err(self.error(format!(
                "attribute '{}' of shape '{key}' has {} channels; a texture needs 1 or 3",
                self.name, a.channels
            )));
        }
        Ok(())
    }

    /// An error for a use outside any shape (an emitter without a shape).
    pub fn outside_mesh_error(&self) -> Error {
        self.error("used outside a shape; mesh attributes exist on meshes only")
    }

    /// Channel `c` of attribute `a` at the hit.
    #[inline]
    fn channel<R: ScalarReal>(
        store: &ParamView,
        a: &AttributeParam,
        si: &SurfaceInteraction<R>,
        c: usize,
    ) -> R {
        let n = a.channels;
        if a.per_face {
            return store.read(a.id, si.prim as usize * n + c);
        }
        let [i0, i1, i2] = si.vertices.map(|i| i as usize * n + c);
        let (b1, b2) = (si.bary.x, si.bary.y);
        let b0 = R::cst(1.0) - b1 - b2;
        store.read::<R>(a.id, i0) * b0
            + store.read::<R>(a.id, i1) * b1
            + store.read::<R>(a.id, i2) * b2
    }

    /// The attribute on every mesh, for the primal statistics.
    fn all_values<'s>(&self, store: &'s ParamStore) -> impl Iterator<Item = f32> + 's {
        let name = self.name.clone();
        store
            .shape_attributes()
            .filter(move |a| a.name == name)
            .flat_map(|a| store.data(a.id).iter().copied())
    }
}

impl TextureT for MeshAttribute {
    /// A 1-channel attribute is grey, as in Mitsuba. A shape without the
    /// attribute (refused at load) would give black.
    #[inline]
    fn eval<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        let Some(a) = store.shape_attribute(si.shape, &self.name) else {
            return V3::zero();
        };
        let v = if a.channels == 1 {
            V3::splat(Self::channel(store, a, si, 0))
        } else {
            V3::new(
                Self::channel(store, a, si, 0),
                Self::channel(store, a, si, 1),
                Self::channel(store, a, si, 2),
            )
        };
        v * R::cst(self.scale)
    }
    /// The mean of an RGB attribute (Mitsuba refuses `eval_1` on one), as
    /// the other textures do.
    #[inline]
    fn eval_1<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
        let Some(a) = store.shape_attribute(si.shape, &self.name) else {
            return R::cst(0.0);
        };
        if a.channels == 1 {
            Self::channel(store, a, si, 0) * R::cst(self.scale)
        } else {
            self.eval(store, si).mean()
        }
    }
    fn mean(&self, store: &ParamStore) -> f32 {
        let (sum, n) = self
            .all_values(store)
            .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
        self.scale * sum / n.max(1) as f32
    }
    fn max(&self, store: &ParamStore) -> f32 {
        self.all_values(store)
            .map(|v| v * self.scale)
            .fold(f32::MIN, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::{MeshAttribute as Data, MeshData, MeshOptions};
    use crate::geometry::{Hit, Mesh, ShapeT};
    use crate::math::Transform;
    use glam::{Vec2, Vec3};

    /// A quad of two triangles with an RGB vertex attribute and a 1-channel
    /// face attribute, registered as shape 0.
    fn quad() -> (Mesh, ParamStore) {
        let data = MeshData {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            faces: vec![[0, 1, 2], [0, 2, 3]],
            attributes: vec![
                Data {
                    name: "vertex_color".into(),
                    channels: 3,
                    per_face: false,
                    data: vec![1., 0., 0., 0., 1., 0., 0., 0., 1., 0.5, 0.5, 0.5],
                },
                Data {
                    name: "face_weight".into(),
                    channels: 1,
                    per_face: true,
                    data: vec![0.25, 0.75],
                },
            ],
            ..Default::default()
        };
        let mut store = ParamStore::new();
        let m = Mesh::new(
            "ply",
            "m",
            "quad.ply",
            data,
            &Transform::default(),
            MeshOptions::default(),
            &mut store,
        )
        .unwrap();
        store.set_shape_attributes(0, m.attributes.to_vec());
        (m, store)
    }

    fn tex(name: &str, scale: f32) -> MeshAttribute {
        MeshAttribute {
            name: name.into(),
            scale,
            loc: SrcLoc {
                file: "/tmp/test.xml".into(),
                line: 1,
            },
            node: "texture 'mesh_attribute'".into(),
        }
    }

    fn hit(prim: u32, b1: f32, b2: f32) -> Hit {
        Hit {
            t: 1.0,
            shape: 0,
            prim,
            uv: Vec2::new(b1, b2),
            instance: None,
        }
    }

    #[test]
    fn vertex_attributes_interpolate_face_attributes_are_constant() {
        let (m, store) = quad();
        let view = store.primal();
        let si = m.point_at::<f32>(&view, &hit(0, 0.2, 0.3), Vec3::ZERO);
        // b0 = 0.5 on vertex 0 (red), 0.2 on 1 (green), 0.3 on 2 (blue)
        let c = tex("vertex_color", 2.0).eval(&view, &si).val();
        assert!(
            (c - Vec3::new(1.0, 0.4, 0.6)).abs().max_element() < 1e-6,
            "{c}"
        );
        // the mean of the channels (0.5, 0.2, 0.3)
        assert!((tex("vertex_color", 1.0).eval_1(&view, &si) - 1.0 / 3.0).abs() < 1e-6);
        let si1 = m.point_at::<f32>(&view, &hit(1, 0.9, 0.05), Vec3::ZERO);
        assert_eq!(
            tex("face_weight", 1.0).eval(&view, &si1).val(),
            Vec3::splat(0.75)
        );
        assert_eq!(tex("face_weight", 2.0).eval_1(&view, &si), 0.5);
        assert!((tex("face_weight", 1.0).mean(&store) - 0.5).abs() < 1e-6);
        assert_eq!(tex("vertex_color", 3.0).max(&store), 3.0);
    }

    #[test]
    fn derivatives_flow_to_the_attribute_values() {
        use crate::ad::Dual;
        use crate::params::Seeds;
        let (m, store) = quad();
        let tangent: Vec<f32> = (0..12).map(|i| i as f32).collect();
        let seeds = Seeds::tangents(&store, &[("m.vertex_color", &tangent)]).unwrap();
        let view = store.view(&seeds);
        let si = m.point_at::<Dual>(&view, &hit(0, 0.2, 0.3), Vec3::ZERO);
        let c = tex("vertex_color", 1.0).eval(&view, &si);
        // d(red) = 0.5·0 + 0.2·3 + 0.3·6
        assert!((c.x.d - 2.4).abs() < 1e-5, "{:?}", c.x);
    }

    #[test]
    fn missing_attributes_and_other_shapes_are_refused_with_the_place() {
        let (m, _) = quad();
        let shape = Shape::Mesh(m);
        assert!(tex("vertex_color", 1.0).check_shape(&shape, "m").is_ok());
        let e = tex("vertex_foo", 1.0)
            .check_shape(&shape, "m")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("/tmp/test.xml:1: ") && e.contains("vertex_color, face_weight"),
            "{e}"
        );
        let n = super::super::test_node(
            crate::scene::description::Class::Texture,
            "mesh_attribute",
            "t",
            vec![(
                "name",
                crate::scene::description::Value::Str("color".into()),
            )],
        );
        let e = MeshAttribute::from_node(&n).unwrap_err().to_string();
        assert!(
            e.contains("parameter 'name'") && e.contains("vertex_"),
            "{e}"
        );
    }
}
