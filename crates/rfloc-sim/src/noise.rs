//! Seeded noise helpers shared by the models.

use rand::Rng;
use rand_distr::StandardNormal;

/// A zero-mean Gaussian sample with standard deviation `sigma` (0 when `sigma` is not a
/// positive finite number, so a disabled noise term costs no branch at the call site).
pub fn gaussian<R: Rng + ?Sized>(rng: &mut R, sigma: f64) -> f64 {
    if sigma.is_finite() && sigma > 0.0 {
        let z: f64 = rng.sample(StandardNormal);
        z * sigma
    } else {
        0.0
    }
}

/// True with probability `p` (clamped to [0, 1]).
pub fn bernoulli<R: Rng + ?Sized>(rng: &mut R, p: f64) -> bool {
    if p.is_finite() && p > 0.0 {
        rng.random::<f64>() < p.min(1.0)
    } else {
        false
    }
}
