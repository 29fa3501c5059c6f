//! Image losses with their gradients with respect to the rendered image.

use crate::error::{Error, Result};

/// A loss between a rendered image and a target of the same shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loss {
    /// mean |x − y|
    L1,
    /// mean (x − y)², as Mitsuba's tutorials use.
    L2,
    /// mean (x − y)² / (y² + 0.01): relative squared error, which weighs
    /// dark and bright regions alike.
    RelativeL2,
}

impl Loss {
    pub fn parse(name: &str) -> Result<Loss> {
        match name {
            "l1" | "L1" => Ok(Loss::L1),
            "l2" | "L2" | "mse" => Ok(Loss::L2),
            "rel_l2" | "relative_l2" | "relmse" => Ok(Loss::RelativeL2),
            other => Err(Error::Invalid(format!(
                "unknown loss '{other}' (use l1, l2 or rel_l2)"
            ))),
        }
    }

    /// The loss (in f64) and its gradient with respect to `image`.
    pub fn eval(&self, image: &[f32], target: &[f32]) -> Result<(f64, Vec<f32>)> {
        if image.len() != target.len() {
            return Err(Error::Invalid(format!(
                "the target has {} values but the image has {} (same width, height and channels needed)",
                target.len(),
                image.len()
            )));
        }
        let n = image.len() as f64;
        let mut loss = 0.0f64;
        let grad = image
            .iter()
            .zip(target)
            .map(|(&x, &y)| {
                let d = (x - y) as f64;
                let (l, g) = match self {
                    Loss::L1 => (d.abs(), d.signum()),
                    Loss::L2 => (d * d, 2.0 * d),
                    Loss::RelativeL2 => {
                        let s = 1.0 / ((y as f64).powi(2) + 1e-2);
                        (d * d * s, 2.0 * d * s)
                    }
                };
                loss += l;
                (g / n) as f32
            })
            .collect();
        Ok((loss / n, grad))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradients_match_finite_differences() {
        let x = [0.2f32, 0.7, 1.5, 0.0];
        let y = [0.25f32, 0.5, 1.0, 0.1];
        for loss in [Loss::L1, Loss::L2, Loss::RelativeL2] {
            let (_, g) = loss.eval(&x, &y).unwrap();
            for i in 0..x.len() {
                let h = 1e-3;
                let mut a = x;
                let mut b = x;
                a[i] += h;
                b[i] -= h;
                let fd = (loss.eval(&a, &y).unwrap().0 - loss.eval(&b, &y).unwrap().0)
                    / (2.0 * h as f64);
                assert!(
                    (fd - g[i] as f64).abs() < 1e-3,
                    "{loss:?} {i}: {fd} vs {}",
                    g[i]
                );
            }
        }
        assert!(Loss::L2.eval(&x, &y[..3]).is_err());
    }
}
