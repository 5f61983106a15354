//! Gain pattern of an antenna behind a parabolic reflector, as a function of the angle off
//! boresight α:
//!
//! `G(α) = 10·log10( b + (1 − b)·((1 + cos α)/2)^k )` dB, 0 dB on boresight,
//!
//! where `b` is the back-lobe level (linear power ratio) and `k` sets the beam width. This is
//! a modelling choice (neither seed gives a measured pattern); see the XBee and emitter
//! modules for how `k` and `b` were chosen.

use serde::{Deserialize, Serialize};

/// Reflector gain pattern parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReflectorPattern {
    /// Beam exponent `k`.
    pub exponent: f64,
    /// Back-lobe level in dB (negative; −10 dB = 10 % of the boresight power).
    pub back_lobe_db: f64,
}

impl ReflectorPattern {
    /// A pattern whose half-power beam width is `hpbw_deg` with the given back lobe.
    #[must_use]
    pub fn from_hpbw(hpbw_deg: f64, back_lobe_db: f64) -> Self {
        let b = 10f64.powf(back_lobe_db / 10.0).clamp(0.0, 0.49);
        let half = (0.5 * hpbw_deg).to_radians();
        let base = (1.0 + half.cos()) / 2.0;
        Self {
            exponent: ((0.5 - b) / (1.0 - b)).ln() / base.ln(),
            back_lobe_db,
        }
    }

    /// Gain in dB relative to boresight at `alpha` radians off boresight.
    #[must_use]
    pub fn gain_db(&self, alpha: f64) -> f64 {
        let b = 10f64.powf(self.back_lobe_db / 10.0).clamp(0.0, 1.0);
        let lobe = ((1.0 + alpha.cos()) / 2.0)
            .max(0.0)
            .powf(self.exponent.max(0.0));
        10.0 * (b + (1.0 - b) * lobe).log10()
    }

    /// Full angle between the −3 dB points, degrees (numerical, 0.01° resolution).
    #[must_use]
    pub fn hpbw_deg(&self) -> f64 {
        let mut a = 0.0_f64;
        while a < 180.0 && self.gain_db(a.to_radians()) > -3.0 {
            a += 0.01;
        }
        2.0 * a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boresight_zero_back_lobe_floor_and_hpbw() {
        let p = ReflectorPattern::from_hpbw(76.0, -10.0);
        assert!(p.gain_db(0.0).abs() < 1e-12);
        assert!((p.gain_db(std::f64::consts::PI) + 10.0).abs() < 1e-9);
        let h = p.hpbw_deg();
        assert!((h - 76.0).abs() < 0.2, "{h}"); // −3 dB is a power ratio of 0.501, not 0.5
        assert!(p.gain_db(0.3) > p.gain_db(0.6));
    }
}
