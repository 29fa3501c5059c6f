//! Fresnel reflectance of smooth interfaces (dielectric and conductor), the
//! diffuse Fresnel reflectance, and the named indices of refraction that
//! Mitsuba 3 accepts for `int_ior` / `ext_ior`.

use crate::ad::{Float, Real, ScalarReal};
use crate::math::{Spectrum, V3};
use glam::Vec3;

/// Unpolarised Fresnel reflectance of a dielectric interface with relative
/// index of refraction `eta` = η_inside / η_outside, for incident cosine
/// `cos_theta_i` (positive: arriving from outside, the side of +z).
///
/// Returns `(F, cos_theta_t, eta_it, eta_ti)`: the reflectance, the signed
/// cosine of the refracted direction (opposite side of the incident one;
/// 0 under total internal reflection), and the relative indices of
/// refraction along the incident → transmitted path and back.
#[inline]
pub fn fresnel_dielectric<R: ScalarReal>(cos_theta_i: R, eta: R) -> (R, R, R, R) {
    let outside = cos_theta_i.val() >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, eta.recip())
    } else {
        (eta.recip(), eta)
    };
    // Snell: sin²θt = η_ti² sin²θi
    let cos_t2 = -(-(cos_theta_i * cos_theta_i) + 1.0) * (eta_ti * eta_ti) + 1.0;
    let cos_i = cos_theta_i.abs();
    let cos_t = cos_t2.safe_sqrt();
    let r = if eta.val() == 1.0 {
        R::cst(0.0)
    } else if cos_i.val() == 0.0 {
        R::cst(1.0)
    } else {
        // s- and p-polarised amplitude ratios
        let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
        let a_p = (cos_t - eta_it * cos_i) / (cos_t + eta_it * cos_i);
        (a_s * a_s + a_p * a_p) * 0.5
    };
    let cos_t_signed = if outside { -cos_t } else { cos_t };
    (r, cos_t_signed, eta_it, eta_ti)
}

/// [`fresnel_dielectric`]'s values, primal, for one path or for lanes:
/// the same formulas with selects for its branches (the path tracer in
/// lanes, `bsdf/lanes.rs`).
#[inline(always)]
pub(crate) fn fresnel_dielectric_primal<F: Float>(cos_theta_i: F, eta: F) -> (F, F, F, F) {
    let outside = cos_theta_i.ge(0.0);
    let inv = eta.recip();
    let (eta_it, eta_ti) = (F::select(outside, eta, inv), F::select(outside, inv, eta));
    let cos_t2 = -(-(cos_theta_i * cos_theta_i) + 1.0) * (eta_ti * eta_ti) + 1.0;
    let cos_i = cos_theta_i.abs();
    let cos_t = cos_t2.safe_sqrt();
    let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
    let a_p = (cos_t - eta_it * cos_i) / (cos_t + eta_it * cos_i);
    let r = (a_s * a_s + a_p * a_p) * 0.5;
    let r = F::select(cos_i.equals(0.0), F::cst(1.0), r);
    let r = F::select(eta.equals(1.0), F::cst(0.0), r);
    (r, F::select(outside, -cos_t, cos_t), eta_it, eta_ti)
}

/// Unpolarised Fresnel reflectance of a conductor with complex index of
/// refraction `eta + i k` (relative to the outside medium), for one colour
/// channel; exact formula (e.g. pbrt-v3 §8.2.1, `FrConductor`).
#[inline]
pub fn fresnel_conductor_1<R: Real>(cos_theta_i: R, eta: R, k: R) -> R {
    let c2 = cos_theta_i * cos_theta_i;
    let s2 = -c2 + 1.0;
    let s4 = s2 * s2;
    let t0 = eta * eta - k * k - s2;
    let a2b2 = (t0 * t0 + eta * eta * k * k * 4.0).safe_sqrt();
    let a = ((a2b2 + t0) * 0.5).safe_sqrt();
    let t1 = a2b2 + c2;
    let t2 = cos_theta_i * a * 2.0;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = a2b2 * c2 + s4;
    let t4 = t2 * s2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    (rs + rp) * 0.5
}

/// [`fresnel_conductor_1`] for each RGB channel.
#[inline]
pub fn fresnel_conductor<R: Real>(cos_theta_i: R, eta: Spectrum<R>, k: Spectrum<R>) -> Spectrum<R> {
    V3::new(
        fresnel_conductor_1(cos_theta_i, eta.x, k.x),
        fresnel_conductor_1(cos_theta_i, eta.y, k.y),
        fresnel_conductor_1(cos_theta_i, eta.z, k.z),
    )
}

/// Hemispherical average of the dielectric Fresnel reflectance,
/// `∫ F(cos θ) 2 cos θ dcos θ`, by the fits Mitsuba 3 uses: Egan and
/// Hilgeman 1973 for `eta < 1`, d'Eon and Irving 2011 ("A quantized-diffusion
/// model for rendering translucent materials") otherwise.
pub fn fresnel_diffuse_reflectance<R: ScalarReal>(eta: R) -> R {
    if eta.val() < 1.0 {
        eta * eta * -1.4399 + eta * 0.7099 + 0.6681 + eta.recip() * 0.0636
    } else {
        let x = eta.recip();
        // Horner form of 0.919317 − 3.4793 x + 6.75335 x² − 7.80989 x³ + 4.98554 x⁴ − 1.36881 x⁵
        ((((x * -1.36881 + 4.98554) * x - 7.80989) * x + 6.75335) * x - 3.4793) * x + 0.919317
    }
}

/// Refraction of `wi` (pointing away from the surface) through the
/// interface with normal `m`, given the signed cosine `cos_theta_t` and
/// `eta_ti` from [`fresnel_dielectric`] (evaluated at `dot(wi, m)`).
/// Generic so that delta refraction moves with an attached `wi`.
#[inline]
pub fn refract<R: Real>(wi: V3<R>, m: V3<R>, cos_theta_t: R, eta_ti: R) -> V3<R> {
    m * (wi.dot(m) * eta_ti + cos_theta_t) - wi * eta_ti
}

/// Mirror reflection of `wi` about `m`.
#[inline]
pub fn reflect<R: Real>(wi: V3<R>, m: V3<R>) -> V3<R> {
    m * (wi.dot(m) * 2.0) - wi
}

/// Indices of refraction by material name, as listed in Mitsuba 3's
/// documentation (dielectric plugins).
pub const IOR_TABLE: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

/// The index of refraction called `name` (case-insensitive).
pub fn lookup_ior(name: &str) -> Option<f32> {
    let lower = name.to_lowercase();
    IOR_TABLE.iter().find(|(n, _)| *n == lower).map(|&(_, v)| v)
}

/// Complex indices of refraction of conductors in linear sRGB, as Mitsuba
/// 3 (scalar_rgb) derives them from its spectral tables (`material`
/// parameter of `conductor` / `roughconductor`): `(name, eta, k)`.
pub const CONDUCTOR_TABLE: &[(&str, [f32; 3], [f32; 3])] = &[
    (
        "Ag",
        [0.155276, 0.116728, 0.138388],
        [4.82835, 3.12222, 2.1469],
    ),
    ("Al", [1.6575, 0.880405, 0.521244], [9.22381, 6.2695, 4.837]),
    (
        "AlAs",
        [3.6053, 3.23294, 2.21632],
        [0.000679437, 0.0, 0.00751271],
    ),
    (
        "AlAs_palik",
        [3.6053, 3.23294, 2.21632],
        [0.000679437, 0.0, 0.00751271],
    ),
    ("AlSb", [0.0, 4.13937, 4.66925], [0.0, 0.0940091, 1.30057]),
    (
        "AlSb_palik",
        [0.0, 4.13937, 4.66925],
        [0.0, 0.0940091, 1.30057],
    ),
    (
        "Au",
        [0.143036, 0.375307, 1.44205],
        [3.983, 2.38556, 1.60336],
    ),
    (
        "Be",
        [4.18501, 3.18503, 2.78406],
        [3.83547, 3.01012, 2.86899],
    ),
    (
        "Be_palik",
        [4.18501, 3.18503, 2.78406],
        [3.83547, 3.01012, 2.86899],
    ),
    ("Cr", [4.36967, 2.91651, 1.6549], [5.20655, 4.23131, 3.7547]),
    ("CsI", [2.1449, 1.70232, 1.66243], [0.0, 0.0, 0.0]),
    ("CsI_palik", [2.1449, 1.70232, 1.66243], [0.0, 0.0, 0.0]),
    (
        "Cu",
        [0.201005, 0.92375, 1.10222],
        [3.91326, 2.45305, 2.14209],
    ),
    (
        "Cu2O",
        [3.55177, 2.94987, 2.75188],
        [0.114207, 0.193897, 0.606134],
    ),
    (
        "Cu2O_palik",
        [3.55177, 2.94987, 2.75188],
        [0.114207, 0.193897, 0.606134],
    ),
    (
        "CuO",
        [3.24754, 2.44781, 2.21022],
        [0.52109, 0.570031, 0.722179],
    ),
    (
        "CuO_palik",
        [3.24754, 2.44781, 2.21022],
        [0.52109, 0.570031, 0.722179],
    ),
    (
        "Cu_palik",
        [0.213229, 0.919715, 1.10241],
        [3.92187, 2.45733, 2.13658],
    ),
    (
        "Hg",
        [2.39894, 1.44003, 0.90957],
        [6.32759, 4.37192, 3.42176],
    ),
    (
        "HgTe",
        [4.77904, 3.2312, 2.6599],
        [1.63161, 1.58081, 1.72929],
    ),
    (
        "HgTe_palik",
        [4.77904, 3.2312, 2.6599],
        [1.63161, 1.58081, 1.72929],
    ),
    (
        "Hg_palik",
        [2.39894, 1.44003, 0.90957],
        [6.32759, 4.37192, 3.42176],
    ),
    (
        "Ir",
        [3.0863, 2.08219, 1.61791],
        [5.59215, 4.06709, 3.26731],
    ),
    (
        "Ir_palik",
        [3.0863, 2.08219, 1.61791],
        [5.59215, 4.06709, 3.26731],
    ),
    (
        "K",
        [0.0640432, 0.0464098, 0.0381849],
        [2.1042, 1.34894, 0.913126],
    ),
    (
        "K_palik",
        [0.0640432, 0.0464098, 0.0381849],
        [2.1042, 1.34894, 0.913126],
    ),
    (
        "Li",
        [0.265791, 0.195618, 0.220949],
        [3.54015, 2.31112, 1.66861],
    ),
    (
        "Li_palik",
        [0.265791, 0.195618, 0.220949],
        [3.54015, 2.31112, 1.66861],
    ),
    (
        "MgO",
        [2.08958, 1.65072, 1.59488],
        [4.3327e-12, 0.0, 2.49865e-11],
    ),
    (
        "MgO_palik",
        [2.08958, 1.65072, 1.59488],
        [4.3327e-12, 0.0, 2.49865e-11],
    ),
    (
        "Mo",
        [4.48397, 3.52513, 2.77631],
        [4.11144, 3.42083, 3.15061],
    ),
    (
        "Mo_palik",
        [4.48397, 3.52513, 2.77631],
        [4.11144, 3.42083, 3.15061],
    ),
    (
        "Na_palik",
        [0.0602694, 0.0561409, 0.0619884],
        [3.17927, 2.11249, 1.57904],
    ),
    (
        "Nb",
        [3.42007, 2.79009, 2.39563],
        [3.44139, 2.73767, 2.57975],
    ),
    (
        "Nb_palik",
        [3.42007, 2.79009, 2.39563],
        [3.44139, 2.73767, 2.57975],
    ),
    (
        "Ni_palik",
        [2.3673, 1.66337, 1.46708],
        [4.49881, 3.05015, 2.34544],
    ),
    (
        "Rh",
        [2.58579, 1.86022, 1.55426],
        [6.78226, 4.70299, 3.97607],
    ),
    (
        "Rh_palik",
        [2.58579, 1.86022, 1.55426],
        [6.78226, 4.70299, 3.97607],
    ),
    (
        "Se",
        [4.05831, 2.84294, 2.82085],
        [0.75405, 0.638444, 0.521808],
    ),
    (
        "Se-e",
        [5.72285, 4.16574, 4.08134],
        [0.871136, 1.10516, 1.56532],
    ),
    (
        "Se-e_palik",
        [5.72285, 4.16574, 4.08134],
        [0.871136, 1.10516, 1.56532],
    ),
    (
        "Se_palik",
        [4.05831, 2.84294, 2.82085],
        [0.75405, 0.638444, 0.521808],
    ),
    (
        "SiC",
        [3.17234, 2.52597, 2.47937],
        [7.53766e-07, 0.0, 1.01925e-05],
    ),
    (
        "SiC_palik",
        [3.17234, 2.52597, 2.47937],
        [7.53766e-07, 0.0, 1.01925e-05],
    ),
    ("SnTe", [4.52425, 1.98164, 1.28159], [0.0, 0.0, 0.0]),
    ("SnTe_palik", [4.52425, 1.98164, 1.28159], [0.0, 0.0, 0.0]),
    (
        "Ta",
        [2.06272, 2.39294, 2.62793],
        [2.40836, 1.74149, 1.94703],
    ),
    (
        "Ta_palik",
        [2.06272, 2.39294, 2.62793],
        [2.40836, 1.74149, 1.94703],
    ),
    (
        "Te",
        [7.39023, 4.4821, 2.63711],
        [3.25602, 3.52706, 3.29205],
    ),
    (
        "Te-e",
        [7.50891, 4.29643, 2.36999],
        [5.58393, 4.94721, 3.99759],
    ),
    (
        "Te-e_palik",
        [7.50891, 4.29643, 2.36999],
        [5.58393, 4.94721, 3.99759],
    ),
    (
        "Te_palik",
        [7.39023, 4.4821, 2.63711],
        [3.25602, 3.52706, 3.29205],
    ),
    ("ThF4", [1.83071, 1.44223, 1.38765], [0.0, 0.0, 0.0]),
    ("ThF4_palik", [1.83071, 1.44223, 1.38765], [0.0, 0.0, 0.0]),
    (
        "TiC",
        [3.70053, 2.83742, 2.58229],
        [3.26564, 2.35159, 2.17279],
    ),
    (
        "TiC_palik",
        [3.70053, 2.83742, 2.58229],
        [3.26564, 2.35159, 2.17279],
    ),
    (
        "TiN",
        [1.64845, 1.15052, 1.37982],
        [3.36833, 1.9435, 1.10207],
    ),
    (
        "TiN_palik",
        [1.64845, 1.15052, 1.37982],
        [3.36833, 1.9435, 1.10207],
    ),
    (
        "TiO2",
        [3.45661, 2.80174, 2.90517],
        [0.000105265, 0.0, 0.000652887],
    ),
    (
        "TiO2-e",
        [3.10656, 2.51317, 2.58244],
        [2.97516e-05, 0.0, 0.000182698],
    ),
    (
        "TiO2-e_palik",
        [3.10656, 2.51317, 2.58244],
        [2.97516e-05, 0.0, 0.000182698],
    ),
    (
        "TiO2_palik",
        [3.45661, 2.80174, 2.90517],
        [0.000105265, 0.0, 0.000652887],
    ),
    (
        "VC",
        [3.65757, 2.75274, 2.53267],
        [3.0683, 2.19869, 1.96319],
    ),
    (
        "VC_palik",
        [3.65757, 2.75274, 2.53267],
        [3.0683, 2.19869, 1.96319],
    ),
    (
        "VN",
        [2.8656, 2.11919, 1.94009],
        [3.03224, 2.05612, 1.61631],
    ),
    (
        "VN_palik",
        [2.8656, 2.11919, 1.94009],
        [3.03224, 2.05612, 1.61631],
    ),
    (
        "V_palik",
        [4.27758, 3.51295, 2.76107],
        [3.4913, 2.88945, 3.11152],
    ),
    (
        "W",
        [4.37082, 3.30025, 2.99841],
        [3.50064, 2.60487, 2.27323],
    ),
    (
        "a-C",
        [2.94405, 2.22714, 1.96816],
        [0.887465, 0.799299, 0.81529],
    ),
    ("d-C", [2.70872, 2.31883, 2.2289], [0.0, 0.0, 0.0]),
    ("d-C_palik", [2.70872, 2.31883, 2.2289], [0.0, 0.0, 0.0]),
];

/// `(eta, k)` of the conductor called `name` (case-sensitive, as Mitsuba).
pub fn lookup_conductor(name: &str) -> Option<(Vec3, Vec3)> {
    CONDUCTOR_TABLE
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, e, k)| (Vec3::from(*e), Vec3::from(*k)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_fresnel_known_values() {
        // normal incidence: ((η−1)/(η+1))²
        let (f, ct, eit, eti) = fresnel_dielectric(1.0f32, 1.5);
        assert!((f - 0.04).abs() < 1e-6 && (ct + 1.0).abs() < 1e-6);
        assert!((eit - 1.5).abs() < 1e-6 && (eti - 1.0 / 1.5).abs() < 1e-6);
        // from inside beyond the critical angle: total internal reflection
        let (f, ct, _, _) = fresnel_dielectric(-0.3f32, 1.5);
        assert_eq!((f, ct), (1.0, 0.0));
        // symmetry: same reflectance for the reciprocal pair of angles
        let (f1, ct1, _, _) = fresnel_dielectric(0.6f32, 1.33);
        let (f2, _, _, _) = fresnel_dielectric(ct1, 1.33);
        assert!((f1 - f2).abs() < 1e-5, "{f1} {f2}");
        // Brewster angle: p-polarised reflectance vanishes, F = Rs/2
        let tb = 1.5f32.atan();
        let (f, _, _, _) = fresnel_dielectric(tb.cos(), 1.5);
        let rs = ((tb.cos() - 1.5 * (1.0 - tb.sin().powi(2) / 2.25).sqrt())
            / (tb.cos() + 1.5 * (1.0 - tb.sin().powi(2) / 2.25).sqrt()))
        .powi(2);
        assert!((f - rs / 2.0).abs() < 1e-5);
    }

    #[test]
    fn conductor_fresnel_limits() {
        // k = 0 reduces to the dielectric formula
        for c in [0.1f32, 0.5, 0.9] {
            let a = fresnel_conductor_1(c, 1.5, 0.0);
            let b = fresnel_dielectric(c, 1.5).0;
            assert!((a - b).abs() < 1e-5, "{a} {b}");
        }
        // eta = 0, k = 1 is a perfect mirror (Mitsuba's material "none")
        assert!((fresnel_conductor_1(0.3f32, 0.0, 1.0) - 1.0).abs() < 1e-6);
        // normal incidence: ((n−1)² + k²) / ((n+1)² + k²)
        let (n, k) = (0.2f32, 3.9f32);
        let want = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor_1(1.0, n, k) - want).abs() < 1e-5);
    }

    #[test]
    fn diffuse_fresnel_matches_integral() {
        // ∫ F(μ) 2μ dμ by the midpoint rule vs the fits (≤ 1% apart)
        for eta in [1.2f32, 1.49, 1.0 / 1.49, 2.0] {
            let n = 20000;
            let mut s = 0.0f64;
            for i in 0..n {
                let mu = (i as f32 + 0.5) / n as f32;
                s += (fresnel_dielectric(mu, eta).0 * 2.0 * mu) as f64 / n as f64;
            }
            let fit = fresnel_diffuse_reflectance(eta) as f64;
            assert!((fit - s).abs() < 0.01 * s, "eta {eta}: fit {fit} vs {s}");
        }
        assert_eq!(lookup_ior("BK7"), Some(1.5046));
        assert!(lookup_conductor("Au").is_some() && lookup_conductor("au").is_none());
    }
}
