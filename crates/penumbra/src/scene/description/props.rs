//! The scene description as parsed from a file or a Python dict: a tree of
//! plugin nodes with typed properties. Plugin constructors query their
//! properties by name; every property must be queried, so that an unknown
//! or misspelt parameter is an error, never silently ignored.

use crate::error::{Error, Result, SrcLoc};
use crate::math::Transform;
use glam::Vec3;
use std::cell::Cell;
use std::fmt;
use std::rc::Rc;

/// The family a plugin belongs to (the XML tag).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Class {
    Scene,
    Shape,
    Bsdf,
    Texture,
    Emitter,
    Sensor,
    Film,
    Rfilter,
    Sampler,
    Integrator,
    Medium,
    Phase,
    Volume,
    /// A spectrum plugin (`<spectrum type="…">`): read as a property and
    /// converted to its value while the XML is read, never an object of
    /// the tree, so [`Class::from_tag`] does not name it.
    Spectrum,
}

impl Class {
    pub fn from_tag(tag: &str) -> Option<Class> {
        Some(match tag {
            "scene" => Class::Scene,
            "shape" => Class::Shape,
            "bsdf" => Class::Bsdf,
            "texture" => Class::Texture,
            "emitter" => Class::Emitter,
            "sensor" => Class::Sensor,
            "film" => Class::Film,
            "rfilter" => Class::Rfilter,
            "sampler" => Class::Sampler,
            "integrator" => Class::Integrator,
            "medium" => Class::Medium,
            "phase" => Class::Phase,
            "volume" => Class::Volume,
            _ => return None,
        })
    }
    pub fn tag(self) -> &'static str {
        match self {
            Class::Scene => "scene",
            Class::Shape => "shape",
            Class::Bsdf => "bsdf",
            Class::Texture => "texture",
            Class::Emitter => "emitter",
            Class::Sensor => "sensor",
            Class::Film => "film",
            Class::Rfilter => "rfilter",
            Class::Sampler => "sampler",
            Class::Integrator => "integrator",
            Class::Medium => "medium",
            Class::Phase => "phase",
            Class::Volume => "volume",
            Class::Spectrum => "spectrum",
        }
    }
}

/// A property value.
#[derive(Clone, Debug)]
pub enum Value {
    Float(f64),
    Int(i64),
    Bool(bool),
    Str(String),
    /// `<rgb>` (linear RGB).
    Rgb(Vec3),
    /// `<spectrum value="v"/>`: a constant spectrum.
    Spectrum(f32),
    /// `<point>`.
    Point(Vec3),
    /// `<vector>`.
    Vector(Vec3),
    Transform(Transform),
    /// A nested or referenced plugin.
    Node(Rc<Node>),
}

impl Value {
    pub(crate) fn kind(&self) -> &'static str {
        match self {
            Value::Float(_) => "float",
            Value::Int(_) => "integer",
            Value::Bool(_) => "boolean",
            Value::Str(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Spectrum(_) => "spectrum",
            Value::Point(_) => "point",
            Value::Vector(_) => "vector",
            Value::Transform(_) => "transform",
            Value::Node(_) => "object",
        }
    }
}

/// A named property with the place it was written.
#[derive(Debug)]
pub struct Prop {
    pub name: String,
    pub value: Value,
    pub loc: SrcLoc,
    /// A nested object written without a `name` attribute: `name` was
    /// made up by the loader (Mitsuba calls such children `_arg_0`,
    /// `_arg_1`, … where it shows their names, e.g. in moment channels).
    pub unnamed: bool,
    used: Cell<bool>,
}

impl Prop {
    pub fn new(name: impl Into<String>, value: Value, loc: SrcLoc) -> Prop {
        Prop {
            name: name.into(),
            value,
            loc,
            unnamed: false,
            used: Cell::new(false),
        }
    }
}

/// One plugin instance: `<bsdf type="diffuse" id="red"> … </bsdf>`.
#[derive(Debug)]
pub struct Node {
    pub class: Class,
    /// The plugin name (`type` attribute): "diffuse", "ply", …
    pub plugin: String,
    pub id: Option<String>,
    /// Prefix of this object's parameter keys: its id, or its parent's
    /// prefix followed by the property name (`"plane.bsdf"`), as Mitsuba's
    /// `traverse()` names them.
    pub key: String,
    pub loc: SrcLoc,
    pub props: Vec<Prop>,
}

impl fmt::Display for Node {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} '{}'", self.class.tag(), self.plugin)?;
        if let Some(id) = &self.id {
            write!(f, " (id '{id}')")?;
        }
        Ok(())
    }
}

impl Node {
    pub fn new(class: Class, plugin: &str, id: Option<String>, key: String, loc: SrcLoc) -> Node {
        Node {
            class,
            plugin: plugin.to_string(),
            id,
            key,
            loc,
            props: Vec::new(),
        }
    }

    /// An error about this node, at its place in the file.
    pub fn error(&self, msg: impl fmt::Display) -> Error {
        Error::scene(&self.loc, format!("{self}: {msg}"))
    }

    /// An error about property `p` of this node, at the property's place.
    pub fn prop_error(&self, p: &Prop, msg: impl fmt::Display) -> Error {
        Error::scene(&p.loc, format!("{self}, parameter '{}': {msg}", p.name))
    }

    /// The property called `name`, marked as used.
    pub fn prop(&self, name: &str) -> Option<&Prop> {
        let p = self.props.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    pub fn has(&self, name: &str) -> bool {
        self.props.iter().any(|p| p.name == name)
    }

    fn wrong_type(&self, p: &Prop, want: &str) -> Error {
        self.prop_error(p, format!("must be a {want}, found a {}", p.value.kind()))
    }

    pub fn float_opt(&self, name: &str) -> Result<Option<f32>> {
        let Some(p) = self.prop(name) else {
            return Ok(None);
        };
        let v = match &p.value {
            Value::Float(v) => *v as f32,
            Value::Int(v) => *v as f32,
            Value::Spectrum(v) => *v,
            _ => return Err(self.wrong_type(p, "float")),
        };
        if !v.is_finite() {
            return Err(self.prop_error(p, format!("must be finite, found {v}")));
        }
        Ok(Some(v))
    }

    pub fn float(&self, name: &str, default: f32) -> Result<f32> {
        Ok(self.float_opt(name)?.unwrap_or(default))
    }

    /// A required float.
    pub fn float_req(&self, name: &str) -> Result<f32> {
        self.float_opt(name)?
            .ok_or_else(|| self.error(format!("missing required parameter '{name}'")))
    }

    /// A float that must be > 0 (`positive`) or ≥ 0.
    pub fn float_checked(&self, name: &str, default: f32, positive: bool) -> Result<f32> {
        let v = self.float(name, default)?;
        let ok = if positive { v > 0.0 } else { v >= 0.0 };
        if !ok {
            let p = self
                .prop(name)
                .expect("a non-default value came from a property");
            return Err(self.prop_error(
                p,
                format!(
                    "must be {}, found {v}",
                    if positive { "> 0" } else { ">= 0" }
                ),
            ));
        }
        Ok(v)
    }

    pub fn int(&self, name: &str, default: i64) -> Result<i64> {
        let Some(p) = self.prop(name) else {
            return Ok(default);
        };
        match &p.value {
            Value::Int(v) => Ok(*v),
            _ => Err(self.wrong_type(p, "integer")),
        }
    }

    /// An integer that must be ≥ `min`.
    pub fn int_min(&self, name: &str, default: i64, min: i64) -> Result<i64> {
        let v = self.int(name, default)?;
        if v < min {
            let p = self
                .prop(name)
                .expect("a non-default value came from a property");
            return Err(self.prop_error(p, format!("must be >= {min}, found {v}")));
        }
        Ok(v)
    }

    pub fn bool(&self, name: &str, default: bool) -> Result<bool> {
        let Some(p) = self.prop(name) else {
            return Ok(default);
        };
        match &p.value {
            Value::Bool(v) => Ok(*v),
            _ => Err(self.wrong_type(p, "boolean")),
        }
    }

    pub fn string_opt(&self, name: &str) -> Result<Option<String>> {
        let Some(p) = self.prop(name) else {
            return Ok(None);
        };
        match &p.value {
            Value::Str(v) => Ok(Some(v.clone())),
            _ => Err(self.wrong_type(p, "string")),
        }
    }

    pub fn string(&self, name: &str, default: &str) -> Result<String> {
        Ok(self
            .string_opt(name)?
            .unwrap_or_else(|| default.to_string()))
    }

    /// A string that must be one of `choices` (first is the default).
    pub fn choice(&self, name: &str, choices: &[&str]) -> Result<String> {
        let v = self.string(name, choices[0])?;
        if !choices.contains(&v.as_str()) {
            let p = self
                .prop(name)
                .expect("a non-default value came from a property");
            return Err(self.prop_error(p, format!("'{v}' is not one of: {}", choices.join(", "))));
        }
        Ok(v)
    }

    /// A point or vector (`<point>`, `<vector>`, or an `<rgb>` used as one).
    pub fn vec3_opt(&self, name: &str) -> Result<Option<Vec3>> {
        let Some(p) = self.prop(name) else {
            return Ok(None);
        };
        match &p.value {
            Value::Point(v) | Value::Vector(v) | Value::Rgb(v) => Ok(Some(*v)),
            Value::Float(v) => Ok(Some(Vec3::splat(*v as f32))),
            _ => Err(self.wrong_type(p, "point or vector")),
        }
    }

    pub fn vec3(&self, name: &str, default: Vec3) -> Result<Vec3> {
        Ok(self.vec3_opt(name)?.unwrap_or(default))
    }

    pub fn transform(&self, name: &str) -> Result<Transform> {
        let Some(p) = self.prop(name) else {
            return Ok(Transform::IDENTITY);
        };
        match &p.value {
            Value::Transform(t) => Ok(*t),
            _ => Err(self.wrong_type(p, "transform")),
        }
    }

    /// The nested plugin called `name`.
    pub fn child(&self, name: &str) -> Result<Option<Rc<Node>>> {
        let Some(p) = self.prop(name) else {
            return Ok(None);
        };
        match &p.value {
            Value::Node(n) => Ok(Some(n.clone())),
            _ => Err(self.wrong_type(p, "nested object")),
        }
    }

    /// The nested objects of `class` with the properties that hold them
    /// (their names), in file order, marked as used.
    pub fn child_props(&self, class: Class) -> Vec<(&Prop, Rc<Node>)> {
        self.props
            .iter()
            .filter_map(|p| match &p.value {
                Value::Node(n) if n.class == class => {
                    p.used.set(true);
                    Some((p, n.clone()))
                }
                _ => None,
            })
            .collect()
    }

    /// All nested plugins of a class, in file order (marked used).
    pub fn children(&self, class: Class) -> Vec<Rc<Node>> {
        self.child_props(class)
            .into_iter()
            .map(|(_, n)| n)
            .collect()
    }

    /// Fails on the first property no constructor asked for: an unknown or
    /// misspelt parameter, or one that does not apply to this plugin.
    pub fn check_all_used(&self) -> Result<()> {
        match self.props.iter().find(|p| !p.used.get()) {
            None => Ok(()),
            Some(p) => Err(Error::scene(
                &p.loc,
                format!(
                    "{self}: unknown parameter '{}' (a {}); check the name against the plugin's documentation",
                    p.name,
                    p.value.kind()
                ),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loc(line: u32) -> SrcLoc {
        SrcLoc {
            file: "s.xml".into(),
            line,
        }
    }

    #[test]
    fn typed_access_and_unused_detection() {
        let mut n = Node::new(
            Class::Bsdf,
            "roughconductor",
            Some("gold".into()),
            "gold".into(),
            loc(3),
        );
        n.props.push(Prop::new("alpha", Value::Float(0.2), loc(4)));
        n.props
            .push(Prop::new("distrbution", Value::Str("ggx".into()), loc(5)));
        assert_eq!(n.float("alpha", 0.1).unwrap(), 0.2);
        let e = n.int("alpha", 1).unwrap_err().to_string();
        assert!(
            e.starts_with("s.xml:4:") && e.contains("must be a integer"),
            "{e}"
        );
        let e = n.check_all_used().unwrap_err().to_string();
        assert!(
            e.starts_with("s.xml:5:") && e.contains("unknown parameter 'distrbution'"),
            "{e}"
        );
    }

    #[test]
    fn choices_and_ranges_are_checked() {
        let mut n = Node::new(Class::Bsdf, "roughconductor", None, "b".into(), loc(1));
        n.props.push(Prop::new(
            "distribution",
            Value::Str("phong".into()),
            loc(2),
        ));
        n.props.push(Prop::new("alpha", Value::Float(-1.0), loc(3)));
        let e = n
            .choice("distribution", &["beckmann", "ggx"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("'phong' is not one of: beckmann, ggx"), "{e}");
        let e = n.float_checked("alpha", 0.1, true).unwrap_err().to_string();
        assert!(e.starts_with("s.xml:3:") && e.contains("> 0"), "{e}");
    }
}
