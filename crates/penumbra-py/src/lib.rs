//! `penumbra._core`: the native half of the Python package `penumbra`.
//!
//! Thin bindings of the Rust library: scenes (load, parameters, update),
//! primal / forward-mode / reverse-mode rendering, image IO. Everything a
//! user sees (Mitsuba-style dicts, `traverse`, torch, optimisers) is built
//! on top in `python/penumbra`. Long computations run on a worker thread
//! with the GIL released while the calling thread polls for Ctrl-C and
//! reports progress; Rust errors become Python exceptions, and a panic in
//! the library becomes a `RuntimeError` instead of killing the interpreter.

use glam::{Vec2, Vec3};
use numpy::ndarray::{ArrayView, Dimension, Ix1, Ix2};
use numpy::{
    AllowTypeChange, PyArray, PyArray1, PyArrayDyn, PyArrayLike, PyArrayMethods, PyReadonlyArray,
    PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use penumbra::diff::{gradient_seed as derive_gradient_seed, render_backward, render_forward};
use penumbra::geometry::Ray;
use penumbra::image::{self, Image};
use penumbra::integrator::{render, Integrator, RenderOptions, Rendered};
use penumbra::optim::pose::{normals_key, Pose, PoseLayout};
use penumbra::params::Domain;
use penumbra::scene::{Class, Scene, RAYS_PER_TASK};
use penumbra::Error;
use pyo3::create_exception;
use pyo3::exceptions::{PyKeyError, PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

create_exception!(
    penumbra,
    SceneError,
    PyValueError,
    "A scene description (file, string or dict) is invalid; the message names the place."
);
create_exception!(
    penumbra,
    ParamError,
    PyValueError,
    "A parameter value or tangent is invalid (shape, domain, non-finite value, read-only)."
);
create_exception!(
    penumbra,
    FileError,
    PyOSError,
    "A file could not be read or written (missing, unreadable, unsupported format)."
);

/// Converts a library error into the matching Python exception.
fn to_py(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Scene { .. } => SceneError::new_err(msg),
        Error::File { .. } => FileError::new_err(msg),
        Error::Param { .. } => ParamError::new_err(msg),
        Error::Invalid(_) => PyValueError::new_err(msg),
        Error::Interrupted => PyKeyboardInterrupt::new_err("rendering interrupted"),
    }
}

/// How a long computation reports progress.
enum Progress<'py> {
    None,
    /// A text bar on stderr.
    Bar(&'static str),
    /// A Python callable `f(done, total)`.
    Call(Bound<'py, PyAny>),
}

impl<'py> Progress<'py> {
    fn from_arg(arg: Option<&Bound<'py, PyAny>>, label: &'static str) -> PyResult<Self> {
        let Some(a) = arg else {
            return Ok(Progress::None);
        };
        if a.is_none() {
            return Ok(Progress::None);
        }
        if a.is_callable() {
            return Ok(Progress::Call(a.clone()));
        }
        Ok(if a.is_truthy()? {
            Progress::Bar(label)
        } else {
            Progress::None
        })
    }
}

/// Runs `job` on a worker thread with the GIL released; meanwhile the
/// calling thread wakes every 50 ms to check for signals (Ctrl-C sets the
/// cancel flag and the job stops at the next tile) and to report progress.
fn run_detached<T, F>(
    py: Python<'_>,
    mut opts: RenderOptions,
    progress: &Progress<'_>,
    job: F,
) -> PyResult<T>
where
    T: Send,
    F: FnOnce(&RenderOptions) -> penumbra::Result<T> + Send,
{
    let cancel = Arc::new(AtomicBool::new(false));
    let counts = Arc::new((AtomicUsize::new(0), AtomicUsize::new(0)));
    opts.cancel = Some(cancel.clone());
    if !matches!(progress, Progress::None) {
        let c = counts.clone();
        opts.progress = Some(Arc::new(move |done, total| {
            c.0.store(done, Ordering::Relaxed);
            c.1.store(total, Ordering::Relaxed);
        }));
    }
    let finished = (Mutex::new(false), Condvar::new());
    let mut pending: Option<PyErr> = None;
    let mut shown = (usize::MAX, usize::MAX);
    let start = Instant::now();
    let outcome = std::thread::scope(|s| {
        let handle = s.spawn(|| {
            let r = job(&opts);
            *finished.0.lock().unwrap_or_else(|p| p.into_inner()) = true;
            finished.1.notify_all();
            r
        });
        loop {
            let over = py.detach(|| {
                let g = finished.0.lock().unwrap_or_else(|p| p.into_inner());
                let (g, _) = finished
                    .1
                    .wait_timeout_while(g, Duration::from_millis(50), |done| !*done)
                    .unwrap_or_else(|p| p.into_inner());
                *g
            });
            let now = (
                counts.0.load(Ordering::Relaxed),
                counts.1.load(Ordering::Relaxed),
            );
            if now != shown && now.1 > 0 && pending.is_none() {
                shown = now;
                match progress {
                    Progress::None => {}
                    Progress::Bar(label) => {
                        let pct = 100 * now.0 / now.1;
                        let bar: String = (0..30)
                            .map(|i| if i * 100 < pct * 30 { '#' } else { '.' })
                            .collect();
                        let mut err = std::io::stderr().lock();
                        let _ = write!(
                            err,
                            "\r{label} [{bar}] {pct:3}% ({:.1} s)",
                            start.elapsed().as_secs_f64()
                        );
                        let _ = err.flush();
                    }
                    Progress::Call(f) => {
                        if let Err(e) = f.call1((now.0, now.1)) {
                            cancel.store(true, Ordering::Relaxed);
                            pending = Some(e);
                        }
                    }
                }
            }
            if over {
                break;
            }
            if pending.is_none() {
                if let Err(e) = py.check_signals() {
                    cancel.store(true, Ordering::Relaxed);
                    pending = Some(e);
                }
            }
        }
        handle.join()
    });
    if let Progress::Bar(_) = progress {
        let _ = writeln!(std::io::stderr());
    }
    if let Some(e) = pending {
        return Err(e);
    }
    match outcome {
        Ok(r) => r.map_err(to_py),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in the renderer (please report it): {what}"
            )))
        }
    }
}

/// A numpy float32 array of the given shape holding `data`.
fn array<'py>(
    py: Python<'py>,
    data: Vec<f32>,
    shape: Vec<usize>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    PyArray1::from_vec(py, data).reshape(shape)
}

fn image_array<'py>(py: Python<'py>, r: Rendered) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let c = r.channels();
    array(py, r.data, vec![r.height, r.width, c])
}

/// The data of a float32 array in row-major order (copied, so that it can
/// cross threads).
fn to_vec(a: &PyReadonlyArrayDyn<'_, f32>) -> Vec<f32> {
    match a.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => a.as_array().iter().copied().collect(),
    }
}

/// An integrator plugin built from a description (`{'type': 'path', …}`
/// or `<integrator>` XML); passed to the render functions to override the
/// scene's own integrator.
#[pyclass(name = "Integrator", module = "penumbra._core", frozen)]
struct PyIntegrator {
    inner: Integrator,
}

#[pymethods]
impl PyIntegrator {
    fn __repr__(&self) -> String {
        // Mitsuba's max_depth: -1 for unbounded
        let depth = |d: u32| if d == u32::MAX { -1 } else { d as i64 };
        match &self.inner {
            Integrator::Path(p) => format!(
                "Integrator(path, max_depth={}, rr_depth={}, hide_emitters={})",
                depth(p.max_depth),
                p.rr_depth,
                p.hide_emitters
            ),
            Integrator::VolPath(v) => format!(
                "Integrator(volpath, max_depth={}, rr_depth={}, hide_emitters={})",
                depth(v.max_depth),
                v.rr_depth,
                v.hide_emitters
            ),
            Integrator::Direct(_) => "Integrator(direct)".into(),
            Integrator::Aov(a) => format!("Integrator(aov, channels={:?})", a.channel_names()),
            Integrator::Moment(m) => {
                format!("Integrator(moment, channels={:?})", m.channel_names())
            }
        }
    }
}

/// A float array argument of `ray_intersect` / `ray_test`. float32 and
/// float64 arrays are read in place (float64 rounded to float32 per
/// element, as numpy's `astype(float32)` rounds): numpy's conversion would
/// be a pass over the rays on the calling thread. Anything else (lists,
/// other dtypes) is converted to float32 by numpy.
enum Floats<'py, D: Dimension> {
    F32(PyArrayLike<'py, f32, D, AllowTypeChange>),
    F64(PyReadonlyArray<'py, f64, D>),
}

impl<'py, D: Dimension + 'static> Floats<'py, D> {
    fn extract(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(a) = obj.cast::<PyArray<f64, D>>() {
            return Ok(Floats::F64(a.try_readonly()?));
        }
        obj.extract().map(Floats::F32).map_err(|e| {
            let msg = format!("argument '{name}': {}", e.value(obj.py()));
            PyErr::from_type(e.get_type(obj.py()), msg)
        })
    }

    fn view(&self) -> FloatView<'_, D> {
        let (shape, data) = match self {
            Floats::F32(a) => {
                let v = a.as_array();
                let shape = v.shape().to_vec();
                (
                    shape,
                    v.to_slice().map_or(Data::Strided32(v), Data::Packed32),
                )
            }
            Floats::F64(a) => {
                let v = a.as_array();
                let shape = v.shape().to_vec();
                (
                    shape,
                    v.to_slice().map_or(Data::Strided64(v), Data::Packed64),
                )
            }
        };
        FloatView { shape, data }
    }
}

/// A view of a [`Floats`], read as float32: row-major contiguous data (the
/// usual case) as a slice, indexed directly; anything else strided.
struct FloatView<'a, D: Dimension> {
    shape: Vec<usize>,
    data: Data<'a, D>,
}

enum Data<'a, D: Dimension> {
    Packed32(&'a [f32]),
    Packed64(&'a [f64]),
    Strided32(ArrayView<'a, f32, D>),
    Strided64(ArrayView<'a, f64, D>),
}

impl FloatView<'_, Ix2> {
    /// Calls `f(k, row)` for rows `first + k`, `k < n`, of an `(N, 3)`
    /// array: the array's kind is matched once, not per row (a per-row
    /// match and bounds checks cost a tenth of a ray's traversal).
    #[inline]
    fn rows3(&self, first: usize, n: usize, mut f: impl FnMut(usize, Vec3)) {
        match &self.data {
            Data::Packed32(s) => {
                for (k, r) in s[3 * first..3 * (first + n)].chunks_exact(3).enumerate() {
                    f(k, Vec3::new(r[0], r[1], r[2]));
                }
            }
            Data::Packed64(s) => {
                for (k, r) in s[3 * first..3 * (first + n)].chunks_exact(3).enumerate() {
                    f(k, Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32));
                }
            }
            Data::Strided32(a) => {
                for k in 0..n {
                    let i = first + k;
                    f(k, Vec3::new(a[[i, 0]], a[[i, 1]], a[[i, 2]]));
                }
            }
            Data::Strided64(a) => {
                for k in 0..n {
                    let i = first + k;
                    f(
                        k,
                        Vec3::new(a[[i, 0]] as f32, a[[i, 1]] as f32, a[[i, 2]] as f32),
                    );
                }
            }
        }
    }
}

impl FloatView<'_, Ix1> {
    /// Calls `f(k, value)` for elements `first + k`, `k < n`.
    #[inline]
    fn values(&self, first: usize, n: usize, mut f: impl FnMut(usize, f32)) {
        match &self.data {
            Data::Packed32(s) => s[first..first + n]
                .iter()
                .enumerate()
                .for_each(|(k, &v)| f(k, v)),
            Data::Packed64(s) => s[first..first + n]
                .iter()
                .enumerate()
                .for_each(|(k, &v)| f(k, v as f32)),
            Data::Strided32(a) => (0..n).for_each(|k| f(k, a[first + k])),
            Data::Strided64(a) => (0..n).for_each(|k| f(k, a[first + k] as f32)),
        }
    }
}

/// The rays of `ray_intersect` / `ray_test`: views of the caller's arrays,
/// with the shapes checked. They are read on rayon's threads with the GIL
/// released ([`RayArrays::ray`]), so that nothing proportional to the
/// number of rays runs on the calling thread alone.
struct RayArrays<'a> {
    o: FloatView<'a, Ix2>,
    d: FloatView<'a, Ix2>,
    tmax: Option<FloatView<'a, Ix1>>,
}

impl<'a> RayArrays<'a> {
    fn new(
        origins: &'a Floats<'_, Ix2>,
        directions: &'a Floats<'_, Ix2>,
        tmax: Option<&'a Floats<'_, Ix1>>,
    ) -> PyResult<RayArrays<'a>> {
        let (o, d) = (origins.view(), directions.view());
        if o.shape[1] != 3 || o.shape != d.shape {
            return Err(PyValueError::new_err(format!(
                "origins and directions must both be (N, 3) arrays; got {:?} and {:?}",
                o.shape, d.shape
            )));
        }
        let tmax = tmax.map(|t| t.view());
        if let Some(t) = &tmax {
            if t.shape[0] != o.shape[0] {
                return Err(PyValueError::new_err(format!(
                    "tmax must be an (N,) array with N = {} (one per ray); got {:?}",
                    o.shape[0], t.shape
                )));
            }
        }
        Ok(RayArrays { o, d, tmax })
    }

    fn len(&self) -> usize {
        self.o.shape[0]
    }

    /// Calls `f(k, ray)` for rays `first + k`, `k < n` (within `len()`).
    /// Packed float32 origins and directions (what users pass) are read
    /// ray by ray as they are traced; other arrays are converted a task at
    /// a time into `buf` first.
    fn for_each(&self, first: usize, n: usize, buf: &mut Vec<Ray>, mut f: impl FnMut(usize, &Ray)) {
        let tmax = match self.tmax.as_ref().map(|t| &t.data) {
            None => None,
            Some(Data::Packed32(t)) => Some(&t[first..first + n]),
            Some(_) => return self.for_each_converted(first, n, buf, f),
        };
        let (Data::Packed32(o), Data::Packed32(d)) = (&self.o.data, &self.d.data) else {
            return self.for_each_converted(first, n, buf, f);
        };
        let rows = |s: &'a [f32]| s[3 * first..3 * (first + n)].chunks_exact(3);
        for (k, (o, d)) in rows(o).zip(rows(d)).enumerate() {
            let ray = Ray {
                o: Vec3::new(o[0], o[1], o[2]),
                d: Vec3::new(d[0], d[1], d[2]),
                tmin: 0.0,
                tmax: tmax.map_or(f32::INFINITY, |t| t[k]),
            };
            f(k, &ray);
        }
    }

    fn for_each_converted(
        &self,
        first: usize,
        n: usize,
        buf: &mut Vec<Ray>,
        mut f: impl FnMut(usize, &Ray),
    ) {
        self.read(first, n, buf);
        for (k, ray) in buf.iter().enumerate() {
            f(k, ray);
        }
    }

    /// Rays `first..first + n` (within `len()`) into `out`.
    fn read(&self, first: usize, n: usize, out: &mut Vec<Ray>) {
        let ray = Ray {
            o: Vec3::ZERO,
            d: Vec3::ZERO,
            tmin: 0.0,
            tmax: f32::INFINITY,
        };
        out.clear();
        out.resize(n, ray);
        self.o.rows3(first, n, |k, v| out[k].o = v);
        self.d.rows3(first, n, |k, v| out[k].d = v);
        if let Some(t) = &self.tmax {
            t.values(first, n, |k, v| out[k].tmax = v);
        }
    }
}

/// A loaded scene: geometry, materials, emitters, sensors, integrator and
/// the parameter store.
#[pyclass(name = "Scene", module = "penumbra._core")]
struct PyScene {
    inner: Scene,
}

/// Swaps in an integrator for the duration of one computation.
fn with_integrator<T>(
    scene: &mut Scene,
    integrator: Option<&PyIntegrator>,
    f: impl FnOnce(&mut Scene) -> PyResult<T>,
) -> PyResult<T> {
    match integrator {
        None => f(scene),
        Some(i) => {
            let saved = std::mem::replace(&mut scene.integrator, i.inner.clone());
            let r = f(scene);
            scene.integrator = saved;
            r
        }
    }
}

fn options(
    spp: Option<u32>,
    (sppp, sppi): (Option<u32>, Option<u32>),
    seed: u64,
    sensor: usize,
    threads: Option<usize>,
    force: bool,
) -> RenderOptions {
    RenderOptions {
        spp,
        sppp,
        sppi,
        seed,
        sensor,
        threads,
        force,
        ..Default::default()
    }
}

/// Applies pending parameter changes so that a render never sees stale
/// acceleration structures or sampling tables.
fn refresh(scene: &mut Scene) -> PyResult<()> {
    if scene.params.iter().any(|(_, p)| p.dirty) {
        scene.update().map_err(to_py)?;
    }
    Ok(())
}

fn domain_name(d: Domain) -> &'static str {
    match d {
        Domain::Finite => "finite",
        Domain::NonNegative => "nonnegative",
        Domain::Positive => "positive",
        Domain::UnitInterval => "unit_interval",
        Domain::OpenSignedUnit => "open_signed_unit",
    }
}

impl PyScene {
    fn require(&self, key: &str) -> PyResult<penumbra::params::ParamId> {
        self.inner
            .params
            .require(key)
            .map_err(|e| PyKeyError::new_err(e.to_string()))
    }
}

#[pymethods]
impl PyScene {
    /// The first surface each of N rays hits: `origins` and `directions`
    /// are `(N, 3)` arrays (any float type; directions need not be unit
    /// vectors: `t` is in their units), `tmax` an optional `(N,)` array of
    /// maximum distances (default: infinite). Returns a dict of arrays, as
    /// Mitsuba's `PreliminaryIntersection3f` names them: `t` `(N,)`
    /// float32 (`inf` where the ray misses), `shape_index` and
    /// `prim_index` `(N,)` int32 (−1 where it misses; shapes in scene
    /// order, triangles in mesh order), `prim_uv` `(N, 2)` float32 (the
    /// barycentric coordinates of vertices 1 and 2 of the triangle, or the
    /// shape's own surface coordinates). Traced on the scene as of its last
    /// `update()`, in parallel (tasks of 1024 rays) with the GIL released;
    /// float32 and float64 arrays are read in place, so no other thread may
    /// write to them during the call.
    #[pyo3(signature = (origins, directions, tmax=None))]
    fn ray_intersect<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        tmax: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (o, d) = (
            Floats::extract("origins", origins)?,
            Floats::extract("directions", directions)?,
        );
        let tmax = tmax.map(|t| Floats::extract("tmax", t)).transpose()?;
        let rays = RayArrays::new(&o, &d, tmax.as_ref())?;
        let scene = &self.inner;
        let n = rays.len();
        // zeroed allocations (calloc: no pass over them here); every
        // element is written below, on rayon's threads
        let (mut t, mut shape, mut prim, mut uv) = (
            vec![0.0f32; n],
            vec![0i32; n],
            vec![0i32; n],
            vec![0.0f32; 2 * n],
        );
        py.detach(|| {
            t.par_chunks_mut(RAYS_PER_TASK)
                .zip(shape.par_chunks_mut(RAYS_PER_TASK))
                .zip(prim.par_chunks_mut(RAYS_PER_TASK))
                .zip(uv.par_chunks_mut(2 * RAYS_PER_TASK))
                .enumerate()
                .with_max_len(1)
                .for_each_init(Vec::new, |buf, (task, (((t, shape), prim), uv))| {
                    rays.for_each(task * RAYS_PER_TASK, t.len(), buf, |k, ray| {
                        let h = scene.intersect(ray);
                        let (s, p, u) = h.map_or((-1, -1, Vec2::ZERO), |h| {
                            (h.shape as i32, h.prim as i32, h.uv)
                        });
                        t[k] = h.map_or(f32::INFINITY, |h| h.t);
                        (shape[k], prim[k], uv[2 * k], uv[2 * k + 1]) = (s, p, u.x, u.y);
                    })
                })
        });
        let out = PyDict::new(py);
        out.set_item("t", PyArray1::from_vec(py, t))?;
        out.set_item("shape_index", PyArray1::from_vec(py, shape))?;
        out.set_item("prim_index", PyArray1::from_vec(py, prim))?;
        out.set_item("prim_uv", array(py, uv, vec![n, 2])?)?;
        Ok(out)
    }

    /// Whether each of N rays hits any surface before `tmax` (arguments as
    /// in `ray_intersect`): an `(N,)` bool array.
    #[pyo3(signature = (origins, directions, tmax=None))]
    fn ray_test<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        tmax: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (o, d) = (
            Floats::extract("origins", origins)?,
            Floats::extract("directions", directions)?,
        );
        let tmax = tmax.map(|t| Floats::extract("tmax", t)).transpose()?;
        let rays = RayArrays::new(&o, &d, tmax.as_ref())?;
        let scene = &self.inner;
        let mut hit = vec![false; rays.len()];
        py.detach(|| {
            hit.par_chunks_mut(RAYS_PER_TASK)
                .enumerate()
                .with_max_len(1)
                .for_each_init(Vec::new, |buf, (task, hit)| {
                    rays.for_each(task * RAYS_PER_TASK, hit.len(), buf, |k, ray| {
                        hit[k] = scene.occluded(ray);
                    })
                })
        });
        Ok(PyArray1::from_vec(py, hit))
    }

    /// Keys of all parameters, in scene order.
    fn param_keys(&self) -> Vec<String> {
        self.inner
            .params
            .iter()
            .map(|(_, p)| p.key.clone())
            .collect()
    }

    /// `(shape, differentiable, discontinuous, read_only, domain)` of `key`.
    fn param_info(&self, key: &str) -> PyResult<(Vec<usize>, bool, bool, bool, &'static str)> {
        let p = self.inner.params.get(self.require(key)?);
        Ok((
            p.shape.clone(),
            p.flags.differentiable,
            p.flags.discontinuous,
            p.flags.read_only,
            domain_name(p.domain),
        ))
    }

    /// A copy of the values of `key`, shaped like the parameter.
    fn get_param<'py>(&self, py: Python<'py>, key: &str) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let p = self.inner.params.get(self.require(key)?);
        array(py, p.data.clone(), p.shape.clone())
    }

    /// Replaces the values of `key` (any float32 array with as many
    /// elements; shape checks happen in Python). Marks it for `update`.
    fn set_param(&mut self, key: &str, values: PyReadonlyArrayDyn<'_, f32>) -> PyResult<()> {
        self.require(key)?;
        let v = to_vec(&values);
        self.inner.params.set(key, &v).map_err(to_py)
    }

    /// Keys changed since the last update.
    fn dirty_keys(&self) -> Vec<String> {
        self.inner
            .params
            .iter()
            .filter(|(_, p)| p.dirty)
            .map(|(_, p)| p.key.clone())
            .collect()
    }

    /// Applies parameter changes (refits the BVH after vertex moves,
    /// recomputes normals, envmap sampling tables, BSDF sampling weights);
    /// returns the keys that were updated.
    fn update(&mut self, py: Python<'_>) -> PyResult<Vec<String>> {
        let keys = self.dirty_keys();
        let scene = &mut self.inner;
        py.detach(|| scene.update()).map_err(to_py)?;
        Ok(keys)
    }

    fn sensor_count(&self) -> usize {
        self.inner.sensors.len()
    }

    /// `(height, width)` of the image sensor `sensor` renders (its crop window).
    fn film_size(&self, sensor: usize) -> PyResult<(usize, usize)> {
        let s = self.inner.sensor(sensor).map_err(to_py)?;
        Ok((s.film.crop_size.1, s.film.crop_size.0))
    }

    /// Channel names of a primal render.
    #[pyo3(signature = (sensor=0, integrator=None))]
    fn channel_names(
        &self,
        sensor: usize,
        integrator: Option<PyRef<'_, PyIntegrator>>,
    ) -> PyResult<Vec<String>> {
        let i = integrator
            .as_ref()
            .map_or(&self.inner.integrator, |i| &i.inner);
        let mut names = i.channel_names();
        if self.inner.sensor(sensor).map_err(to_py)?.film.alpha {
            names.insert(3.min(names.len()), "A".into());
        }
        Ok(names)
    }

    /// An independent copy of the scene (parameters included).
    fn clone_scene(&self) -> PyScene {
        PyScene {
            inner: self.inner.clone(),
        }
    }

    /// Primal render: `(height, width, channels)` float32.
    #[pyo3(signature = (spp=None, seed=0, sensor=0, integrator=None, progress=None, threads=None, force=false))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &mut self,
        py: Python<'py>,
        spp: Option<u32>,
        seed: u64,
        sensor: usize,
        integrator: Option<PyRef<'_, PyIntegrator>>,
        progress: Option<&Bound<'py, PyAny>>,
        threads: Option<usize>,
        force: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let progress = Progress::from_arg(progress, "render")?;
        refresh(&mut self.inner)?;
        let opts = options(spp, (None, None), seed, sensor, threads, force);
        let r = with_integrator(&mut self.inner, integrator.as_deref(), |scene| {
            let scene = &*scene;
            run_detached(py, opts, &progress, |o| render(scene, o))
        })?;
        image_array(py, r)
    }

    /// Forward mode: the derivative image along the given tangents
    /// (`[(key, flat float32 array)]`), `(height, width, 3)`.
    #[pyo3(signature = (tangents, spp=None, sppp=None, sppi=None, seed=0, sensor=0, integrator=None, progress=None, threads=None, force=false))]
    #[allow(clippy::too_many_arguments)]
    fn render_forward<'py>(
        &mut self,
        py: Python<'py>,
        tangents: Vec<(String, PyReadonlyArrayDyn<'py, f32>)>,
        spp: Option<u32>,
        sppp: Option<u32>,
        sppi: Option<u32>,
        seed: u64,
        sensor: usize,
        integrator: Option<PyRef<'_, PyIntegrator>>,
        progress: Option<&Bound<'py, PyAny>>,
        threads: Option<usize>,
        force: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let progress = Progress::from_arg(progress, "render_forward")?;
        let mut owned = Vec::with_capacity(tangents.len());
        for (k, a) in &tangents {
            self.require(k)?;
            owned.push((k.clone(), to_vec(a)));
        }
        refresh(&mut self.inner)?;
        let opts = options(spp, (sppp, sppi), seed, sensor, threads, force);
        let r = with_integrator(&mut self.inner, integrator.as_deref(), |scene| {
            run_detached(py, opts, &progress, |o| {
                let t: Vec<(&str, &[f32])> = owned
                    .iter()
                    .map(|(k, v)| (k.as_str(), v.as_slice()))
                    .collect();
                render_forward(scene, &t, o)
            })
        })?;
        image_array(py, r)
    }

    /// Reverse mode (path replay): gradients `{key: array}` of a loss whose
    /// derivative with respect to the image is `d_image` (height × width ×
    /// 3). `seed` is the gradient pass's own seed, used as given.
    #[pyo3(signature = (d_image, keys=None, spp=None, sppp=None, sppi=None, seed=0, sensor=0, integrator=None, progress=None, threads=None, force=false))]
    #[allow(clippy::too_many_arguments)]
    fn render_backward<'py>(
        &mut self,
        py: Python<'py>,
        d_image: PyReadonlyArrayDyn<'py, f32>,
        keys: Option<Vec<String>>,
        spp: Option<u32>,
        sppp: Option<u32>,
        sppi: Option<u32>,
        seed: u64,
        sensor: usize,
        integrator: Option<PyRef<'_, PyIntegrator>>,
        progress: Option<&Bound<'py, PyAny>>,
        threads: Option<usize>,
        force: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let progress = Progress::from_arg(progress, "render_backward")?;
        if let Some(keys) = &keys {
            for k in keys {
                self.require(k)?;
            }
        }
        let d = to_vec(&d_image);
        refresh(&mut self.inner)?;
        let opts = options(spp, (sppp, sppi), seed, sensor, threads, force);
        let grads = with_integrator(&mut self.inner, integrator.as_deref(), |scene| {
            run_detached(py, opts, &progress, |o| {
                let k: Option<Vec<&str>> = keys
                    .as_ref()
                    .map(|v| v.iter().map(String::as_str).collect());
                render_backward(scene, &d, k.as_deref(), o)
            })
        })?;
        let out = PyDict::new(py);
        for e in grads.entries {
            out.set_item(e.key, array(py, e.data, e.shape)?)?;
        }
        Ok(out)
    }

    /// The table of `penumbra params`: key, shape, flags, domain and a
    /// value summary of `keys` (default: all), one line each.
    #[pyo3(signature = (keys=None))]
    fn params_table(&self, keys: Option<Vec<String>>) -> PyResult<String> {
        let params = &self.inner.params;
        let ids = match keys {
            Some(keys) => keys
                .iter()
                .map(|k| self.require(k))
                .collect::<PyResult<Vec<_>>>()?,
            None => params.iter().map(|(id, _)| id).collect(),
        };
        Ok(params.table(&ids))
    }

    fn __repr__(&self) -> String {
        let s = &self.inner;
        let size = s
            .sensors
            .first()
            .map(|x| format!("{}x{}", x.film.crop_size.0, x.film.crop_size.1))
            .unwrap_or_default();
        format!(
            "Scene(shapes={}, bsdfs={}, emitters={}, sensors={}, film={size}, params={})",
            s.shapes.len(),
            s.bsdfs.len(),
            s.emitters.len(),
            s.sensors.len(),
            s.params.len()
        )
    }
}

/// Loads a Mitsuba 3 XML scene file; `defines` override its `<default>`s.
#[pyfunction]
#[pyo3(signature = (path, defines=Vec::new()))]
fn load_file(py: Python<'_>, path: PathBuf, defines: Vec<(String, String)>) -> PyResult<PyScene> {
    let inner = py
        .detach(|| Scene::load_file(&path, &defines))
        .map_err(to_py)?;
    Ok(PyScene { inner })
}

/// Loads a scene from XML text; `path` names it in messages and is the
/// base of relative file names.
#[pyfunction]
#[pyo3(signature = (text, path, defines=Vec::new()))]
fn load_string(
    py: Python<'_>,
    text: String,
    path: PathBuf,
    defines: Vec<(String, String)>,
) -> PyResult<PyScene> {
    let inner = py
        .detach(|| Scene::load_str(&text, &path, &defines))
        .map_err(to_py)?;
    Ok(PyScene { inner })
}

/// The gradient pass's seed that follows a render with `seed`, unless
/// `seed_grad` is given (the library's one rule, `penumbra::diff::gradient_seed`).
#[pyfunction]
fn gradient_seed(seed: u64) -> u64 {
    derive_gradient_seed(seed)
}

/// Builds the `<integrator>` of a scene text that holds only that.
#[pyfunction]
fn load_integrator(text: &str, path: PathBuf) -> PyResult<PyIntegrator> {
    let root = penumbra::scene::parse_str(text, &path, &[]).map_err(to_py)?;
    let nodes = root.children(Class::Integrator);
    let [node] = nodes.as_slice() else {
        return Err(SceneError::new_err(format!(
            "{}: expected exactly one <integrator>, found {}",
            path.display(),
            nodes.len()
        )));
    };
    root.check_all_used().map_err(to_py)?;
    let inner = Integrator::from_node(node).map_err(to_py)?;
    Ok(PyIntegrator { inner })
}

/// Reads an EXR / PNG / JPEG image as `(height, width, channels)` float32.
/// With `linear`, 8/16-bit colour channels are decoded from sRGB.
#[pyfunction]
#[pyo3(signature = (path, linear=true))]
fn read_image<'py>(
    py: Python<'py>,
    path: PathBuf,
    linear: bool,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let mut img = py.detach(|| image::read_image(&path)).map_err(to_py)?;
    let is_exr = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if linear && !is_exr {
        let c = img.channels;
        let alpha = |k: usize| (c == 2 && k == 1) || (c == 4 && k == 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            if !alpha(i % c) {
                *v = image::srgb_to_linear(*v);
            }
        }
    }
    array(py, img.data, vec![img.height, img.width, img.channels])
}

/// Writes `(height, width, channels)` float32 as EXR (linear float32,
/// channel names given or Y/YA/RGB/RGBA) or PNG (8-bit sRGB).
#[pyfunction]
#[pyo3(signature = (path, data, channel_names=None))]
fn write_image(
    py: Python<'_>,
    path: PathBuf,
    data: PyReadonlyArrayDyn<'_, f32>,
    channel_names: Option<Vec<String>>,
) -> PyResult<()> {
    let shape = data.shape();
    if shape.len() != 3 {
        return Err(PyValueError::new_err(format!(
            "an image must have shape (height, width, channels), got {shape:?}"
        )));
    }
    let img = Image {
        height: shape[0],
        width: shape[1],
        channels: shape[2],
        data: to_vec(&data),
    };
    let p: &Path = &path;
    py.detach(|| match &channel_names {
        Some(names) => {
            let n: Vec<&str> = names.iter().map(String::as_str).collect();
            image::write_exr(p, &img, &n)
        }
        None => image::write_image(p, &img),
    })
    .map_err(to_py)
}

/// The library's pose layout named in Python: "points", "directions" or
/// "matrix".
fn pose_layout_of(name: &str) -> PyResult<PoseLayout> {
    match name {
        "points" => Ok(PoseLayout::Points),
        "directions" => Ok(PoseLayout::Directions),
        "matrix" => Ok(PoseLayout::Matrix),
        _ => Err(PyValueError::new_err(format!(
            "pose layout must be 'points', 'directions' or 'matrix', got '{name}'"
        ))),
    }
}

/// How a pose moves the parameter `key` of `shape` ("points" or
/// "matrix"), and the vertex normals key that turns with mesh positions
/// (`penumbra::optim::pose`); a ParamError for other parameters.
#[pyfunction]
fn pose_layout(key: &str, shape: Vec<usize>) -> PyResult<(&'static str, Option<String>)> {
    let layout = PoseLayout::of_param(key, &shape).map_err(to_py)?;
    let name = match layout {
        PoseLayout::Matrix => "matrix",
        _ => "points",
    };
    Ok((name, normals_key(key)))
}

fn pose_of(
    layout: PoseLayout,
    base: &[f32],
    t: [f64; 3],
    r: [f64; 3],
    pivot: [f64; 3],
) -> PyResult<Pose> {
    Pose::check_len(layout, base.len()).map_err(PyValueError::new_err)?;
    Ok(Pose {
        translation: t.into(),
        rotation: r.into(),
        pivot: pivot.into(),
    })
}

/// The default pivot of a pose of `base` (the centroid of points, the
/// origin of a transform).
#[pyfunction]
fn pose_default_pivot(layout: &str, base: PyReadonlyArrayDyn<'_, f32>) -> PyResult<[f64; 3]> {
    let layout = pose_layout_of(layout)?;
    let base = to_vec(&base);
    Pose::check_len(layout, base.len()).map_err(PyValueError::new_err)?;
    Ok(Pose::default_pivot(layout, &base).to_array())
}

/// `base` moved by the pose (translation `t`, rotation vector `r` in
/// radians, about `pivot`): a flat float32 array.
#[pyfunction]
fn pose_apply<'py>(
    py: Python<'py>,
    layout: &str,
    base: PyReadonlyArrayDyn<'py, f32>,
    t: [f64; 3],
    r: [f64; 3],
    pivot: [f64; 3],
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let layout = pose_layout_of(layout)?;
    let base = to_vec(&base);
    let pose = pose_of(layout, &base, t, r, pivot)?;
    let n = base.len();
    array(py, pose.apply(layout, &base), vec![n])
}

/// `(∂L/∂t, ∂L/∂r)` from `grad` = ∂L/∂values at the posed `base`.
#[pyfunction]
fn pose_backprop(
    layout: &str,
    base: PyReadonlyArrayDyn<'_, f32>,
    grad: PyReadonlyArrayDyn<'_, f32>,
    t: [f64; 3],
    r: [f64; 3],
    pivot: [f64; 3],
) -> PyResult<([f64; 3], [f64; 3])> {
    let layout = pose_layout_of(layout)?;
    let (base, grad) = (to_vec(&base), to_vec(&grad));
    if grad.len() != base.len() {
        return Err(PyValueError::new_err(format!(
            "the gradient has {} values, the parameter {}",
            grad.len(),
            base.len()
        )));
    }
    let g = pose_of(layout, &base, t, r, pivot)?.backprop(layout, &base, &grad);
    Ok((g.translation.to_array(), g.rotation.to_array()))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("ParamError", py.get_type::<ParamError>())?;
    m.add("FileError", py.get_type::<FileError>())?;
    m.add_class::<PyScene>()?;
    m.add_class::<PyIntegrator>()?;
    m.add_function(wrap_pyfunction!(load_file, m)?)?;
    m.add_function(wrap_pyfunction!(load_string, m)?)?;
    m.add_function(wrap_pyfunction!(load_integrator, m)?)?;
    m.add_function(wrap_pyfunction!(gradient_seed, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(pose_layout, m)?)?;
    m.add_function(wrap_pyfunction!(pose_default_pivot, m)?)?;
    m.add_function(wrap_pyfunction!(pose_apply, m)?)?;
    m.add_function(wrap_pyfunction!(pose_backprop, m)?)?;
    m.add_function(wrap_pyfunction!(write_image, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
