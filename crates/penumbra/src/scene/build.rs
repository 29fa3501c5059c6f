//! Assembles a [`Scene`] from the parsed description: builds every plugin
//! once (objects referenced from several places are shared), wires shapes
//! to their BSDFs and area emitters, and builds the acceleration structure.

use super::{Class, LoadContext, Node, Prop, Scene, SceneDescription, ShapeInfo, Value};
use crate::bsdf::{Bsdf, BsdfT};
use crate::emitter::{Emitter, EmitterT};
use crate::error::Result;
use crate::geometry::accel::Accel;
use crate::geometry::{Instance, Shape, ShapeGroup};
use crate::integrator::{Integrator, PathIntegrator};
use crate::math::DiscreteDistribution;
use crate::medium::Medium;
use crate::sensor::Sensor;
use crate::texture::{AttributeUses, MeshAttribute};
use std::collections::{HashMap, HashSet};
use std::rc::Rc;

/// Builds plugins, remembering which node became which object.
struct Builder {
    ctx: LoadContext,
    bsdfs: Vec<Bsdf>,
    /// The `mesh_attribute` textures of each BSDF, checked against every
    /// shape using it.
    bsdf_attribute_uses: Vec<Vec<MeshAttribute>>,
    bsdf_of_node: HashMap<*const Node, u32>,
    shapes: Vec<Shape>,
    shape_info: Vec<ShapeInfo>,
    groups: Vec<ShapeGroup>,
    group_of_node: HashMap<*const Node, u32>,
    instances: Vec<Instance>,
    emitters: Vec<Emitter>,
    /// Mitsuba's `sampling_weight` of each emitter.
    emitter_weights: Vec<f32>,
    environment: Option<u32>,
    sensors: Vec<Sensor>,
    media: Vec<Medium>,
    medium_of_node: HashMap<*const Node, u32>,
    /// Area emitters that shapes built (the nodes), so that one declared at
    /// the top level and referenced from a shape is built there only.
    area_emitter_nodes: HashSet<*const Node>,
    integrator: Option<Integrator>,
}

impl Builder {
    fn bsdf(&mut self, node: &Rc<Node>) -> Result<u32> {
        if let Some(&i) = self.bsdf_of_node.get(&Rc::as_ptr(node)) {
            return Ok(i);
        }
        let i = self.new_bsdf(node)?;
        self.bsdf_of_node.insert(Rc::as_ptr(node), i);
        Ok(i)
    }

    /// Builds a BSDF that is not shared: no node pointer is remembered.
    fn new_bsdf(&mut self, node: &Node) -> Result<u32> {
        let b = Bsdf::from_node(node, &mut self.ctx)?;
        node.check_all_used()?;
        self.bsdfs.push(b);
        self.bsdf_attribute_uses
            .push(std::mem::take(&mut self.ctx.state::<AttributeUses>().0));
        Ok(self.bsdfs.len() as u32 - 1)
    }

    /// The BSDF of a shape that names none: Mitsuba's default, a diffuse
    /// with reflectance 0.5, or 0 when the shape is an area light (so that
    /// lights do not reflect, as in Mitsuba 3).
    fn default_bsdf(&mut self, shape: &Node) -> Result<u32> {
        let mut node = Node::new(
            Class::Bsdf,
            "diffuse",
            None,
            format!("{}.bsdf", shape.key),
            shape.loc.clone(),
        );
        if shape.child("emitter")?.is_some() {
            node.props.push(Prop::new(
                "reflectance",
                Value::Float(0.0),
                shape.loc.clone(),
            ));
        }
        // Not through `bsdf`: the node is dropped on return, so its address
        // can be reused by the next default node and hit a stale entry of
        // `bsdf_of_node` (the next shape would get this shape's BSDF).
        self.new_bsdf(&node)
    }

    /// The medium built from `node` (once per node: a medium referenced by
    /// several shapes is one medium).
    fn medium(&mut self, node: &Rc<Node>) -> Result<u32> {
        if let Some(&i) = self.medium_of_node.get(&Rc::as_ptr(node)) {
            return Ok(i);
        }
        let m = Medium::from_node(node, &mut self.ctx)?;
        self.media.push(m);
        let i = self.media.len() as u32 - 1;
        self.medium_of_node.insert(Rc::as_ptr(node), i);
        Ok(i)
    }

    /// The medium a shape names as `interior` or `exterior`, if any.
    fn shape_medium(&mut self, shape: &Node, side: &str) -> Result<Option<u32>> {
        let Some(n) = shape.child(side)? else {
            return Ok(None);
        };
        if n.class != Class::Medium {
            let p = shape.prop(side).expect("a child came from a property");
            return Err(shape.prop_error(
                p,
                format!("must be a <medium>, found a <{}>", n.class.tag()),
            ));
        }
        self.medium(&n).map(Some)
    }

    /// A sensor and the medium it sits in (a nested `<medium>` or a
    /// reference to one, under any name, as in Mitsuba).
    fn sensor(&mut self, node: &Node) -> Result<()> {
        let medium = match node.child_props(Class::Medium).as_slice() {
            [] => None,
            [(_, m)] => Some(self.medium(m)?),
            [_, (p, _), ..] => {
                return Err(node.prop_error(p, "a sensor sits in one medium; remove the others"))
            }
        };
        let mut sensor = Sensor::from_node(node, &mut self.ctx.store)?;
        sensor.medium = medium;
        self.sensors.push(sensor);
        Ok(())
    }

    fn emitter(&mut self, node: &Node, shape: Option<u32>) -> Result<u32> {
        let (e, weight) = Emitter::from_node_weighted(node, shape, &mut self.ctx)?;
        node.check_all_used()?;
        self.emitter_weights.push(weight);
        let i = self.emitters.len() as u32;
        if e.is_environment() {
            if self.environment.is_some() {
                return Err(node
                    .error("a scene can have only one environment emitter (constant or envmap)"));
            }
            self.environment = Some(i);
        }
        self.emitters.push(e);
        Ok(i)
    }

    /// A shape declared at the top level of the scene: a shape group, an
    /// instance, or a shape rendered where it is.
    fn shape(&mut self, node: &Rc<Node>) -> Result<()> {
        match node.plugin.as_str() {
            "shapegroup" => self.group(node).map(|_| ()),
            "instance" => self.instance(node),
            _ => self.plain_shape(node, None).map(|_| ()),
        }
    }

    /// The shape group built from `node` (once per node: every instance
    /// referencing it shares it). Refuses what Mitsuba 3 refuses in a
    /// group: other groups, instances, emitters, objects other than shapes.
    fn group(&mut self, node: &Rc<Node>) -> Result<u32> {
        if let Some(&g) = self.group_of_node.get(&Rc::as_ptr(node)) {
            return Ok(g);
        }
        let g = self.groups.len() as u32;
        let mut members = Vec::new();
        for p in &node.props {
            let Value::Node(child) = &p.value else {
                continue;
            };
            if child.class != Class::Shape {
                return Err(node.prop_error(
                    p,
                    format!(
                        "a shape group holds only shapes, found a <{}>; put it inside one of \
                         the group's shapes (or give each shape a <ref> to it)",
                        child.class.tag()
                    ),
                ));
            }
            match child.plugin.as_str() {
                "shapegroup" => {
                    return Err(node.prop_error(
                        p,
                        "shape groups cannot be nested (nor can they in Mitsuba 3); declare \
                         the inner group at the top level and instance its shapes' group there",
                    ))
                }
                "instance" => {
                    return Err(node.prop_error(
                        p,
                        "instances cannot be nested in a shape group (nor can they in Mitsuba \
                         3); place the instance at the top level of the scene",
                    ))
                }
                _ => {}
            }
            if let Some(e) = child
                .props
                .iter()
                .find(|q| matches!(&q.value, Value::Node(n) if n.class == Class::Emitter))
            {
                return Err(child.prop_error(
                    e,
                    "emitters cannot be instanced (nor can they in Mitsuba 3): an area light \
                     cannot be a shape of a shape group; declare the emitting shape outside \
                     the group",
                ));
            }
            members.push(self.plain_shape(child, Some(g))?);
            // the property named the member; it is used
            node.prop(&p.name);
        }
        if node.prop("to_world").is_some() {
            crate::warn(format!(
                "{}: {node}: 'to_world' of a shape group is ignored (as by Mitsuba 3); place \
                 the group with each instance's to_world",
                node.loc
            ));
        }
        node.check_all_used()?;
        self.groups.push(ShapeGroup {
            key: node.key.clone(),
            members,
        });
        self.group_of_node.insert(Rc::as_ptr(node), g);
        Ok(g)
    }

    /// An instance: the shape group it references, placed by its
    /// `to_world`. It has no BSDF, emitter or media of its own, as in
    /// Mitsuba 3.
    fn instance(&mut self, node: &Rc<Node>) -> Result<()> {
        let mut group = None;
        for p in &node.props {
            let Value::Node(child) = &p.value else {
                continue;
            };
            let refusal = match child.class {
                Class::Shape if child.plugin == "shapegroup" => {
                    if group.is_some() {
                        return Err(node.prop_error(
                            p,
                            "an instance places one shape group (as in Mitsuba 3); remove the \
                             other references or add an instance for each group",
                        ));
                    }
                    group = Some(child.clone());
                    node.prop(&p.name);
                    continue;
                }
                Class::Shape => format!(
                    "an instance references a shape group, found {child}; put the shape in a \
                     <shape type=\"shapegroup\" id=\"…\"> and reference that"
                ),
                Class::Bsdf => "an instance has no BSDF of its own (as in Mitsuba 3): its \
                                materials are those of its group's shapes; give them the <bsdf>"
                    .into(),
                Class::Emitter => "emitters cannot be instanced (nor can they in Mitsuba 3); \
                                   declare the emitting shape outside any group"
                    .into(),
                Class::Medium => "an instance has no media of its own (Mitsuba 3 refuses \
                                  them): give its group's shapes their interior and exterior"
                    .into(),
                _ => format!(
                    "an instance holds only a reference to a shape group, found a <{}>",
                    child.class.tag()
                ),
            };
            return Err(node.prop_error(p, refusal));
        }
        let Some(group_node) = group else {
            return Err(node.error(
                "an instance needs a shape group: add <ref id=\"…\"/> naming a <shape \
                 type=\"shapegroup\" id=\"…\"> (as in Mitsuba 3)",
            ));
        };
        let group = self.group(&group_node)?;
        let to_world = node.transform("to_world")?;
        let inst = Instance::new(&node.key, group, &to_world, &mut self.ctx.store)
            .map_err(|e| node.error(e))?;
        node.check_all_used()?;
        self.instances.push(inst);
        Ok(())
    }

    /// A shape (not a group nor an instance), in shape group `group` if
    /// any; returns its index.
    fn plain_shape(&mut self, node: &Rc<Node>, group: Option<u32>) -> Result<u32> {
        let shape = Shape::from_node(node, &mut self.ctx)?;
        let index = self.shapes.len() as u32;
        let bsdf = match node.child("bsdf")? {
            Some(b) => self.bsdf(&b)?,
            None => self.default_bsdf(node)?,
        };
        let emitter = match node.child("emitter")? {
            Some(e) => {
                self.area_emitter_nodes.insert(Rc::as_ptr(&e));
                Some(self.emitter(&e, Some(index))?)
            }
            None => None,
        };
        let interior = self.shape_medium(node, "interior")?;
        let exterior = self.shape_medium(node, "exterior")?;
        node.check_all_used()?;
        // the area emitter's textures are evaluated on this shape too
        let emitter_uses = std::mem::take(&mut self.ctx.state::<AttributeUses>().0);
        for t in self.bsdf_attribute_uses[bsdf as usize]
            .iter()
            .chain(&emitter_uses)
        {
            t.check_shape(&shape, &node.key)?;
        }
        if let Some(m) = shape.as_mesh() {
            self.ctx
                .store
                .set_shape_attributes(index, m.attributes.to_vec());
        }
        self.shapes.push(shape);
        self.shape_info.push(ShapeInfo {
            key: node.key.clone(),
            bsdf,
            bsdf_flags: self.bsdfs[bsdf as usize].flags(),
            emitter,
            interior,
            exterior,
            group,
        });
        Ok(index)
    }
}

impl Scene {
    /// Builds a scene from a parsed scene description.
    pub fn from_description(desc: &SceneDescription) -> Result<Scene> {
        let root = &*desc.root;
        let mut b = Builder {
            ctx: LoadContext::new(desc.resolver.clone()),
            bsdfs: Vec::new(),
            bsdf_attribute_uses: Vec::new(),
            bsdf_of_node: HashMap::new(),
            shapes: Vec::new(),
            shape_info: Vec::new(),
            groups: Vec::new(),
            group_of_node: HashMap::new(),
            instances: Vec::new(),
            emitters: Vec::new(),
            emitter_weights: Vec::new(),
            environment: None,
            sensors: Vec::new(),
            media: Vec::new(),
            medium_of_node: HashMap::new(),
            area_emitter_nodes: HashSet::new(),
            integrator: None,
        };
        // area emitters declared at the top level: built by the shapes that
        // reference them (as in Mitsuba 3), checked after the loop
        let mut top_level_areas = Vec::new();
        for p in &root.props {
            let Some(node) = root.child(&p.name)? else {
                return Err(
                    root.prop_error(p, "only objects may appear at the top level of a scene")
                );
            };
            match node.class {
                Class::Shape => b.shape(&node)?,
                Class::Bsdf => {
                    b.bsdf(&node)?;
                }
                Class::Emitter if node.plugin == "area" => top_level_areas.push(node),
                Class::Emitter => {
                    b.emitter(&node, None)?;
                    if let Some(t) = b.ctx.state::<AttributeUses>().0.first() {
                        return Err(t.outside_mesh_error());
                    }
                }
                Class::Sensor => b.sensor(&node)?,
                Class::Medium => {
                    b.medium(&node)?;
                }
                Class::Integrator => {
                    if b.integrator.is_some() {
                        return Err(node.error("a scene can have only one <integrator>"));
                    }
                    b.integrator = Some(Integrator::from_node(&node)?);
                }
                // textures are built where they are used (and shared there)
                Class::Texture => {}
                Class::Phase | Class::Volume => {
                    return Err(node.error(format!(
                        "a <{}> belongs inside a <medium>, not at the top level",
                        node.class.tag()
                    )))
                }
                Class::Spectrum => unreachable!("spectra are property values"),
                Class::Film | Class::Rfilter | Class::Sampler | Class::Scene => {
                    return Err(node.error(format!(
                        "a <{}> belongs inside a <sensor> (or <film>), not at the top level",
                        node.class.tag()
                    )))
                }
            }
        }
        for node in top_level_areas {
            if !b.area_emitter_nodes.contains(&Rc::as_ptr(&node)) {
                // Mitsuba 3 drops such an emitter without a word
                crate::warn(format!(
                    "{}: {node}: an area emitter at the top level that no shape references is \
                     ignored (as by Mitsuba 3); nest it in a <shape> or reference it from one",
                    node.loc
                ));
            }
        }
        root.check_all_used()?;
        if b.sensors.is_empty() {
            return Err(
                root.error("the scene has no <sensor>; add one (e.g. a perspective camera)")
            );
        }
        let store = b.ctx.store;
        let accel = Accel::build_instanced(&b.shapes, &b.groups, &b.instances, &store);
        let (center, radius) = accel.bounding_sphere();
        for e in &mut b.emitters {
            e.set_scene_bounds(center, radius);
        }
        let emitter_distribution = if b.emitters.is_empty() {
            None
        } else {
            Some(
                DiscreteDistribution::new(&b.emitter_weights).ok_or_else(|| {
                    root.error("all emitters have sampling_weight 0: nothing could be sampled")
                })?,
            )
        };
        Ok(Scene {
            emitter_distribution,
            params: store,
            shapes: b.shapes,
            shape_info: b.shape_info,
            groups: b.groups,
            instances: b.instances,
            bsdfs: b.bsdfs,
            emitters: b.emitters,
            environment: b.environment,
            sensors: b.sensors,
            media: b.media,
            // Mitsuba's default: `path`, unbounded, roulette from depth 5
            integrator: b.integrator.unwrap_or(Integrator::Path(PathIntegrator::new(
                u32::MAX,
                5,
                false,
            ))),
            accel,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Scene;
    use std::path::Path;

    #[test]
    fn medium_errors_name_file_line_and_problem() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_scenes");
        for (file, line, needle) in [
            (
                "medium_interior.xml",
                6,
                "medium 'fog' (id 'fog'): unknown medium plugin 'fog'",
            ),
            (
                "medium_sensor.xml",
                9,
                "medium 'homogeneous', parameter 'sigma_t': a homogeneous medium needs a constant",
            ),
            (
                "medium_missing_grid.xml",
                8,
                "volume 'gridvolume', parameter 'filename': file 'missing.vol' not found",
            ),
        ] {
            let p = dir.join(file);
            let e = Scene::load_file(&p, &[]).unwrap_err().to_string();
            let prefix = format!("{}:{line}: ", p.display());
            assert!(e.starts_with(&prefix), "expected '{prefix}' in: {e}");
            assert!(e.contains(needle) && !e.contains('\n'), "{e}");
        }
    }

    #[test]
    fn default_bsdf_is_black_on_area_lights_only() {
        let scene = Scene::load_str(
            r#"<scene version="3.0.0">
                <sensor type="perspective"/>
                <shape type="rectangle" id="light"><emitter type="area"/></shape>
                <shape type="rectangle" id="wall"/>
            </scene>"#,
            Path::new("t.xml"),
            &[],
        )
        .unwrap();
        let value = |key: &str| {
            scene
                .params
                .data(scene.params.require(key).unwrap())
                .to_vec()
        };
        assert!(value("light.bsdf.reflectance.value")
            .iter()
            .all(|&v| v == 0.0));
        assert!(value("wall.bsdf.reflectance.value")
            .iter()
            .all(|&v| v == 0.5));
    }
}
