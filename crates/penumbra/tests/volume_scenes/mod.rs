//! The volume scenes (scenes/volume_homog.xml, volume_hetero.xml, copied
//! from Mitsuba's reference kit) and where their images are not defined by
//! the scene alone.

use penumbra::bsdf::Bsdf;
use penumbra::geometry::Ray;
use penumbra::scene::Scene;
use std::path::PathBuf;

/// Loads `scenes/<name>.xml` with the given `<default>` overrides.
pub fn load(name: &str, defines: &[(&str, &str)]) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenes/{name}.xml"));
    let defines: Vec<(String, String)> = defines
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    Scene::load_file(&path, &defines).unwrap()
}

/// The pixels of the volume scenes whose camera rays (any of 4×4 points
/// in the pixel) reach the ground inside the medium box's footprint
/// (|x|, |z| ≤ 0.5 + a margin). The box's bottom face lies in the
/// ground's plane, so which of the two coplanar surfaces a ray meets
/// first (and whether the path is then inside the medium) is decided by
/// rounding: Mitsuba's reference shows it changing from one triangle of
/// the face to the other. Those pixels are left out.
pub fn box_footprint(scene: &Scene) -> Vec<bool> {
    let sensor = &scene.sensors[0];
    let (w, h) = sensor.film.crop_size;
    let store = scene.params.primal();
    let margin = 0.02;
    let mut mask = vec![false; w * h];
    for (p, m) in mask.iter_mut().enumerate() {
        let (x, y) = (p % w, p / w);
        *m = (0..16).any(|k| {
            let film = glam::Vec2::new(
                (x as f32 + (k % 4) as f32 / 3.0) / w as f32,
                (y as f32 + (k / 4) as f32 / 3.0) / h as f32,
            );
            let mut ray: Ray = sensor.ray::<f32>(&store, film, glam::Vec2::ZERO).val();
            while let Some(hit) = scene.intersect(&ray) {
                let q = ray.at(hit.t);
                if q.y.abs() < 1e-3 && q.x.abs() < 0.5 + margin && q.z.abs() < 0.5 + margin {
                    return true;
                }
                if !matches!(scene.shape_bsdf(hit.shape), Bsdf::Null(_)) {
                    return false;
                }
                ray = Ray::new(q + ray.d * 1e-3, ray.d);
            }
            false
        });
    }
    mask
}

/// [`box_footprint`] of `scenes/<name>.xml` as a predicate on (x, y).
#[allow(dead_code)]
pub fn box_footprint_mask(name: &str) -> impl Fn(usize, usize) -> bool {
    let scene = load(name, &[]);
    let w = scene.sensors[0].film.crop_size.0;
    let mask = box_footprint(&scene);
    move |x, y| mask[y * w + x]
}
