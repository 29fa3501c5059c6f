//! Triangle meshes whose vertex data lives in the [`ParamStore`], so that
//! vertex positions (and normals, texture coordinates) are differentiable.
//!
//! Parameters (Mitsuba's `traverse()` names):
//! - `<key>.vertex_positions`: `[n, 3]`, world space (`to_world` applied at
//!   load), flags [`ParamFlags::GEOMETRY`], domain [`Domain::Finite`];
//! - `<key>.vertex_normals`: `[n, 3]`, world space, unit length, flags
//!   [`ParamFlags::SHADING_FRAME`] (no edge moves, frames turn), if the
//!   file has normals or they were computed (not with `face_normals`);
//! - `<key>.vertex_texcoords`: `[n, 2]`, if the file has uvs;
//! - `<key>.to_world`: `[4, 4]`, row-major, geometry: the transform the
//!   vertices are placed by (not a Mitsuba mesh parameter: Penumbra's way
//!   to move or optimise a whole mesh rigidly). Setting it moves the
//!   vertices and normals by the change from the previous value.
//!
//! Faces (topology) are not parameters: they stay in the mesh.
//!
//! Degenerate input that Mitsuba renders is accepted, with one warning per
//! mesh that counts what was skipped ([`SkippedFaces`]):
//! - faces that repeat a vertex index, and faces that repeat another face
//!   (the same three vertices, in any order or orientation), are removed at
//!   load: they are degenerate whatever the positions become (a repeated
//!   face would double the area that emitter sampling sees there);
//! - faces of three distinct vertices with zero area (coincident or
//!   collinear positions) are kept, because a later update of the vertex
//!   positions may give them an area; while their area is zero, they are
//!   never hit, never sampled and add nothing to the vertex normals (see
//!   [`is_degenerate`]), so they render as nothing, as in Mitsuba.
//!
//! Vertices are never renumbered: `vertex_positions` keeps the file's
//! vertex order and count. Edges shared by more than two faces
//! (non-manifold) are rendered as they are, with a warning: nothing in the
//! renderer relies on manifoldness (the edge table treats such an edge as
//! one junction, see [`crate::geometry::edges`]).

use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::geometry::edges::EdgeTable;
use crate::geometry::{DiffRay, Hit, PositionSample, ShapeT, SurfaceInteraction, SurfacePoint};
use crate::math::{warp, DiscreteDistribution, Frame, Transform, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use glam::{Vec2, Vec3};
use rdst::RadixSort;
use std::sync::OnceLock;

/// Mesh data as read from a file (object space), before validation.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub texcoords: Option<Vec<Vec2>>,
    pub faces: Vec<[u32; 3]>,
    /// Extra per-vertex or per-face values (vertex colours...).
    pub attributes: Vec<MeshAttribute>,
}

/// A named per-vertex or per-face attribute as read from a file:
/// `channels` values per vertex (or face), row-major.
#[derive(Clone, Debug)]
pub struct MeshAttribute {
    /// Mitsuba's name: `vertex_<name>` or `face_<name>`.
    pub name: String,
    pub channels: usize,
    pub per_face: bool,
    pub data: Vec<f32>,
}

/// A mesh attribute in the parameter store, `<key>.<name>` shaped
/// `[n, channels]` (Mitsuba's traverse key for it), read by the
/// `mesh_attribute` texture.
#[derive(Clone, Debug)]
pub struct AttributeParam {
    pub name: String,
    pub id: ParamId,
    pub channels: usize,
    pub per_face: bool,
}

/// Options of the mesh plugins (`ply`, `obj`, `rectangle`, `cube`).
#[derive(Clone, Copy, Debug, Default)]
pub struct MeshOptions {
    /// Flat shading: no vertex normals, the shading normal is the geometric one.
    pub face_normals: bool,
    /// Inverts geometric and shading normals.
    pub flip_normals: bool,
}

/// Faces of a mesh file that [`Mesh::new`] skipped (see the module
/// documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SkippedFaces {
    /// Faces of zero area at load: those with a repeated vertex index
    /// (removed) and those whose positions are coincident or collinear
    /// (kept, ignored while their area is zero).
    pub zero_area: usize,
    /// Faces with the same three vertices as an earlier face (removed).
    pub duplicate: usize,
}

/// A triangle mesh (see the module documentation for its parameters).
#[derive(Clone, Debug)]
pub struct Mesh {
    /// Plugin name (`ply`, `obj`, `rectangle`, `cube`).
    pub plugin: &'static str,
    /// Parameter-key prefix (the shape's id).
    pub key: String,
    /// Where the data came from (file path or plugin), for messages.
    pub source: String,
    pub faces: Vec<[u32; 3]>,
    pub positions: ParamId,
    pub normals: Option<ParamId>,
    pub texcoords: Option<ParamId>,
    /// Boxed slice rather than Vec: keeps `Shape::Mesh` from outgrowing
    /// the other shape variants (clippy's large_enum_variant).
    pub attributes: Box<[AttributeParam]>,
    /// `<key>.to_world` (`[4, 4]`, row-major): the transform the vertices
    /// were placed by; setting it moves them (and the normals) by the
    /// change, and its derivative moves them likewise.
    pub to_world_id: ParamId,
    /// The transform the stored vertices are placed by now (boxed: the
    /// shape enum stays small).
    to_world: Box<Transform>,
    pub face_normals: bool,
    pub flip_normals: bool,
    /// What was skipped at load (reported once, as a warning).
    pub skipped: SkippedFaces,
    /// Number of edges shared by more than two faces (rendered as they are).
    pub non_manifold_edges: usize,
    /// Triangle selection by area for [`ShapeT::sample_position`].
    area_distr: DiscreteDistribution,
    /// Set when the mesh is two triangles of equal area sharing an edge
    /// (a `rectangle`, a quad light read from a file): positions are then
    /// sampled without the area distribution.
    quad: Option<QuadSampling>,
    area: f32,
    /// Faces around each vertex, for the derivatives of vertex normals that
    /// follow the positions (empty without vertex normals).
    vertex_faces: VertexFaces,
    /// Unit geometric normal per face (flipped with `flip_normals`; zero
    /// for a degenerate face) and twice its area, derived from the
    /// positions with the area table (f32, not differentiated: used by
    /// position sampling and f32 hits).
    face_n: Vec<Vec3>,
    face_area2: Vec<f32>,
    /// The welded edges and their kinds, built on first use by
    /// [`Mesh::edges`] (only the boundary terms of visibility derivatives
    /// read them, and welding a large mesh costs more than its area table)
    /// and, once built, refreshed with the areas (boxed: the shape enum
    /// stays small).
    edges: OnceLock<Box<EdgeTable>>,
}

impl Mesh {
    /// Validates `data`, applies `to_world` (positions; normals by the
    /// inverse transpose), computes smooth vertex normals when the data has
    /// none and `face_normals` is off, and registers the vertex buffers in
    /// `store` under `key`.
    ///
    /// Errors (naming `source` and the face or vertex): empty mesh,
    /// non-finite values, face index out of range, no face of non-zero
    /// area. Zero-area and duplicate faces and non-manifold edges are
    /// accepted with one warning (see the module documentation).
    pub fn new(
        plugin: &'static str,
        key: &str,
        source: &str,
        mut data: MeshData,
        to_world: &Transform,
        opts: MeshOptions,
        store: &mut ParamStore,
    ) -> Result<Mesh> {
        let err = |msg: String| Error::Invalid(format!("{source}: {msg}"));
        if data.positions.is_empty() || data.faces.is_empty() {
            return Err(err(format!(
                "empty mesh ({} vertices, {} faces); a shape needs at least one triangle",
                data.positions.len(),
                data.faces.len()
            )));
        }
        for (i, p) in data.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(err(format!("vertex {i} has a non-finite position {p}")));
            }
        }
        if let Some(ns) = &data.normals {
            if ns.len() != data.positions.len() {
                return Err(err(format!(
                    "{} normals for {} vertices",
                    ns.len(),
                    data.positions.len()
                )));
            }
            if let Some(i) = ns.iter().position(|n| !n.is_finite()) {
                return Err(err(format!("vertex {i} has a non-finite normal {}", ns[i])));
            }
        }
        if let Some(uv) = &data.texcoords {
            if uv.len() != data.positions.len() {
                return Err(err(format!(
                    "{} texture coordinates for {} vertices",
                    uv.len(),
                    data.positions.len()
                )));
            }
            if let Some(i) = uv.iter().position(|t| !t.is_finite()) {
                return Err(err(format!(
                    "vertex {i} has non-finite texture coordinates {}",
                    uv[i]
                )));
            }
        }
        let nv = data.positions.len();
        for a in &data.attributes {
            let n = if a.per_face { data.faces.len() } else { nv };
            if a.data.len() != n * a.channels {
                return Err(err(format!(
                    "attribute '{}' has {} values for {n} {} of {} channels",
                    a.name,
                    a.data.len(),
                    if a.per_face { "faces" } else { "vertices" },
                    a.channels
                )));
            }
            if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
                return Err(err(format!(
                    "attribute '{}' has a non-finite value at {}",
                    a.name,
                    i / a.channels
                )));
            }
        }
        for (f, face) in data.faces.iter().enumerate() {
            if let Some(&bad) = face.iter().find(|&&i| i as usize >= nv) {
                return Err(err(format!(
                    "face {f} refers to vertex {bad}, but the mesh has {nv} vertices"
                )));
            }
        }
        // to world space
        for p in data.positions.iter_mut() {
            *p = to_world.point(*p);
            if !p.is_finite() {
                return Err(err("to_world maps a vertex to a non-finite position".into()));
            }
        }
        if let Some(ns) = data.normals.as_mut() {
            for n in ns.iter_mut() {
                *n = to_world.normal(*n).normalize_or_zero();
            }
        }
        let n_read = data.faces.len();
        let (skipped, kept) = remove_degenerate_faces(&mut data.faces, &data.positions);
        for a in data.attributes.iter_mut().filter(|a| a.per_face) {
            let c = a.channels;
            a.data = kept
                .iter()
                .flat_map(|&f| a.data[f * c..(f + 1) * c].iter().copied())
                .collect();
        }
        let non_manifold_edges = count_non_manifold_edges(&data.faces);
        let mut notes = Vec::new();
        if skipped.zero_area > 0 {
            notes.push(format!("{} zero-area", skipped.zero_area));
        }
        if skipped.duplicate > 0 {
            notes.push(format!("{} duplicate", skipped.duplicate));
        }
        let mut msg = Vec::new();
        if !notes.is_empty() {
            msg.push(format!(
                "skipped {} of {n_read} faces (they render as nothing, as in Mitsuba)",
                notes.join(" and ")
            ));
        }
        if non_manifold_edges > 0 {
            msg.push(format!(
                "{non_manifold_edges} edges are shared by more than two faces (non-manifold); rendered as they are"
            ));
        }
        if !msg.is_empty() {
            crate::warn(format!("{source}: {}", msg.join("; ")));
        }

        let opts_normals = if opts.face_normals {
            None
        } else {
            Some(match data.normals.take() {
                Some(n) => n,
                None => vertex_normals(&data.positions, &data.faces),
            })
        };

        let flat3 = |v: &[Vec3]| v.iter().flat_map(|p| p.to_array()).collect::<Vec<f32>>();
        let positions = store.add(
            format!("{key}.vertex_positions"),
            flat3(&data.positions),
            vec![nv, 3],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        let normals = match opts_normals {
            Some(n) => Some(store.add(
                format!("{key}.vertex_normals"),
                flat3(&n),
                vec![nv, 3],
                ParamFlags::SHADING_FRAME,
                Domain::Finite,
            )?),
            None => None,
        };
        let to_world_id = store.add(
            format!("{key}.to_world"),
            to_world.m.transpose().to_cols_array().to_vec(),
            vec![4, 4],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        let texcoords = match &data.texcoords {
            Some(uv) => Some(store.add(
                format!("{key}.vertex_texcoords"),
                uv.iter().flat_map(|t| t.to_array()).collect(),
                vec![nv, 2],
                ParamFlags::DIFFERENTIABLE,
                Domain::Finite,
            )?),
            None => None,
        };
        let attributes = data
            .attributes
            .into_iter()
            .map(|a| {
                let n = a.data.len() / a.channels;
                let id = store.add(
                    format!("{key}.{}", a.name),
                    a.data,
                    vec![n, a.channels],
                    ParamFlags::DIFFERENTIABLE,
                    Domain::Finite,
                )?;
                Ok(AttributeParam {
                    name: a.name,
                    id,
                    channels: a.channels,
                    per_face: a.per_face,
                })
            })
            .collect::<Result<Box<[_]>>>()?;
        let vertex_faces = if normals.is_some() {
            VertexFaces::new(nv, &data.faces)
        } else {
            VertexFaces::default()
        };
        let mut mesh = Mesh {
            to_world_id,
            to_world: Box::new(*to_world),
            vertex_faces,
            plugin,
            key: key.to_string(),
            source: source.to_string(),
            faces: data.faces,
            positions,
            normals,
            texcoords,
            attributes,
            face_normals: opts.face_normals,
            flip_normals: opts.flip_normals,
            skipped,
            non_manifold_edges,
            area_distr: DiscreteDistribution::default(),
            quad: None,
            area: 0.0,
            face_n: Vec::new(),
            face_area2: Vec::new(),
            edges: OnceLock::new(),
        };
        mesh.update_areas(store)?;
        Ok(mesh)
    }

    /// Number of triangles.
    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// Number of vertices.
    pub fn vertex_count(&self, store: &ParamStore) -> usize {
        store.data(self.positions).len() / 3
    }

    /// World-space vertex `i` (f32).
    #[inline(always)]
    pub fn vertex(&self, store: &ParamStore, i: u32) -> Vec3 {
        let i = 3 * i as usize;
        // one bounds check for the three coordinates
        Vec3::from_slice(&store.data(self.positions)[i..i + 3])
    }

    /// The three world-space vertices of triangle `f` (f32).
    #[inline(always)]
    pub fn triangle(&self, store: &ParamStore, f: usize) -> [Vec3; 3] {
        let [a, b, c] = self.faces[f];
        [
            self.vertex(store, a),
            self.vertex(store, b),
            self.vertex(store, c),
        ]
    }

    /// Whether triangle `f` currently has zero area (see [`is_degenerate`]):
    /// it is then never hit nor sampled.
    pub fn face_is_degenerate(&self, f: usize) -> bool {
        self.face_n[f] == Vec3::ZERO
    }

    fn update_areas(&mut self, store: &ParamStore) -> Result<()> {
        let (areas, normals): (Vec<f32>, Vec<Vec3>) = (0..self.faces.len())
            .map(|f| {
                let [p0, p1, p2] = self.triangle(store, f);
                if is_degenerate(p0, p1, p2) {
                    (0.0, Vec3::ZERO)
                } else {
                    let c = (p1 - p0).as_dvec3().cross((p2 - p0).as_dvec3());
                    let n = c.normalize().as_vec3();
                    let n = if self.flip_normals { -n } else { n };
                    (0.5 * c.length() as f32, n)
                }
            })
            .unzip();
        self.face_area2 = areas.iter().map(|a| 2.0 * a).collect();
        self.face_n = normals;
        self.area_distr = DiscreteDistribution::new(&areas).ok_or_else(|| {
            Error::Invalid(format!(
                "{}: every face of the mesh has zero area; a shape needs at least one triangle",
                self.source
            ))
        })?;
        self.area = self.area_distr.sum() as f32;
        self.quad = QuadSampling::new(&self.faces, &areas);
        if let Some(edges) = self.edges.get_mut() {
            let normals = self.normals.map(|id| store.data(id));
            edges.refresh(&self.faces, store.data(self.positions), normals);
        }
        Ok(())
    }

    /// The welded edges and their kinds at the positions and normals of
    /// `store` (built on the first call, kept up to date by
    /// [`Mesh::parameters_changed`] from then on).
    pub fn edges(&self, store: &ParamStore) -> &EdgeTable {
        self.edges.get_or_init(|| {
            let normals = self.normals.map(|id| store.data(id));
            Box::new(EdgeTable::new(
                &self.faces,
                store.data(self.positions),
                normals,
            ))
        })
    }

    /// Refreshes what depends on the vertex positions after `changed`
    /// parameters were updated: the area table, and (as Mitsuba does) the
    /// vertex normals, recomputed from the positions unless the normals were
    /// updated too.
    pub fn parameters_changed(
        &mut self,
        store: &mut ParamStore,
        changed: &[ParamId],
    ) -> Result<()> {
        let transformed = changed.contains(&self.to_world_id);
        if transformed {
            self.apply_to_world_change(store)?;
        }
        if !changed.contains(&self.positions) && !transformed {
            return Ok(());
        }
        if let Some(nid) = self.normals {
            if !changed.contains(&nid) && !transformed {
                let d = store.data(self.positions);
                let pos: Vec<Vec3> = d.chunks_exact(3).map(Vec3::from_slice).collect();
                let n = vertex_normals(&pos, &self.faces);
                let flat: Vec<f32> = n.iter().flat_map(|v| v.to_array()).collect();
                let key = store.get(nid).key.clone();
                // (this marks the normals dirty too; harmless: they are
                // read through the store at every hit)
                store.set(&key, &flat)?;
            }
        }
        self.update_areas(store)
    }

    /// Moves the vertices (and normals) by the change from the transform
    /// they were placed by to the new value of `<key>.to_world`.
    fn apply_to_world_change(&mut self, store: &mut ParamStore) -> Result<()> {
        let key = store.get(self.to_world_id).key.clone();
        let rows = store.data(self.to_world_id);
        let new = Transform::new(glam::Mat4::from_cols_slice(rows).transpose())
            .filter(|t| t.m.determinant().abs() > 0.0)
            .ok_or_else(|| Error::Param {
                key: key.clone(),
                msg: "the transform is not invertible".into(),
            })?;
        let change = new.after(&self.to_world.inverse());
        let moved: Vec<f32> = store
            .data(self.positions)
            .chunks_exact(3)
            .flat_map(|p| change.point(Vec3::from_slice(p)).to_array())
            .collect();
        let positions_key = store.get(self.positions).key.clone();
        store.set(&positions_key, &moved)?;
        if let Some(nid) = self.normals {
            let turned: Vec<f32> = store
                .data(nid)
                .chunks_exact(3)
                .flat_map(|n| {
                    change
                        .normal(Vec3::from_slice(n))
                        .normalize_or_zero()
                        .to_array()
                })
                .collect();
            let normals_key = store.get(nid).key.clone();
            store.set(&normals_key, &turned)?;
        }
        *self.to_world = new;
        Ok(())
    }

    /// The change of `to_world` along its tangent (rows 0–2, value zero),
    /// if reads of it carry derivatives in `R`.
    fn to_world_tangent<R: ScalarReal>(&self, store: &ParamView) -> Option<[[R; 4]; 3]> {
        if !R::tracks(store, self.to_world_id) {
            return None;
        }
        Some(std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                let i = 4 * r + c;
                store.read::<R>(self.to_world_id, i) - store.value(self.to_world_id, i)
            })
        }))
    }

    /// Geometric normal of triangle `f` (unit, flipped if `flip_normals`;
    /// zero for a degenerate face).
    pub fn face_normal(&self, store: &ParamStore, f: usize) -> Vec3 {
        let [p0, p1, p2] = self.triangle(store, f);
        let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        if self.flip_normals {
            -n
        } else {
            n
        }
    }

    /// The vertex indices and positions (in `R`) of triangle `prim`.
    #[inline(always)]
    pub(crate) fn triangle_r<R: ScalarReal>(
        &self,
        store: &ParamView,
        prim: u32,
    ) -> ([usize; 3], [V3<R>; 3]) {
        let [i0, i1, i2] = self.faces[prim as usize];
        let idx = [i0 as usize, i1 as usize, i2 as usize];
        let ps = idx.map(|i| store.read3(self.positions, i));
        match self.to_world_tangent::<R>(store) {
            // p = M(θ) q with q = M⁻¹ p the object-space point
            Some(dm) => (
                idx,
                ps.map(|p| {
                    let q = self.to_world.inv.transform_point3(p.val());
                    let row = |r: [R; 4]| r[0] * q.x + r[1] * q.y + r[2] * q.z + r[3];
                    p + V3::new(row(dm[0]), row(dm[1]), row(dm[2]))
                }),
            ),
            None => (idx, ps),
        }
    }

    /// Differentiable re-evaluation of a ray hit on triangle `hit.prim`,
    /// the point sliding along `ray` (whose origin and direction may carry
    /// derivatives): Möller–Trumbore (Möller and Trumbore 1997, "Fast,
    /// Minimum Storage Ray/Triangle Intersection") in `R` from the vertex
    /// positions read through the store.
    pub fn triangle_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let (idx, [p0, p1, p2]) = self.triangle_r::<R>(store, hit.prim);
        let (o, d) = (ray.o, ray.d);
        let (t, b1, b2, p) = if !R::DIFFERENTIABLE {
            // The traversal's own solve gives the barycentrics; the point
            // is interpolated from them (as Mitsuba does), so it lies on
            // the triangle whatever origin offset the traced ray had.
            let (b1, b2) = (R::cst(hit.uv.x), R::cst(hit.uv.y));
            let p = p0 * (R::cst(1.0) - b1 - b2) + p1 * b1 + p2 * b2;
            ((p - o).dot(d), b1, b2, p)
        } else {
            // solved again in R for the derivatives of t and the
            // barycentrics: the point slides along the ray
            let e1 = p1 - p0;
            let e2 = p2 - p0;
            let pvec = d.cross(e2);
            let det = e1.dot(pvec);
            let (t, b1, b2) = if det.val() != 0.0 && det.is_finite() {
                let inv = det.recip();
                let tvec = o - p0;
                let qvec = tvec.cross(e1);
                (e2.dot(qvec) * inv, tvec.dot(pvec) * inv, d.dot(qvec) * inv)
            } else {
                (R::cst(hit.t), R::cst(hit.uv.x), R::cst(hit.uv.y))
            };
            (t, b1, b2, o + d * t)
        };
        let mut si = self.local_geometry(store, hit, idx, [p0, p1, p2], b1, b2, p, t);
        si.wi = si.to_local(-d);
        si
    }

    /// The point and geometric normal of the hit (primal), as
    /// [`Mesh::triangle_interaction`] computes them in f32: the point
    /// interpolated at the traversal's barycentrics, the face's normal.
    pub fn triangle_point_primal(&self, store: &ParamView, hit: &Hit) -> SurfacePoint {
        let (_, [p0, p1, p2]) = self.triangle_r::<f32>(store, hit.prim);
        let (b1, b2) = (hit.uv.x, hit.uv.y);
        let p = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
        SurfacePoint {
            p: p.val(),
            n: self.face_n[hit.prim as usize],
        }
    }

    /// The texture coordinates at barycentrics `b` = (b1, b2) of triangle
    /// `prim` (primal): interpolated from the mesh's, or `b` itself where
    /// it has none (as [`Mesh::triangle_interaction`]).
    #[inline]
    pub(crate) fn uv_primal(&self, store: &ParamStore, prim: u32, b: Vec2) -> Vec2 {
        let Some(tid) = self.texcoords else {
            return b;
        };
        let t = store.data(tid);
        let tc = |i: u32| Vec2::from_slice(&t[2 * i as usize..2 * i as usize + 2]);
        let [i0, i1, i2] = self.faces[prim as usize];
        tc(i0) * (1.0 - b.x - b.y) + tc(i1) * b.x + tc(i2) * b.y
    }

    /// The point of [`ShapeT::sample_position`] for `u`: its triangle,
    /// barycentrics, position and normal, without the uv the lanes' light
    /// samples do not read.
    #[inline(always)]
    pub(crate) fn sample_point(&self, store: &ParamStore, u: Vec2) -> (usize, Vec2, Vec3, Vec3) {
        let (f, b) = match &self.quad {
            Some(quad) => quad.sample(u),
            None => {
                let (f, _, ux) = self.area_distr.sample_reuse(u.x);
                (f, warp::square_to_uniform_triangle(Vec2::new(ux, u.y)))
            }
        };
        let [p0, p1, p2] = self.triangle(store, f);
        let b0 = 1.0 - b.x - b.y;
        (f, b, p0 * b0 + p1 * b.x + p2 * b.y, self.face_n[f])
    }

    /// The corners of triangle `prim` as the path tracer in lanes reads
    /// them for a primal hit (it interpolates them itself, many hits at
    /// once): the positions, the shading normals at the corners (the
    /// vertex normals, or the face normal where the mesh has none), and the
    /// face normal, both oriented as [`Mesh::triangle_interaction`] orients
    /// them (with `flip_normals`).
    #[inline(always)]
    pub(crate) fn corners_primal(
        &self,
        store: &ParamStore,
        prim: u32,
    ) -> ([Vec3; 3], [Vec3; 3], Vec3) {
        let face = self.faces[prim as usize];
        let read = |id: ParamId, i: u32| Vec3::from_slice(&store.data(id)[3 * i as usize..]);
        let n = self.face_n[prim as usize];
        let ns = match self.normals {
            Some(nid) => {
                let ns = face.map(|i| read(nid, i));
                if self.flip_normals {
                    ns.map(|v| -v)
                } else {
                    ns
                }
            }
            None => [n; 3],
        };
        (face.map(|i| read(self.positions, i)), ns, n)
    }

    /// The vertex normal of vertex `v` recomputed from the positions in `R`
    /// (the same formula as [`vertex_normals`]).
    fn derived_normal<R: ScalarReal>(&self, store: &ParamView, v: usize) -> V3<R> {
        let mut acc = V3::zero();
        for &f in self.vertex_faces.of(v) {
            let face = self.faces[f as usize];
            let p = face.map(|i| store.read3(self.positions, i as usize));
            let k = face
                .iter()
                .position(|&i| i as usize == v)
                .expect("the adjacency lists faces of the vertex");
            acc += corner_normal(p, k);
        }
        acc.normalize()
    }

    /// The point of triangle `hit.prim` at the fixed barycentrics `hit.uv`,
    /// moving with the triangle's vertices; `wi` is left zero.
    pub fn triangle_point<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let (idx, [p0, p1, p2]) = self.triangle_r::<R>(store, hit.prim);
        let (b1, b2) = (R::cst(hit.uv.x), R::cst(hit.uv.y));
        let p = p0 * (R::cst(1.0) - b1 - b2) + p1 * b1 + p2 * b2;
        self.local_geometry(store, hit, idx, [p0, p1, p2], b1, b2, p, R::cst(hit.t))
    }

    /// Normals, uv and shading frame at barycentrics (b1, b2) of a
    /// triangle with vertex indices `idx` and positions `ps`; `wi` zero.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn local_geometry<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        idx: [usize; 3],
        ps: [V3<R>; 3],
        b1: R,
        b2: R,
        p: V3<R>,
        t: R,
    ) -> SurfaceInteraction<R> {
        let [i0, i1, i2] = idx;
        let b0 = R::cst(1.0) - b1 - b2;
        let e1 = ps[1] - ps[0];
        let e2 = ps[2] - ps[0];
        let (mut n, area_scale) = if R::DIFFERENTIABLE {
            let cross = e1.cross(e2);
            let area_scale = cross.length();
            (cross / area_scale, area_scale)
        } else {
            // the unit normal kept per face (flipped with `flip_normals`,
            // undone here as below it is flipped with the shading normal)
            // and twice the face's area, the barycentric area scale
            let f = hit.prim as usize;
            let n = self.face_n[f];
            let n = if self.flip_normals { -n } else { n };
            (V3::cst(n), R::cst(self.face_area2[f]))
        };
        // Mitsuba's mesh.cpp: the tangents of the normal's coordinate
        // system unless the triangle's texture coordinates give ∂p/∂u and
        // ∂p/∂v (solving [e1 e2] = [∂p/∂u ∂p/∂v] [Δuv1 Δuv2]).
        let fallback = || {
            let f = Frame::from_normal(n);
            (f.s, f.t)
        };
        let (uv, (dp_du, dp_dv)) = match self.texcoords {
            Some(tid) => {
                let read2 = |i: usize| store.read2::<R>(tid, i);
                let (t0, t1, t2) = (read2(i0), read2(i1), read2(i2));
                let uv = V2::new(
                    t0.x * b0 + t1.x * b1 + t2.x * b2,
                    t0.y * b0 + t1.y * b1 + t2.y * b2,
                );
                let (du1, du2) = (t1 - t0, t2 - t0);
                let det = du1.x * du2.y - du1.y * du2.x;
                let tangents = if det.val() != 0.0 && det.is_finite() {
                    let inv = det.recip();
                    (
                        (e1 * du2.y - e2 * du1.y) * inv,
                        (e2 * du1.x - e1 * du2.x) * inv,
                    )
                } else {
                    fallback()
                };
                (uv, tangents)
            }
            None => (V2::new(b1, b2), fallback()),
        };
        let mut ns = match self.normals {
            Some(nid) => {
                // As Mitsuba recomputes vertex normals from moved positions
                // (unless the normals are set too), their derivative follows
                // the positions' unless they carry their own.
                let follow = R::tracks(store, self.positions) && !R::tracks(store, nid);
                let dm = self.to_world_tangent::<R>(store);
                let normal = |i: usize| -> V3<R> {
                    let mut n: V3<R> = store.read3(nid, i);
                    if follow {
                        let d = self.derived_normal::<R>(store, i);
                        n += d - V3::cst(d.val());
                    }
                    // n ∝ A⁻ᵀ n_obj for the linear part A of to_world:
                    // dn = −A⁻ᵀ dAᵀ n
                    if let Some(dm) = &dm {
                        let nv = n.val();
                        let da_t_n = V3::new(
                            dm[0][0] * nv.x + dm[1][0] * nv.y + dm[2][0] * nv.z,
                            dm[0][1] * nv.x + dm[1][1] * nv.y + dm[2][1] * nv.z,
                            dm[0][2] * nv.x + dm[1][2] * nv.y + dm[2][2] * nv.z,
                        );
                        let inv_t = glam::Mat3::from_mat4(self.to_world.inv).transpose();
                        let c = |r: usize| V3::cst(inv_t.row(r));
                        n -= V3::new(c(0).dot(da_t_n), c(1).dot(da_t_n), c(2).dot(da_t_n));
                    }
                    n
                };
                let (n0, n1, n2) = (normal(i0), normal(i1), normal(i2));
                let s = n0 * b0 + n1 * b1 + n2 * b2;
                if s.length_squared().val() > 0.0 {
                    s.normalize()
                } else {
                    n
                }
            }
            None => n,
        };
        if self.flip_normals {
            n = -n;
            ns = -ns;
        }
        SurfaceInteraction {
            t,
            p,
            n,
            sh_frame: Frame::from_normal_tangent(ns, dp_du),
            uv,
            dp_du,
            dp_dv,
            wi: V3::zero(),
            area_scale,
            shape: hit.shape,
            prim: hit.prim,
            vertices: idx.map(|i| i as u32),
            bary: V2::new(b1, b2),
        }
    }
}

impl ShapeT for Mesh {
    fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        self.triangle_interaction(store, ray, hit)
    }

    fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        _p: Vec3,
    ) -> SurfaceInteraction<R> {
        self.triangle_point(store, hit)
    }

    /// Picks a triangle by area, then a uniform point in it (a quad: see
    /// `QuadSampling`); the density is 1 / total area.
    #[inline]
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        let (f, b, p, n) = self.sample_point(store, u);
        PositionSample {
            p,
            n,
            uv: self.uv_primal(store, f as u32, b),
            local: b,
            pdf: 1.0 / self.area,
            prim: f as u32,
        }
    }

    fn surface_area(&self) -> f32 {
        self.area
    }
}

/// Uniform position sampling of a mesh of two triangles of equal area
/// that share an edge (and any number of faces of zero area, which are
/// never sampled): the unit square's half u + v ≤ 1 maps affinely onto the
/// first triangle and the half u + v > 1 onto the second. An affine map has
/// a constant Jacobian, so each half lands uniformly on its triangle, and
/// each triangle, holding half of the area, is reached with probability ½:
/// the density is 1 / area, as with the area distribution and a triangle
/// warp, for one comparison instead of the distribution's search and the
/// warp. The square's corner (0, 0) is the first triangle's own vertex,
/// (1, 1) the second's, (1, 0) and (0, 1) the two shared ones.
#[derive(Clone, Copy, Debug)]
struct QuadSampling {
    /// The two faces.
    faces: [usize; 2],
    /// Per face: which of the weights (own vertex, s0, s1) belong to the
    /// face's second and third vertex (its barycentrics b1, b2).
    picks: [[usize; 2]; 2],
}

impl QuadSampling {
    /// `Some` when exactly two faces have an area, they share two vertices
    /// and their areas agree to 1e-6 (relative): a parallelogram, up to the
    /// rounding of its corners (~1e-7). The density on each face then
    /// differs from 1 / area by at most that relative 1e-6, far below any
    /// render's Monte Carlo error.
    fn new(faces: &[[u32; 3]], areas: &[f32]) -> Option<QuadSampling> {
        let mut with_area = (0..faces.len()).filter(|&f| areas[f] > 0.0);
        let (Some(i0), Some(i1), None) = (with_area.next(), with_area.next(), with_area.next())
        else {
            return None;
        };
        let ([f0, f1], [a0, a1]) = ([faces[i0], faces[i1]], [areas[i0], areas[i1]]);
        if (a0 - a1).abs() > 1e-6 * (a0 + a1) {
            return None;
        }
        let shared: Vec<u32> = f0.iter().copied().filter(|v| f1.contains(v)).collect();
        let &[s0, s1] = shared.as_slice() else {
            return None;
        };
        let picks = |f: [u32; 3]| {
            // the weight of each of the face's vertices: 0 for its own, 1
            // and 2 for the shared s0 and s1
            let weight_of = |v: u32| {
                if v == s0 {
                    1
                } else if v == s1 {
                    2
                } else {
                    0
                }
            };
            [weight_of(f[1]), weight_of(f[2])]
        };
        Some(QuadSampling {
            faces: [i0, i1],
            picks: [picks(f0), picks(f1)],
        })
    }

    /// The face and the barycentrics (of its second and third vertex) of
    /// the point `u` maps to.
    #[inline]
    fn sample(&self, u: Vec2) -> (usize, Vec2) {
        // weights of (own vertex, s0, s1); the own vertex's from the same
        // rounded sum as the test, so that it is never negative
        let sum = u.x + u.y;
        // without a branch: the two halves are equally likely, so a jump
        // would be mispredicted on every other light sample
        let second = sum > 1.0;
        let f = second as usize;
        let w = [
            if second { sum - 1.0 } else { 1.0 - sum },
            if second { 1.0 - u.y } else { u.x },
            if second { 1.0 - u.x } else { u.y },
        ];
        // read, not scattered into place: three stores at computed indices
        // and one wide load of two of them defeated the processor's
        // store-to-load forwarding (a stall of ~13 % of the light sample
        // on cbox, docs/perf/render_loop.md)
        let [k1, k2] = self.picks[f];
        (self.faces[f], Vec2::new(w[k1], w[k2]))
    }
}

/// Whether the triangle (p0, p1, p2) has zero area: coincident or
/// collinear vertices, up to the rounding of f32 positions (the cross
/// product is computed in f64, relative to the edge lengths), or
/// non-finite. The one test of degeneracy shared by loading, area
/// sampling, vertex normals and the acceleration structure, so that they
/// agree on which faces exist.
pub fn is_degenerate(p0: Vec3, p1: Vec3, p2: Vec3) -> bool {
    let (e1, e2) = ((p1 - p0).as_dvec3(), (p2 - p0).as_dvec3());
    let cross = e1.cross(e2).length();
    // `!(a > b)` is also true for NaN
    !(cross > 1e-12 * e1.length() * e2.length())
}

/// Removes the faces that are degenerate whatever the positions (a repeated
/// vertex index) and the faces that repeat an earlier one (the same vertex
/// set), and counts, with them, the faces of zero area at `positions`
/// (which stay).
fn remove_degenerate_faces(
    faces: &mut Vec<[u32; 3]>,
    positions: &[Vec3],
) -> (SkippedFaces, Vec<usize>) {
    let mut skipped = SkippedFaces::default();
    let repeats_index = |&[a, b, c]: &[u32; 3]| a == b || b == c || a == c;
    // a face repeats an earlier one where its sorted vertex indices equal
    // those of a face with a lower index: sorted by (vertex set, face),
    // each run of one vertex set starts with the face that stays (a radix
    // sort: a mesh of millions of faces is checked at every load)
    let mut keys: Vec<u128> = faces
        .iter()
        .enumerate()
        .filter(|(_, face)| !repeats_index(face))
        .map(|(f, face)| {
            let mut v = *face;
            v.sort_unstable();
            (v[0] as u128) << 96 | (v[1] as u128) << 64 | (v[2] as u128) << 32 | f as u128
        })
        .collect();
    keys.radix_sort_unstable();
    let mut repeat = vec![false; faces.len()];
    for run in keys.chunk_by(|a, b| a >> 32 == b >> 32) {
        for &k in &run[1..] {
            repeat[k as u32 as usize] = true;
        }
    }
    let mut keep = |f: usize| {
        if repeats_index(&faces[f]) {
            skipped.zero_area += 1;
            return false;
        }
        if repeat[f] {
            skipped.duplicate += 1;
            return false;
        }
        let p = |i: u32| positions[i as usize];
        let [a, b, c] = faces[f];
        if is_degenerate(p(a), p(b), p(c)) {
            skipped.zero_area += 1;
        }
        true
    };
    // the indices of the kept faces, to filter the face attributes alike
    let kept: Vec<usize> = (0..faces.len()).filter(|&f| keep(f)).collect();
    *faces = kept.iter().map(|&f| faces[f]).collect();
    (skipped, kept)
}

/// Number of edges shared by more than two faces.
fn count_non_manifold_edges(faces: &[[u32; 3]]) -> usize {
    let mut edges: Vec<u64> = Vec::with_capacity(faces.len() * 3);
    for t in faces {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (a, b) = if a < b { (a, b) } else { (b, a) };
            edges.push(((a as u64) << 32) | b as u64);
        }
    }
    // a radix sort: a mesh of millions of faces is checked at every load
    edges.radix_sort_unstable();
    edges
        .chunk_by(|a, b| a == b)
        .filter(|run| run.len() > 2)
        .count()
}

/// Smooth vertex normals: the face normals of the triangles around each
/// vertex, weighted by the triangle's angle at that vertex (Thürmer and
/// Wüthrich 1998, "Computing Vertex Normals from Polygonal Facets"), as
/// Mitsuba 3 computes them. Degenerate faces are left out (their normal
/// is undefined, and a collinear face would weigh its rounding noise by an
/// angle of π). Unused vertices get a zero normal.
pub fn vertex_normals(positions: &[Vec3], faces: &[[u32; 3]]) -> Vec<Vec3> {
    let mut acc = vec![Vec3::ZERO; positions.len()];
    for f in faces {
        let p = f.map(|i| V3::<f32>::cst(positions[i as usize]));
        for (k, &i) in f.iter().enumerate() {
            acc[i as usize] += corner_normal(p, k).val();
        }
    }
    acc.iter().map(|n| n.normalize_or_zero()).collect()
}

/// What corner `k` of the triangle `p` adds to its vertex's normal: the
/// unit face normal weighted by the corner's angle (Thürmer and Wüthrich
/// 1998, "Computing vertex normals from polygonal facets"); zero for a
/// degenerate face.
fn corner_normal<R: ScalarReal>(p: [V3<R>; 3], k: usize) -> V3<R> {
    if is_degenerate(p[0].val(), p[1].val(), p[2].val()) {
        return V3::zero();
    }
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
    let d0 = (p[(k + 1) % 3] - p[k]).normalize();
    let d1 = (p[(k + 2) % 3] - p[k]).normalize();
    n * d0.dot(d1).clamp(-1.0, 1.0).acos()
}

/// The faces around each vertex (compressed rows: the faces of vertex `v`
/// are `faces[offsets[v]..offsets[v + 1]]`).
#[derive(Clone, Debug, Default)]
struct VertexFaces {
    offsets: Vec<u32>,
    faces: Vec<u32>,
}

impl VertexFaces {
    fn new(vertex_count: usize, faces: &[[u32; 3]]) -> Self {
        let mut offsets = vec![0u32; vertex_count + 1];
        for f in faces {
            for &v in f {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        let mut next = offsets.clone();
        let mut out = vec![0u32; 3 * faces.len()];
        for (fi, f) in faces.iter().enumerate() {
            for &v in f {
                out[next[v as usize] as usize] = fi as u32;
                next[v as usize] += 1;
            }
        }
        VertexFaces {
            offsets,
            faces: out,
        }
    }

    fn of(&self, v: usize) -> &[u32] {
        &self.faces[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::geometry::{DiffRay, Ray};
    use crate::params::Seeds;

    fn tet() -> MeshData {
        MeshData {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            normals: None,
            texcoords: None,
            faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            attributes: Vec::new(),
        }
    }

    fn build(data: MeshData) -> Result<(Mesh, ParamStore)> {
        let mut store = ParamStore::new();
        let m = Mesh::new(
            "ply",
            "m",
            "test.ply",
            data,
            &Transform::IDENTITY,
            MeshOptions::default(),
            &mut store,
        )?;
        Ok((m, store))
    }

    /// Face attributes follow the faces that are kept; they and vertex
    /// attributes become parameters `<key>.<name>` shaped `[n, channels]`.
    #[test]
    fn attributes_become_parameters_and_follow_kept_faces() {
        let mut d = tet();
        // a repeated index (removed) and a duplicate of face 0 (removed)
        d.faces.insert(1, [0, 0, 1]);
        d.faces.push([2, 1, 0]);
        d.attributes = vec![
            MeshAttribute {
                name: "face_id".into(),
                channels: 1,
                per_face: true,
                data: vec![0.0, 9.0, 1.0, 2.0, 3.0, 9.0],
            },
            MeshAttribute {
                name: "vertex_color".into(),
                channels: 3,
                per_face: false,
                data: vec![0.5; 12],
            },
        ];
        let (m, store) = build(d.clone()).unwrap();
        assert_eq!(m.face_count(), 4);
        let id = store.require("m.face_id").unwrap();
        assert_eq!(store.data(id), &[0.0, 1.0, 2.0, 3.0]);
        assert_eq!(store.get(id).shape, vec![4, 1]);
        let id = store.require("m.vertex_color").unwrap();
        assert_eq!(store.get(id).shape, vec![4, 3]);
        d.attributes[1].data.pop();
        let e = build(d).unwrap_err().to_string();
        assert!(
            e.contains("test.ply") && e.contains("'vertex_color' has 11 values"),
            "{e}"
        );
    }

    #[test]
    fn validation_errors_name_file_and_element() {
        let mut d = tet();
        d.positions[2].y = f32::NAN;
        let e = build(d).unwrap_err().to_string();
        assert!(
            e.contains("test.ply") && e.contains("vertex 2") && e.contains("non-finite"),
            "{e}"
        );

        let mut d = tet();
        d.faces[1] = [0, 1, 7];
        let e = build(d).unwrap_err().to_string();
        assert!(e.contains("face 1") && e.contains("vertex 7"), "{e}");

        let mut d = tet();
        d.positions[1].z = f32::INFINITY;
        let e = build(d).unwrap_err().to_string();
        assert!(
            e.contains("test.ply") && e.contains("vertex 1") && e.contains("non-finite"),
            "{e}"
        );

        // only zero-area faces: nothing to render or sample
        let mut d = tet();
        d.faces = vec![[0, 1, 1], [2, 2, 2]];
        let e = build(d).unwrap_err().to_string();
        assert!(e.contains("test.ply") && e.contains("zero area"), "{e}");

        let e = build(MeshData::default()).unwrap_err().to_string();
        assert!(e.contains("empty mesh"), "{e}");
        assert!(build(tet()).is_ok());
    }

    /// Zero-area and duplicate faces (which Mitsuba renders as nothing) are
    /// counted and skipped; vertices keep their numbering, and the area and
    /// normals are those of the mesh without them.
    #[test]
    fn zero_area_and_duplicate_faces_are_skipped_and_counted() {
        let mut d = tet();
        // vertices 4, 5 on the line through 0 and 1
        d.positions.push(Vec3::new(2.0, 0.0, 0.0));
        d.positions.push(Vec3::new(3.0, 0.0, 0.0));
        d.faces.push([1, 2, 2]); // repeated index
        d.faces.push([0, 4, 5]); // collinear positions
        d.faces.push([1, 0, 2]); // face 0 = [0, 2, 1], other orientation
        d.faces.push([3, 0, 1]); // face 1 = [0, 1, 3], rotated
        let (m, store) = build(d).unwrap();
        assert_eq!(
            m.skipped,
            SkippedFaces {
                zero_area: 2,
                duplicate: 2
            }
        );
        // the collinear face stays (it may gain area), ignored while flat
        assert_eq!(m.face_count(), 5);
        assert!(m.face_is_degenerate(4) && !m.face_is_degenerate(0));
        assert_eq!(m.vertex_count(&store), 6);
        assert_eq!(store.get(m.positions).shape, vec![6, 3]);
        let (clean, clean_store) = build(tet()).unwrap();
        assert!((m.surface_area() - clean.surface_area()).abs() < 1e-6);
        let (n, cn) = (
            store.data(m.normals.unwrap()),
            clean_store.data(clean.normals.unwrap()),
        );
        for (a, b) in n[..12].iter().zip(cn) {
            assert!((a - b).abs() < 1e-6, "{n:?} vs {cn:?}");
        }
        assert_eq!(m.non_manifold_edges, 0);
        assert_eq!(clean.skipped, SkippedFaces::default());
    }

    /// An edge shared by three faces renders (as in Mitsuba) and is
    /// counted.
    #[test]
    fn non_manifold_edges_are_accepted_and_counted() {
        let mut d = tet();
        d.positions.push(Vec3::new(0.5, -1.0, 0.3));
        d.faces.push([0, 1, 4]); // edge 0-1 now in three faces
        let (m, _) = build(d).unwrap();
        assert_eq!(m.non_manifold_edges, 1);
        assert_eq!(m.face_count(), 5);
    }

    /// A face that is flat at load is never hit nor sampled; once an update
    /// of the positions gives it an area it is, and when it flattens again
    /// it is not.
    #[test]
    fn zero_area_face_follows_position_updates() {
        use crate::geometry::{Accel, Shape};
        let d = MeshData {
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(-1.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0), // on the line 3-4: face 1 is flat
            ],
            faces: vec![[0, 1, 2], [3, 4, 5]],
            ..Default::default()
        };
        let (m, mut store) = build(d).unwrap();
        assert_eq!(m.skipped.zero_area, 1);
        let mut shapes = vec![Shape::Mesh(m)];
        let mut accel = Accel::build(&shapes, &store);
        let ray = Ray::new(Vec3::new(0.0, 0.2, 5.0), -Vec3::Z);
        let hit_prim = |a: &Accel| a.intersect(&ray).map(|h| (h.prim, h.t));
        let sampled = |s: &[Shape], store: &ParamStore| {
            let Shape::Mesh(m) = &s[0] else {
                unreachable!()
            };
            (0..64)
                .map(|k| {
                    let u = Vec2::new((k as f32 + 0.5) / 64.0, 0.5);
                    m.sample_position(store, u).prim
                })
                .collect::<std::collections::HashSet<u32>>()
        };
        assert_eq!(hit_prim(&accel).map(|h| h.0), Some(0));
        assert_eq!(sampled(&shapes, &store), [0].into());

        let mut move_vertex_5 = |y: f32, shapes: &mut Vec<Shape>, accel: &mut Accel| {
            let mut p = store.data(store.id("m.vertex_positions").unwrap()).to_vec();
            p[16] = y;
            store.set("m.vertex_positions", &p).unwrap();
            let changed = store.take_dirty();
            shapes[0].parameters_changed(&mut store, &changed).unwrap();
            accel.update(shapes, &store);
            (hit_prim(accel), sampled(shapes, &store))
        };
        let (hit, prims) = move_vertex_5(1.0, &mut shapes, &mut accel);
        let (prim, t) = hit.unwrap();
        assert!(prim == 1 && (t - 4.0).abs() < 1e-5, "{hit:?}");
        assert_eq!(prims, [0, 1].into());
        let (hit, prims) = move_vertex_5(0.0, &mut shapes, &mut accel);
        assert_eq!(hit.map(|h| h.0), Some(0));
        assert_eq!(prims, [0].into());
    }

    #[test]
    fn smooth_normals_are_angle_weighted() {
        let (m, store) = build(tet()).unwrap();
        let nid = m.normals.unwrap();
        // vertex 0: three right angles with face normals -x, -y, -z
        let n0 = Vec3::from_slice(&store.data(nid)[0..3]);
        assert!((n0 - Vec3::splat(-1.0).normalize()).length() < 1e-6, "{n0}");
        // vertex 1: faces -z (45°), -y (45°), and the slanted face (60°)
        let w = [
            (Vec3::new(0.0, 0.0, -1.0), 45f32.to_radians()),
            (Vec3::new(0.0, -1.0, 0.0), 45f32.to_radians()),
            (Vec3::splat(1.0).normalize(), 60f32.to_radians()),
        ];
        let want = w
            .iter()
            .fold(Vec3::ZERO, |a, (n, t)| a + *n * *t)
            .normalize();
        let n1 = Vec3::from_slice(&store.data(nid)[3..6]);
        assert!((n1 - want).length() < 1e-5, "{n1} vs {want}");
        assert!((m.surface_area() - (1.5 + 3f32.sqrt() / 2.0)).abs() < 1e-5);
    }

    #[test]
    fn to_world_applies_to_positions_and_normals() {
        let mut store = ParamStore::new();
        let mut d = tet();
        d.normals = Some(vec![Vec3::Z; 4]);
        let t = Transform::new(glam::Mat4::from_scale(Vec3::new(2.0, 1.0, 0.5))).unwrap();
        let m = Mesh::new("ply", "m", "t", d, &t, MeshOptions::default(), &mut store).unwrap();
        assert_eq!(m.vertex(&store, 1), Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(m.vertex(&store, 3), Vec3::new(0.0, 0.0, 0.5));
        let n = Vec3::from_slice(&store.data(m.normals.unwrap())[0..3]);
        assert!((n - Vec3::Z).length() < 1e-6);
        assert_eq!(store.get(m.positions).shape, vec![4, 3]);
        assert!(store.get(m.positions).flags.discontinuous);
        // flat shading: no normals parameter
        let mut store = ParamStore::new();
        let opts = MeshOptions {
            face_normals: true,
            flip_normals: false,
        };
        let m = Mesh::new("ply", "m", "t", tet(), &t, opts, &mut store).unwrap();
        assert!(m.normals.is_none() && store.id("m.vertex_normals").is_none());
    }

    /// Derivatives of t and p with respect to each coordinate of each vertex
    /// (forward mode) against central finite differences.
    #[test]
    fn dual_hit_derivatives_match_finite_differences() {
        let mut d = tet();
        d.positions[3] = Vec3::new(0.2, 0.3, 1.0);
        d.texcoords = Some(vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.2),
            Vec2::new(0.1, 0.9),
            Vec2::new(0.5, 0.5),
        ]);
        let (m, mut store) = build(d).unwrap();
        // hits face 3 (1,2,3) from outside
        let ray = Ray::new(
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(-0.55, -0.6, -0.62).normalize(),
        );
        let hit = Hit {
            t: 0.0,
            shape: 0,
            prim: 3,
            uv: Vec2::ZERO,
            instance: None,
        };
        // the hit is re-solved from the vertices in R (a Dual without
        // tangents for the primal values: the f32 re-evaluation takes the
        // traversal's barycentrics, which this hand-made hit lacks)
        let primal = |store: &ParamStore| {
            let si = m.surface_interaction::<Dual>(&store.primal(), &DiffRay::cst(&ray), &hit);
            (si.t.v, si.p.val(), si.uv.x.v, si.n.val())
        };
        assert!(primal(&store).0 > 0.0);
        let base: Vec<f32> = store.data(m.positions).to_vec();
        let eps = 1e-3;
        for k in [3usize, 4, 5, 6, 7, 8, 9, 10, 11] {
            let mut tan = vec![0.0; base.len()];
            tan[k] = 1.0;
            let seeds = Seeds::tangents(&store, &[("m.vertex_positions", &tan)]).unwrap();
            let sd = m.surface_interaction::<Dual>(&store.view(&seeds), &DiffRay::cst(&ray), &hit);
            let eval = |store: &mut ParamStore, delta: f32| {
                let mut p = base.clone();
                p[k] += delta;
                store.set("m.vertex_positions", &p).unwrap();
                primal(store)
            };
            let sp = eval(&mut store, eps);
            let sm = eval(&mut store, -eps);
            store.set("m.vertex_positions", &base).unwrap();
            let fd_t = (sp.0 - sm.0) / (2.0 * eps);
            assert!(
                (sd.t.d - fd_t).abs() < 2e-3 * (1.0 + fd_t.abs()),
                "k={k}: {} vs {fd_t}",
                sd.t.d
            );
            let fd_p = (sp.1 - sm.1) / (2.0 * eps);
            let dp = Vec3::new(sd.p.x.d, sd.p.y.d, sd.p.z.d);
            assert!(
                (dp - fd_p).length() < 2e-3 * (1.0 + fd_p.length()),
                "k={k}: {dp} vs {fd_p}"
            );
            let fd_u = (sp.2 - sm.2) / (2.0 * eps);
            assert!(
                (sd.uv.x.d - fd_u).abs() < 2e-3 * (1.0 + fd_u.abs()),
                "k={k}"
            );
            let fd_n = (sp.3 - sm.3) / (2.0 * eps);
            let dn = Vec3::new(sd.n.x.d, sd.n.y.d, sd.n.z.d);
            assert!(
                (dn - fd_n).length() < 5e-3 * (1.0 + fd_n.length()),
                "k={k}: {dn} vs {fd_n}"
            );
        }
        // vertex 0 is not on face 3: zero derivative
        let mut tan = vec![0.0; base.len()];
        tan[0] = 1.0;
        let seeds = Seeds::tangents(&store, &[("m.vertex_positions", &tan)]).unwrap();
        let sd = m.surface_interaction::<Dual>(&store.view(&seeds), &DiffRay::cst(&ray), &hit);
        assert_eq!(sd.t.d, 0.0);
    }

    #[test]
    fn hit_geometry_and_flip() {
        let (m, _) = build(tet()).unwrap();
        let mut store = ParamStore::new();
        let opts = MeshOptions {
            face_normals: true,
            flip_normals: true,
        };
        let mf = Mesh::new(
            "ply",
            "f",
            "t",
            tet(),
            &Transform::IDENTITY,
            opts,
            &mut store,
        )
        .unwrap();
        let (_, s2) = build(tet()).unwrap();
        let ray = Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z);
        // as the traversal reports it: face 0 = (0, 2, 1), barycentrics
        // (b1, b2) of vertices 2 and 1 at (0.2, 0.3)
        let hit = Hit {
            t: 5.0,
            shape: 0,
            prim: 0,
            uv: Vec2::new(0.3, 0.2),
            instance: None,
        };
        let si = m.surface_interaction::<f32>(&s2.primal(), &DiffRay::cst(&ray), &hit);
        assert!((si.t - 5.0).abs() < 1e-5);
        assert!((si.p.val() - Vec3::new(0.2, 0.3, 0.0)).length() < 1e-6);
        // face 0 = (0,2,1): normal -z, barycentric uv without texcoords
        assert!((si.n.val() - -Vec3::Z).length() < 1e-6);
        assert!((si.uv.val() - Vec2::new(0.3, 0.2)).length() < 1e-6);
        assert!(si.wi.z < 0.0, "viewer on the back side: {:?}", si.wi);
        let sf = mf.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &hit);
        assert!((sf.n.val() - Vec3::Z).length() < 1e-6);
        assert!((sf.sh_frame.n.val() - Vec3::Z).length() < 1e-6);
        assert!((sf.wi.z - 1.0).abs() < 1e-5);
    }

    /// A quad (two triangles of equal area sharing an edge, here a skewed
    /// parallelogram whose faces list their vertices in different orders)
    /// is sampled by the affine map of the unit square onto it: every point
    /// is `q0 + u (s0 − q0) + v (s1 − q0)`, on the face the sample reports
    /// at the barycentrics it reports, with density 1 / area; faces of zero
    /// area beside it change nothing. A mesh of two triangles of different
    /// areas keeps the area distribution.
    #[test]
    fn a_quad_is_sampled_by_the_affine_map_of_the_square() {
        let (q0, s0, s1) = (
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.5),
            Vec3::new(0.5, 1.0, 0.0),
        );
        // vertices s1, q0, q1, s0; faces (s0, s1, q0) and (q1, s1, s0)
        let d = MeshData {
            positions: vec![s1, q0, s0 + s1 - q0, s0],
            faces: vec![[3, 0, 1], [2, 0, 3]],
            ..Default::default()
        };
        let (m, store) = build(d).unwrap();
        assert!(m.quad.is_some());
        for i in 0..17 {
            for j in 0..17 {
                let u = Vec2::new(i as f32 / 16.0, j as f32 / 16.0) * 0.999 + 0.0005;
                let s = m.sample_position(&store, u);
                let expected = q0 + u.x * (s0 - q0) + u.y * (s1 - q0);
                assert!(
                    (s.p - expected).length() < 1e-5,
                    "u {u}: {} vs {expected}",
                    s.p
                );
                let [p0, p1, p2] = m.triangle(&store, s.prim as usize);
                let b = s.local;
                assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6, "{b}");
                let on_face = p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y;
                assert!((on_face - s.p).length() < 1e-6);
                assert!((s.pdf * m.surface_area() - 1.0).abs() < 1e-6);
            }
        }
        // a flat face beside the quad (vertex 4 on the line through 1 and
        // 3) is never sampled and does not change the sampling
        let with_flat = MeshData {
            positions: vec![s1, q0, s0 + s1 - q0, s0, q0 + 2.0 * (s0 - q0)],
            faces: vec![[1, 3, 4], [3, 0, 1], [2, 0, 3]],
            ..Default::default()
        };
        let (flat, flat_store) = build(with_flat).unwrap();
        let u = Vec2::new(0.3, 0.6);
        let (a, b) = (
            flat.sample_position(&flat_store, u),
            m.sample_position(&store, u),
        );
        assert!(flat.quad.is_some() && a.prim == b.prim + 1 && a.p == b.p);
        let uneven = MeshData {
            positions: vec![q0, s0, s1, 2.0 * (s0 + s1)],
            faces: vec![[0, 1, 2], [1, 3, 2]],
            ..Default::default()
        };
        assert!(build(uneven).unwrap().0.quad.is_none());
    }

    /// Area sampling is uniform: χ²-test of sample counts per triangle
    /// against area fractions, and points lie on their triangle with pdf
    /// 1/area.
    #[test]
    fn area_sampling_is_uniform() {
        let mut d = tet();
        d.positions[3] = Vec3::new(0.0, 0.0, 3.0);
        let (m, store) = build(d).unwrap();
        let n = 40_000usize;
        let mut counts = [0usize; 4];
        let mut half = [0usize; 2];
        let mut rng = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..n {
            let s = m.sample_position(&store, Vec2::new(next(), next()));
            counts[s.prim as usize] += 1;
            assert!((s.pdf - 1.0 / m.surface_area()).abs() < 1e-6);
            if s.prim == 0 {
                // face 0 is the unit right triangle in z=0: split by x < 0.5
                // has area fractions 3/4 (x<0.5) and 1/4
                half[(s.p.x >= 0.5) as usize] += 1;
                assert!(
                    s.p.z.abs() < 1e-6
                        && s.p.x >= 0.0
                        && s.p.y >= 0.0
                        && s.p.x + s.p.y <= 1.0 + 1e-6
                );
            }
        }
        let total = m.surface_area() as f64;
        let mut chi2 = 0.0;
        for (f, &c) in counts.iter().enumerate() {
            let [p0, p1, p2] = m.triangle(&store, f);
            let e = n as f64 * (0.5 * (p1 - p0).cross(p2 - p0).length() as f64) / total;
            chi2 += (c as f64 - e).powi(2) / e;
        }
        let n0 = counts[0] as f64;
        for (k, frac) in [(0usize, 0.75), (1, 0.25)] {
            let e = n0 * frac;
            chi2 += (half[k] as f64 - e).powi(2) / e;
        }
        // 4 dof (3 + 1); p = 1e-3 critical value of χ²(4) is 18.47
        assert!(
            chi2 < 18.47,
            "chi2 = {chi2}, counts {counts:?}, half {half:?}"
        );
    }

    #[test]
    fn normals_follow_moved_positions() {
        let (mut m, mut store) = build(tet()).unwrap();
        let mut p = store.data(m.positions).to_vec();
        p[11] = 2.0; // vertex 3 z
        store.set("m.vertex_positions", &p).unwrap();
        let changed = store.take_dirty();
        let before = m.surface_area();
        m.parameters_changed(&mut store, &changed).unwrap();
        assert!(m.surface_area() > before);
        let pos: Vec<Vec3> = p.chunks_exact(3).map(Vec3::from_slice).collect();
        let want = vertex_normals(&pos, &m.faces);
        let got = Vec3::from_slice(&store.data(m.normals.unwrap())[3..6]);
        assert!((got - want[1]).length() < 1e-6);
    }

    fn load_ref(name: &str) -> (Mesh, ParamStore) {
        let p = crate::testing::repo_file(&format!("scenes/meshes/{name}"));
        let data = crate::geometry::ply::load_ply(&p).unwrap();
        build(data).unwrap()
    }

    #[test]
    fn reference_meshes_load() {
        let (m, s) = load_ref("icosphere3.ply");
        assert_eq!((m.vertex_count(&s), m.face_count()), (642, 1280));
        assert!(m.normals.is_some() && m.texcoords.is_none());
        let (m, s) = load_ref("displaced_sphere.ply");
        assert_eq!((m.vertex_count(&s), m.face_count()), (163_842, 327_680));
        for name in ["plane_uv.ply", "uv_sphere.ply"] {
            assert!(load_ref(name).0.texcoords.is_some(), "{name}");
        }
    }
}
