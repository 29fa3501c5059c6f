// STUB until the geometry branch lands.
use crate::geometry::{Hit, Ray, Shape};
use crate::params::ParamStore;
#[derive(Clone, Debug)]
pub struct Accel;
impl Accel {
    pub fn build(_s: &[Shape], _p: &ParamStore) -> Accel {
        Accel
    }
    pub fn intersect(&self, _r: &Ray) -> Option<Hit> {
        None
    }
    pub fn occluded(&self, _r: &Ray) -> bool {
        false
    }
    pub fn update(&mut self, _s: &[Shape], _p: &ParamStore) {}
    pub fn bounding_sphere(&self) -> (glam::Vec3, f32) {
        (glam::Vec3::ZERO, 1.0)
    }
}
