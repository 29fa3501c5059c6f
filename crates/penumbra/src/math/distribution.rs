//! Discrete and piecewise-constant distributions for importance sampling
//! (emitter selection, triangle selection by area, environment maps).

use glam::Vec2;

/// A discrete distribution over `n` entries proportional to given weights.
#[derive(Clone, Debug, Default)]
pub struct DiscreteDistribution {
    /// Normalised cumulative sums: `cdf[i] = P(index < i)`, `cdf[n] = 1`.
    cdf: Vec<f64>,
    /// `pmf[i] = cdf[i+1] − cdf[i]` as f32, and its reciprocal in f64 (0
    /// for entries of no mass): sampling reads them instead of dividing.
    pmf: Vec<f32>,
    inv_pmf: Vec<f64>,
    /// Sum of the weights before normalisation.
    sum: f64,
}

impl DiscreteDistribution {
    /// `None` if there are no weights, a weight is negative or not finite,
    /// or all are zero.
    pub fn new(weights: &[f32]) -> Option<Self> {
        let mut cdf = Vec::with_capacity(weights.len() + 1);
        cdf.push(0.0f64);
        let mut acc = 0.0f64;
        for &w in weights {
            if !(w >= 0.0) || !w.is_finite() {
                return None;
            }
            acc += w as f64;
            cdf.push(acc);
        }
        if !(acc > 0.0) {
            return None;
        }
        for c in cdf.iter_mut() {
            *c /= acc;
        }
        let pmf: Vec<f32> = cdf.windows(2).map(|c| (c[1] - c[0]) as f32).collect();
        let inv_pmf = pmf
            .iter()
            .map(|&p| if p > 0.0 { 1.0 / p as f64 } else { 0.0 })
            .collect();
        Some(DiscreteDistribution {
            cdf,
            pmf,
            inv_pmf,
            sum: acc,
        })
    }

    pub fn len(&self) -> usize {
        self.pmf.len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Sum of the (unnormalised) weights.
    pub fn sum(&self) -> f64 {
        self.sum
    }
    /// Probability of entry `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf[i]
    }
    /// Samples an index; returns it, its probability and `u` rescaled to
    /// [0,1) within the chosen entry (so it can be reused).
    #[inline]
    pub fn sample_reuse(&self, u: f32) -> (usize, f32, f32) {
        let n = self.len();
        if n == 1 {
            // a single entry (one emitter, a one-triangle mesh): all mass
            return (0, 1.0, u.clamp(0.0, 1.0 - f32::EPSILON));
        }
        let u64 = u as f64;
        // i with cdf[i] ≤ u < cdf[i + 1]
        let mut i = if n <= 16 {
            // a few entries (emitters, a rectangle's triangles): a scan
            // without branches to mispredict beats the binary search
            self.cdf[1..n].iter().filter(|&&c| c <= u64).count()
        } else {
            self.cdf
                .partition_point(|&c| c <= u64)
                .saturating_sub(1)
                .min(n - 1)
        };
        // skip zero-mass entries backwards (u rounded onto their boundary)
        while self.pmf[i] == 0.0 && i > 0 {
            i -= 1;
        }
        let r = ((u64 - self.cdf[i]) * self.inv_pmf[i]) as f32;
        (i, self.pmf[i], r.clamp(0.0, 1.0 - f32::EPSILON))
    }
}

/// A piecewise-constant 2D distribution over [0,1]² on a `w × h` grid
/// (marginal over rows, conditional within each row), used to importance
/// sample environment maps (pbrt-v3 §13.6.7).
#[derive(Clone, Debug, Default)]
pub struct Distribution2D {
    rows: Vec<DiscreteDistribution>,
    marginal: DiscreteDistribution,
    w: usize,
    h: usize,
}

impl Distribution2D {
    /// `weights` is row-major, `h` rows of `w` values. `None` if all zero.
    pub fn new(weights: &[f32], w: usize, h: usize) -> Option<Self> {
        assert_eq!(weights.len(), w * h, "Distribution2D: weights must be w*h");
        let uniform_row = vec![1.0f32; w];
        let mut rows = Vec::with_capacity(h);
        let mut row_sums = Vec::with_capacity(h);
        for y in 0..h {
            let row = &weights[y * w..(y + 1) * w];
            match DiscreteDistribution::new(row) {
                Some(d) => {
                    row_sums.push(d.sum() as f32);
                    rows.push(d);
                }
                None => {
                    row_sums.push(0.0);
                    rows.push(DiscreteDistribution::new(&uniform_row)?);
                }
            }
        }
        let marginal = DiscreteDistribution::new(&row_sums)?;
        Some(Distribution2D {
            rows,
            marginal,
            w,
            h,
        })
    }

    /// Samples a point in [0,1]²; returns it with its density (w.r.t. area
    /// in [0,1]²).
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (y, py, _) = self.marginal.sample_reuse(u.y);
        let (x, px, _) = self.rows[y].sample_reuse(u.x);
        let ry = (u.y as f64 - self.marginal.cdf[y]) / py.max(f32::MIN_POSITIVE) as f64;
        let rx = (u.x as f64 - self.rows[y].cdf[x]) / px.max(f32::MIN_POSITIVE) as f64;
        let p = Vec2::new(
            (x as f32 + rx.clamp(0.0, 1.0) as f32) / self.w as f32,
            (y as f32 + ry.clamp(0.0, 1.0) as f32) / self.h as f32,
        );
        (p, px * py * (self.w * self.h) as f32)
    }

    /// Density of [`Distribution2D::sample`] at `p` in [0,1]².
    pub fn pdf(&self, p: Vec2) -> f32 {
        let x = ((p.x * self.w as f32) as usize).min(self.w - 1);
        let y = ((p.y * self.h as f32) as usize).min(self.h - 1);
        self.marginal.pmf(y) * self.rows[y].pmf(x) * (self.w * self.h) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn discrete_sampling_frequencies_match_pmf() {
        let d = DiscreteDistribution::new(&[1.0, 0.0, 3.0, 4.0]).unwrap();
        let n = 80000;
        let mut counts = [0usize; 4];
        for k in 0..n {
            let (i, p, r) = d.sample_reuse((k as f32 + 0.5) / n as f32);
            assert!((0.0..1.0).contains(&r));
            assert_eq!(p, d.pmf(i));
            counts[i] += 1;
        }
        assert_eq!(counts[1], 0);
        for (i, c) in counts.iter().enumerate() {
            assert!((*c as f32 / n as f32 - d.pmf(i)).abs() < 1e-3);
        }
    }

    #[test]
    fn invalid_weights_are_rejected() {
        assert!(DiscreteDistribution::new(&[]).is_none());
        assert!(DiscreteDistribution::new(&[0.0, 0.0]).is_none());
        assert!(DiscreteDistribution::new(&[1.0, f32::NAN]).is_none());
        assert!(DiscreteDistribution::new(&[1.0, -1.0]).is_none());
    }

    #[test]
    fn distribution_2d_pdf_matches_sampling() {
        let (w, h) = (4, 3);
        let weights: Vec<f32> = (0..w * h).map(|i| (i % 5) as f32 + 0.5).collect();
        let d = Distribution2D::new(&weights, w, h).unwrap();
        let total: f32 = weights.iter().sum();
        let n = 100;
        for i in 0..n {
            for j in 0..n {
                let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let (p, pdf) = d.sample(u);
                assert!((pdf - d.pdf(p)).abs() < 1e-3 * pdf);
                let (x, y) = ((p.x * w as f32) as usize, (p.y * h as f32) as usize);
                let want = weights[y.min(h - 1) * w + x.min(w - 1)] / total * (w * h) as f32;
                assert!((pdf - want).abs() < 1e-3 * want);
            }
        }
    }
}
