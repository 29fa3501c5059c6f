//! Edge tables of triangle meshes: the edges across which the image of a
//! mesh can jump, for the boundary terms of visibility derivatives
//! (`crate::diff`, docs/architecture.md §1).
//!
//! Edges are found on WELDED vertices: vertices at bit-identical positions
//! are one vertex, so the duplicated vertices of uv or normal seams (a cube
//! with one normal per face, a sphere's uv seam) do not make the faces on
//! either side look like two meshes with boundary edges there. Counting a
//! seam as two boundary edges would count its boundary term twice (the
//! bias of Mitsuba's projective integrators on flat-shaded meshes with
//! seams, its issue #1895).
//!
//! Each undirected welded edge is listed once, with its faces, and
//! classified from the current positions and normals:
//! - [`EdgeKind::Boundary`]: one face (of non-zero area). The image jumps
//!   there wherever the edge is visible.
//! - [`EdgeKind::Sharp`]: two faces across which the shading can jump:
//!   without vertex normals (flat shading), faces that are not coplanar;
//!   with vertex normals, faces whose vertices at the edge carry different
//!   normals (a normal seam: the mesh asks for a crease there).
//! - [`EdgeKind::Smooth`]: two faces with continuous shading: the image
//!   jumps there only where the edge is a silhouette (both faces on the
//!   same side of the edge as seen from the camera), which depends on the
//!   viewpoint and is decided per render ([`EdgeTable::is_silhouette`]).
//! - [`EdgeKind::NonManifold`]: more than two faces. Whatever their
//!   arrangement, the boundary estimators measure the jump across the edge
//!   by tracing rays on both sides, so the edge is always a candidate and,
//!   listed once, is counted once: nothing is lost by not pairing its faces.
//! - [`EdgeKind::Inert`]: all faces have zero area now (never hit).
//!
//! Texture seams are assumed continuous (the texture agrees on both sides),
//! so a uv seam alone does not make an edge sharp.
//!
//! The table is built on first use (`Mesh::edges`) and from then on
//! refreshed when the positions change: the kinds are recomputed, and the
//! welding is redone if vertices that were welded no longer coincide (a
//! change of topology as the edges see it). Vertices that come to
//! coincide after the table was built stay distinct until then.

use crate::geometry::mesh::is_degenerate;
use glam::Vec3;
use rustc_hash::FxHashMap;

/// What an edge is (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeKind {
    Boundary,
    Sharp,
    Smooth,
    NonManifold,
    Inert,
}

/// One undirected welded edge.
#[derive(Clone, Copy, Debug)]
pub struct Edge {
    /// The first face of the edge and the corner `k` of that face where the
    /// edge starts: the edge runs from corner `k` to corner `(k + 1) % 3`
    /// of `faces[face]` (mesh vertex indices, so positions are read as the
    /// face reads them, derivatives included).
    pub face: u32,
    pub corner: u8,
    /// The second face, if any (`u32::MAX` if none); for a non-manifold
    /// edge, one of the others.
    pub other_face: u32,
    /// The vertex of `face` and of `other_face` opposite the edge (mesh
    /// vertex indices; `u32::MAX` without a second face).
    pub opposite: [u32; 2],
    /// Number of faces on the edge (≥ 1).
    pub face_count: u32,
    pub kind: EdgeKind,
}

impl Edge {
    /// The mesh vertex indices of the edge's endpoints.
    pub fn vertices(&self, faces: &[[u32; 3]]) -> [u32; 2] {
        let f = faces[self.face as usize];
        let k = self.corner as usize;
        [f[k], f[(k + 1) % 3]]
    }
}

/// The edges of a mesh (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct EdgeTable {
    /// The welded representative (lowest index at the same position) of
    /// every vertex.
    weld: Vec<u32>,
    pub edges: Vec<Edge>,
}

/// A position as a hashable key; −0 and +0 are one position.
fn position_key(p: Vec3) -> [u32; 3] {
    (p + Vec3::ZERO).to_array().map(f32::to_bits)
}

/// The world-space position of vertex `i` of a flat `[n, 3]` buffer.
fn position(positions: &[f32], i: u32) -> Vec3 {
    Vec3::from_slice(&positions[3 * i as usize..3 * i as usize + 3])
}

impl EdgeTable {
    /// The table of the mesh `faces` over the flat `[n, 3]` `positions`;
    /// `normals` are the vertex normals (flat `[n, 3]`), `None` for a
    /// flat-shaded mesh.
    pub fn new(faces: &[[u32; 3]], positions: &[f32], normals: Option<&[f32]>) -> EdgeTable {
        let mut table = EdgeTable::default();
        table.refresh(faces, positions, normals);
        table
    }

    /// Recomputes the kinds after the positions or normals changed; welds
    /// again first if welded vertices came apart (or on first use).
    pub fn refresh(&mut self, faces: &[[u32; 3]], positions: &[f32], normals: Option<&[f32]>) {
        let n = positions.len() / 3;
        let welded_apart = self.weld.len() != n
            || self.weld.iter().enumerate().any(|(i, &w)| {
                position_key(position(positions, i as u32)) != position_key(position(positions, w))
            });
        if welded_apart {
            self.build(faces, positions);
        }
        let live: Vec<bool> = faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| position(positions, i));
                !is_degenerate(a, b, c)
            })
            .collect();
        for e in &mut self.edges {
            e.kind = classify(e, faces, positions, normals, &live);
        }
    }

    /// Welds the vertices and lists every edge once with its faces.
    fn build(&mut self, faces: &[[u32; 3]], positions: &[f32]) {
        let n = positions.len() / 3;
        let mut first: FxHashMap<[u32; 3], u32> = FxHashMap::default();
        first.reserve(n);
        self.weld = (0..n as u32)
            .map(|i| {
                *first
                    .entry(position_key(position(positions, i)))
                    .or_insert(i)
            })
            .collect();
        // (welded endpoints, face, corner), sorted so that an edge's faces
        // are adjacent
        let mut half: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(3 * faces.len());
        for (f, face) in faces.iter().enumerate() {
            let w = face.map(|i| self.weld[i as usize]);
            // a face with two corners at one position has no edges (zero
            // area); if the corners come apart, the table is built again
            if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (w[k], w[(k + 1) % 3]);
                half.push((a.min(b), a.max(b), f as u32, k as u8));
            }
        }
        half.sort_unstable();
        self.edges = half
            .chunk_by(|x, y| (x.0, x.1) == (y.0, y.1))
            .map(|run| {
                let (_, _, f0, k0) = run[0];
                let opposite_of = |f: u32, k: u8| faces[f as usize][(k as usize + 2) % 3];
                let (other_face, opposite1) = match run.get(1) {
                    Some(&(_, _, f1, k1)) => (f1, opposite_of(f1, k1)),
                    None => (u32::MAX, u32::MAX),
                };
                Edge {
                    face: f0,
                    corner: k0,
                    other_face,
                    opposite: [opposite_of(f0, k0), opposite1],
                    face_count: run.len() as u32,
                    kind: EdgeKind::Inert,
                }
            })
            .collect();
    }

    /// Number of edges of each kind: (boundary, sharp, smooth, non-manifold,
    /// inert).
    pub fn counts(&self) -> [usize; 5] {
        let mut c = [0; 5];
        for e in &self.edges {
            c[e.kind as usize] += 1;
        }
        c
    }

    /// Whether the two faces of edge `e` lie on the same side of the edge
    /// as seen along the rays of a camera (`eye`: a position for a pinhole,
    /// a view direction for parallel rays): then the surface folds away
    /// from the viewer at the edge, and the edge is a silhouette. Decided
    /// from the faces' opposite vertices, so it does not depend on the
    /// faces' winding.
    pub fn is_silhouette(e: &Edge, faces: &[[u32; 3]], positions: &[f32], eye: Eye) -> bool {
        if e.other_face == u32::MAX {
            return true;
        }
        let [a, b] = e.vertices(faces).map(|i| position(positions, i));
        let m = match eye {
            Eye::Point(c) => (a - c).cross(b - c),
            Eye::Direction(d) => (b - a).cross(d),
        };
        let side = |i: u32| m.dot(position(positions, i) - a);
        side(e.opposite[0]) * side(e.opposite[1]) > 0.0
    }
}

impl EdgeTable {
    /// Whether the viewer (`eye`) looks into the fold of edge `e`: the
    /// opposite vertex of its second face lies on the viewer's side of the
    /// first face's plane. Radiance may jump across such an edge even when
    /// the shading is smooth (one face shadows the other), unlike across a
    /// convex smooth edge seen from outside.
    pub fn is_concave(e: &Edge, faces: &[[u32; 3]], positions: &[f32], eye: Eye) -> bool {
        if e.other_face == u32::MAX {
            return false;
        }
        let [a, b] = e.vertices(faces).map(|i| position(positions, i));
        let n = (b - a).cross(position(positions, e.opposite[0]) - a);
        let viewer = match eye {
            Eye::Point(c) => n.dot(c - a),
            Eye::Direction(d) => -n.dot(d),
        };
        viewer * n.dot(position(positions, e.opposite[1]) - a) > 0.0
    }
}

/// Where camera rays come from, for [`EdgeTable::is_silhouette`].
#[derive(Clone, Copy, Debug)]
pub enum Eye {
    /// All rays leave this point (pinhole).
    Point(Vec3),
    /// All rays are parallel to this direction (orthographic).
    Direction(Vec3),
}

fn classify(
    e: &Edge,
    faces: &[[u32; 3]],
    positions: &[f32],
    normals: Option<&[f32]>,
    live: &[bool],
) -> EdgeKind {
    if e.face_count > 2 {
        return EdgeKind::NonManifold;
    }
    let live0 = live[e.face as usize];
    let live1 = e.other_face != u32::MAX && live[e.other_face as usize];
    match (live0, live1) {
        (false, false) => return EdgeKind::Inert,
        (true, false) | (false, true) => return EdgeKind::Boundary,
        (true, true) => {}
    }
    let [a, b] = e.vertices(faces);
    let (pa, pb) = (position(positions, a), position(positions, b));
    match normals {
        None => {
            // coplanar if the second face's opposite vertex lies in the
            // plane of the first face (relative to the edge length: the
            // positions are f32)
            let p0 = position(positions, e.opposite[0]);
            let p1 = position(positions, e.opposite[1]);
            let n = (pb - pa).cross(p0 - pa).normalize_or_zero();
            let off = n.dot(p1 - pa).abs();
            let scale = (pb - pa).length().max((p1 - pa).length());
            if off > 1e-5 * scale {
                EdgeKind::Sharp
            } else {
                EdgeKind::Smooth
            }
        }
        Some(ns) => {
            // the second face's vertices at the edge's two positions
            let f1 = faces[e.other_face as usize];
            let key = |i: u32| position_key(position(positions, i));
            let normal_at = |i: u32| position(ns, i);
            let seam = [a, b].iter().any(|&v| {
                f1.iter()
                    .filter(|&&u| key(u) == key(v))
                    .any(|&u| u != v && normal_at(u).distance(normal_at(v)) > 1e-4)
            });
            if seam {
                EdgeKind::Sharp
            } else {
                EdgeKind::Smooth
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes::cube::cube_data;

    fn flat(v: &[Vec3]) -> Vec<f32> {
        v.iter().flat_map(|p| p.to_array()).collect()
    }

    #[test]
    fn flat_cube_has_twelve_sharp_edges_and_six_smooth_diagonals() {
        // the cube of the `cube` plugin has 24 vertices (4 per face):
        // welded, 8 corners and 18 edges
        let d = cube_data();
        let t = EdgeTable::new(&d.faces, &flat(&d.positions), None);
        assert_eq!(t.edges.len(), 18);
        assert_eq!(t.counts(), [0, 12, 6, 0, 0]);
        for e in t.edges.iter().filter(|e| e.kind == EdgeKind::Smooth) {
            // the diagonals: their endpoints differ in two coordinates
            let [a, b] = e
                .vertices(&d.faces)
                .map(|i| d.positions[i as usize] * 0.5 + 0.5);
            assert_eq!((a - b).abs().element_sum(), 2.0, "{a} {b}");
        }
    }

    #[test]
    fn cube_with_one_normal_per_face_has_normal_seams_at_its_twelve_edges() {
        let d = cube_data();
        let normals = flat(d.normals.as_ref().unwrap());
        let t = EdgeTable::new(&d.faces, &flat(&d.positions), Some(&normals));
        assert_eq!(t.counts(), [0, 12, 6, 0, 0]);
    }

    #[test]
    fn open_quad_has_four_boundary_edges() {
        let p = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let faces = [[0, 1, 2], [0, 2, 3]];
        let t = EdgeTable::new(&faces, &flat(&p), None);
        assert_eq!(t.counts(), [4, 0, 1, 0, 0]);
        // seen from above, the diagonal is no silhouette; every boundary
        // edge is one
        let eye = Eye::Point(Vec3::new(0.3, 0.4, 2.0));
        for e in &t.edges {
            assert_eq!(
                EdgeTable::is_silhouette(e, &faces, &flat(&p), eye),
                e.kind == EdgeKind::Boundary
            );
        }
    }

    /// A uv sphere with a duplicated seam column and duplicated poles, as
    /// mesh files have them.
    fn uv_sphere(rings: usize, segments: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..=segments {
                // the last column repeats the first (bit-identical), each
                // pole is repeated once per column
                let phi = std::f32::consts::TAU * (j % segments) as f32 / segments as f32;
                p.push(if i == 0 || i == rings {
                    Vec3::new(0.0, 0.0, theta.cos())
                } else {
                    Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    )
                });
            }
        }
        let idx = |i: usize, j: usize| (i * (segments + 1) + j) as u32;
        let mut f = Vec::new();
        for i in 0..rings {
            for j in 0..segments {
                let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
                if i > 0 {
                    f.push([a, b, d]);
                }
                if i + 1 < rings {
                    f.push([b, c, d]);
                }
            }
        }
        (p, f)
    }

    #[test]
    fn welded_uv_sphere_is_closed_and_smooth() {
        let (p, faces) = uv_sphere(8, 12);
        let normals = flat(&p);
        let t = EdgeTable::new(&faces, &flat(&p), Some(&normals));
        // closed: no boundary edge despite the seam and the poles;
        // Euler: V − E + F = 2 with V = 12·7 + 2
        let v = 12 * 7 + 2;
        assert_eq!(v as i64 - t.edges.len() as i64 + faces.len() as i64, 2);
        assert_eq!(t.counts(), [0, 0, t.edges.len(), 0, 0]);
        // flat-shaded, every edge is sharp but the diagonals of the
        // (planar) quads between two rings
        let t = EdgeTable::new(&faces, &flat(&p), None);
        let diagonals = 6 * 12;
        assert_eq!(t.counts(), [0, t.edges.len() - diagonals, diagonals, 0, 0]);
        // silhouettes from far away along +x: edges near the x = 0 circle
        let eye = Eye::Point(Vec3::new(100.0, 0.0, 0.0));
        let pos = flat(&p);
        let sil: Vec<&Edge> = t
            .edges
            .iter()
            .filter(|e| EdgeTable::is_silhouette(e, &faces, &pos, eye))
            .collect();
        assert!(!sil.is_empty());
        for e in sil {
            let [a, b] = e.vertices(&faces).map(|i| p[i as usize]);
            assert!(a.x.abs().min(b.x.abs()) < 0.3, "{a} {b}");
        }
    }

    #[test]
    fn refresh_follows_moved_positions() {
        let mut p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let faces = [[0, 1, 2], [0, 2, 3]];
        let mut t = EdgeTable::new(&faces, &flat(&p), None);
        // folding the quad makes its diagonal sharp
        p[3].z = 0.5;
        t.refresh(&faces, &flat(&p), None);
        assert_eq!(t.counts(), [4, 1, 0, 0, 0]);
        // collapsing a face leaves the other's edges as boundary, its own
        // inert
        p[3] = p[2];
        t.refresh(&faces, &flat(&p), None);
        assert_eq!(t.counts(), [3, 0, 0, 0, 2]);
    }

    #[test]
    fn non_manifold_edge_is_listed_once() {
        // three triangles on the edge (0, 1)
        let p = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.5, 1.0, 0.0),
            Vec3::new(0.5, -1.0, 0.0),
            Vec3::new(0.5, 0.0, 1.0),
        ];
        let faces = [[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let t = EdgeTable::new(&faces, &flat(&p), None);
        assert_eq!(t.edges.len(), 7);
        assert_eq!(t.counts(), [6, 0, 0, 1, 0]);
    }
}
