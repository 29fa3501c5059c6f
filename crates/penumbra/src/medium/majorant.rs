//! The majorant grid of a heterogeneous medium: a coarse grid over its
//! extinction grid's unit cube (at most [`CELLS`] cells per axis, each a
//! block of voxels), holding per cell an upper bound of σ_t over the cell,
//! so that tracking takes tentative collisions at the rate of the local
//! majorant instead of the largest extinction of the whole medium: a cell
//! where the density is low or zero costs few or no lookups.
//!
//! A cell's bound is [`super::heterogeneous::MAJORANT_FACTOR`] × `scale` ×
//! the largest voxel (over channels) that a lookup in the cell reads,
//! the voxel beyond each face included (the trilinear filter's reach), so
//! it bounds σ_t at every point of the cell, and at points a rounding
//! error outside it. Primal values only: the same grid serves every
//! number type, and the sampling decisions do not depend on it.
//!
//! Rays are walked through the cells with a 3D DDA (Amanatides and Woo
//! 1987, "A fast voxel traversal algorithm for ray tracing"), in the
//! cube's coordinates (a ray maps to a ray under the grid's affine
//! `to_world`, with the same distances t); the parts of a range outside
//! the cube (inside the medium's world box, which is larger than a rotated
//! cube) take the whole medium's majorant.

use crate::geometry::Ray;
use crate::math::Transform;
use crate::params::ParamStore;
use crate::volume::GridVolume;
use glam::{Vec3, Vec4};

/// Cells along each axis at most. 16³ cells of 4³ voxels for a 64³ grid:
/// on `volume_hetero` they hold 14 % of the majorant of the whole grid on
/// average over its volume (8³ cells 21 %, 32³ cells 11 %). Rendering it
/// took the same time with 8³ cells and 12 % longer with 32³, where the
/// DDA's steps cost more than the lookups they save.
const CELLS: usize = 16;

/// Expected tentative collisions a cell must save, on average over the
/// cells, for the walk from cell to cell to pay: below it the tracking
/// takes the grid's largest majorant along the whole range instead (one
/// segment, no DDA). Callgrind on `volume_hetero`: a DDA step costs about
/// 160 instructions, a tentative collision's lookup 375 in a render and
/// 870 more on the reverse-mode tape, so a gradient (which walks twice:
/// primal image, then recorded pass) breaks even at about 0.26 collisions
/// per cell, a render at 0.42. With the density at 0.3 everywhere (the
/// usual first guess of a reconstruction) the walk took a quarter of the
/// render's time.
const SAVING_PER_CELL: f32 = 0.25;

/// A coarse grid of majorants over an extinction grid's unit cube.
#[derive(Clone, Debug)]
pub(super) struct MajorantGrid {
    /// World to lattice coordinates, where cell (i, j, k) spans
    /// [i, i+1] × [j, j+1] × [k, k+1].
    to_lattice: Transform,
    /// The unit cube's far corner in lattice coordinates (at most `res`:
    /// the last cell of an axis may reach past the grid).
    extent: Vec3,
    /// Cells along x, y, z.
    res: [usize; 3],
    /// Voxels per cell along x, y, z.
    voxels: [usize; 3],
    /// Per cell, x fastest: the majorant (primal, with `scale`).
    majorants: Vec<f32>,
    /// The largest majorant, if the cells differ so little that tracking
    /// against it everywhere is cheaper than walking them (see
    /// [`SAVING_PER_CELL`]): a uniform grid, the usual first guess of a
    /// reconstruction, or a dense and nearly even one.
    single: Option<f32>,
}

/// A part of a ray's range with the majorant that bounds σ_t along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Segment {
    pub t0: f32,
    pub t1: f32,
    pub majorant: f32,
}

impl MajorantGrid {
    /// The grid over `grid`'s cube, or `None` if its `to_world` is not
    /// affine (a projective map bends rays: the whole medium's majorant
    /// is used then). Its values are set by [`MajorantGrid::update`].
    pub fn new(grid: &GridVolume) -> Option<MajorantGrid> {
        let to_local = grid.to_local();
        if to_local.m.row(3) != Vec4::W {
            return None;
        }
        let voxels = grid.res.map(|n| n.div_ceil(CELLS));
        let res = [0, 1, 2].map(|a| grid.res[a].div_ceil(voxels[a]));
        let extent = Vec3::from_array([0, 1, 2].map(|a| grid.res[a] as f32 / voxels[a] as f32));
        Some(MajorantGrid {
            to_lattice: Transform::scale(extent).after(to_local),
            extent,
            res,
            voxels,
            majorants: vec![0.0; res.iter().product()],
            single: None,
        })
    }

    /// Refreshes the majorants from the grid's values: `factor` × the
    /// largest value each cell reads.
    pub fn update(&mut self, grid: &GridVolume, store: &ParamStore, factor: f32) {
        self.majorants = grid.cell_maxima(store, self.voxels, self.res);
        for m in &mut self.majorants {
            *m *= factor;
        }
        let max = self.majorants.iter().copied().fold(0.0, f32::max);
        let mean =
            self.majorants.iter().map(|&m| m as f64).sum::<f64>() / self.majorants.len() as f64;
        // a typical crossing: the cube root of a cell's world volume (the
        // lattice's cells have unit volume)
        let cell_length = self.to_lattice.inv.determinant().abs().cbrt();
        let saving = (max as f64 - mean) * cell_length as f64;
        self.single = (saving < SAVING_PER_CELL as f64).then_some(max);
    }

    /// The majorant to track against along whole ranges instead of
    /// walking the cells, if the cells differ too little for the walk to
    /// pay.
    pub fn single(&self) -> Option<f32> {
        self.single
    }

    /// The segments of `ray` over `[t0, t1]` (a range inside the medium's
    /// box), each cell's majorant raised to `floor`; parts outside the
    /// cube take `outside`.
    pub fn walk(&self, ray: &Ray, t0: f32, t1: f32, outside: f32, floor: f32) -> Walk<'_> {
        let g0 = self.to_lattice.point(ray.o);
        let dg = self.to_lattice.vector(ray.d);
        // the part of [t0, t1] inside the cube
        let (mut ta, mut tb) = (t0, t1);
        let mut inv = [0.0; 3];
        for a in 0..3 {
            if dg[a] != 0.0 {
                inv[a] = 1.0 / dg[a];
                let (u, v) = (-g0[a] * inv[a], (self.extent[a] - g0[a]) * inv[a]);
                ta = ta.max(u.min(v));
                tb = tb.min(u.max(v));
            } else if !(0.0..=self.extent[a]).contains(&g0[a]) {
                tb = f32::NEG_INFINITY;
            }
        }
        if !(ta < tb) {
            return Walk::uniform(t0, t1, outside);
        }
        let mut cell = [0i32; 3];
        let mut step = [0i32; 3];
        let mut t_next = [f32::INFINITY; 3];
        for a in 0..3 {
            let g = g0[a] + ta * dg[a];
            cell[a] = (g.max(0.0) as i32).min(self.res[a] as i32 - 1);
            if dg[a] != 0.0 {
                step[a] = if dg[a] > 0.0 { 1 } else { -1 };
                t_next[a] = boundary(cell[a], step[a], g0[a], inv[a]);
            }
        }
        Walk {
            majorants: &self.majorants,
            res: self.res.map(|n| n as i32),
            outside,
            floor,
            t: t0,
            grid_end: tb,
            end: t1,
            state: State::Before(ta),
            g0,
            inv,
            cell,
            step,
            t_next,
        }
    }
}

/// The t at which a ray at lattice coordinate g0 + t/inv (along one axis)
/// leaves `cell` in direction `step`.
#[inline(always)]
fn boundary(cell: i32, step: i32, g0: f32, inv: f32) -> f32 {
    ((cell + (step > 0) as i32) as f32 - g0) * inv
}

#[derive(Clone, Copy, Debug)]
enum State {
    /// Before the cube, which the ray enters at the given t.
    Before(f32),
    /// In the cube's cells.
    Grid,
    /// After the cube, to the end of the range.
    After,
    Done,
}

/// The segments of a ray's range in order, with their majorants; those of
/// majorant 0 and empty ones left out.
pub(super) struct Walk<'a> {
    majorants: &'a [f32],
    res: [i32; 3],
    outside: f32,
    floor: f32,
    /// Where the walk is.
    t: f32,
    /// Where the ray leaves the cube.
    grid_end: f32,
    /// The end of the range.
    end: f32,
    state: State,
    /// The ray in lattice coordinates: origin, reciprocal direction.
    g0: Vec3,
    inv: [f32; 3],
    cell: [i32; 3],
    step: [i32; 3],
    /// Where the ray leaves the current cell's slab, per axis.
    t_next: [f32; 3],
}

impl Walk<'_> {
    /// A single segment [t0, t1] of majorant `m` (a medium without a
    /// majorant grid).
    pub fn uniform(t0: f32, t1: f32, m: f32) -> Walk<'static> {
        Walk {
            majorants: &[],
            res: [0; 3],
            outside: m,
            floor: 0.0,
            t: t0,
            grid_end: t0,
            end: t1,
            state: State::After,
            g0: Vec3::ZERO,
            inv: [0.0; 3],
            cell: [0; 3],
            step: [0; 3],
            t_next: [f32::INFINITY; 3],
        }
    }

    /// No segment at all.
    pub fn empty() -> Walk<'static> {
        Walk {
            state: State::Done,
            ..Walk::uniform(0.0, 0.0, 0.0)
        }
    }
}

impl Iterator for Walk<'_> {
    type Item = Segment;

    #[inline]
    fn next(&mut self) -> Option<Segment> {
        loop {
            let t0 = self.t;
            let (t1, majorant) = match self.state {
                State::Before(ta) => {
                    self.state = State::Grid;
                    (ta, self.outside)
                }
                State::Grid => {
                    let [x, y, z] = self.cell;
                    let i = ((z * self.res[1] + y) * self.res[0] + x) as usize;
                    let m = self.majorants[i].max(self.floor);
                    let a = if self.t_next[0] < self.t_next[1] {
                        if self.t_next[0] < self.t_next[2] {
                            0
                        } else {
                            2
                        }
                    } else if self.t_next[1] < self.t_next[2] {
                        1
                    } else {
                        2
                    };
                    let exit = self.t_next[a].min(self.grid_end);
                    if self.t_next[a] >= self.grid_end {
                        self.state = State::After;
                    } else {
                        self.cell[a] += self.step[a];
                        // leaving the lattice before the cube's end (by
                        // rounding): the rest takes the outside majorant
                        if !(0..self.res[a]).contains(&self.cell[a]) {
                            self.state = State::After;
                        }
                        self.t_next[a] =
                            boundary(self.cell[a], self.step[a], self.g0[a], self.inv[a]);
                    }
                    (exit, m)
                }
                State::After => {
                    self.state = State::Done;
                    (self.end, self.outside)
                }
                State::Done => return None,
            };
            self.t = self.t.max(t1);
            if majorant > 0.0 && t1 > t0 {
                return Some(Segment { t0, t1, majorant });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::heterogeneous::MAJORANT_FACTOR;
    use super::*;
    use crate::scene::Scene;
    use crate::testing::Pcg32;

    /// A scene whose only medium has a `res` grid of `data` (one channel)
    /// as its extinction, with `scale` 2 and the given volume options.
    fn medium_scene(name: &str, res: [usize; 3], data: &[f32], volume: &str) -> Scene {
        let dir = std::env::temp_dir().join(format!("penumbra-majorant-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut b = b"VOL\x03".to_vec();
        for v in [1, res[0] as i32, res[1] as i32, res[2] as i32, 1] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0].iter().chain(data) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(dir.join(format!("{name}.vol")), b).unwrap();
        let xml = format!(
            r#"<scene version="3.0.0">
                <sensor type="perspective"/>
                <medium type="heterogeneous" id="medium">
                    <volume type="gridvolume" name="sigma_t">
                        <string name="filename" value="{name}.vol"/>
                        {volume}
                    </volume>
                    <float name="scale" value="2"/>
                </medium>
            </scene>"#
        );
        Scene::load_str(&xml, &dir.join(format!("{name}.xml")), &[]).unwrap()
    }

    /// A sparse random grid: random values in two balls, with holes, and
    /// zeros elsewhere.
    fn sparse(res: [usize; 3], rng: &mut Pcg32) -> Vec<f32> {
        let centres = [Vec3::new(0.3, 0.3, 0.4), Vec3::new(0.75, 0.6, 0.7)];
        let mut data = Vec::new();
        for z in 0..res[2] {
            for y in 0..res[1] {
                for x in 0..res[0] {
                    let p = (Vec3::new(x as f32, y as f32, z as f32) + 0.5)
                        / Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
                    let inside = centres.iter().any(|c| p.distance(*c) < 0.2);
                    let u = rng.next_f32();
                    data.push(if inside && u > 0.3 {
                        rng.next_f32() * 3.0
                    } else {
                        0.0
                    });
                }
            }
        }
        data
    }

    /// A ray through the box [-1, 1]³ (the grids below are placed inside
    /// it) from a random point outside towards a random point inside.
    fn random_ray(rng: &mut Pcg32) -> Ray {
        let p = |rng: &mut Pcg32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let o = (p(rng) - 0.5) * 6.0;
        let target = (p(rng) - 0.5) * 2.0;
        Ray::new(o, (target - o).normalize())
    }

    /// Every point of every segment, its ends included (cell faces), has
    /// σ_t ≤ the segment's majorant / MAJORANT_FACTOR (so that null
    /// collisions exist where σ_t > 0), for grids whose cells are blocks of
    /// several voxels, a rotated and scaled `to_world`, both filters and
    /// the wrap modes; the segments cover the whole range but where the
    /// majorant is 0.
    #[test]
    fn majorants_bound_the_extinction_everywhere() {
        let mut rng = Pcg32::new(7);
        let res = [37, 20, 50];
        let data = sparse(res, &mut rng);
        let to_world = r#"<transform name="to_world">
                <translate x="-0.5" y="-0.5" z="-0.5"/>
                <scale x="1.2" y="0.9" z="1.5"/>
                <rotate x="1" y="2" z="0.5" angle="35"/>
            </transform>"#;
        for (i, options) in [
            r#"<string name="filter_type" value="trilinear"/>"#,
            r#"<string name="filter_type" value="nearest"/>"#,
            r#"<string name="wrap_mode" value="repeat"/>"#,
            r#"<string name="wrap_mode" value="mirror"/>"#,
        ]
        .iter()
        .enumerate()
        {
            let scene = medium_scene(
                &format!("bound{i}"),
                res,
                &data,
                &format!("{options}{to_world}"),
            );
            let medium = &scene.media[0];
            let grid = medium.majorant_grid.as_ref().unwrap();
            assert_eq!((grid.voxels, grid.res), ([3, 2, 4], [13, 10, 13]));
            let store = scene.params.primal();
            let (mut points, mut empty_length) = (0, 0.0);
            for _ in 0..2000 {
                let ray = random_ray(&mut rng);
                let Some((t0, t1)) = medium.clip(&ray, f32::INFINITY) else {
                    continue;
                };
                let segments: Vec<Segment> = medium.segments(&store, &ray, f32::INFINITY).collect();
                let mut t = t0;
                for s in &segments {
                    assert!(s.t0 >= t && s.t1 > s.t0, "{segments:?}");
                    // what lies between two segments has majorant 0
                    let gap = s.t0 - t;
                    if gap > 0.0 {
                        empty_length += gap;
                        let mid = ray.at(t + gap / 2.0);
                        assert_eq!(
                            medium.extinction::<f32>(&store, mid).val().max_element(),
                            0.0
                        );
                    }
                    t = s.t1;
                    let ends = [
                        s.t0,
                        s.t1,
                        s.t0 + 1e-4 * (s.t1 - s.t0),
                        s.t1 - 1e-4 * (s.t1 - s.t0),
                    ];
                    let inner = (0..4).map(|_| s.t0 + rng.next_f32() * (s.t1 - s.t0));
                    for u in ends.into_iter().chain(inner) {
                        let sigma = medium
                            .extinction::<f32>(&store, ray.at(u))
                            .val()
                            .max_element();
                        assert!(
                            sigma * MAJORANT_FACTOR <= s.majorant * (1.0 + 1e-6),
                            "{options}: σ_t {sigma} at t = {u} in {s:?}"
                        );
                        points += 1;
                    }
                }
                assert!(t <= t1 + 1e-5 * t1.abs());
            }
            assert!(
                points > 20_000 && empty_length > 10.0,
                "{points} {empty_length}"
            );
        }
    }

    /// A grid whose cells differ little is tracked along each ray in one
    /// segment of its largest majorant, without walking the cells; a sparse
    /// one walks them.
    #[test]
    fn even_grids_are_tracked_in_one_segment() {
        let res = [32, 32, 32];
        let mut rng = Pcg32::new(5);
        let sparse_scene = medium_scene("sparse32", res, &sparse(res, &mut rng), "");
        let grid = sparse_scene.media[0].majorant_grid.as_ref().unwrap();
        assert_eq!(grid.single(), None);
        let n = res.iter().product();
        let even: Vec<f32> = (0..n).map(|_| 1.0 + 0.05 * rng.next_f32()).collect();
        let scene = medium_scene("even32", res, &even, "");
        let medium = &scene.media[0];
        let single = medium.majorant_grid.as_ref().unwrap().single().unwrap();
        assert!(
            (single - MAJORANT_FACTOR * 2.0 * 1.05).abs() < 1e-3,
            "{single}"
        );
        let store = scene.params.primal();
        let mut crossed = 0;
        for _ in 0..200 {
            let ray = random_ray(&mut rng);
            let Some((t0, t1)) = medium.clip(&ray, f32::INFINITY) else {
                continue;
            };
            let segments: Vec<Segment> = medium.segments(&store, &ray, f32::INFINITY).collect();
            let majorant = single.max(medium.majorant);
            assert_eq!(segments, [Segment { t0, t1, majorant }]);
            crossed += 1;
        }
        assert!(crossed > 50, "{crossed}");
    }

    /// The walk visits the cells a ray crosses in order, each from where
    /// the ray enters it to where it leaves it: against the sorted
    /// crossings of the ray with every cell plane, found independently.
    #[test]
    fn walk_visits_the_crossed_cells_in_order() {
        let res = [64, 32, 20];
        let scene = medium_scene(
            "dda",
            res,
            &vec![1.0; res.iter().product()],
            r#"<transform name="to_world">
                <scale x="2" y="1" z="1.5"/>
                <translate x="-1" y="-0.5" z="-0.75"/>
            </transform>"#,
        );
        let medium = &scene.media[0];
        let mut grid = medium.majorant_grid.clone().unwrap();
        assert_eq!((grid.voxels, grid.res), ([4, 2, 2], [16, 16, 10]));
        // each cell's majorant names it
        let cells = grid.res;
        grid.majorants = (0..grid.majorants.len()).map(|i| i as f32 + 1.0).collect();
        let mut rng = Pcg32::new(3);
        let mut crossed = 0;
        for _ in 0..500 {
            let ray = random_ray(&mut rng);
            let Some((t0, t1)) = medium.clip(&ray, f32::INFINITY) else {
                continue;
            };
            // the crossings, in lattice coordinates (cell size 1)
            let lattice = |p: Vec3| {
                (p + Vec3::new(1.0, 0.5, 0.75)) / Vec3::new(2.0, 1.0, 1.5)
                    * Vec3::new(16.0, 16.0, 10.0)
            };
            let g0 = lattice(ray.o);
            let dg = lattice(ray.o + ray.d) - g0;
            let mut ts = vec![t0, t1];
            for a in 0..3 {
                for k in 0..=cells[a] {
                    let t = (k as f32 - g0[a]) / dg[a];
                    if t > t0 && t < t1 {
                        ts.push(t);
                    }
                }
            }
            ts.sort_by(f32::total_cmp);
            let expected: Vec<(f32, f32, f32)> = ts
                .windows(2)
                .filter(|w| w[1] - w[0] > 1e-4)
                .map(|w| {
                    let c = lattice(ray.at((w[0] + w[1]) / 2.0)).floor();
                    let i = (c.z as usize * cells[1] + c.y as usize) * cells[0] + c.x as usize;
                    (w[0], w[1], i as f32 + 1.0)
                })
                .collect();
            let got: Vec<Segment> = grid
                .walk(&ray, t0, t1, 0.0, 0.0)
                .filter(|s| s.t1 - s.t0 > 1e-4)
                .collect();
            assert_eq!(got.len(), expected.len(), "{got:?}\n{expected:?}");
            for (s, e) in got.iter().zip(&expected) {
                assert_eq!(s.majorant, e.2, "{got:?}\n{expected:?}");
                assert!(
                    (s.t0 - e.0).abs() < 1e-4 && (s.t1 - e.1).abs() < 1e-4,
                    "{s:?} {e:?}"
                );
            }
            crossed += got.len();
        }
        assert!(crossed > 5000, "{crossed}");
    }

    /// Ratio tracking through the majorant grid (and delta tracking's
    /// probability of passing, for a grey medium) estimate the analytic
    /// transmittance of a grid that varies along x only: zero over its
    /// first third, then a ramp, read trilinearly, so σ_t is linear
    /// between voxel centres and constant beyond the outer ones. Oblique
    /// rays cross empty and dense cells. Fixed seeds; the tolerance is 4
    /// standard errors of the estimate (plus float rounding).
    #[test]
    fn tracking_estimates_the_analytic_transmittance() {
        let res = [32, 4, 4];
        let n = res[0];
        let ramp: Vec<f32> = (0..n).map(|i| (i as f32 - 10.0).max(0.0) * 0.1).collect();
        let data: Vec<f32> = (0..res.iter().product::<usize>())
            .map(|i| ramp[i % n])
            .collect();
        let scene = medium_scene("ramp", res, &data, "");
        let medium = &scene.media[0];
        let store = scene.params.primal();
        let sigma = |x: f32| {
            // voxel centres at (i + ½)/n; clamped beyond the outer ones
            let u = (x * n as f32 - 0.5).clamp(0.0, (n - 1) as f32);
            let i = (u as usize).min(n - 2);
            2.0 * (ramp[i] + (u - i as f32) * (ramp[i + 1] - ramp[i]))
        };
        let mut sampler_rng = scene.sensors[0].sampler.stream(11, 0, 0, 1);
        for (o, d) in [
            (Vec3::new(-0.5, 0.5, 0.5), Vec3::new(1.0, 0.0, 0.0)),
            (Vec3::new(-0.2, 0.1, 0.3), Vec3::new(1.0, 0.6, 0.2)),
            (Vec3::new(1.3, 0.9, 0.2), Vec3::new(-1.0, -0.3, 0.5)),
        ] {
            let ray = Ray::new(o, d.normalize());
            let (t0, t1) = medium.clip(&ray, f32::INFINITY).unwrap();
            // the optical depth, by the trapezoid rule on a fine grid (σ_t
            // is piecewise linear in t, with kinks at voxel centres)
            let steps = 200_000;
            let dt = (t1 - t0) as f64 / steps as f64;
            let depth: f64 = (0..steps)
                .map(|k| {
                    let t = t0 as f64 + (k as f64 + 0.5) * dt;
                    sigma(ray.at(t as f32).x) as f64 * dt
                })
                .sum();
            let expected = (-depth).exp();
            let trials = 20_000;
            let (mut sum, mut sum2, mut passed) = (0.0f64, 0.0f64, 0usize);
            for k in 0..trials {
                let mut rng = scene.sensors[0].sampler.stream(5, k, 0, 1);
                let tr = medium
                    .transmittance::<f32>(&store, &ray, f32::INFINITY, &mut rng)
                    .x as f64;
                sum += tr;
                sum2 += tr * tr;
                let flight =
                    medium.sample_free_flight::<f32>(&store, &ray, f32::INFINITY, &mut sampler_rng);
                passed += matches!(flight, crate::medium::FreeFlight::Pass { .. }) as usize;
            }
            let n = trials as f64;
            let mean = sum / n;
            let se = ((sum2 / n - mean * mean) / (n - 1.0)).sqrt();
            assert!(
                (mean - expected).abs() <= 4.0 * se + 1e-5,
                "ratio tracking {mean} ± {se}, analytic {expected} (optical depth {depth})"
            );
            let p = passed as f64 / n;
            let se = (expected * (1.0 - expected) / n).sqrt();
            assert!(
                (p - expected).abs() <= 4.0 * se + 1e-5,
                "delta tracking passes {p} ± {se}, analytic {expected}"
            );
            assert!(depth > 0.5 && expected > 0.01, "{depth}");
        }
    }
}
