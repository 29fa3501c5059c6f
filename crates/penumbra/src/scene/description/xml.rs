//! The Mitsuba 3 XML scene format → a tree of [`Node`]s.
//!
//! Parsing happens in three steps:
//! 1. *lowering*: the XML text (via `roxmltree`) becomes an owned element
//!    tree; `<default>` values are recorded in document order, `$name`
//!    references in attribute values are substituted, `<path>` search
//!    folders are added to the file's [`FileResolver`], and `<include>`d
//!    files (found by that resolver) are spliced in place;
//! 2. *upgrade*: elements of files of an older scene version are rewritten
//!    to Mitsuba 3's names ([`super::upgrade`]);
//! 3. *building*: elements become plugin [`Node`]s with typed [`Prop`]s;
//!    `<transform>` operations are composed, `<ref>`s resolved (also to
//!    objects declared later in the file, as in Mitsuba), and every nested
//!    object receives its parameter-key prefix (as Mitsuba's `traverse()`
//!    names parameters).
//!
//! Plugins are not constructed here: that is done from the returned tree.

use super::props::{Class, Node, Prop, Value};
use super::resolver::FileResolver;
use super::spectrum::{self, SpectrumUse};
use super::spectrum_plugin;
use super::upgrade::{self, Version};
use crate::error::{Error, Result, SrcLoc};
use crate::math::Transform;
use glam::{Mat3, Mat4, Vec3};
use std::collections::HashMap;
use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// Deepest chain of nested `<include>`s accepted (as Mitsuba).
const MAX_INCLUDE_DEPTH: usize = 15;

/// Tags that declare a plugin object.
const PLUGIN_TAGS: &[&str] = &[
    "shape",
    "bsdf",
    "texture",
    "emitter",
    "sensor",
    "film",
    "rfilter",
    "sampler",
    "integrator",
    "medium",
    "phase",
    "volume",
];
/// Tags that declare a typed property.
const PROPERTY_TAGS: &[&str] = &[
    "float",
    "integer",
    "boolean",
    "string",
    "rgb",
    "spectrum",
    "point",
    "vector",
    "transform",
];
/// Operations allowed inside `<transform>`.
const TRANSFORM_OPS: &[&str] = &["translate", "rotate", "scale", "matrix", "lookat"];

/// A parsed scene: its tree of objects, and the file resolver with which
/// its plugins find their files (the main file's, see [`FileResolver`]).
/// It dereferences to the root node.
#[derive(Debug)]
pub struct SceneDescription {
    pub root: Rc<Node>,
    pub resolver: FileResolver,
}

impl Deref for SceneDescription {
    type Target = Node;
    fn deref(&self) -> &Node {
        &self.root
    }
}

/// Parses a scene file. `defines` are `-D name=value` overrides of <default> values.
pub fn parse_file(path: &Path, defines: &[(String, String)]) -> Result<SceneDescription> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read scene file: {e}")))?;
    parse_str(&text, path, defines)
}

/// Parses scene text; `path` names it in messages, and its folder is where
/// relative file names are searched first.
pub fn parse_str(
    text: &str,
    path: &Path,
    defines: &[(String, String)],
) -> Result<SceneDescription> {
    let mut lowerer = Lowerer {
        vars: defines.iter().cloned().collect(),
        known: Vec::new(),
        include_stack: vec![canonical(path)],
        resolvers: Vec::new(),
        versions: Vec::new(),
    };
    let (mut root, resolver) = lowerer.load(text, path)?;
    lowerer.check_defines(defines, &root.loc)?;
    root.check_attrs(&["version", "type"])?;
    if let Some(t) = root.attr("type") {
        if t != "scene" {
            return Err(root.err(format!("<scene type='{t}'>: only the type 'scene' exists")));
        }
    }
    upgrade::upgrade(&mut root);
    let mut declared = HashMap::new();
    declare_ids(&root, &mut declared)?;
    let mut builder = Builder {
        declared,
        built: HashMap::new(),
        building: Vec::new(),
        unnamed: 0,
        resolver: &resolver,
    };
    let mut node = Node::new(Class::Scene, "scene", None, String::new(), root.loc.clone());
    builder.fill(&mut node, &root, true)?;
    Ok(SceneDescription {
        root: Rc::new(node),
        resolver,
    })
}

/// The parameter-key prefix of a nested object (shared with the Python dict loader later).
///
/// An object with an id is keyed by its id; otherwise by its parent's key,
/// a dot and its property name (just the name at the top level).
pub fn child_key(parent_key: &str, name: &str, id: Option<&str>) -> String {
    match id {
        Some(id) => id.to_string(),
        None if parent_key.is_empty() => name.to_string(),
        None => format!("{parent_key}.{name}"),
    }
}

fn canonical(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

// ---------------------------------------------------------------------------
// Pass 1: XML → owned elements (defaults, substitution, includes)

/// An XML element after `$name` substitution and `<include>` expansion.
#[derive(Debug)]
pub(super) struct Elem {
    pub(super) tag: String,
    pub(super) attrs: Vec<(String, String)>,
    pub(super) children: Vec<Elem>,
    pub(super) loc: SrcLoc,
    /// The scene version of the file the element is written in.
    pub(super) version: Version,
}

impl Elem {
    pub(super) fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    fn err(&self, msg: impl Into<String>) -> Error {
        Error::scene(&self.loc, msg)
    }

    /// `<float name='alpha'>`, for messages.
    fn describe(&self) -> String {
        match self.attr("name") {
            Some(n) => format!("<{} name='{n}'>", self.tag),
            None => format!("<{}>", self.tag),
        }
    }

    fn req_attr(&self, name: &str) -> Result<&str> {
        self.attr(name)
            .ok_or_else(|| self.err(format!("{} needs a '{name}' attribute", self.describe())))
    }

    fn check_attrs(&self, allowed: &[&str]) -> Result<()> {
        for (k, _) in &self.attrs {
            if !allowed.contains(&k.as_str()) {
                return Err(self.err(format!(
                    "unknown attribute '{k}' on {}; expected: {}",
                    self.describe(),
                    allowed.join(", ")
                )));
            }
        }
        Ok(())
    }
}

struct Lowerer {
    /// `$name` values: the defines, then `<default>`s not overridden.
    vars: HashMap<String, String>,
    /// Variable names the scene knows, in order of first appearance: those
    /// declared with `<default>` and those referenced as `$name`.
    known: Vec<String>,
    /// Canonical paths of the files being read (for include cycles).
    include_stack: Vec<PathBuf>,
    /// The file resolver of each file being read (the innermost last).
    resolvers: Vec<FileResolver>,
    /// The scene version of each file being read (the innermost last).
    versions: Vec<Version>,
}

impl Lowerer {
    /// Parses `text` (the contents of `path`) and lowers its root element;
    /// returns it with the file's resolver as it is at the end of the file.
    fn load(&mut self, text: &str, path: &Path) -> Result<(Elem, FileResolver)> {
        let opts = roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        };
        let doc = roxmltree::Document::parse_with_options(text, opts).map_err(|e| {
            let pos = e.pos();
            Error::scene(
                &SrcLoc {
                    file: path.to_path_buf(),
                    line: pos.row,
                },
                format!("malformed XML: {e}"),
            )
        })?;
        let root = doc.root_element();
        let loc = SrcLoc {
            file: path.to_path_buf(),
            line: doc.text_pos_at(root.range().start).row,
        };
        let main = self.versions.is_empty();
        let tag = root.tag_name().name();
        if main && tag != "scene" {
            return Err(Error::scene(
                &loc,
                format!(
                    "the root element is <{tag}>; a scene file's root must be <scene \
                     version=\"3.0.0\">"
                ),
            ));
        }
        let version = match (root.attribute("version"), self.versions.last()) {
            (Some(v), _) => Version::parse(v).ok_or_else(|| {
                Error::scene(
                    &loc,
                    format!(
                        "invalid scene version '{v}': write three numbers, as in \
                         <scene version=\"3.0.0\">"
                    ),
                )
            })?,
            // an included file without a version is read as its includer
            (None, Some(&including)) => including,
            (None, None) => {
                return Err(Error::scene(
                    &loc,
                    "the <scene> tag has no 'version' attribute; write <scene \
                     version=\"3.0.0\"> for a Mitsuba 3 scene (older versions are upgraded)",
                ))
            }
        };
        let mut resolver = self.resolvers.last().cloned().unwrap_or_default();
        resolver.prepend(path.parent().unwrap_or(Path::new("")));
        self.resolvers.push(resolver);
        self.versions.push(version);
        let elem = self.lower(root, path);
        self.versions.pop();
        let resolver = self.resolvers.pop().expect("pushed above");
        Ok((elem?, resolver))
    }

    fn lower(&mut self, node: roxmltree::Node, path: &Path) -> Result<Elem> {
        let loc = SrcLoc {
            file: path.to_path_buf(),
            line: node.document().text_pos_at(node.range().start).row,
        };
        let tag = node.tag_name().name().to_string();
        let what = match node.attribute("name") {
            Some(n) => format!("<{tag} name='{n}'>"),
            None => format!("<{tag}>"),
        };
        let mut attrs = Vec::new();
        for a in node.attributes() {
            let v = self.substitute(a.value(), &loc, &what, a.name())?;
            attrs.push((a.name().to_string(), v));
        }
        let mut elem = Elem {
            tag,
            attrs,
            children: Vec::new(),
            loc,
            version: *self.versions.last().expect("lowered within load"),
        };
        let file_root = node.parent().is_some_and(|p| p.is_root());
        for c in node.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "path" => {
                    let p = self.lower(c, path)?;
                    self.search_path(&p, file_root)?;
                }
                "default" => {
                    let d = self.lower(c, path)?;
                    self.default(&d)?;
                }
                "include" => {
                    let inc = self.lower(c, path)?;
                    self.include(&inc, &mut elem.children)?;
                }
                _ => elem.children.push(self.lower(c, path)?),
            }
        }
        Ok(elem)
    }

    /// `<default name="spp" value="64"/>`: a value for `$spp` unless a define
    /// (or an earlier default) already gave one, as in Mitsuba.
    fn default(&mut self, d: &Elem) -> Result<()> {
        d.check_attrs(&["name", "value"])?;
        let name = d.req_attr("name")?;
        let value = d.req_attr("value")?;
        let valid = name.chars().next().is_some_and(|c| !c.is_ascii_digit())
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !valid {
            return Err(d.err(format!(
                "<default name='{name}'>: a variable name must consist of letters, digits and \
                 '_' and not start with a digit"
            )));
        }
        self.vars
            .entry(name.to_string())
            .or_insert_with(|| value.to_string());
        self.know(name);
        Ok(())
    }

    fn know(&mut self, name: &str) {
        if !self.known.iter().any(|k| k == name) {
            self.known.push(name.to_string());
        }
    }

    /// Fails on a define (`-D name=value`, or a keyword argument of the
    /// Python loaders) that the scene neither declares nor references: a
    /// typo would otherwise be ignored without a word.
    fn check_defines(&self, defines: &[(String, String)], loc: &SrcLoc) -> Result<()> {
        let Some((name, value)) = defines.iter().find(|(name, _)| !self.known.contains(name))
        else {
            return Ok(());
        };
        let list = if self.known.is_empty() {
            "it has none".to_string()
        } else {
            format!("its defaults are: {}", self.known.join(", "))
        };
        Err(Error::scene(
            loc,
            format!("-D {name}={value}: the scene has no default '{name}'; {list}"),
        ))
    }

    /// `<path value="…"/>`: a folder searched before the others by the
    /// current file's resolver (a relative one is found by that resolver).
    fn search_path(&mut self, p: &Elem, file_root: bool) -> Result<()> {
        if !file_root {
            return Err(p.err(
                "<path> adds a search folder for the whole file: put it directly inside the \
                 file's <scene>",
            ));
        }
        p.check_attrs(&["value"])?;
        let value = p.req_attr("value")?;
        let resolver = self.resolvers.last_mut().expect("lowered within load");
        let dir = resolver
            .resolve(value)
            .filter(|d| d.is_dir())
            .ok_or_else(|| {
                p.err(format!(
                    "<path value='{value}'>: folder not found (looked in: {})",
                    resolver.describe()
                ))
            })?;
        resolver.prepend(&dir);
        Ok(())
    }

    /// `<include filename="…"/>`: the file (found by the current file's
    /// resolver) is read; its `<scene>` children (or its single root
    /// object) are spliced in place.
    fn include(&mut self, inc: &Elem, out: &mut Vec<Elem>) -> Result<()> {
        inc.check_attrs(&["filename"])?;
        let filename = inc.req_attr("filename")?;
        let resolver = self.resolvers.last().expect("lowered within load");
        let full = resolver.resolve(filename).ok_or_else(|| {
            inc.err(format!(
                "cannot read included file '{filename}': not found (looked in: {})",
                resolver.describe()
            ))
        })?;
        let text = std::fs::read_to_string(&full).map_err(|e| {
            inc.err(format!(
                "cannot read included file '{filename}' (looked for {}): {e}",
                full.display()
            ))
        })?;
        let canon = canonical(&full);
        if self.include_stack.contains(&canon) {
            let chain: Vec<String> = self
                .include_stack
                .iter()
                .chain(std::iter::once(&canon))
                .map(|p| p.display().to_string())
                .collect();
            return Err(inc.err(format!(
                "include cycle: {}; remove one of these <include>s",
                chain.join(" includes ")
            )));
        }
        if self.include_stack.len() > MAX_INCLUDE_DEPTH {
            return Err(inc.err(format!(
                "<include>s are nested more than {MAX_INCLUDE_DEPTH} levels deep"
            )));
        }
        self.include_stack.push(canon);
        let (mut root, _) = self.load(&text, &full)?;
        self.include_stack.pop();
        if root.tag == "scene" {
            root.check_attrs(&["version", "type"])?;
            out.extend(root.children);
        } else {
            // the version of the file, not an attribute of the object
            root.attrs.retain(|(k, _)| k != "version");
            out.push(root);
        }
        Ok(())
    }

    /// Replaces every `$name` in an attribute value. The longest name made
    /// of letters, digits and '_' is looked up first; failing that, its
    /// longest defined prefix (Mitsuba substitutes plain substrings, so
    /// `"$res_hi"` with only `res` defined reads `res`). A `$` not followed
    /// by a name stays as is.
    fn substitute(&mut self, value: &str, loc: &SrcLoc, what: &str, attr: &str) -> Result<String> {
        if !value.contains('$') {
            return Ok(value.to_string());
        }
        let mut out = String::new();
        let mut rest = value;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            let name = &after[..len];
            if name.is_empty() {
                out.push('$');
                rest = after;
                continue;
            }
            let found = (1..=len)
                .rev()
                .find_map(|l| self.vars.get(&name[..l]).map(|v| (l, v)));
            let Some((l, v)) = found else {
                return Err(Error::scene(
                    loc,
                    format!(
                        "undefined variable '${name}' in attribute {attr}=\"{value}\" of {what}; \
                         declare it with <default name=\"{name}\" value=\"...\"/> before its use, \
                         or define it on the command line (-D {name}=...)"
                    ),
                ));
            };
            out.push_str(v);
            self.know(&name[..l]);
            rest = &after[l..];
        }
        out.push_str(rest);
        Ok(out)
    }
}

// ---------------------------------------------------------------------------
// Pass 2: elements → nodes

/// Collects every object declared with an id, anywhere in the tree (a
/// `<ref>` may name an object declared later, as in Mitsuba); ids must be
/// unique.
fn declare_ids<'a>(e: &'a Elem, declared: &mut HashMap<&'a str, &'a Elem>) -> Result<()> {
    for c in &e.children {
        if let (Some(_), Some(id)) = (Class::from_tag(&c.tag), c.attr("id")) {
            if let Some(prev) = declared.insert(id, c) {
                return Err(c.err(format!(
                    "duplicate id '{id}': it is already used by the <{}> declared at {}; ids \
                     must be unique",
                    prev.tag, prev.loc
                )));
            }
        }
        declare_ids(c, declared)?;
    }
    Ok(())
}

struct Builder<'a> {
    /// Every object declared with an id.
    declared: HashMap<&'a str, &'a Elem>,
    /// The objects with an id built so far (a `<ref>` may have built one
    /// before its declaration is reached).
    built: HashMap<String, Rc<Node>>,
    /// Ids of the objects being built, outermost first (a `<ref>` to one of
    /// them is a cycle).
    building: Vec<String>,
    /// Counter for `_unnamed_<n>` top-level objects.
    unnamed: usize,
    /// The scene's file resolver (as the plugins' files, `.spd` spectra are
    /// found by it).
    resolver: &'a FileResolver,
}

impl<'a> Builder<'a> {
    /// Builds the object declared by `e` (a plugin tag), or returns it if a
    /// `<ref>` built it already.
    fn object(&mut self, e: &'a Elem, class: Class, key: String) -> Result<Rc<Node>> {
        e.check_attrs(&["type", "id", "name"])?;
        let plugin = e.attr("type").ok_or_else(|| {
            e.err(format!(
                "<{}> needs a 'type' attribute naming the plugin (e.g. <{} type=\"...\">)",
                e.tag, e.tag
            ))
        })?;
        let id = e.attr("id");
        if let Some(id) = id {
            if id.is_empty() {
                return Err(e.err(format!("<{}>: the id must not be empty", e.tag)));
            }
            if let Some(node) = self.built.get(id) {
                return Ok(node.clone());
            }
            self.building.push(id.to_string());
        }
        let mut node = Node::new(class, plugin, id.map(str::to_string), key, e.loc.clone());
        self.fill(&mut node, e, false)?;
        let node = Rc::new(node);
        if let Some(id) = id {
            self.building.pop();
            self.built.insert(id.to_string(), node.clone());
        }
        Ok(node)
    }

    /// The object `<ref id="…">` (`c`) names, built on first use.
    fn reference(&mut self, c: &Elem, id: &str) -> Result<Rc<Node>> {
        if let Some(node) = self.built.get(id) {
            return Ok(node.clone());
        }
        if let Some(i) = self.building.iter().position(|b| b == id) {
            return Err(c.err(format!(
                "<ref id='{id}'>: circular reference {} -> {id}; an object cannot contain itself",
                self.building[i..].join(" -> ")
            )));
        }
        let Some(&decl) = self.declared.get(id) else {
            let mut known: Vec<&str> = self.declared.keys().copied().collect();
            known.sort_unstable();
            let known = if known.is_empty() {
                "none".to_string()
            } else {
                known.join(", ")
            };
            return Err(c.err(format!(
                "<ref id='{id}'>: no object with id '{id}' is declared in the scene (ids \
                 declared: {known}); check the spelling"
            )));
        };
        let class = Class::from_tag(&decl.tag).expect("declared objects have a plugin tag");
        // keyed by its id wherever it is built
        self.object(decl, class, id.to_string())
    }

    /// The object an unnamed child `c` would contribute, as a tag, for the
    /// `<tag>_<n>` naming of several unnamed objects of one kind.
    fn unnamed_tag(&self, c: &Elem) -> Option<&'static str> {
        if c.attr("name").is_some() {
            return None;
        }
        if let Some(class) = Class::from_tag(&c.tag) {
            return Some(class.tag());
        }
        if c.tag == "ref" {
            let decl = self.declared.get(c.attr("id")?)?;
            return Class::from_tag(&decl.tag).map(Class::tag);
        }
        None
    }

    /// Adds the properties and nested objects declared inside `e` to `node`.
    fn fill(&mut self, node: &mut Node, e: &'a Elem, top_level: bool) -> Result<()> {
        // several unnamed children of one tag are named <tag>_0, <tag>_1, …
        let tags: Vec<Option<&'static str>> =
            e.children.iter().map(|c| self.unnamed_tag(c)).collect();
        let mut total: HashMap<&str, usize> = HashMap::new();
        for t in tags.iter().flatten() {
            *total.entry(t).or_default() += 1;
        }
        let mut seen: HashMap<&str, usize> = HashMap::new();
        let mut unnamed_members = 0;
        let mut auto_name = |t: &'static str| -> String {
            if total[t] > 1 {
                let n = seen.entry(t).or_default();
                *n += 1;
                format!("{t}_{}", *n - 1)
            } else {
                t.to_string()
            }
        };

        for (c, tag) in e.children.iter().zip(&tags) {
            let tag_s = c.tag.as_str();
            if let Some(class) = Class::from_tag(tag_s) {
                if class == Class::Scene {
                    return Err(c.err(
                        "a <scene> cannot be nested inside another object; use <include \
                         filename=\"...\"/> to combine scene files",
                    ));
                }
                let name = if top_level {
                    match c.attr("id") {
                        Some(id) => id.to_string(),
                        None => {
                            self.unnamed += 1;
                            format!("_unnamed_{}", self.unnamed - 1)
                        }
                    }
                } else {
                    match c.attr("name") {
                        Some(n) => n.to_string(),
                        None => auto_name(tag.expect("unnamed plugin has a tag")),
                    }
                };
                let key = if node.class == Class::Shape && node.plugin == "shapegroup" {
                    // a shape group's shapes are keyed under the group as
                    // Mitsuba's traverse() keys them: by id, else `shape`,
                    // `shape_1`, `shape_2`, … in file order (and by name,
                    // which Python dicts give as Mitsuba's load_dict does)
                    let member = match (c.attr("id"), c.attr("name")) {
                        (Some(id), _) | (None, Some(id)) => id.to_string(),
                        (None, None) => {
                            unnamed_members += 1;
                            match unnamed_members {
                                1 => "shape".to_string(),
                                k => format!("shape_{}", k - 1),
                            }
                        }
                    };
                    format!("{}.{member}", node.key)
                } else {
                    child_key(&node.key, &name, c.attr("id"))
                };
                let child = self.object(c, class, key)?;
                let mut prop = Prop::new(name, Value::Node(child), c.loc.clone());
                prop.unnamed = c.attr("name").is_none();
                push_prop(node, prop)?;
            } else if tag_s == "ref" {
                c.check_attrs(&["id", "name"])?;
                let id = c.req_attr("id")?;
                let target = self.reference(c, id)?;
                let name = match c.attr("name") {
                    Some(n) => n.to_string(),
                    None => match tag {
                        Some(t) => auto_name(t),
                        None => target.class.tag().to_string(),
                    },
                };
                let mut prop = Prop::new(name, Value::Node(target), c.loc.clone());
                prop.unnamed = c.attr("name").is_none();
                push_prop(node, prop)?;
            } else if PROPERTY_TAGS.contains(&tag_s) {
                let (name, value) = property(c, node.class == Class::Emitter, self.resolver)?;
                push_prop(node, Prop::new(name, value, c.loc.clone()))?;
            } else if TRANSFORM_OPS.contains(&tag_s) {
                return Err(c.err(format!(
                    "<{tag_s}> is a transform operation: it belongs inside <transform \
                     name=\"to_world\">…</transform>"
                )));
            } else {
                let mut valid: Vec<&str> = PLUGIN_TAGS.to_vec();
                valid.extend_from_slice(PROPERTY_TAGS);
                valid.extend_from_slice(&["ref", "include", "default"]);
                return Err(c.err(format!(
                    "unknown tag <{tag_s}> inside <{}>; valid tags: {}",
                    e.tag,
                    valid.join(", ")
                )));
            }
        }
        Ok(())
    }
}

fn push_prop(node: &mut Node, p: Prop) -> Result<()> {
    if let Some(prev) = node.props.iter().find(|q| q.name == p.name) {
        return Err(Error::scene(
            &p.loc,
            format!(
                "{node}: parameter '{}' is given twice (first at {}); remove one",
                p.name, prev.loc
            ),
        ));
    }
    node.props.push(p);
    Ok(())
}

// ---------------------------------------------------------------------------
// Typed properties

/// Parses a typed property element into (name, value); `in_emitter` when
/// it is a property of an `<emitter>` (spectra are converted differently
/// there).
fn property(c: &Elem, in_emitter: bool, resolver: &FileResolver) -> Result<(String, Value)> {
    let allowed: &[&str] = match c.tag.as_str() {
        "point" | "vector" => &["name", "value", "x", "y", "z"],
        "spectrum" => &["name", "value", "filename"],
        "transform" => &["name"],
        _ => &["name", "value"],
    };
    if let (Some(t), "spectrum") = (c.attr("type"), c.tag.as_str()) {
        return spectrum_plugin(c, t, in_emitter, resolver);
    }
    c.check_attrs(allowed)?;
    let name = c.req_attr("name")?.to_string();
    if c.tag != "transform" {
        if let Some(ch) = c.children.first() {
            return Err(ch.err(format!(
                "{} cannot contain <{}>; only objects and <transform> have children",
                c.describe(),
                ch.tag
            )));
        }
    }
    let value = match c.tag.as_str() {
        "float" => Value::Float(number(c, "value", c.req_attr("value")?)?),
        "integer" => {
            let s = c.req_attr("value")?;
            Value::Int(s.trim().parse::<i64>().map_err(|_| {
                c.err(format!(
                    "expected an integer for {}, found '{s}'",
                    c.describe()
                ))
            })?)
        }
        "boolean" => {
            let s = c.req_attr("value")?;
            match s.trim().to_ascii_lowercase().as_str() {
                "true" => Value::Bool(true),
                "false" => Value::Bool(false),
                _ => {
                    return Err(c.err(format!(
                        "expected true or false for {}, found '{s}'",
                        c.describe()
                    )))
                }
            }
        }
        "string" => Value::Str(c.req_attr("value")?.to_string()),
        "rgb" => {
            let v = numbers(c, "value", c.req_attr("value")?)?;
            match v.len() {
                1 => Value::Rgb(Vec3::splat(v[0] as f32)),
                3 => Value::Rgb(to_vec3(&v)),
                n => {
                    return Err(c.err(format!(
                        "expected 1 or 3 numbers for {}, found {n}",
                        c.describe()
                    )))
                }
            }
        }
        "spectrum" => spectrum(c, in_emitter, resolver)?,
        "point" => Value::Point(xyz(c, 0.0)?),
        "vector" => Value::Vector(xyz(c, 0.0)?),
        "transform" => Value::Transform(transform(c)?),
        t => unreachable!("not a property tag: {t}"),
    };
    Ok((name, value))
}

/// `<spectrum>`: a constant, `wavelength:value` pairs, or an `.spd` file,
/// converted to RGB as Mitsuba 3's RGB variants do (see
/// [`super::spectrum`]); `in_emitter` when it is a direct property of an
/// `<emitter>`; a file is found by the current file's `resolver`.
fn spectrum(c: &Elem, in_emitter: bool, resolver: &FileResolver) -> Result<Value> {
    let name = c.req_attr("name")?;
    let usage = SpectrumUse::of(name, in_emitter);
    let (wavelengths, values) = match (c.attr("value"), c.attr("filename")) {
        (Some(s), None) if !s.contains(':') => {
            let v = numbers(c, "value", s)?;
            if v.len() != 1 {
                return Err(c.err(format!(
                    "{}: expected one number (a constant spectrum) or wavelength:value pairs, \
                     found {} numbers",
                    c.describe(),
                    v.len()
                )));
            }
            return Ok(match usage {
                SpectrumUse::Emission => Value::Rgb(spectrum::constant_to_rgb(v[0] as f32, usage)),
                _ => Value::Spectrum(v[0] as f32),
            });
        }
        (Some(s), None) => wavelength_value_pairs(c, s)?,
        (None, Some(f)) => spd_file(c, f, resolver)?,
        _ => {
            return Err(c.err(format!(
                "{} needs either a 'value' or a 'filename' attribute",
                c.describe()
            )))
        }
    };
    spectrum::check_samples(&wavelengths).map_err(|m| c.err(format!("{}: {m}", c.describe())))?;
    let (rgb, clamped) = spectrum::samples_to_rgb(&wavelengths, &values, usage);
    if clamped {
        warn_clamped(c, rgb);
    }
    Ok(Value::Rgb(rgb))
}

/// `<spectrum type="…" name="…">` with its parameters as child
/// properties: a spectrum plugin, converted by
/// [`super::spectrum_plugin`].
fn spectrum_plugin(
    c: &Elem,
    plugin: &str,
    in_emitter: bool,
    resolver: &FileResolver,
) -> Result<(String, Value)> {
    c.check_attrs(&["name", "type"])?;
    let name = c.req_attr("name")?.to_string();
    let mut node = Node::new(Class::Spectrum, plugin, None, name.clone(), c.loc.clone());
    for p in &c.children {
        if !PROPERTY_TAGS.contains(&p.tag.as_str()) || p.tag == "spectrum" {
            return Err(p.err(format!(
                "{} cannot contain <{}>; a spectrum plugin's parameters are <float>, \
                 <string> or <rgb> properties",
                c.describe(),
                p.tag
            )));
        }
        let (pname, value) = property(p, false, resolver)?;
        push_prop(&mut node, Prop::new(pname, value, p.loc.clone()))?;
    }
    let (value, clamped) = spectrum_plugin::to_value(&node, SpectrumUse::of(&name, in_emitter))?;
    if let (true, Value::Rgb(rgb)) = (clamped, &value) {
        warn_clamped(c, *rgb);
    }
    Ok((name, value))
}

/// Warns that the colour of spectrum `c` was clamped into range.
fn warn_clamped(c: &Elem, rgb: Vec3) {
    crate::warn::warn(format!(
        "{}: {}: the spectrum's colour is outside the sRGB gamut; clamped to {rgb} (as Mitsuba)",
        c.loc,
        c.describe()
    ));
}

/// `value="400:0.1, 500:0.5"`: wavelengths (nm) and values.
fn wavelength_value_pairs(c: &Elem, s: &str) -> Result<(Vec<f64>, Vec<f64>)> {
    s.split(|ch: char| ch == ',' || ch.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| match t.split_once(':') {
            Some((w, v)) => Ok((number(c, "value", w)?, number(c, "value", v)?)),
            None => Err(c.err(format!(
                "{}: expected wavelength:value pairs, found '{t}'",
                c.describe()
            ))),
        })
        .collect::<Result<Vec<_>>>()
        .map(|pairs| pairs.into_iter().unzip())
}

/// `filename="x.spd"`, found by `resolver` as every file of the scene:
/// wavelength/value lines.
fn spd_file(c: &Elem, filename: &str, resolver: &FileResolver) -> Result<(Vec<f64>, Vec<f64>)> {
    if !Path::new(filename)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("spd"))
    {
        return Err(c.err(format!(
            "{}: spectrum file '{filename}' must be an .spd file (lines of 'wavelength value')",
            c.describe()
        )));
    }
    let full = resolver.resolve(filename).ok_or_else(|| {
        c.err(format!(
            "{}: spectrum file '{filename}' not found (looked in: {})",
            c.describe(),
            resolver.describe()
        ))
    })?;
    let text = std::fs::read_to_string(&full).map_err(|e| {
        c.err(format!(
            "{}: cannot read spectrum file '{filename}' ({}): {e}",
            c.describe(),
            full.display()
        ))
    })?;
    spectrum::parse_spd(&text)
        .map_err(|m| c.err(format!("{}: {}: {m}", c.describe(), full.display())))
}

/// One finite number from attribute `attr` of `c`.
fn number(c: &Elem, attr: &str, s: &str) -> Result<f64> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(c.err(format!(
            "expected a number for {}{}, found '{s}'",
            c.describe(),
            if attr == "value" {
                String::new()
            } else {
                format!(" (attribute '{attr}')")
            }
        ))),
    }
}

/// A list of numbers separated by commas and/or whitespace.
fn numbers(c: &Elem, attr: &str, s: &str) -> Result<Vec<f64>> {
    s.split(|ch: char| ch == ',' || ch.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| number(c, attr, t))
        .collect()
}

fn to_vec3(v: &[f64]) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

/// Exactly three numbers from attribute `attr`.
fn vec3_attr(c: &Elem, attr: &str) -> Result<Vec3> {
    let s = c
        .attr(attr)
        .ok_or_else(|| c.err(format!("{} needs a '{attr}' attribute", c.describe())))?;
    let v = numbers(c, attr, s)?;
    if v.len() != 3 {
        return Err(c.err(format!(
            "expected 3 numbers for attribute '{attr}' of {}, found {} ('{s}')",
            c.describe(),
            v.len()
        )));
    }
    Ok(to_vec3(&v))
}

/// A vector given as `value="x, y, z"` or as attributes x, y, z (missing
/// components are `default`).
fn xyz(c: &Elem, default: f32) -> Result<Vec3> {
    let has_xyz = ["x", "y", "z"].iter().any(|a| c.attr(a).is_some());
    if c.attr("value").is_some() {
        if has_xyz {
            return Err(c.err(format!(
                "{}: give either 'value' or 'x'/'y'/'z', not both",
                c.describe()
            )));
        }
        return vec3_attr(c, "value");
    }
    let comp = |a: &str| -> Result<f32> {
        match c.attr(a) {
            Some(s) => Ok(number(c, a, s)? as f32),
            None => Ok(default),
        }
    };
    Ok(Vec3::new(comp("x")?, comp("y")?, comp("z")?))
}

/// `<transform name="…">` with its operations applied in file order, each
/// composed on the left of the previous ones (M = op_n ∘ … ∘ op_1).
fn transform(c: &Elem) -> Result<Transform> {
    let mut m = Transform::IDENTITY;
    for op in &c.children {
        let t = match op.tag.as_str() {
            "translate" => {
                op.check_attrs(&["value", "x", "y", "z"])?;
                Transform::translate(xyz(op, 0.0)?)
            }
            "rotate" => {
                op.check_attrs(&["value", "x", "y", "z", "angle"])?;
                let axis = xyz(op, 0.0)?;
                if axis.length_squared() == 0.0 {
                    return Err(op.err(
                        "<rotate> needs a non-zero axis (e.g. x=\"1\" or value=\"0, 1, 0\")",
                    ));
                }
                let angle = number(op, "angle", op.req_attr("angle")?)? as f32;
                Transform::rotate(axis, angle)
            }
            "scale" => {
                op.check_attrs(&["value", "x", "y", "z"])?;
                let s = match op.attr("value") {
                    Some(v) if !["x", "y", "z"].iter().any(|a| op.attr(a).is_some()) => {
                        let v = numbers(op, "value", v)?;
                        match v.len() {
                            1 => Vec3::splat(v[0] as f32),
                            3 => to_vec3(&v),
                            n => {
                                return Err(op.err(format!(
                                    "expected 1 or 3 numbers for <scale value>, found {n}"
                                )))
                            }
                        }
                    }
                    _ => xyz(op, 1.0)?,
                };
                if s.x * s.y * s.z == 0.0 {
                    return Err(op.err(format!("<scale> by {s} is singular (a zero scale factor)")));
                }
                Transform::scale(s)
            }
            "matrix" => {
                op.check_attrs(&["value"])?;
                let v = numbers(op, "value", op.req_attr("value")?)?;
                let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
                let mat = match v.len() {
                    // row-major in the file; glam's arrays are column-major
                    16 => Mat4::from_cols_slice(&v).transpose(),
                    9 => Mat4::from_mat3(Mat3::from_cols_slice(&v).transpose()),
                    n => {
                        return Err(op.err(format!(
                            "expected 16 (4x4) or 9 (3x3) numbers for <matrix value>, found {n}"
                        )))
                    }
                };
                Transform::new(mat)
                    .ok_or_else(|| op.err("<matrix> is singular (not invertible)"))?
            }
            "lookat" => {
                op.check_attrs(&["origin", "target", "up"])?;
                let origin = vec3_attr(op, "origin")?;
                let target = vec3_attr(op, "target")?;
                let up = vec3_attr(op, "up")?;
                Transform::look_at(origin, target, up).ok_or_else(|| {
                    op.err(
                        "degenerate <lookat>: origin equals target, or 'up' is zero or \
                         parallel to the viewing direction",
                    )
                })?
            }
            t => {
                return Err(op.err(format!(
                    "unknown tag <{t}> inside <transform>; valid operations: {}",
                    TRANSFORM_OPS.join(", ")
                )))
            }
        };
        m = t.after(&m);
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "<scene version=\"3.0.0\">\n";

    fn parse(text: &str) -> Result<SceneDescription> {
        parse_str(text, Path::new("t.xml"), &[])
    }

    fn err(text: &str) -> String {
        match parse(text) {
            Ok(_) => panic!("expected an error for:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    /// The bundled scenes of the repository (scenes/).
    fn reference_scenes() -> PathBuf {
        crate::testing::repo_file("scenes")
    }

    fn load_ref(name: &str, defines: &[(String, String)]) -> SceneDescription {
        let p = crate::testing::repo_file(&format!("scenes/{name}"));
        parse_file(&p, defines).unwrap_or_else(|e| panic!("{name}: {e}"))
    }

    fn child(n: &Node, name: &str) -> Rc<Node> {
        n.child(name)
            .unwrap()
            .unwrap_or_else(|| panic!("{n} has no child '{name}'"))
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    /// A fresh directory for files of one test.
    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("penumbra-xml-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn all_reference_scenes_parse() {
        let mut parsed = Vec::new();
        for entry in std::fs::read_dir(reference_scenes()).unwrap() {
            let p = entry.unwrap().path();
            if p.extension().is_some_and(|e| e == "xml") {
                let root = parse_file(&p, &[]).unwrap_or_else(|e| panic!("{e}"));
                assert_eq!(root.class, Class::Scene);
                assert_eq!(root.key, "");
                assert!(!root.children(Class::Shape).is_empty(), "{}", p.display());
                parsed.push(p.file_stem().unwrap().to_string_lossy().into_owned());
            }
        }
        for name in ["bsdfs", "cbox", "geom", "mesh_heavy", "textured"] {
            assert!(
                parsed.iter().any(|p| p == name),
                "scenes/{name}.xml not found"
            );
        }
    }

    #[test]
    fn cbox_values_keys_and_refs() {
        let root = load_ref("cbox.xml", &[]);
        let light = child(&root, "light");
        assert_eq!(light.key, "light");
        assert_eq!(light.loc.line, 45);
        let t = light.transform("to_world").unwrap();
        assert!(close(t.point(Vec3::ZERO), Vec3::new(0.0, 0.99, 0.01)));
        // rectangle normal +z → rotated 90° about x → -y (points down)
        assert!(close(
            t.normal(Vec3::Z).normalize(),
            Vec3::new(0.0, -1.0, 0.0)
        ));
        // the referenced bsdf keeps its own key and is shared
        let red = child(&root, "red");
        assert_eq!(red.key, "red");
        assert_eq!(red.class, Class::Bsdf);
        let red_wall = child(&root, "red-wall");
        assert!(Rc::ptr_eq(&child(&red_wall, "bsdf"), &red));
        let white = child(&root, "white");
        assert!(Rc::ptr_eq(&child(&light, "bsdf"), &white));
        assert!(Rc::ptr_eq(&child(&child(&root, "floor"), "bsdf"), &white));
        // the area emitter without id is keyed under its shape
        let em = child(&light, "emitter");
        assert_eq!(em.key, "light.emitter");
        assert_eq!(em.plugin, "area");
        let rad = em.vec3_opt("radiance").unwrap().unwrap();
        assert!(close(rad, Vec3::new(18.387, 13.9873, 6.75357)));
        // defaults substituted
        let sensor = child(&root, "sensor");
        let sampler = child(&sensor, "sampler");
        assert_eq!(sampler.key, "sensor.sampler");
        assert_eq!(sampler.int("sample_count", 0).unwrap(), 64);
        let film = child(&sensor, "film");
        assert_eq!(film.int("width", 0).unwrap(), 256);
        assert_eq!(child(&film, "rfilter").key, "sensor.film.rfilter");
        let integ = child(&root, "integrator");
        assert_eq!(integ.int("max_depth", 0).unwrap(), 8);
    }

    #[test]
    fn defines_override_defaults() {
        let d = [("spp".to_string(), "16".to_string())];
        let root = load_ref("cbox.xml", &d);
        let sampler = child(&child(&root, "sensor"), "sampler");
        assert_eq!(sampler.int("sample_count", 0).unwrap(), 16);
        let film = child(&child(&root, "sensor"), "film");
        assert_eq!(film.int("width", 0).unwrap(), 256);
    }

    #[test]
    fn unknown_defines_are_errors_that_list_the_defaults() {
        let dir = temp_dir("unknown-define");
        std::fs::write(
            dir.join("inc.xml"),
            "<scene version=\"3.0.0\">\n<default name=\"max_depth\" value=\"3\"/>\n</scene>",
        )
        .unwrap();
        let text = "<scene version=\"3.0.0\">\n<default name=\"res\" value=\"8\"/>\n\
                    <include filename=\"inc.xml\"/>\n\
                    <bsdf type=\"diffuse\"><float name=\"a\" value=\"$spp\"/></bsdf></scene>";
        let scene = dir.join("scene.xml");
        let define = |k: &str, v: &str| vec![(k.to_string(), v.to_string())];
        // declared here, declared in an include, or only referenced: known
        for (k, v) in [("res", "4"), ("max_depth", "2"), ("spp", "1")] {
            let mut d = define(k, v);
            if k != "spp" {
                d.extend(define("spp", "1"));
            }
            parse_str(text, &scene, &d).unwrap_or_else(|e| panic!("-D {k}: {e}"));
        }
        let mut d = define("spp", "1");
        d.extend(define("resolution", "32"));
        let e = parse_str(text, &scene, &d).unwrap_err().to_string();
        assert!(
            e.contains(
                "scene.xml:1: -D resolution=32: the scene has no default 'resolution'; \
                        its defaults are: res, max_depth, spp"
            ),
            "{e}"
        );
    }

    #[test]
    fn textured_keys_and_volume_refs() {
        let root = load_ref("textured.xml", &[]);
        let bsdf = child(&child(&root, "plane"), "bsdf");
        assert_eq!(bsdf.key, "plane.bsdf");
        let tex = child(&bsdf, "reflectance");
        assert_eq!(tex.key, "plane.bsdf.reflectance");
        assert_eq!((tex.class, tex.plugin.as_str()), (Class::Texture, "bitmap"));
        assert_eq!(tex.string("filename", "").unwrap(), "textures/texture.exr");
        // to_uv scale x=2 y=1: z defaults to 1
        let sphere_tex = child(&child(&child(&root, "sphere"), "bsdf"), "reflectance");
        let uv = sphere_tex.transform("to_uv").unwrap();
        assert!(close(uv.point(Vec3::ONE), Vec3::new(2.0, 1.0, 1.0)));

        // the medium setup of the reference kit's volume_hetero.xml (media do
        // not render yet, so the scene itself is not bundled)
        let root = parse(&format!(
            "{HEAD}<medium type=\"heterogeneous\" id=\"medium\">\n\
             <volume type=\"gridvolume\" name=\"sigma_t\">\n\
             <string name=\"filename\" value=\"volumes/density.vol\"/></volume>\n\
             <phase type=\"isotropic\"/></medium>\n\
             <shape type=\"cube\" id=\"medium_box\"><transform name=\"to_world\">\n\
             <scale value=\"0.5\"/><translate y=\"0.5\"/></transform>\n\
             <bsdf type=\"null\"/><ref name=\"interior\" id=\"medium\"/></shape></scene>"
        ))
        .unwrap();
        let medium = child(&root, "medium");
        let bx = child(&root, "medium_box");
        assert!(Rc::ptr_eq(&child(&bx, "interior"), &medium));
        assert_eq!(child(&medium, "sigma_t").key, "medium.sigma_t");
        assert_eq!(child(&medium, "phase").key, "medium.phase");
        // <translate y="0.5"/>: missing components are 0
        let t = bx.transform("to_world").unwrap();
        assert!(close(t.point(Vec3::ZERO), Vec3::new(0.0, 0.5, 0.0)));
    }

    #[test]
    fn transform_ops_compose_on_the_left() {
        let root = parse(&format!(
            "{HEAD}<shape type=\"cube\" id=\"c\"><transform name=\"to_world\">\n\
             <scale x=\"2\" y=\"3\"/>\n\
             <rotate value=\"0, 0, 1\" angle=\"90\"/>\n\
             <translate value=\"1 2 3\"/>\n\
             <matrix value=\"1 0 0 10  0 1 0 0  0 0 1 0  0 0 0 1\"/>\n\
             <matrix value=\"0 -1 0  1 0 0  0 0 1\"/>\n\
             </transform></shape></scene>"
        ))
        .unwrap();
        let t = child(&root, "c").transform("to_world").unwrap();
        let s = Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0));
        let r = Mat4::from_rotation_z(90f32.to_radians());
        let tr = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0));
        let m4 = Mat4::from_translation(Vec3::new(10.0, 0.0, 0.0));
        let m3 = Mat4::from_rotation_z(90f32.to_radians());
        let want = m3 * m4 * tr * r * s;
        assert!(t.m.abs_diff_eq(want, 1e-5), "{:?}\n{:?}", t.m, want);
        assert!((t.m * t.inv).abs_diff_eq(Mat4::IDENTITY, 1e-5));
        // a concrete point: (1,1,0) → scale (2,3,0) → rot (-3,2,0)
        // → +(1,2,3) = (-2,4,3) → +x10 = (8,4,3) → rot (-4,8,3)
        assert!(close(
            t.point(Vec3::new(1.0, 1.0, 0.0)),
            Vec3::new(-4.0, 8.0, 3.0)
        ));
    }

    #[test]
    fn lookat_after_scale() {
        let root = parse(&format!(
            "{HEAD}<shape type=\"rectangle\" id=\"l\"><transform name=\"to_world\">\n\
             <scale value=\"0.5\"/>\n\
             <lookat origin=\"0, 3, 0\" target=\"0, 0, 0\" up=\"0, 0, 1\"/>\n\
             </transform></shape></scene>"
        ))
        .unwrap();
        let t = child(&root, "l").transform("to_world").unwrap();
        assert!(close(t.point(Vec3::ZERO), Vec3::new(0.0, 3.0, 0.0)));
        assert!(close(t.point(Vec3::Z), Vec3::new(0.0, 2.5, 0.0)));
        assert!(close(t.vector(Vec3::Y), Vec3::new(0.0, 0.0, 0.5)));
    }

    #[test]
    fn naming_of_unnamed_children_and_keys() {
        let root = parse(&format!(
            "{HEAD}<bsdf type=\"diffuse\" id=\"a\"/>\n\
             <shape type=\"sphere\">\n\
               <bsdf type=\"blendbsdf\">\n\
                 <float name=\"weight\" value=\"0.3\"/>\n\
                 <ref id=\"a\"/>\n\
                 <bsdf type=\"conductor\"/>\n\
               </bsdf>\n\
             </shape>\n\
             <shape type=\"sphere\"/>\n\
             <emitter type=\"constant\" name=\"ignored_at_top\"/>\n\
             </scene>"
        ))
        .unwrap();
        let names: Vec<&str> = root.props.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["a", "_unnamed_0", "_unnamed_1", "_unnamed_2"]);
        let s0 = child(&root, "_unnamed_0");
        assert_eq!(s0.key, "_unnamed_0");
        assert_eq!(s0.loc.line, 3);
        let blend = child(&s0, "bsdf");
        assert_eq!(blend.key, "_unnamed_0.bsdf");
        assert!(Rc::ptr_eq(&child(&blend, "bsdf_0"), &child(&root, "a")));
        let b1 = child(&blend, "bsdf_1");
        assert_eq!(b1.key, "_unnamed_0.bsdf.bsdf_1");
        assert_eq!(b1.plugin, "conductor");
        assert_eq!(blend.props[0].loc.line, 5);
        assert_eq!(child(&root, "_unnamed_2").class, Class::Emitter);
        assert_eq!(child_key("", "x", None), "x");
        assert_eq!(child_key("p", "x", None), "p.x");
        assert_eq!(child_key("p", "x", Some("id")), "id");
    }

    #[test]
    fn nested_objects_with_ids_are_keyed_by_id_and_referable() {
        let root = parse(&format!(
            "{HEAD}<shape type=\"sphere\" id=\"s\">\n\
               <bsdf type=\"diffuse\">\n\
                 <texture type=\"checkerboard\" name=\"reflectance\" id=\"checks\"/>\n\
               </bsdf>\n\
             </shape>\n\
             <bsdf type=\"diffuse\" id=\"other\"><ref name=\"reflectance\" id=\"checks\"/></bsdf>\n\
             </scene>"
        ))
        .unwrap();
        let tex = child(&child(&child(&root, "s"), "bsdf"), "reflectance");
        assert_eq!(tex.key, "checks");
        assert_eq!(child(&child(&root, "s"), "bsdf").key, "s.bsdf");
        assert!(Rc::ptr_eq(
            &child(&child(&root, "other"), "reflectance"),
            &tex
        ));
        // a ref to an enclosing object is a cycle
        let e = err(&format!(
            "{HEAD}<bsdf type=\"blendbsdf\" id=\"b\">\n<ref id=\"b\"/>\n</bsdf></scene>"
        ));
        assert!(
            e.starts_with("t.xml:3:") && e.contains("circular reference b -> b"),
            "{e}"
        );
    }

    #[test]
    fn typed_values_and_substitution() {
        let root = parse_str(
            &format!(
                "{HEAD}<default name=\"name\" value=\"bunny\"/>\n\
                 <default name=\"res\" value=\"8\"/>\n\
                 <shape type=\"ply\" id=\"$name\">\n\
                   <string name=\"filename\" value=\"meshes/$name.ply\"/>\n\
                   <string name=\"price\" value=\"5$ and $res_hi $\"/>\n\
                   <boolean name=\"flip\" value=\"TRUE\"/>\n\
                   <integer name=\"n\" value=\"-3\"/>\n\
                   <float name=\"f\" value=\"1e-2\"/>\n\
                   <rgb name=\"grey\" value=\"0.5\"/>\n\
                   <rgb name=\"col\" value=\"0.1,0.2 0.3\"/>\n\
                   <spectrum name=\"s\" value=\"0.25\"/>\n\
                   <point name=\"p\" x=\"1\" z=\"3\"/>\n\
                   <vector name=\"v\" value=\"4, 5, 6\"/>\n\
                   <float name=\"extra\" value=\"$extra\"/>\n\
                 </shape></scene>"
            ),
            Path::new("t.xml"),
            &[("extra".to_string(), "7".to_string())],
        )
        .unwrap();
        let s = child(&root, "bunny");
        assert_eq!(s.id.as_deref(), Some("bunny"));
        assert_eq!(s.string("filename", "").unwrap(), "meshes/bunny.ply");
        assert_eq!(s.string("price", "").unwrap(), "5$ and 8_hi $");
        assert!(s.bool("flip", false).unwrap());
        assert_eq!(s.int("n", 0).unwrap(), -3);
        assert_eq!(s.float("f", 0.0).unwrap(), 0.01);
        assert_eq!(s.vec3_opt("grey").unwrap(), Some(Vec3::splat(0.5)));
        assert_eq!(s.vec3_opt("col").unwrap(), Some(Vec3::new(0.1, 0.2, 0.3)));
        assert!(matches!(s.prop("s").unwrap().value, Value::Spectrum(v) if v == 0.25));
        assert!(
            matches!(s.prop("p").unwrap().value, Value::Point(v) if v == Vec3::new(1.0, 0.0, 3.0))
        );
        assert!(
            matches!(s.prop("v").unwrap().value, Value::Vector(v) if v == Vec3::new(4.0, 5.0, 6.0))
        );
        assert_eq!(s.float("extra", 0.0).unwrap(), 7.0);
        assert_eq!(s.prop("col").unwrap().loc.line, 11);
        s.check_all_used().unwrap();
    }

    /// Spectrum plugins: grey and RGB values as Mitsuba 3.9.1's scalar_rgb
    /// variant loads them (`mi.traverse`); blackbody, regular and irregular
    /// emission as its llvm_ad_spectral variant renders them (a constant
    /// environment seen by a 1-pixel camera, 4 × 2²⁰ samples, whose
    /// standard errors are below 0.03 % of the values). Ours is the
    /// 1000-wavelength sum of Mitsuba's parser, whose error grows where a
    /// spectrum is cut off inside the visible range: 0.5 % in blue for a
    /// blackbody cut at 450 nm.
    #[test]
    fn spectrum_plugins_become_values_as_in_mitsuba() {
        let root = parse(&format!(
            "{HEAD}<bsdf type=\"diffuse\" id=\"b\">\n\
               <spectrum type=\"uniform\" name=\"reflectance\"><float name=\"value\" value=\"0.5\"/></spectrum>\n\
               <spectrum type=\"d65\" name=\"alpha\"><float name=\"scale\" value=\"0.2\"/></spectrum>\n\
               <spectrum type=\"d65\" name=\"specular_reflectance\"><rgb name=\"color\" value=\"0.2, 0.5, 0.8\"/><float name=\"scale\" value=\"0.5\"/></spectrum>\n\
               <spectrum type=\"srgb\" name=\"diffuse_reflectance\"><rgb name=\"color\" value=\"0.2, 0.5, 0.8\"/></spectrum>\n\
             </bsdf>\n\
             <emitter type=\"constant\" id=\"e\">\n\
               <spectrum type=\"uniform\" name=\"u\"><float name=\"value\" value=\"0.5\"/></spectrum>\n\
               <spectrum type=\"d65\" name=\"d\"/>\n\
               <spectrum type=\"blackbody\" name=\"bb3000\"><float name=\"temperature\" value=\"3000\"/></spectrum>\n\
               <spectrum type=\"blackbody\" name=\"bb6500\"><float name=\"temperature\" value=\"6500\"/>\
                 <float name=\"wavelength_min\" value=\"450\"/><float name=\"wavelength_max\" value=\"650\"/></spectrum>\n\
               <spectrum type=\"regular\" name=\"reg\"><float name=\"wavelength_min\" value=\"400\"/>\
                 <float name=\"wavelength_max\" value=\"700\"/><string name=\"values\" value=\"0.1, 0.5, 0.9\"/></spectrum>\n\
               <spectrum type=\"irregular\" name=\"irr\"><string name=\"wavelengths\" value=\"400, 500, 700\"/>\
                 <string name=\"values\" value=\"0.1 0.5 0.9\"/></spectrum>\n\
             </emitter></scene>"
        ))
        .unwrap();
        let (b, e) = (child(&root, "b"), child(&root, "e"));
        let grey = |n: &Node, name: &str| match n.prop(name).unwrap().value {
            Value::Spectrum(v) => v,
            ref v => panic!("{name}: {v:?}"),
        };
        let rgb = |n: &Node, name: &str| match n.prop(name).unwrap().value {
            Value::Rgb(v) => v,
            ref v => panic!("{name}: {v:?}"),
        };
        assert_eq!(grey(&b, "reflectance"), 0.5);
        assert_eq!(grey(&b, "alpha"), 0.2);
        assert_eq!(rgb(&b, "specular_reflectance"), Vec3::new(0.1, 0.25, 0.4));
        assert_eq!(rgb(&b, "diffuse_reflectance"), Vec3::new(0.2, 0.5, 0.8));
        // unlike <spectrum value="0.5"/>, grey inside an emitter too
        assert_eq!(grey(&e, "u"), 0.5);
        assert_eq!(grey(&e, "d"), 1.0);
        for (name, mitsuba, tolerance) in [
            ("bb3000", [733.81726, 349.90588, 112.79073], 2e-3),
            ("bb6500", [36898.863, 44767.926, 20138.336], 6e-3),
            ("reg", [0.8730664, 0.4591739, 0.18145032], 2e-3),
            ("irr", [0.9188228, 0.5660357, 0.24179433], 2e-3),
        ] {
            let ours = rgb(&e, name);
            let err = (ours - Vec3::from(mitsuba)).abs() / Vec3::from(mitsuba);
            assert!(
                err.max_element() < tolerance,
                "{name}: {ours}, Mitsuba {mitsuba:?}"
            );
        }
    }

    #[test]
    fn spectra_become_rgb_as_in_mitsuba() {
        // expected values: Mitsuba 3.9.1 (scalar_rgb) loading the same XML
        let root = parse(&format!(
            "{HEAD}<bsdf type=\"diffuse\" id=\"b\">\n\
               <spectrum name=\"reflectance\" value=\"400:0.1, 500:0.5, 600:0.9\"/>\n\
               <spectrum name=\"eta\" value=\"400:1.5 500:0.5 700:0.2\"/>\n\
               <spectrum name=\"k\" value=\"3\"/>\n\
             </bsdf>\n\
             <emitter type=\"point\" id=\"e\">\n\
               <spectrum name=\"intensity\" value=\"400:1, 550:3, 700:2\"/>\n\
             </emitter>\n\
             <emitter type=\"constant\" id=\"c\">\n\
               <spectrum name=\"radiance\" value=\"5\"/>\n\
             </emitter></scene>"
        ))
        .unwrap();
        let b = child(&root, "b");
        let e = child(&root, "e");
        let rgb = |n: &Node, name: &str| match n.prop(name).unwrap().value {
            Value::Rgb(v) => v,
            ref v => panic!("{name}: {v:?}"),
        };
        let near =
            |a: Vec3, b: [f32; 3]| (a - Vec3::from(b)).abs().max_element() < 2e-4 * a.max_element();
        assert!(near(rgb(&b, "reflectance"), [0.223602, 0.711799, 0.274743]));
        assert!(near(rgb(&b, "eta"), [0.309274, 0.402677, 1.0235]));
        assert!(matches!(b.prop("k").unwrap().value, Value::Spectrum(v) if v == 3.0));
        assert!(near(rgb(&e, "intensity"), [3.08176, 2.70313, 1.40413]));
        // a constant on an emitter is a flat emission spectrum, not a grey
        assert!(near(
            rgb(&child(&root, "c"), "radiance"),
            [6.02397, 4.74146, 4.54458]
        ));
    }

    #[test]
    fn includes_are_spliced_and_checked() {
        let d = temp_dir("include");
        std::fs::create_dir_all(d.join("sub")).unwrap();
        std::fs::write(
            d.join("sub/materials.xml"),
            "<scene version=\"3.0.0\">\n  <bsdf type=\"diffuse\" id=\"mat\">\n\
             <rgb name=\"reflectance\" value=\"$refl\"/></bsdf>\n</scene>\n",
        )
        .unwrap();
        std::fs::write(d.join("sub/light.xml"), "<emitter type=\"constant\"/>\n").unwrap();
        let main = d.join("main.xml");
        std::fs::write(
            &main,
            "<scene version=\"3.0.0\">\n<default name=\"refl\" value=\"0.3\"/>\n\
             <include filename=\"sub/materials.xml\"/>\n\
             <shape type=\"sphere\" id=\"s\"><ref id=\"mat\"/></shape>\n\
             <include filename=\"sub/$inc.xml\"/>\n</scene>\n",
        )
        .unwrap();
        let root = parse_file(&main, &[("inc".to_string(), "light".to_string())]).unwrap();
        let mat = child(&root, "mat");
        assert_eq!(mat.loc.file, d.join("sub/materials.xml"));
        assert_eq!(mat.loc.line, 2);
        assert_eq!(mat.vec3_opt("reflectance").unwrap(), Some(Vec3::splat(0.3)));
        assert!(Rc::ptr_eq(&child(&child(&root, "s"), "bsdf"), &mat));
        assert_eq!(child(&root, "_unnamed_0").class, Class::Emitter);

        // a cycle: a.xml → b.xml → a.xml
        std::fs::write(
            d.join("a.xml"),
            "<scene version=\"3.0.0\">\n<include filename=\"b.xml\"/>\n</scene>\n",
        )
        .unwrap();
        std::fs::write(
            d.join("b.xml"),
            "<scene version=\"3.0.0\">\n\n<include filename=\"a.xml\"/>\n</scene>\n",
        )
        .unwrap();
        let e = parse_file(&d.join("a.xml"), &[]).unwrap_err().to_string();
        assert!(e.contains("b.xml:3:") && e.contains("include cycle"), "{e}");
        // a malformed included file is reported at its own line
        std::fs::write(d.join("bad.xml"), "<scene version=\"3.0.0\">\n<shape>\n").unwrap();
        let e = err(&format!(
            "{HEAD}<include filename=\"{}\"/></scene>",
            d.join("bad.xml").display()
        ));
        assert!(e.contains("bad.xml:") && e.contains("malformed XML"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn files_are_found_through_the_search_paths_as_in_mitsuba() {
        let d = temp_dir("paths");
        for sub in ["assets", "inc", "other"] {
            std::fs::create_dir_all(d.join(sub)).unwrap();
        }
        let scene = |body: &str| format!("<scene version=\"3.0.0\">\n{body}\n</scene>\n");
        let write = |name: &str, body: &str| std::fs::write(d.join(name), scene(body)).unwrap();
        std::fs::write(d.join("assets/mesh.obj"), "").unwrap();
        std::fs::write(d.join("other/o.obj"), "").unwrap();
        // the included file's own folder, then its includer's list (the
        // scene folder and the scene's paths)
        write(
            "inc/a.xml",
            "<path value=\"../other\"/>\n<include filename=\"b.xml\"/>\n\
             <include filename=\"c.xml\"/>\n<include filename=\"d.xml\"/>",
        );
        write("inc/b.xml", "<bsdf type=\"diffuse\" id=\"b\"/>");
        write("c.xml", "<bsdf type=\"diffuse\" id=\"c\"/>");
        write("assets/d.xml", "<bsdf type=\"diffuse\" id=\"d\"/>");
        write(
            "main.xml",
            "<path value=\"assets\"/>\n<include filename=\"inc/a.xml\"/>",
        );
        let desc = parse_file(&d.join("main.xml"), &[]).unwrap();
        for (id, file) in [("b", "inc/b.xml"), ("c", "c.xml"), ("d", "assets/d.xml")] {
            assert_eq!(child(&desc, id).loc.file, d.join(file));
        }
        // plugins search the main file's paths, then its folder; a <path>
        // of an included file only serves that file's <include>s
        assert_eq!(
            desc.resolver.resolve("mesh.obj"),
            Some(d.join("assets/mesh.obj"))
        );
        assert_eq!(desc.resolver.resolve("c.xml"), Some(d.join("c.xml")));
        assert_eq!(desc.resolver.resolve("o.obj"), None);

        write(
            "nested.xml",
            "<shape type=\"obj\">\n<path value=\"assets\"/></shape>",
        );
        let e = parse_file(&d.join("nested.xml"), &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nested.xml:3:") && e.contains("directly inside the file's <scene>"),
            "{e}"
        );
        write("missing.xml", "\n<path value=\"textures\"/>");
        let e = parse_file(&d.join("missing.xml"), &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("missing.xml:3:") && e.contains("<path value='textures'>: folder not found"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn refs_may_precede_the_declaration() {
        let root = parse(&format!(
            "{HEAD}<shape type=\"sphere\" id=\"s\"><ref id=\"m\"/></shape>\n\
             <shape type=\"sphere\" id=\"t\"><ref name=\"bsdf\" id=\"tex_user\"/></shape>\n\
             <bsdf type=\"diffuse\" id=\"m\"/>\n\
             <shape type=\"sphere\"><bsdf type=\"diffuse\" id=\"tex_user\">\n\
               <ref name=\"reflectance\" id=\"checks\"/></bsdf></shape>\n\
             <texture type=\"checkerboard\" id=\"checks\"/>\n\
             </scene>"
        ))
        .unwrap();
        let m = child(&root, "m");
        assert_eq!((m.key.as_str(), m.loc.line), ("m", 4));
        assert!(Rc::ptr_eq(&child(&child(&root, "s"), "bsdf"), &m));
        // a forward ref to an object nested in a later one, itself with a
        // forward ref
        let user = child(&child(&root, "t"), "bsdf");
        assert_eq!(user.key, "tex_user");
        assert!(Rc::ptr_eq(
            &child(&child(&root, "_unnamed_0"), "bsdf"),
            &user
        ));
        assert!(Rc::ptr_eq(
            &child(&user, "reflectance"),
            &child(&root, "checks")
        ));
        let names: Vec<&str> = root.props.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["s", "t", "m", "_unnamed_0", "checks"]);
    }

    #[test]
    fn files_of_older_versions_are_upgraded() {
        let root = parse(
            "<scene version=\"0.6.0\">\n\
             <integrator type=\"path\"><integer name=\"maxDepth\" value=\"3\"/></integrator>\n\
             <sensor type=\"perspective\"><string name=\"fovAxis\" value=\"x\"/>\n\
               <transform name=\"toWorld\"><translate z=\"5\"/></transform></sensor>\n\
             <shape type=\"sphere\"><bsdf type=\"dielectric\">\n\
               <float name=\"intIOR\" value=\"1.5\"/></bsdf></shape>\n\
             <bsdf type=\"diffuse\" id=\"d\"><texture type=\"bitmap\" name=\"diffuseReflectance\">\n\
               <float name=\"uscale\" value=\"2\"/><float name=\"voffset\" value=\"0.5\"/>\n\
             </texture></bsdf>\n\
             <bsdf type=\"roughconductor\" id=\"r\"><rgb name=\"diffuseReflectance\" value=\"1\"/></bsdf>\n\
             </scene>",
        )
        .unwrap();
        let integ = child(&root, "_unnamed_0");
        assert_eq!(integ.int("max_depth", 0).unwrap(), 3);
        let sensor = child(&root, "_unnamed_1");
        assert_eq!(sensor.string("fov_axis", "").unwrap(), "x");
        let t = sensor.transform("to_world").unwrap();
        assert!(close(t.point(Vec3::ZERO), Vec3::new(0.0, 0.0, 5.0)));
        let glass = child(&child(&root, "_unnamed_2"), "bsdf");
        assert_eq!(glass.float("int_ior", 0.0).unwrap(), 1.5);
        // diffuse's diffuseReflectance is its reflectance; the uv scale and
        // offset are a to_uv transform: translate, then scale
        let tex = child(&child(&root, "d"), "reflectance");
        assert!(!tex.has("uscale") && !tex.has("voffset"));
        let uv = tex.transform("to_uv").unwrap();
        assert!(close(uv.point(Vec3::ZERO), Vec3::new(0.0, 0.5, 0.0)));
        assert!(close(uv.point(Vec3::X), Vec3::new(2.0, 0.5, 0.0)));
        // renamed for diffuse only, as in Mitsuba
        assert!(child(&root, "r").has("diffuse_reflectance"));
        // from 2.0.0 on, names are kept
        let root = parse(
            "<scene version=\"2.1.0\"><integrator type=\"path\">\n\
             <integer name=\"maxDepth\" value=\"3\"/></integrator></scene>",
        )
        .unwrap();
        assert!(child(&root, "_unnamed_0").has("maxDepth"));
    }

    /// Each entry: (scene text, line of the error, words the message must contain).
    #[test]
    fn bad_inputs_give_located_messages() {
        let cases: &[(&str, u32, &[&str])] = &[
            (
                "<scene version=\"3.0.0\">\n<shape type=\"sphere\">\n</scene>",
                3,
                &["malformed XML"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"sphere\">\n<bdsf type=\"diffuse\"/>\n</shape></scene>",
                3,
                &["unknown tag <bdsf>", "valid tags", "bsdf"],
            ),
            ("<scene version=\"3.0.0\">\n\n<shape/></scene>", 3, &["<shape>", "'type'"]),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"diffuse\">\n<float value=\"1\"/></bsdf></scene>",
                3,
                &["<float>", "'name'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n\n<float name=\"alpha\"/></bsdf></scene>",
                4,
                &["alpha", "'value'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<float name='alpha' value='abc'/></bsdf></scene>",
                3,
                &["expected a number for <float name='alpha'>, found 'abc'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<rgb name='refl' value='0.1, 0.2'/></bsdf></scene>",
                3,
                &["<rgb name='refl'>", "1 or 3", "found 2"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\">\n<point name='center' value='1 2'/></shape></scene>",
                3,
                &["<point name='center'>", "expected 3 numbers"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<float name='a' valeu='1'/></bsdf></scene>",
                3,
                &["unknown attribute 'valeu'", "<float name='a'>"],
            ),
            (
                "<scene version=\"3.0.0\">\n<sampler type=\"x\">\n<integer name='sample_count' value='$spp'/></sampler></scene>",
                3,
                &["undefined variable '$spp'", "<default name=\"spp\"", "-D spp="],
            ),
            ("<scene>\n</scene>", 1, &["'version'", "Mitsuba 3"]),
            ("\n<scene version=\"2.0\">\n</scene>", 2, &["invalid scene version '2.0'"]),
            ("<scene version=\"banana\">\n</scene>", 1, &["invalid scene version 'banana'"]),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum name='eta' value='500:1.5, 400:1.4'/></bsdf></scene>",
                3,
                &["<spectrum name='eta'>", "wavelengths must increase, found 400 after 500"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum name='r' value='400:0.5, 500'/></bsdf></scene>",
                3,
                &["<spectrum name='r'>", "expected wavelength:value pairs, found '500'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<emitter type=\"x\">\n<spectrum type='blackbody' name='radiance'/></emitter></scene>",
                3,
                &["spectrum 'blackbody'", "missing required parameter 'temperature'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<emitter type=\"x\">\n<spectrum type='blackbody' name='radiance'>\n<float name='temperature' value='3000'/>\n<float name='scale' value='2'/></spectrum></emitter></scene>",
                5,
                &["spectrum 'blackbody'", "unknown parameter 'scale'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum type='srgb' name='reflectance'>\n<rgb name='color' value='1.5, 0.2, 0.2'/></spectrum></bsdf></scene>",
                4,
                &["parameter 'color'", "must lie in [0, 1]"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum type='irregular' name='reflectance'>\n<string name='wavelengths' value='400, 500'/>\n<string name='values' value='0.1, 0.5, 3'/></spectrum></bsdf></scene>",
                5,
                &["parameter 'values'", "3 values for 2 wavelengths"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum type='regular' name='reflectance'>\n<float name='wavelength_min' value='400'/>\n<string name='values' value='0.1, 0.5'/></spectrum></bsdf></scene>",
                3,
                &["spectrum 'regular'", "missing required parameter 'wavelength_max'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum type='cie1931' name='reflectance'/></bsdf></scene>",
                3,
                &["unknown spectrum plugin 'cie1931'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum name='r' filename='r.csv'/></bsdf></scene>",
                3,
                &["'r.csv' must be an .spd file"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<spectrum name='r' filename='missing.spd'/></bsdf></scene>",
                3,
                &["spectrum file 'missing.spd' not found"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><transform name='to_world'>\n<matrix value='1 0 0 0 0 1 0 0 0 0 0 0 0 0 0 1'/>\n</transform></shape></scene>",
                3,
                &["<matrix>", "singular"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><transform name='to_world'>\n<matrix value='1 0 0 0 0 1 0 0'/>\n</transform></shape></scene>",
                3,
                &["16", "9", "found 8"],
            ),
            (
                "<scene version=\"3.0.0\">\n<sensor type=\"x\"><transform name='to_world'>\n\n<lookat origin='0,0,1' target='0,0,0' up='0,0,1'/>\n</transform></sensor></scene>",
                4,
                &["degenerate <lookat>"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\" id=\"red\"/>\n<shape type=\"y\">\n<ref id=\"blue\"/></shape></scene>",
                4,
                &["'blue'", "ids declared: red", "check the spelling"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\" id=\"red\"/>\n<shape type=\"y\" id=\"red\"/></scene>",
                3,
                &["duplicate id 'red'", "t.xml:2"],
            ),
            (
                "<scene version=\"3.0.0\">\n<integrator type=\"x\">\n<integer name='max_depth' value='3.5'/></integrator></scene>",
                3,
                &["expected an integer for <integer name='max_depth'>, found '3.5'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<film type=\"x\">\n<boolean name='banner' value='yes'/></film></scene>",
                3,
                &["true or false", "banner", "'yes'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><transform name='to_world'>\n<rotate x='1'/>\n</transform></shape></scene>",
                3,
                &["<rotate>", "'angle'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><transform name='to_world'>\n<rotate angle='3'/>\n</transform></shape></scene>",
                3,
                &["<rotate>", "non-zero axis"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\">\n<translate x='1'/></shape></scene>",
                3,
                &["<translate>", "inside <transform"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><transform name='to_world'>\n<shear x='1'/>\n</transform></shape></scene>",
                3,
                &["unknown tag <shear>", "translate, rotate, scale, matrix, lookat"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><transform name='to_world'>\n<scale x='0'/>\n</transform></shape></scene>",
                3,
                &["<scale>", "singular"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\">\n<scene version=\"3.0.0\"/></shape></scene>",
                3,
                &["<scene> cannot be nested"],
            ),
            (
                "<scene version=\"3.0.0\">\n<bsdf type=\"x\">\n<float name='a' value='1'/>\n<float name='a' value='2'/></bsdf></scene>",
                4,
                &["parameter 'a' is given twice", "t.xml:3"],
            ),
            (
                "<scene version=\"3.0.0\">\n\n<include filename=\"nope/missing.xml\"/></scene>",
                3,
                &["cannot read included file 'nope/missing.xml'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\" idd=\"y\"/></scene>",
                2,
                &["unknown attribute 'idd'", "type, id, name"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><point name='p' value='1,2,3' x='1'/></shape></scene>",
                2,
                &["either 'value' or 'x'/'y'/'z'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<shape type=\"x\"><float name='r' value='inf'/></shape></scene>",
                2,
                &["expected a number", "'inf'"],
            ),
            (
                "<scene version=\"3.0.0\">\n<default name=\"spp\"/></scene>",
                2,
                &["<default name='spp'>", "'value'"],
            ),
            ("<shape type=\"sphere\"/>", 1, &["root element is <shape>"]),
        ];
        assert!(cases.len() >= 15);
        for (text, line, needles) in cases {
            let e = err(text);
            let prefix = format!("t.xml:{line}:");
            assert!(
                e.starts_with(&prefix),
                "expected '{prefix}' in: {e}\nfor:\n{text}"
            );
            for n in *needles {
                assert!(e.contains(n), "expected '{n}' in: {e}\nfor:\n{text}");
            }
        }
    }

    #[test]
    fn bad_scene_files_name_file_and_line() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_scenes");
        let cases: &[(&str, u32, &str)] = &[
            ("malformed.xml", 6, "malformed XML"),
            ("unknown_tag.xml", 5, "unknown tag <bdsf>"),
            ("missing_include.xml", 4, "does_not_exist.xml"),
            ("undefined_variable.xml", 6, "'$spp'"),
            ("bad_number.xml", 5, "found 'abc'"),
            ("invalid_version.xml", 3, "invalid scene version '2.0'"),
            ("unknown_ref.xml", 6, "'blue'"),
        ];
        for (file, line, needle) in cases {
            let p = dir.join(file);
            let e = parse_file(&p, &[]).unwrap_err().to_string();
            let prefix = format!("{}:{line}:", p.display());
            assert!(e.starts_with(&prefix), "expected '{prefix}' in: {e}");
            assert!(e.contains(needle), "expected '{needle}' in: {e}");
        }
        let e = parse_file(&dir.join("no_such_scene.xml"), &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no_such_scene.xml") && e.contains("cannot read"),
            "{e}"
        );
    }
}
