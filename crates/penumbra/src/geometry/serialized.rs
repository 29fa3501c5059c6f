//! Mitsuba's `.serialized` mesh files (the format of Mitsuba 0.x, read by
//! Mitsuba 3's `serialized` plugin and still common in published scenes).
//!
//! A file holds one or more indexed triangle meshes, little endian. Each
//! shape starts with an uncompressed header, the format identifier
//! `0x041C` (u16) and the version (u16, 3 or 4), followed by a zlib stream
//! holding:
//! - a u32 of flags: [`HAS_NORMALS`], [`HAS_TEXCOORDS`], [`HAS_COLORS`],
//!   [`DOUBLE_PRECISION`] (else single precision), and 0x0010, documented
//!   as "use face normals" but ignored by Mitsuba 3 (its renders with and
//!   without it are identical), so ignored here too;
//! - version 4 only: the shape's name, UTF-8, null-terminated;
//! - the vertex count and the triangle count (u64 each);
//! - positions (xyz per vertex), then normals (xyz), texture coordinates
//!   (uv) and vertex colours (rgb) when their flags are set, as f32 or f64;
//! - the triangles' vertex indices, u32 (u64 above 2³² vertices).
//!
//! The file ends with a dictionary: the byte offset of every shape's header
//! (u64 in version 4, u32 in version 3), then the number of shapes (u32).
//! The first shape is at offset 0; the others are found through the
//! dictionary (`shape_index`).
//!
//! Vertex colours become the mesh attribute `vertex_color` (3 channels,
//! values as stored), which the `mesh_attribute` texture reads, as PLY
//! colours are read. Mitsuba 3.9.1 reads past them instead: its
//! `serialized` plugin has no `vertex_color` attribute, and a
//! `mesh_attribute` texture naming it fails when rendered ("Invalid
//! attribute requested vertex_color"). Penumbra renders such files.

use crate::error::{Error, Result};
use crate::geometry::mesh::{MeshAttribute, MeshData};
use flate2::read::ZlibDecoder;
use glam::{Vec2, Vec3};
use std::io::Read;
use std::path::Path;

/// The format identifier that starts every shape.
pub const MAGIC: u16 = 0x041C;
/// Flag: per-vertex normals follow the positions.
pub const HAS_NORMALS: u32 = 0x0001;
/// Flag: per-vertex texture coordinates follow.
pub const HAS_TEXCOORDS: u32 = 0x0002;
/// Flag: per-vertex colours follow.
pub const HAS_COLORS: u32 = 0x0008;
/// Flag: vertex data is f64 (else f32).
pub const DOUBLE_PRECISION: u32 = 0x2000;

/// One shape of a `.serialized` file, in object space, not yet validated.
#[derive(Debug)]
pub struct SerializedShape {
    pub data: MeshData,
    /// The name stored in the file (version 4; empty in version 3).
    pub name: String,
}

/// Reads shape `shape_index` of a `.serialized` file.
pub fn load_serialized(path: &Path, shape_index: usize) -> Result<SerializedShape> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e))?;
    read_serialized(&bytes, shape_index).map_err(|m| {
        Error::file(
            path,
            format!("not a valid Mitsuba .serialized mesh file: {m}"),
        )
    })
}

/// Reads shape `shape_index` from the bytes of a whole `.serialized` file;
/// errors are plain messages.
pub fn read_serialized(
    bytes: &[u8],
    shape_index: usize,
) -> std::result::Result<SerializedShape, String> {
    let version = header(bytes, 0)?;
    let start = if shape_index == 0 {
        0
    } else {
        shape_offset(bytes, version, shape_index)?
    };
    if start != 0 {
        let v = header(bytes, start)?;
        if v != version {
            return Err(format!(
                "shape {shape_index} has version {v}, the file version {version}"
            ));
        }
    }
    let mut z = Fields {
        inner: ZlibDecoder::new(&bytes[start + 4..]),
    };
    let flags = z.u32()?;
    let mut name = Vec::new();
    if version == 4 {
        loop {
            match z.bytes::<1>()?[0] {
                0 => break,
                c => name.push(c),
            }
        }
    }
    let vertex_count = z.u64()?;
    let face_count = z.u64()?;
    if vertex_count > u32::MAX as u64 {
        return Err(format!(
            "{vertex_count} vertices; Penumbra's meshes hold at most 2^32 - 1"
        ));
    }
    let (nv, nf) = (vertex_count as usize, face_count as usize);
    let double = flags & DOUBLE_PRECISION != 0;
    let positions = z.reals(nv * 3, double, "vertex positions")?;
    let normals = if flags & HAS_NORMALS != 0 {
        Some(z.reals(nv * 3, double, "vertex normals")?)
    } else {
        None
    };
    let texcoords = if flags & HAS_TEXCOORDS != 0 {
        Some(z.reals(nv * 2, double, "texture coordinates")?)
    } else {
        None
    };
    let mut attributes = Vec::new();
    if flags & HAS_COLORS != 0 {
        attributes.push(MeshAttribute {
            name: "vertex_color".into(),
            channels: 3,
            per_face: false,
            data: z.reals(nv * 3, double, "vertex colors")?,
        });
    }
    let mut faces = Vec::with_capacity(nf.min(1 << 20));
    for _ in 0..nf {
        let mut f = [0u32; 3];
        for i in &mut f {
            *i = u32::from_le_bytes(z.bytes().map_err(|e| format!("{e} in the triangles"))?);
        }
        faces.push(f);
    }
    let vec3s = |v: Vec<f32>| v.chunks_exact(3).map(Vec3::from_slice).collect();
    Ok(SerializedShape {
        data: MeshData {
            positions: vec3s(positions),
            normals: normals.map(vec3s),
            texcoords: texcoords.map(|t| t.chunks_exact(2).map(Vec2::from_slice).collect()),
            faces,
            attributes,
        },
        name: String::from_utf8_lossy(&name).into_owned(),
    })
}

/// Checks the shape header at `at` and returns its version.
fn header(bytes: &[u8], at: usize) -> std::result::Result<u16, String> {
    let h = bytes
        .get(at..at + 4)
        .ok_or_else(|| format!("truncated: no shape header at byte {at}"))?;
    let magic = u16::from_le_bytes([h[0], h[1]]);
    if magic != MAGIC {
        return Err(format!(
            "wrong format identifier 0x{magic:04X} at byte {at} (expected 0x{MAGIC:04X})"
        ));
    }
    match u16::from_le_bytes([h[2], h[3]]) {
        v @ (3 | 4) => Ok(v),
        v => Err(format!("unsupported version {v} (Mitsuba writes 3 or 4)")),
    }
}

/// The byte offset of shape `index` from the dictionary at the file's end.
fn shape_offset(bytes: &[u8], version: u16, index: usize) -> std::result::Result<usize, String> {
    let n = bytes.len();
    let tail = |from: usize, len: usize| -> std::result::Result<&[u8], String> {
        bytes
            .get(from..from + len)
            .ok_or_else(|| "truncated: the shape dictionary at the end is cut off".to_string())
    };
    let count = u32::from_le_bytes(tail(n.saturating_sub(4), 4)?.try_into().unwrap()) as usize;
    if index >= count {
        return Err(format!(
            "shape_index {index} is out of range: the file holds {count} shape{} (0..{})",
            if count == 1 { "" } else { "s" },
            count.saturating_sub(1)
        ));
    }
    let offset = if version == 4 {
        let at = (n - 4)
            .checked_sub(8 * (count - index))
            .ok_or("truncated: the shape dictionary at the end is cut off")?;
        u64::from_le_bytes(tail(at, 8)?.try_into().unwrap())
    } else {
        let at = (n - 4)
            .checked_sub(4 * (count - index))
            .ok_or("truncated: the shape dictionary at the end is cut off")?;
        u32::from_le_bytes(tail(at, 4)?.try_into().unwrap()) as u64
    };
    if offset >= n as u64 {
        return Err(format!(
            "the dictionary puts shape {index} at byte {offset}, past the end ({n} bytes)"
        ));
    }
    Ok(offset as usize)
}

/// Little-endian fields of a decompressed shape.
struct Fields<R: Read> {
    inner: R,
}

impl<R: Read> Fields<R> {
    fn bytes<const N: usize>(&mut self) -> std::result::Result<[u8; N], String> {
        let mut b = [0u8; N];
        self.inner.read_exact(&mut b).map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => "truncated (the data ends early)".to_string(),
            _ => format!("corrupt compressed data ({e})"),
        })?;
        Ok(b)
    }
    fn u32(&mut self) -> std::result::Result<u32, String> {
        self.bytes().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> std::result::Result<u64, String> {
        self.bytes().map(u64::from_le_bytes)
    }
    /// `n` reals, f64 (`double`) or f32, as f32. Reads as it goes rather
    /// than trusting the count for one allocation: a corrupt count then
    /// ends in "truncated", not in an allocation failure.
    fn reals(
        &mut self,
        n: usize,
        double: bool,
        what: &str,
    ) -> std::result::Result<Vec<f32>, String> {
        let mut v = Vec::with_capacity(n.min(1 << 22));
        for _ in 0..n {
            let x = if double {
                self.bytes().map(|b| f64::from_le_bytes(b) as f32)
            } else {
                self.bytes().map(f32::from_le_bytes)
            };
            v.push(x.map_err(|e| format!("{e} in the {what}"))?);
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::write::ZlibEncoder;
    use std::io::Write;

    /// One shape of `version` with `flags`: a triangle, or a quad with
    /// normals and uvs when `HAS_NORMALS | HAS_TEXCOORDS` are set.
    fn shape(version: u16, flags: u32, name: &str) -> Vec<u8> {
        let quad = flags & HAS_NORMALS != 0;
        let positions: &[[f64; 3]] = if quad {
            &[
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ]
        } else {
            &[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.5]]
        };
        let faces: &[[u32; 3]] = if quad {
            &[[0, 1, 2], [0, 2, 3]]
        } else {
            &[[0, 1, 2]]
        };
        let mut body = flags.to_le_bytes().to_vec();
        if version == 4 {
            body.extend(name.as_bytes());
            body.push(0);
        }
        body.extend((positions.len() as u64).to_le_bytes());
        body.extend((faces.len() as u64).to_le_bytes());
        let mut reals = |v: f64| {
            if flags & DOUBLE_PRECISION != 0 {
                body.extend(v.to_le_bytes())
            } else {
                body.extend((v as f32).to_le_bytes())
            }
        };
        positions.iter().flatten().for_each(|&c| reals(c));
        if quad {
            (0..4).for_each(|_| [0.0, 0.0, 1.0].iter().for_each(|&c| reals(c)));
            positions
                .iter()
                .for_each(|p| [p[0], p[1]].iter().for_each(|&c| reals(c)));
        }
        if flags & HAS_COLORS != 0 {
            // vertex i has colour (0.1 i, 0.2, 0.5 + 0.1 i)
            (0..positions.len()).for_each(|i| {
                [0.1 * i as f64, 0.2, 0.5 + 0.1 * i as f64]
                    .iter()
                    .for_each(|&c| reals(c))
            });
        }
        faces
            .iter()
            .flatten()
            .for_each(|i| body.extend(i.to_le_bytes()));
        let mut z = ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&body).unwrap();
        let mut out = MAGIC.to_le_bytes().to_vec();
        out.extend(version.to_le_bytes());
        out.extend(z.finish().unwrap());
        out
    }

    /// Shapes concatenated, then the dictionary of `version`.
    fn file(version: u16, shapes: &[Vec<u8>]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut offsets = Vec::new();
        for s in shapes {
            offsets.push(out.len());
            out.extend(s);
        }
        for o in offsets {
            if version == 4 {
                out.extend((o as u64).to_le_bytes());
            } else {
                out.extend((o as u32).to_le_bytes());
            }
        }
        out.extend((shapes.len() as u32).to_le_bytes());
        out
    }

    #[test]
    fn shapes_are_found_through_the_dictionary_in_both_versions() {
        for version in [3, 4] {
            let f = file(
                version,
                &[
                    shape(version, 0x1000, "tri"),
                    shape(
                        version,
                        HAS_NORMALS | HAS_TEXCOORDS | DOUBLE_PRECISION,
                        "quad",
                    ),
                    shape(version, HAS_COLORS, "coloured"),
                    shape(version, HAS_COLORS | DOUBLE_PRECISION, "coloured64"),
                ],
            );
            let tri = read_serialized(&f, 0).unwrap();
            assert_eq!(tri.data.positions[2], Vec3::new(0.0, 3.0, 0.5));
            assert_eq!(tri.data.faces, vec![[0, 1, 2]]);
            assert!(tri.data.normals.is_none() && tri.data.texcoords.is_none());
            assert_eq!(tri.name, if version == 4 { "tri" } else { "" });
            let quad = read_serialized(&f, 1).unwrap();
            assert_eq!(quad.data.faces, vec![[0, 1, 2], [0, 2, 3]]);
            assert_eq!(quad.data.normals.unwrap()[3], Vec3::Z);
            assert_eq!(quad.data.texcoords.unwrap()[2], Vec2::new(1.0, 1.0));
            assert!(quad.data.attributes.is_empty());
            for index in [2, 3] {
                let coloured = read_serialized(&f, index).unwrap();
                assert_eq!(coloured.data.faces, vec![[0, 1, 2]]);
                let [c] = coloured.data.attributes.as_slice() else {
                    panic!("one attribute: {:?}", coloured.data.attributes)
                };
                assert_eq!(
                    (c.name.as_str(), c.channels, c.per_face),
                    ("vertex_color", 3, false)
                );
                let want: Vec<f32> = (0..3)
                    .flat_map(|i| [0.1 * i as f32, 0.2, 0.5 + 0.1 * i as f32])
                    .collect();
                for (a, b) in c.data.iter().zip(&want) {
                    assert!((a - b).abs() < 1e-7, "{:?} vs {want:?}", c.data);
                }
            }
        }
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let good = file(4, &[shape(4, 0, "a"), shape(4, 0, "b")]);
        let e = read_serialized(&good, 2).unwrap_err();
        assert!(
            e.contains("shape_index 2 is out of range") && e.contains("2 shapes (0..1)"),
            "{e}"
        );
        let mut magic = good.clone();
        magic[0] = 0x42;
        let e = read_serialized(&magic, 0).unwrap_err();
        assert!(e.contains("wrong format identifier 0x0442"), "{e}");
        let mut version = good.clone();
        version[2] = 7;
        let e = read_serialized(&version, 0).unwrap_err();
        assert!(e.contains("unsupported version 7"), "{e}");
        let one = shape(4, 0, "a");
        for cut in [2, 10, one.len() - 6] {
            let e = read_serialized(&one[..cut], 0).unwrap_err();
            assert!(e.contains("truncated"), "cut at {cut}: {e}");
        }
        let e = read_serialized(&good[..good.len() - 2], 1).unwrap_err();
        assert!(e.contains("out of range") || e.contains("truncated"), "{e}");
    }

    #[test]
    fn load_names_the_file() {
        let path = std::env::temp_dir().join(format!(
            "penumbra_serialized_{}.serialized",
            std::process::id()
        ));
        std::fs::write(&path, [0x1C, 0x04, 4, 0, 1, 2]).unwrap();
        let e = load_serialized(&path, 0).unwrap_err().to_string();
        std::fs::remove_file(&path).ok();
        assert!(
            e.contains(&path.display().to_string()) && e.contains(".serialized mesh file"),
            "{e}"
        );
    }
}
