//! A latent rigid pose (translation `t`, rotation vector `r` in radians,
//! about a pivot `c`) mapped onto a parameter, so that an optimiser can
//! recover where an object or the camera is instead of moving raw values:
//!
//! - vertex positions (`[n, 3]`): `p = R(r)·(p0 − c) + c + t`;
//! - directions such as vertex normals (`[n, 3]`): `n = R(r)·n0`;
//! - a transform (`[4, 4]`, row-major, e.g. `to_world`):
//!   `M = T(t)·T(c)·R(r)·T(−c)·M0`.
//!
//! All three are one map on homogeneous columns `(a, w)`: `a ↦ R(r)·(a −
//! w·c) + w·(c + t)` (positions have `w = 1`, directions `w = 0`, and a
//! matrix's columns carry their own `w` in its last row), so one
//! implementation serves them and their gradients.
//!
//! `R(r)` is Rodrigues' rotation by `|r|` about `r/|r|`. The gradient with
//! respect to `r` uses the closed form of Gallego & Yezzi 2015 ("A compact
//! formula for the derivative of a 3-D rotation in exponential
//! coordinates", J. Math. Imaging Vis. 51): `∂R/∂r_i = [a_i]_× R` with
//! `a_i = (r_i·r + r × (I − R)·e_i) / |r|²`, i.e. `a_i` is column `i` of the
//! left Jacobian `J(r) = (r·rᵀ + [r]_×(I − R)) / |r|²`. For an output `y =
//! R·u` with loss gradient `g`, `∂L/∂r_i = g·(a_i × y) = a_i·(y × g)`, so
//! `∂L/∂r = J(r)ᵀ·Σ (y × g)`: the torque of the gradients about the pivot,
//! mapped through `Jᵀ` (at `r = 0`, `J = I`).

use crate::diff::Gradients;
use crate::error::{Error, Result};
use crate::params::ParamStore;
use glam::{DMat3, DVec3};

/// How a parameter's values are laid out for a pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseLayout {
    /// `[n, 3]` points: rotated about the pivot and translated.
    Points,
    /// `[n, 3]` directions (normals): rotated only.
    Directions,
    /// A `[4, 4]` row-major transform, composed on the left.
    Matrix,
}

/// The latent pose: translation and rotation vector (radians), and the
/// fixed pivot of the rotation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    pub translation: DVec3,
    pub rotation: DVec3,
    pub pivot: DVec3,
}

/// `∂L/∂t` and `∂L/∂r` of a [`Pose`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseGrad {
    pub translation: DVec3,
    pub rotation: DVec3,
}

impl PoseLayout {
    /// The layout of the parameter `key` of `shape`: a mesh's
    /// `<id>.vertex_positions` (`[n, 3]`) or a `[4, 4]` `<id>.to_world`
    /// (a shape's, or a sensor's); anything else is refused, naming both.
    pub fn of_param(key: &str, shape: &[usize]) -> Result<PoseLayout> {
        let refuse = |what: &str| Error::Param {
            key: key.to_string(),
            msg: format!(
                "a pose moves a mesh's `<id>.vertex_positions` ([n, 3]) or a `<id>.to_world` \
                 transform ([4, 4]); {what}"
            ),
        };
        if key.ends_with(".vertex_positions") {
            match shape {
                [_, 3] => Ok(PoseLayout::Points),
                _ => Err(refuse(&format!("this one has shape {shape:?}"))),
            }
        } else if key.ends_with(".to_world") {
            match shape {
                [4, 4] => Ok(PoseLayout::Matrix),
                _ => Err(refuse(&format!("this one has shape {shape:?}"))),
            }
        } else {
            Err(refuse("this key is neither"))
        }
    }
}

/// The vertex normals that turn with the vertex positions `key`
/// (`<id>.vertex_normals`), if `key` is a mesh's positions.
pub fn normals_key(key: &str) -> Option<String> {
    key.strip_suffix(".vertex_positions")
        .map(|id| format!("{id}.vertex_normals"))
}

/// A pose bound to a parameter of a store: the parameter's pose-free
/// values (those it had when bound) and, for a mesh with vertex normals,
/// the normals, turned with the positions and set together with them so
/// that the mesh does not recompute them.
#[derive(Clone, Debug)]
pub struct PosedParam {
    pub key: String,
    pub layout: PoseLayout,
    pub base: Vec<f32>,
    pub normals: Option<(String, Vec<f32>)>,
    pub pivot: DVec3,
}

impl PosedParam {
    /// Binds to `key` of `store` as it is now; `pivot` defaults to
    /// [`Pose::default_pivot`].
    pub fn new(store: &ParamStore, key: &str, pivot: Option<DVec3>) -> Result<PosedParam> {
        let p = store.get(store.require(key)?);
        let layout = PoseLayout::of_param(key, &p.shape)?;
        let normals = normals_key(key)
            .and_then(|k| store.id(&k).map(|id| (k.clone(), store.data(id).to_vec())));
        Ok(PosedParam {
            key: key.to_string(),
            layout,
            pivot: pivot.unwrap_or_else(|| Pose::default_pivot(layout, &p.data)),
            base: p.data.clone(),
            normals,
        })
    }

    /// The keys this pose writes (and whose gradients it reads).
    pub fn keys(&self) -> Vec<&str> {
        std::iter::once(self.key.as_str())
            .chain(self.normals.as_ref().map(|(k, _)| k.as_str()))
            .collect()
    }

    fn pose(&self, translation: DVec3, rotation: DVec3) -> Pose {
        Pose {
            translation,
            rotation,
            pivot: self.pivot,
        }
    }

    /// Writes the posed values into `store` (call `Scene::update` after).
    pub fn apply(&self, store: &mut ParamStore, translation: DVec3, rotation: DVec3) -> Result<()> {
        let pose = self.pose(translation, rotation);
        store.set(&self.key, &pose.apply(self.layout, &self.base))?;
        if let Some((k, n0)) = &self.normals {
            store.set(k, &pose.apply(PoseLayout::Directions, n0))?;
        }
        Ok(())
    }

    /// `∂L/∂(t, r)` from the parameters' gradients `grads` at the values
    /// [`PosedParam::apply`] wrote for the same `(translation, rotation)`.
    pub fn backprop(
        &self,
        grads: &Gradients,
        translation: DVec3,
        rotation: DVec3,
    ) -> Result<PoseGrad> {
        let pose = self.pose(translation, rotation);
        let get = |k: &str| {
            grads.get(k).ok_or_else(|| Error::Param {
                key: k.to_string(),
                msg: "no gradient was computed for this parameter".into(),
            })
        };
        let mut g = pose.backprop(self.layout, &self.base, get(&self.key)?);
        if let Some((k, n0)) = &self.normals {
            g += pose.backprop(PoseLayout::Directions, n0, get(k)?);
        }
        Ok(g)
    }
}

impl std::ops::AddAssign for PoseGrad {
    fn add_assign(&mut self, o: PoseGrad) {
        self.translation += o.translation;
        self.rotation += o.rotation;
    }
}

/// Below this angle (radians) `J(r)` uses its Taylor series: the closed
/// form divides by `|r|²` and loses all digits as `r → 0`.
const SMALL_ANGLE: f64 = 1e-4;

/// Rodrigues' rotation matrix of the rotation vector `r` (radians).
pub fn rotation_matrix(r: DVec3) -> DMat3 {
    let angle = r.length();
    if angle == 0.0 {
        DMat3::IDENTITY
    } else {
        DMat3::from_axis_angle(r / angle, angle)
    }
}

fn cross_matrix(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// The left Jacobian `J(r)` of Gallego & Yezzi 2015 (see the module
/// documentation): `∂(R(r)·u)/∂r = −[R(r)·u]_× · J(r)`.
fn left_jacobian(r: DVec3) -> DMat3 {
    let k = cross_matrix(r);
    let a2 = r.length_squared();
    if a2.sqrt() < SMALL_ANGLE {
        // series of I + (1 − cos θ)/θ² K + (θ − sin θ)/θ³ K²; the first
        // omitted term is O(θ³)
        DMat3::IDENTITY + k * 0.5 + k * k * (1.0 / 6.0)
    } else {
        let rrt = DMat3::from_cols(r * r.x, r * r.y, r * r.z);
        (rrt + k * (DMat3::IDENTITY - rotation_matrix(r))) * (1.0 / a2)
    }
}

/// The homogeneous columns `(a, w)` of `values` in `layout`, and where
/// each of their three coordinates lives in `values`.
fn columns(layout: PoseLayout, values: &[f32]) -> Vec<(DVec3, f64, [usize; 3])> {
    match layout {
        PoseLayout::Points | PoseLayout::Directions => {
            let w = if layout == PoseLayout::Points {
                1.0
            } else {
                0.0
            };
            (0..values.len() / 3)
                .map(|i| {
                    let idx = [3 * i, 3 * i + 1, 3 * i + 2];
                    (vec_at(values, idx), w, idx)
                })
                .collect()
        }
        PoseLayout::Matrix => (0..4)
            .map(|j| {
                let idx = [j, 4 + j, 8 + j];
                (vec_at(values, idx), values[12 + j] as f64, idx)
            })
            .collect(),
    }
}

fn vec_at(values: &[f32], idx: [usize; 3]) -> DVec3 {
    DVec3::new(
        values[idx[0]] as f64,
        values[idx[1]] as f64,
        values[idx[2]] as f64,
    )
}

impl Pose {
    /// Checks that `values` fit `layout` (a multiple of 3, or 16).
    pub fn check_len(layout: PoseLayout, len: usize) -> Result<(), String> {
        match layout {
            PoseLayout::Matrix if len != 16 => Err(format!(
                "a transform pose needs a [4, 4] matrix (16 values), found {len}"
            )),
            PoseLayout::Points | PoseLayout::Directions if !len.is_multiple_of(3) => Err(format!(
                "a vertex pose needs [n, 3] values, found {len} (not a multiple of 3)"
            )),
            _ => Ok(()),
        }
    }

    /// The default pivot for `base` in `layout`: the centroid of points,
    /// the origin of a transform's frame (its translation, so a camera
    /// turns about its own position), zero for directions (unused).
    pub fn default_pivot(layout: PoseLayout, base: &[f32]) -> DVec3 {
        match layout {
            PoseLayout::Points => {
                let cols = columns(layout, base);
                let n = cols.len().max(1) as f64;
                cols.iter().map(|c| c.0).sum::<DVec3>() / n
            }
            PoseLayout::Matrix => {
                let (origin, w, _) = columns(layout, base)[3];
                if w != 0.0 {
                    origin / w
                } else {
                    origin
                }
            }
            PoseLayout::Directions => DVec3::ZERO,
        }
    }

    /// The posed values of the parameter whose pose-free values are `base`.
    pub fn apply(&self, layout: PoseLayout, base: &[f32]) -> Vec<f32> {
        let rot = rotation_matrix(self.rotation);
        let mut out = base.to_vec();
        for (a, w, idx) in columns(layout, base) {
            let y = rot * (a - w * self.pivot) + w * (self.pivot + self.translation);
            for (k, i) in idx.into_iter().enumerate() {
                out[i] = y[k] as f32;
            }
        }
        out
    }

    /// `∂L/∂(t, r)` from `grad` = `∂L/∂values` at the values
    /// `self.apply(layout, base)` (the chain rule through [`Pose::apply`]).
    pub fn backprop(&self, layout: PoseLayout, base: &[f32], grad: &[f32]) -> PoseGrad {
        let rot = rotation_matrix(self.rotation);
        let (mut d_t, mut torque) = (DVec3::ZERO, DVec3::ZERO);
        for (a, w, idx) in columns(layout, base) {
            let g = vec_at(grad, idx);
            // the rotated part y = R·(a − w·c); the translated part adds w·g
            let y = rot * (a - w * self.pivot);
            d_t += w * g;
            torque += y.cross(g);
        }
        PoseGrad {
            translation: d_t,
            rotation: left_jacobian(self.rotation).transpose() * torque,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base(layout: PoseLayout) -> Vec<f32> {
        match layout {
            PoseLayout::Points => vec![
                0.3, -1.2, 0.5, 1.1, 0.4, -0.7, -0.6, 0.9, 1.3, 0.2, 0.1, 0.0,
            ],
            PoseLayout::Directions => {
                let n = [DVec3::new(0.2, 0.9, -0.3), DVec3::new(-0.8, 0.1, 0.5)];
                n.iter()
                    .flat_map(|v| v.normalize().to_array().map(|x| x as f32))
                    .collect()
            }
            // a scaled, rotated frame at (1, 2, -3), with a non-unit w row
            // so that the general homogeneous case is exercised
            PoseLayout::Matrix => vec![
                0.0, -2.0, 0.0, 1.0, //
                1.5, 0.0, 0.0, 2.0, //
                0.0, 0.0, 0.8, -3.0, //
                0.1, 0.0, 0.2, 1.0,
            ],
        }
    }

    /// A fixed linear loss L = Σ wᵢ·valuesᵢ, so ∂L/∂values = w.
    fn weights(n: usize) -> Vec<f32> {
        (0..n).map(|i| ((i * 7 % 11) as f32 - 5.0) / 5.0).collect()
    }

    fn loss(pose: &Pose, layout: PoseLayout, b: &[f32], w: &[f32]) -> f64 {
        // in f64 so that central differences keep their digits
        let rot = rotation_matrix(pose.rotation);
        columns(layout, b)
            .into_iter()
            .map(|(a, cw, idx)| {
                let y = rot * (a - cw * pose.pivot) + cw * (pose.pivot + pose.translation);
                (0..3).map(|k| y[k] * w[idx[k]] as f64).sum::<f64>()
            })
            .sum()
    }

    /// The analytic gradient matches central differences for all layouts,
    /// at zero rotation, small rotations (the series branch) and large ones.
    #[test]
    fn backprop_matches_finite_differences() {
        let rotations = [
            DVec3::ZERO,
            DVec3::new(3e-5, -2e-5, 1e-5),
            DVec3::new(0.3, -0.5, 0.2),
            DVec3::new(-1.9, 0.7, 2.2),
        ];
        for layout in [
            PoseLayout::Points,
            PoseLayout::Directions,
            PoseLayout::Matrix,
        ] {
            let b = base(layout);
            let w = weights(b.len());
            for r in rotations {
                let pose = Pose {
                    translation: DVec3::new(0.1, -0.2, 0.4),
                    rotation: r,
                    pivot: DVec3::new(0.5, 0.25, -1.0),
                };
                let g = pose.backprop(layout, &b, &w);
                let h = 1e-6;
                for k in 0..6 {
                    let mut e = [0.0; 6];
                    e[k] = h;
                    let shifted = |s: f64| Pose {
                        translation: pose.translation + s * DVec3::new(e[0], e[1], e[2]),
                        rotation: pose.rotation + s * DVec3::new(e[3], e[4], e[5]),
                        ..pose
                    };
                    let fd = (loss(&shifted(1.0), layout, &b, &w)
                        - loss(&shifted(-1.0), layout, &b, &w))
                        / (2.0 * h);
                    let an = if k < 3 {
                        g.translation[k]
                    } else {
                        g.rotation[k - 3]
                    };
                    assert!(
                        (an - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                        "{layout:?} r={r:?} component {k}: analytic {an}, fd {fd}"
                    );
                }
            }
        }
    }

    /// At r = 0 the rotation gradient is the plain torque Σ y × g (the
    /// derivative of R·u is the cross-product matrix −[u]_×).
    #[test]
    fn zero_rotation_gradient_is_the_torque() {
        let b = base(PoseLayout::Points);
        let w = weights(b.len());
        let pose = Pose {
            pivot: Pose::default_pivot(PoseLayout::Points, &b),
            ..Default::default()
        };
        let g = pose.backprop(PoseLayout::Points, &b, &w);
        let torque: DVec3 = b
            .chunks_exact(3)
            .zip(w.chunks_exact(3))
            .map(|(p, g)| {
                let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) - pose.pivot;
                p.cross(DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64))
            })
            .sum();
        assert!((g.rotation - torque).length() < 1e-9, "{g:?} vs {torque}");
    }

    /// Applying a pose keeps lengths and the pivot, translates the pivot by
    /// t, and on a transform equals T(t)·T(c)·R·T(−c)·M0.
    #[test]
    fn apply_is_the_rigid_motion() {
        let pose = Pose {
            translation: DVec3::new(0.5, 0.0, -1.0),
            rotation: DVec3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0),
            pivot: DVec3::new(1.0, 0.0, 0.0),
        };
        // the pivot itself only translates; a point 1 along +z from it
        // turns to +x (a quarter turn about +y)
        let p = pose.apply(PoseLayout::Points, &[1.0, 0.0, 0.0, 1.0, 0.0, 1.0]);
        let want = [1.5, 0.0, -1.0, 2.5, 0.0, -1.0];
        for (a, b) in p.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{p:?}");
        }
        let n = pose.apply(PoseLayout::Directions, &[0.0, 0.0, 1.0]);
        assert!((n[0] - 1.0).abs() < 1e-6 && n[2].abs() < 1e-6, "{n:?}");
        let m0 = base(PoseLayout::Matrix);
        let m = pose.apply(PoseLayout::Matrix, &m0);
        let mat = |v: &[f32]| {
            glam::DMat4::from_cols_array(&std::array::from_fn(|i| v[i] as f64)).transpose()
        };
        let m0m = mat(&m0);
        let c = pose.pivot;
        let want = glam::DMat4::from_translation(pose.translation + c)
            * glam::DMat4::from_mat3(rotation_matrix(pose.rotation))
            * glam::DMat4::from_translation(-c)
            * m0m;
        let got = mat(&m);
        assert!(got.abs_diff_eq(want, 1e-5), "{got} vs {want}");
        assert_eq!(
            Pose::default_pivot(PoseLayout::Matrix, &m0),
            DVec3::new(1.0, 2.0, -3.0)
        );
    }

    /// A bound mesh pose turns the vertex normals with the positions, and
    /// its gradient adds the normals' torque; other keys are refused.
    #[test]
    fn posed_mesh_turns_its_normals() {
        use crate::params::{Domain, ParamFlags};
        let mut store = ParamStore::new();
        let f = ParamFlags::DIFFERENTIABLE;
        let pos = base(PoseLayout::Points);
        let nrm = [0.0, 1.0, 0.0].repeat(4);
        store
            .add(
                "m.vertex_positions",
                pos.clone(),
                vec![4, 3],
                f,
                Domain::Finite,
            )
            .unwrap();
        store
            .add(
                "m.vertex_normals",
                nrm.clone(),
                vec![4, 3],
                f,
                Domain::Finite,
            )
            .unwrap();
        store
            .add(
                "m.bsdf.value",
                vec![0.5; 3],
                vec![3],
                f,
                Domain::UnitInterval,
            )
            .unwrap();
        let b = PosedParam::new(&store, "m.vertex_positions", None).unwrap();
        assert_eq!(b.keys(), ["m.vertex_positions", "m.vertex_normals"]);
        let r = DVec3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        b.apply(&mut store, DVec3::ZERO, r).unwrap();
        let n = store.data(store.id("m.vertex_normals").unwrap());
        assert!((n[0] + 1.0).abs() < 1e-6 && n[1].abs() < 1e-6, "{n:?}");
        let grads = Gradients {
            entries: vec![
                crate::diff::GradEntry {
                    key: "m.vertex_positions".into(),
                    shape: vec![4, 3],
                    data: vec![0.0; 12],
                },
                crate::diff::GradEntry {
                    key: "m.vertex_normals".into(),
                    shape: vec![4, 3],
                    data: weights(12),
                },
            ],
            ..Default::default()
        };
        let g = b.backprop(&grads, DVec3::ZERO, r).unwrap();
        let want = b
            .pose(DVec3::ZERO, r)
            .backprop(PoseLayout::Directions, &nrm, &weights(12));
        assert_eq!(g, want);
        assert!(g.rotation.length() > 0.0);
        let e = PosedParam::new(&store, "m.bsdf.value", None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("neither"), "{e}");
    }
}
