//! A volume sampled on a regular grid (Mitsuba's `gridvolume`), read from
//! Mitsuba's binary `.vol` files. The grid spans the unit cube, placed in
//! the world by `to_world`; values are texel-centred (voxel (i, j, k) at
//! ((i, j, k) + ½) / resolution) and filtered trilinearly or by the nearest
//! voxel, as Mitsuba's 3D textures are.

use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::math::{floor_i64, Spectrum, Transform, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::Vec3;
use std::path::Path;

/// How a point between voxel centres is filtered.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Filter {
    Trilinear,
    Nearest,
}

/// What is read outside the grid.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Wrap {
    Clamp,
    Repeat,
    Mirror,
}

impl Wrap {
    /// Voxel index `i` of a `n`-voxel axis mapped into `0..n`.
    #[inline(always)]
    fn index(self, i: i64, n: usize) -> usize {
        let n = n as i64;
        (match self {
            Wrap::Clamp => i.clamp(0, n - 1),
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n {
                    m
                } else {
                    2 * n - 1 - m
                }
            }
        }) as usize
    }
}

/// The contents of a `.vol` file (version 3, float32 encoding): the
/// resolution, channel count, bounding box and values, x fastest, then y,
/// then z, channels innermost — the row-major `[z, y, x, c]` layout of the
/// grid's parameter.
#[derive(Clone, Debug)]
pub struct VolFile {
    /// Voxels along x, y, z.
    pub res: [usize; 3],
    pub channels: usize,
    /// The box the file says the grid covers (used with `use_grid_bbox`).
    pub bbox: (Vec3, Vec3),
    pub data: Vec<f32>,
}

impl VolFile {
    /// Reads a `.vol` file; errors say what is wrong with it.
    pub fn read(path: &Path) -> Result<VolFile> {
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e))?;
        VolFile::parse(&bytes).map_err(|msg| Error::file(path, msg))
    }

    fn parse(b: &[u8]) -> std::result::Result<VolFile, String> {
        if b.len() < 48 || &b[..3] != b"VOL" {
            return Err("not a Mitsuba .vol file (it must start with 'VOL')".into());
        }
        if b[3] != 3 {
            return Err(format!("unsupported .vol version {} (only 3 is)", b[3]));
        }
        let int = |at: usize| i32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        let float = |at: usize| f32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        let encoding = int(4);
        if encoding != 1 {
            return Err(format!(
                "unsupported .vol encoding {encoding} (only 1, float32, is)"
            ));
        }
        let (x, y, z, c) = (int(8), int(12), int(16), int(20));
        if x <= 0 || y <= 0 || z <= 0 || !(c == 1 || c == 3) {
            return Err(format!(
                "invalid .vol header: resolution {x}×{y}×{z} with {c} channel(s) (1 or 3 \
                 channels, positive resolution)"
            ));
        }
        let res = [x as usize, y as usize, z as usize];
        let channels = c as usize;
        let count = res.iter().product::<usize>() * channels;
        let body = &b[48..];
        if body.len() != 4 * count {
            return Err(format!(
                "truncated or oversized .vol file: {x}×{y}×{z}×{c} float32 values need {} \
                 bytes of data, found {}",
                4 * count,
                body.len()
            ));
        }
        let data: Vec<f32> = body
            .chunks_exact(4)
            .map(|q| f32::from_le_bytes(q.try_into().unwrap()))
            .collect();
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(format!("value {i} of the grid is not finite ({})", data[i]));
        }
        let bbox = (
            Vec3::new(float(24), float(28), float(32)),
            Vec3::new(float(36), float(40), float(44)),
        );
        Ok(VolFile {
            res,
            channels,
            bbox,
            data,
        })
    }
}

/// The grid's values are the parameter `<key>.data` with shape
/// `[z, y, x, c]`, as Mitsuba's `traverse` gives them.
#[derive(Clone, Debug)]
pub struct GridVolume {
    pub data: ParamId,
    /// Voxels along x, y, z.
    pub res: [usize; 3],
    pub channels: usize,
    /// World to the grid's unit cube.
    to_local: Transform,
    /// Its world-space bounding box.
    bbox: (Vec3, Vec3),
    filter: Filter,
    wrap: Wrap,
}

impl GridVolume {
    pub fn from_node(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Self> {
        let filename = node
            .string_opt("filename")?
            .ok_or_else(|| node.error("missing required parameter 'filename' (a .vol file)"))?;
        let path = ctx.resolve_path(node, "filename", &filename)?;
        let file = VolFile::read(&path).map_err(|e| node.error(e))?;
        let filter = match node
            .choice("filter_type", &["trilinear", "nearest"])?
            .as_str()
        {
            "trilinear" => Filter::Trilinear,
            _ => Filter::Nearest,
        };
        let wrap = match node
            .choice("wrap_mode", &["clamp", "repeat", "mirror"])?
            .as_str()
        {
            "clamp" => Wrap::Clamp,
            "repeat" => Wrap::Repeat,
            _ => Wrap::Mirror,
        };
        // RGB variants use three-channel data as it is; the acceleration
        // flag of Mitsuba's GPU texture has no meaning here
        node.bool("raw", false)?;
        node.bool("accel", true)?;
        let mut to_world = node.transform("to_world")?;
        if node.bool("use_grid_bbox", false)? {
            let (lo, hi) = file.bbox;
            let extent = hi - lo;
            if !(extent.min_element() > 0.0) {
                return Err(node.error(format!(
                    "use_grid_bbox: the file's bounding box {lo}..{hi} is empty"
                )));
            }
            let to_bbox = Transform::translate(lo).after(&Transform::scale(extent));
            to_world = to_world.after(&to_bbox);
        }
        let [x, y, z] = file.res;
        let data = ctx
            .store
            .add(
                format!("{}.data", node.key),
                file.data,
                vec![z, y, x, file.channels],
                ParamFlags::DIFFERENTIABLE,
                domain,
            )
            .map_err(|e| node.error(format!("{e} (file {})", path.display())))?;
        Ok(GridVolume {
            data,
            res: file.res,
            channels: file.channels,
            to_local: to_world.inverse(),
            bbox: transformed_unit_cube(&to_world),
            filter,
            wrap,
        })
    }

    pub fn bbox(&self) -> (Vec3, Vec3) {
        self.bbox
    }

    /// The value at world-space point `p`, read from the store in `R`.
    #[inline]
    pub fn eval<R: ScalarReal>(&self, store: &ParamView, p: Vec3) -> Spectrum<R> {
        let q = self.to_local.point(p);
        let res = Vec3::new(self.res[0] as f32, self.res[1] as f32, self.res[2] as f32);
        let x = q * res - 0.5;
        match self.filter {
            Filter::Nearest => {
                let i = x.round();
                self.voxel(store, [i.x as i64, i.y as i64, i.z as i64])
            }
            Filter::Trilinear => {
                // per axis: the two voxels around x (wrapped) and their
                // weights, the three axes at once
                let lo = [floor_i64(x.x), floor_i64(x.y), floor_i64(x.z)];
                let f = x - Vec3::new(lo[0] as f32, lo[1] as f32, lo[2] as f32);
                let g = Vec3::ONE - f;
                let pair = |a: usize| {
                    let (i, n) = (lo[a], self.res[a]);
                    [self.wrap.index(i, n), self.wrap.index(i + 1, n)]
                };
                let (ix, iy, iz) = (pair(0), pair(1), pair(2));
                let (wx, wy, wz) = ([g.x, f.x], [g.y, f.y], [g.z, f.z]);
                let [nx, ny, _] = self.res;
                let mut terms = [(0usize, 0.0f32); 8];
                for (corner, term) in terms.iter_mut().enumerate() {
                    let (dx, dy, dz) = (corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
                    *term = (
                        (iz[dz] * ny + iy[dy]) * nx + ix[dx],
                        wx[dx] * wy[dy] * wz[dz],
                    );
                }
                if self.channels == 1 {
                    V3::splat(R::param_sum(store, self.data, &terms))
                } else {
                    let channel = |c: usize| {
                        R::param_sum(store, self.data, &terms.map(|(i, w)| (3 * i + c, w)))
                    };
                    V3::new(channel(0), channel(1), channel(2))
                }
            }
        }
    }

    /// The value of voxel `i` (x, y, z; wrapped into the grid).
    #[inline]
    fn voxel<R: ScalarReal>(&self, store: &ParamView, i: [i64; 3]) -> Spectrum<R> {
        let [nx, ny, nz] = self.res;
        let (x, y, z) = (
            self.wrap.index(i[0], nx),
            self.wrap.index(i[1], ny),
            self.wrap.index(i[2], nz),
        );
        let at = (z * ny + y) * nx + x;
        if self.channels == 1 {
            V3::splat(store.read(self.data, at))
        } else {
            store.read3(self.data, at)
        }
    }

    pub fn max(&self, store: &ParamStore) -> f32 {
        store.data(self.data).iter().copied().fold(0.0, f32::max)
    }

    /// World to the grid's unit cube.
    pub fn to_local(&self) -> &Transform {
        &self.to_local
    }

    /// For a coarse grid over the unit cube, `cells` along each axis of `k`
    /// voxels each (the last may reach past the grid), the largest value
    /// (over channels) that a lookup at a point of each cell can read:
    /// a point in cell c of an axis reads voxels c·k − 1 ..= (c+1)·k,
    /// wrapped (trilinear lookups reach the voxel on each side; nearest
    /// lookups at the cell's faces too). Row-major `[z, y, x]`; computed
    /// one axis at a time.
    pub fn cell_maxima(&self, store: &ParamStore, k: [usize; 3], cells: [usize; 3]) -> Vec<f32> {
        let data = store.data(self.data);
        let [nx, ny, nz] = self.res;
        let [cx, cy, cz] = cells;
        // per axis and cell, the voxels the cell reads
        let reach: Vec<Vec<Vec<usize>>> = (0..3)
            .map(|a| {
                (0..cells[a])
                    .map(|c| {
                        let (lo, hi) = ((c * k[a]) as i64 - 1, ((c + 1) * k[a]) as i64);
                        (lo..=hi).map(|i| self.wrap.index(i, self.res[a])).collect()
                    })
                    .collect()
            })
            .collect();
        let ch = self.channels;
        let voxel = |i: usize| {
            data[ch * i..ch * (i + 1)]
                .iter()
                .copied()
                .fold(0.0, f32::max)
        };
        // along x: [z, y, cell x]
        let mut along_x = vec![0.0f32; nz * ny * cx];
        for (row, out) in along_x.chunks_exact_mut(cx).enumerate() {
            for (c, m) in out.iter_mut().enumerate() {
                *m = reach[0][c]
                    .iter()
                    .map(|&x| voxel(row * nx + x))
                    .fold(0.0, f32::max);
            }
        }
        // along y: [z, cell y, cell x]
        let mut along_y = vec![0.0f32; nz * cy * cx];
        for z in 0..nz {
            for c in 0..cy {
                for x in 0..cx {
                    along_y[(z * cy + c) * cx + x] = reach[1][c]
                        .iter()
                        .map(|&y| along_x[(z * ny + y) * cx + x])
                        .fold(0.0, f32::max);
                }
            }
        }
        // along z: [cell z, cell y, cell x]
        let mut cellmax = vec![0.0f32; cz * cy * cx];
        for c in 0..cz {
            for yx in 0..cy * cx {
                cellmax[c * cy * cx + yx] = reach[2][c]
                    .iter()
                    .map(|&z| along_y[z * cy * cx + yx])
                    .fold(0.0, f32::max);
            }
        }
        cellmax
    }
}

/// The axis-aligned box around the image of the unit cube.
fn transformed_unit_cube(to_world: &Transform) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for corner in 0..8 {
        let c = Vec3::new(
            (corner & 1) as f32,
            ((corner >> 1) & 1) as f32,
            ((corner >> 2) & 1) as f32,
        );
        let p = to_world.point(c);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A .vol file of `res` voxels with the given values.
    pub(crate) fn vol_bytes(res: [i32; 3], channels: i32, data: &[f32]) -> Vec<u8> {
        let mut b = b"VOL\x03".to_vec();
        for v in [1, res[0], res[1], res[2], channels] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0].iter().chain(data) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    }

    #[test]
    fn vol_files_are_read_and_bad_ones_refused() {
        let data: Vec<f32> = (0..24).map(|i| i as f32).collect();
        let f = VolFile::parse(&vol_bytes([2, 3, 4], 1, &data)).unwrap();
        assert_eq!((f.res, f.channels, f.data.len()), ([2, 3, 4], 1, 24));
        assert_eq!(f.data[23], 23.0);
        let e = VolFile::parse(&vol_bytes([2, 3, 4], 1, &data[..20])).unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        let e = VolFile::parse(b"VOX\x03 and more bytes than the header needs.......").unwrap_err();
        assert!(e.contains("'VOL'"), "{e}");
        let e = VolFile::parse(&vol_bytes([2, 3, 4], 2, &data)).unwrap_err();
        assert!(e.contains("channel"), "{e}");
    }

    #[test]
    fn wrap_modes_map_indices_into_the_grid() {
        let n = 4;
        let got: Vec<_> = (-3..7).map(|i| Wrap::Clamp.index(i, n)).collect();
        assert_eq!(got, [0, 0, 0, 0, 1, 2, 3, 3, 3, 3]);
        let got: Vec<_> = (-3..7).map(|i| Wrap::Repeat.index(i, n)).collect();
        assert_eq!(got, [1, 2, 3, 0, 1, 2, 3, 0, 1, 2]);
        let got: Vec<_> = (-3..7).map(|i| Wrap::Mirror.index(i, n)).collect();
        assert_eq!(got, [2, 1, 0, 0, 1, 2, 3, 3, 2, 1]);
    }
}
