//! Stanford PLY mesh loading (ascii, binary little and big endian) with
//! the `ply-rs-bw` crate.
//!
//! Vertices: `x y z` (any scalar type), optional normals `nx ny nz`,
//! optional texture coordinates `u v` (also `s t`, `texture_u texture_v`,
//! `texture_s texture_t`), used as stored (Mitsuba's convention for PLY).
//! Faces: a list property `vertex_indices` (or `vertex_index`) of any
//! integer type; polygons with more than three vertices are split into a
//! triangle fan (a quad `0 1 2 3` gives `0 1 2` and `0 2 3`). Other
//! elements and properties are ignored.

use crate::error::{Error, Result};
use crate::geometry::mesh::MeshData;
use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{BeginList, Property, PropertyAccess, PropertyAccessResult};
use std::path::Path;

/// Slots: x y z nx ny nz u v.
#[derive(Default)]
struct PlyVertex {
    v: [f32; 8],
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
            Some(i) => {
                self.v[i] = value;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.set_float(name, value as f32)
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        match (vertex_slot(name), p.to_f32_lossy()) {
            (Some(i), Some(v)) => {
                self.v[i] = v;
                PropertyAccessResult::Set
            }
            _ => PropertyAccessResult::Ignored,
        }
    }
}

#[derive(Default)]
struct PlyFace {
    signed: Vec<i32>,
    unsigned: Vec<u32>,
    other: Option<Vec<i64>>,
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
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
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
    read_ply(std::io::BufReader::new(file)).map_err(|m| Error::file(path, m))
}

/// Reads PLY data from any buffered reader; errors are plain messages.
pub fn read_ply<T: std::io::BufRead>(input: T) -> std::result::Result<MeshData, String> {
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
                let verts = vparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| format!("while reading vertices: {e}"))?;
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
                let faces = fparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| format!("while reading faces: {e}"))?;
                data.faces.reserve(faces.len());
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
                }
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
    Ok(data)
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
        let d = read_ply(ascii_quad().as_bytes()).unwrap();
        assert_eq!(d.positions.len(), 4);
        assert_eq!(d.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(d.normals.is_none());
        let uv = d.texcoords.unwrap();
        assert_eq!(uv[2], Vec2::new(1.0, 1.0));
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
            let d = read_ply(&binary(big)[..]).unwrap();
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
