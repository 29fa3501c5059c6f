//! Stanford PLY mesh loading (ascii, binary little and big endian) with
//! the `ply-rs-bw` crate.
//!
//! Vertices: `x y z` (any scalar type), optional normals `nx ny nz`,
//! optional texture coordinates `u v` (also `s t`, `texture_u texture_v`,
//! `texture_s texture_t`), used as stored (Mitsuba's convention for PLY).
//! Faces: a list property `vertex_indices` (or `vertex_index`) of any
//! integer type; polygons with more than three vertices are split into a
//! triangle fan (a quad `0 1 2 3` gives `0 1 2` and `0 2 3`).
//!
//! Other scalar properties of vertices and faces become mesh attributes
//! named as Mitsuba 3 names them (its `ply` plugin): `r g b [a]` or
//! `red green blue [alpha]` form `vertex_color` / `face_color`; runs of
//! consecutive properties `<prefix>_<c>` with the suffixes `x y z w`,
//! `r g b a`, `0 1 2 3` or `1 2 3 4` form `vertex_<prefix>` (1 or 3 of
//! them; `vertex_<prefix>_color` for `r g b`). Values are kept as stored,
//! integers included: Mitsuba 3.9 does not rescale a `uchar` colour to
//! [0, 1] (it warns), so neither do we. A face attribute of a polygon is
//! repeated on each triangle of its fan. Other elements and properties are
//! ignored, with a warning for properties Mitsuba would warn about.

use crate::error::{Error, Result};
use crate::geometry::mesh::{MeshAttribute, MeshData};
use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    BeginList, ElementDef, Property, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType,
};
use std::path::Path;

/// Slots: x y z nx ny nz u v; `extra`: the other scalar properties in
/// header order (the parser sets them in that order).
#[derive(Default)]
struct PlyVertex {
    v: [f32; 8],
    extra: Vec<f32>,
}

fn vertex_slot(name: &str) -> Option<usize> {
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "nx" => 3,
        "ny" => 4,
        "nz" => 5,
        "u" | "s" | "texture_u" | "texture_s" => 6,
        "v" | "t" | "texture_v" | "texture_t" => 7,
        _ => return None,
    })
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        Self::default()
    }
    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match vertex_slot(name) {
            Some(i) => self.v[i] = value,
            None => self.extra.push(value),
        }
        PropertyAccessResult::Set
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.set_float(name, value as f32)
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        match p.to_f32_lossy() {
            Some(v) => self.set_float(name, v),
            None => PropertyAccessResult::Ignored,
        }
    }
}

#[derive(Default)]
struct PlyFace {
    signed: Vec<i32>,
    unsigned: Vec<u32>,
    other: Option<Vec<i64>>,
    /// The scalar properties in header order.
    extra: Vec<f32>,
}

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        Self::default()
    }
    fn begin_list_int(&mut self, name: &str, _len: usize) -> BeginList<'_, i32> {
        if is_index_list(name) {
            BeginList::Fill(&mut self.signed)
        } else {
            BeginList::UseSetter
        }
    }
    fn begin_list_uint(&mut self, name: &str, _len: usize) -> BeginList<'_, u32> {
        if is_index_list(name) {
            BeginList::Fill(&mut self.unsigned)
        } else {
            BeginList::UseSetter
        }
    }
    fn set_float(&mut self, _name: &str, value: f32) -> PropertyAccessResult {
        self.extra.push(value);
        PropertyAccessResult::Set
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.set_float(name, value as f32)
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        if let Some(v) = p.to_f32_lossy() {
            return self.set_float(name, v);
        }
        if !is_index_list(name) {
            return PropertyAccessResult::Ignored;
        }
        let list: Option<Vec<i64>> = match p {
            Property::ListChar(v) => Some(v.iter().map(|&x| x as i64).collect()),
            Property::ListUChar(v) => Some(v.iter().map(|&x| x as i64).collect()),
            Property::ListShort(v) => Some(v.iter().map(|&x| x as i64).collect()),
            Property::ListUShort(v) => Some(v.iter().map(|&x| x as i64).collect()),
            Property::ListInt(v) => Some(v.iter().map(|&x| x as i64).collect()),
            Property::ListUInt(v) => Some(v.iter().map(|&x| x as i64).collect()),
            _ => None,
        };
        match list {
            Some(l) => {
                self.other = Some(l);
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

impl PlyFace {
    fn indices(&self) -> Vec<i64> {
        if let Some(o) = &self.other {
            o.clone()
        } else if !self.signed.is_empty() {
            self.signed.iter().map(|&x| x as i64).collect()
        } else {
            self.unsigned.iter().map(|&x| x as i64).collect()
        }
    }
}

/// Ignores every property (elements other than vertex and face).
struct PlySkip;
impl PropertyAccess for PlySkip {
    fn new() -> Self {
        PlySkip
    }
}

/// Reads a PLY file into object-space mesh data (not yet validated).
pub fn load_ply(path: &Path) -> Result<MeshData> {
    let file = std::fs::File::open(path).map_err(|e| Error::file(path, e))?;
    let (data, notes) =
        read_ply(std::io::BufReader::new(file)).map_err(|m| Error::file(path, m))?;
    for n in notes {
        crate::warn(format!("{}: {n}", path.display()));
    }
    Ok(data)
}

/// Where an attribute's channels are among an element's extra values.
struct AttributeLayout {
    name: String,
    columns: Vec<usize>,
}

/// Groups the extra scalar properties of an element (`(name, is integer)`
/// in header order) into attributes named `<kind>_...` the way Mitsuba 3's
/// PLY loader does; `notes` gets a warning for each property it ignores
/// and each integer colour.
fn group_attributes(
    kind: &str,
    props: &[(String, bool)],
    notes: &mut Vec<String>,
) -> Vec<AttributeLayout> {
    let pos = |n: &str| props.iter().position(|(p, _)| p == n);
    let mut out = Vec::new();
    let mut reserved: Vec<&str> = vec!["r", "g", "b", "a"];
    let colour = [["r", "g", "b", "a"], ["red", "green", "blue", "alpha"]]
        .into_iter()
        .find(|names| names[..3].iter().all(|n| pos(n).is_some()));
    if let Some(names) = colour {
        reserved.extend(names);
        let columns: Vec<usize> = names.iter().filter_map(|n| pos(n)).collect();
        let name = format!("{kind}_color");
        if props[columns[0]].1 {
            notes.push(format!(
                "mesh attribute '{name}' has integer values, used as stored \
                 (as Mitsuba 3 does); colours are expected in [0, 1]"
            ));
        }
        out.push(AttributeLayout { name, columns });
    }
    // Mitsuba's suffix categories: column k of row j is the j-th suffix of
    // category k.
    const SUFFIXES: [&[u8; 4]; 4] = [b"xr01", b"yg12", b"zb23", b"wa34"];
    let mut seen: Vec<String> = Vec::new();
    // (prefix, category, columns) of the run being read
    let mut run: Option<(String, usize, Vec<usize>)> = None;
    let flush = |run: &mut Option<(String, usize, Vec<usize>)>,
                 out: &mut Vec<AttributeLayout>,
                 seen: &mut Vec<String>,
                 notes: &mut Vec<String>| {
        let Some((prefix, category, columns)) = run.take() else {
            return;
        };
        seen.push(prefix.clone());
        let name = format!(
            "{kind}_{prefix}{}",
            if category == 1 { "_color" } else { "" }
        );
        if columns.len() == 1 || columns.len() == 3 {
            out.push(AttributeLayout { name, columns });
        } else {
            notes.push(format!(
                "attribute '{name}' has {} values; attributes need 1 or 3, ignored",
                columns.len()
            ));
        }
    };
    for (i, (name, _)) in props.iter().enumerate() {
        if reserved.contains(&name.as_str()) {
            continue;
        }
        let split = name.rsplit_once('_').filter(|(_, s)| s.len() == 1);
        let Some((prefix, suffix)) = split else {
            notes.push(format!(
                "{kind} property '{name}' has no one-letter suffix (as in 'name_x'), ignored"
            ));
            flush(&mut run, &mut out, &mut seen, notes);
            continue;
        };
        let c = suffix.as_bytes()[0];
        if run.as_ref().is_some_and(|(p, _, _)| p != prefix) {
            flush(&mut run, &mut out, &mut seen, notes);
        }
        match &mut run {
            Some((_, category, columns)) => {
                if columns.len() < 4 && SUFFIXES[columns.len()][*category] == c {
                    columns.push(i);
                } else {
                    notes.push(format!(
                        "{kind} property '{name}' breaks the suffix sequence of its attribute, \
                         which is ignored"
                    ));
                    seen.push(prefix.to_string());
                    run = None;
                }
            }
            None if seen.iter().any(|p| p == prefix) => {
                notes.push(format!(
                    "{kind} property '{name}': attribute '{prefix}' was already read, ignored"
                ));
            }
            None => match SUFFIXES[0].iter().position(|&s| s == c) {
                Some(category) => run = Some((prefix.to_string(), category, vec![i])),
                None => notes.push(format!(
                    "{kind} property '{name}': an attribute cannot start with suffix '{suffix}', ignored"
                )),
            },
        }
    }
    flush(&mut run, &mut out, &mut seen, notes);
    out
}

/// The names of an element's scalar properties other than `reserved`
/// ones, in header order, each with whether it is an integer.
fn extra_scalars(element: &ElementDef, reserved: impl Fn(&str) -> bool) -> Vec<(String, bool)> {
    element
        .properties
        .iter()
        .filter_map(|(name, p)| match &p.data_type {
            PropertyType::Scalar(t) if !reserved(name) => Some((
                name.clone(),
                !matches!(t, ScalarType::Float | ScalarType::Double),
            )),
            _ => None,
        })
        .collect()
}

/// The attributes `layouts` gathers from each element's extra values,
/// each element repeated `repeat(element)` times.
fn gather(
    layouts: Vec<AttributeLayout>,
    extras: &[&[f32]],
    repeat: impl Fn(usize) -> usize,
    per_face: bool,
) -> Vec<MeshAttribute> {
    layouts
        .into_iter()
        .map(|l| {
            let mut data = Vec::with_capacity(extras.len() * l.columns.len());
            for (e, values) in extras.iter().enumerate() {
                for _ in 0..repeat(e) {
                    data.extend(l.columns.iter().map(|&c| values[c]));
                }
            }
            MeshAttribute {
                name: l.name,
                channels: l.columns.len(),
                per_face,
                data,
            }
        })
        .collect()
}

/// Reads PLY data from any buffered reader, with the warnings to show;
/// errors are plain messages.
pub fn read_ply<T: std::io::BufRead>(
    input: T,
) -> std::result::Result<(MeshData, Vec<String>), String> {
    let mut notes = Vec::new();
    let mut reader = Reader::new(input);
    let vparser = Parser::<PlyVertex>::new();
    let fparser = Parser::<PlyFace>::new();
    let sparser = Parser::<PlySkip>::new();
    let header = vparser
        .read_header(&mut reader)
        .map_err(|e| format!("invalid PLY header: {e}"))?;
    let mut data = MeshData::default();
    let mut got_vertices = false;
    for (name, element) in &header.elements {
        match name.as_str() {
            "vertex" => {
                let has = |n: &str| element.properties.contains_key(n);
                for c in ["x", "y", "z"] {
                    if !has(c) {
                        return Err(format!("the vertex element has no '{c}' property"));
                    }
                }
                let normals = has("nx") && has("ny") && has("nz");
                let uvs = ["u", "s", "texture_u", "texture_s"].iter().any(|n| has(n))
                    && ["v", "t", "texture_v", "texture_t"].iter().any(|n| has(n));
                let layouts = group_attributes(
                    "vertex",
                    &extra_scalars(element, |n| vertex_slot(n).is_some()),
                    &mut notes,
                );
                let verts = vparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| format!("while reading vertices: {e}"))?;
                let extras: Vec<&[f32]> = verts.iter().map(|v| &v.extra[..]).collect();
                data.attributes
                    .extend(gather(layouts, &extras, |_| 1, false));
                data.positions = verts
                    .iter()
                    .map(|v| Vec3::new(v.v[0], v.v[1], v.v[2]))
                    .collect();
                if normals {
                    data.normals = Some(
                        verts
                            .iter()
                            .map(|v| Vec3::new(v.v[3], v.v[4], v.v[5]))
                            .collect(),
                    );
                }
                if uvs {
                    data.texcoords =
                        Some(verts.iter().map(|v| Vec2::new(v.v[6], v.v[7])).collect());
                }
                got_vertices = true;
            }
            "face" => {
                if !element.properties.keys().any(|k| is_index_list(k)) {
                    return Err(
                        "the face element has no 'vertex_indices' (or 'vertex_index') list".into(),
                    );
                }
                let layouts =
                    group_attributes("face", &extra_scalars(element, |_| false), &mut notes);
                let faces = fparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| format!("while reading faces: {e}"))?;
                data.faces.reserve(faces.len());
                // triangles of each polygon's fan, for its face attributes
                let mut fan = Vec::with_capacity(faces.len());
                for (f, face) in faces.iter().enumerate() {
                    let idx = face.indices();
                    if idx.len() < 3 {
                        return Err(format!(
                            "face {f} has {} vertices; faces need at least 3",
                            idx.len()
                        ));
                    }
                    if let Some(&bad) = idx.iter().find(|&&i| i < 0 || i > u32::MAX as i64) {
                        return Err(format!("face {f} has an invalid vertex index {bad}"));
                    }
                    for k in 1..idx.len() - 1 {
                        data.faces
                            .push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
                    }
                    fan.push(idx.len() - 2);
                }
                let extras: Vec<&[f32]> = faces.iter().map(|f| &f.extra[..]).collect();
                data.attributes
                    .extend(gather(layouts, &extras, |f| fan[f], true));
            }
            _ => {
                sparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| format!("while reading element '{name}': {e}"))?;
            }
        }
    }
    if !got_vertices {
        return Err("the file has no vertex element".into());
    }
    Ok((data, notes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ascii_quad() -> String {
        "ply\nformat ascii 1.0\ncomment test\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float s\nproperty float t\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n"
            .to_string()
    }

    #[test]
    fn ascii_quad_is_split_and_st_are_uvs() {
        let (d, _) = read_ply(ascii_quad().as_bytes()).unwrap();
        assert_eq!(d.positions.len(), 4);
        assert_eq!(d.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(d.normals.is_none());
        let uv = d.texcoords.unwrap();
        assert_eq!(uv[2], Vec2::new(1.0, 1.0));
    }

    /// Names as Mitsuba 3.9.1 reads them from this header (checked with
    /// its `ply` plugin): `vertex_color` (uchar values kept as stored),
    /// `vertex_foo`, `face_weight`, `face_q_color`; `bar` ignored.
    #[test]
    fn attributes_are_named_and_grouped_as_mitsuba_does() {
        let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float foo_x\nproperty float bar\n\
element face 2\nproperty list uchar int vertex_indices\nproperty float weight_0\n\
property float q_r\nproperty float q_g\nproperty float q_b\nend_header\n\
0 0 0 255 128 0 0.5 7\n1 0 0 0 64 255 0.25 7\n0 1 0 10 20 30 1 7\n1 1 0 1 2 3 2 7\n\
3 0 1 2 0.7 0.1 0.2 0.3\n4 0 1 3 2 0.9 0.4 0.5 0.6\n";
        let (d, notes) = read_ply(ply.as_bytes()).unwrap();
        let get = |n: &str| d.attributes.iter().find(|a| a.name == n).unwrap();
        let c = get("vertex_color");
        assert_eq!((c.channels, c.per_face), (3, false));
        assert_eq!(&c.data[..6], &[255.0, 128.0, 0.0, 0.0, 64.0, 255.0]);
        assert_eq!(get("vertex_foo").data, vec![0.5, 0.25, 1.0, 2.0]);
        // the quad's values repeated on both triangles of its fan
        let w = get("face_weight");
        assert_eq!((w.channels, w.per_face), (1, true));
        assert_eq!(w.data, vec![0.7, 0.9, 0.9]);
        assert_eq!(
            get("face_q_color").data[3..],
            [0.4, 0.5, 0.6, 0.4, 0.5, 0.6]
        );
        assert_eq!(d.attributes.len(), 4);
        assert!(notes.iter().any(|n| n.contains("'bar'")), "{notes:?}");
        assert!(notes.iter().any(|n| n.contains("integer")), "{notes:?}");
    }

    fn binary(big: bool) -> Vec<u8> {
        let fmt = if big {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut b = format!(
            "ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float u\nproperty float v\nproperty uchar red\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n"
        )
        .into_bytes();
        let verts = [
            [0.0f32, 0.0, 0.0, 0.0, 0.0, 1.0, 0.1, 0.2],
            [2.0, 0.0, 0.5, 0.0, 0.0, 1.0, 0.3, 0.4],
            [0.0, 3.0, -1.0, 0.0, 0.0, 1.0, 0.5, 0.6],
        ];
        for v in verts {
            for x in v {
                b.extend(if big {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                });
            }
            b.push(7u8);
        }
        b.push(3);
        for i in [0u32, 1, 2] {
            b.extend(if big {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            });
        }
        b
    }

    #[test]
    fn binary_round_trip_both_endiannesses() {
        for big in [false, true] {
            let (d, _) = read_ply(&binary(big)[..]).unwrap();
            assert_eq!(d.positions[1], Vec3::new(2.0, 0.0, 0.5), "big={big}");
            assert_eq!(d.positions[2], Vec3::new(0.0, 3.0, -1.0));
            assert_eq!(d.normals.as_ref().unwrap()[2], Vec3::Z);
            assert_eq!(d.texcoords.as_ref().unwrap()[1], Vec2::new(0.3, 0.4));
            assert_eq!(d.faces, vec![[0, 1, 2]]);
        }
    }

    #[test]
    fn file_round_trip_and_errors() {
        let dir = std::env::temp_dir().join(format!("penumbra-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("quad.ply");
        std::fs::write(&p, ascii_quad()).unwrap();
        assert_eq!(load_ply(&p).unwrap().faces.len(), 2);
        let p2 = dir.join("bin.ply");
        std::fs::write(&p2, binary(false)).unwrap();
        assert_eq!(load_ply(&p2).unwrap().positions.len(), 3);
        // truncated binary payload
        let mut t = binary(true);
        t.truncate(t.len() - 6);
        std::fs::write(&p2, t).unwrap();
        let e = load_ply(&p2).unwrap_err().to_string();
        assert!(e.contains("bin.ply"), "{e}");
        let e = load_ply(&dir.join("missing.ply")).unwrap_err().to_string();
        assert!(e.contains("missing.ply"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
