//! Particle filter over the emitter position (the seed's section 4.4).
//!
//! Design choices (see `docs/estimators-emitter.md` for the maths):
//! - **State**: each particle is an emitter position in the *world* frame. The robot pose comes
//!   with every measurement and is used to predict the particle's range and bearing, so robot
//!   motion needs no particle transformation.
//! - **Prediction**: a random walk, `N(0, q²·dt)` per axis, for a slowly moving emitter (the
//!   seed uses "a movement model with random acceleration"; with a static or slow target the
//!   random walk is the simpler special case).
//! - **Weights**: the seed's eq. (6)–(8) as reconstructed: `w = t / (|Δ| − c)` clamped to
//!   `[0.1, 1]` (1 when `|Δ| ≤ c`), for distance (metres) and angle (degrees), then
//!   `ℓ = sqrt(w_r·w_θ)`. The particle's weight is multiplied by `ℓ` and the set normalised
//!   (eq. 9).
//! - **Estimate**: weighted mean (eq. 10–11) and weighted covariance of the particle positions.
//! - **Resampling**: when `N_eff = 1/Σw² < N·ratio` (the seed: ratio ½, eq. 12), systematic
//!   (low-variance) resampling, weights reset to `1/N`, then a small roughening jitter.

use nalgebra::Matrix2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rfloc_pose::{angle_diff, Pose2};
use serde::{Deserialize, Serialize};

use crate::antenna::RangeBearing;
use crate::error::EmitterError;
use crate::Point2;

/// Filter constants. [`Default`] gives the seed's values where the seed has them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ParticleFilterConfig {
    /// Number of particles (seed: 1000).
    pub particle_count: usize,
    /// Distance tolerance `t_r` (seed: 0.1).
    pub range_tolerance: f64,
    /// Angle tolerance `t_θ`, per degree (seed: 0.01).
    pub angle_tolerance: f64,
    /// Distance offset `c_r`, metres (seed: 1.0).
    pub range_offset_m: f64,
    /// Angle offset `c_θ`, degrees (seed: 15).
    pub angle_offset_deg: f64,
    /// Lower clamp of each weight element (seed: 0.1).
    pub weight_floor: f64,
    /// Upper clamp of each weight element (seed: 1.0).
    pub weight_ceiling: f64,
    /// Resample when `N_eff < resample_ratio · N` (seed: 0.5).
    pub resample_ratio: f64,
    /// Random-walk process noise of the emitter, m/√s (not in the seed; 0.02 default).
    pub process_noise_m_per_sqrt_s: f64,
    /// Standard deviation of the jitter added after resampling, metres (0.05 default).
    pub roughening_m: f64,
    /// Radius of the uniform disc around the robot that [`EmitterParticleFilter::new`] fills
    /// with particles, metres (10 m default).
    pub init_radius_m: f64,
}

impl Default for ParticleFilterConfig {
    fn default() -> Self {
        Self {
            particle_count: 1000,
            range_tolerance: 0.1,
            angle_tolerance: 0.01,
            range_offset_m: 1.0,
            angle_offset_deg: 15.0,
            weight_floor: 0.1,
            weight_ceiling: 1.0,
            resample_ratio: 0.5,
            process_noise_m_per_sqrt_s: 0.02,
            roughening_m: 0.05,
            init_radius_m: 10.0,
        }
    }
}

impl ParticleFilterConfig {
    /// Checks that the values are usable.
    ///
    /// # Errors
    /// [`EmitterError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), EmitterError> {
        let finite_nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if self.particle_count == 0 {
            return Err(EmitterError::InvalidConfig("particle_count must be > 0"));
        }
        if !(positive_finite(self.range_tolerance) && positive_finite(self.angle_tolerance)) {
            return Err(EmitterError::InvalidConfig(
                "tolerances must be finite and > 0",
            ));
        }
        if !finite_nonneg(self.range_offset_m) || !finite_nonneg(self.angle_offset_deg) {
            return Err(EmitterError::InvalidConfig(
                "offsets must be finite and >= 0",
            ));
        }
        if !(positive_finite(self.weight_floor)
            && self.weight_ceiling.is_finite()
            && self.weight_ceiling >= self.weight_floor)
        {
            return Err(EmitterError::InvalidConfig(
                "need 0 < weight_floor <= weight_ceiling",
            ));
        }
        if !(0.0..=1.0).contains(&self.resample_ratio) {
            return Err(EmitterError::InvalidConfig(
                "resample_ratio must be in [0, 1]",
            ));
        }
        if !(finite_nonneg(self.process_noise_m_per_sqrt_s)
            && finite_nonneg(self.roughening_m)
            && positive_finite(self.init_radius_m))
        {
            return Err(EmitterError::InvalidConfig(
                "noise and init radius must be finite, >= 0",
            ));
        }
        Ok(())
    }

    /// One weight element of eq. (6)/(7): `t / (|Δ| − c)` clamped to `[floor, ceiling]`, and the
    /// ceiling while `|Δ| ≤ c` (the offset has not been crossed yet).
    #[must_use]
    pub fn weight_element(&self, abs_difference: f64, tolerance: f64, offset: f64) -> f64 {
        let excess = abs_difference - offset;
        if excess.is_nan() || excess <= 0.0 {
            return self.weight_ceiling;
        }
        (tolerance / excess).clamp(self.weight_floor, self.weight_ceiling)
    }

    /// The particle likelihood of eq. (8): `sqrt(w_r · w_θ)` for a particle at `particle`, a
    /// robot at `robot` and a measured range/bearing.
    #[must_use]
    pub fn likelihood(&self, robot: &Pose2, particle: &Point2, measured: &RangeBearing) -> f64 {
        let dx = particle.x - robot.x;
        let dy = particle.y - robot.y;
        let range = dx.hypot(dy);
        let bearing = angle_diff(dy.atan2(dx), robot.theta);
        let d_range = (range - measured.range_m).abs();
        let d_angle_deg = angle_diff(bearing, measured.bearing_rad).abs().to_degrees();
        let w_r = self.weight_element(d_range, self.range_tolerance, self.range_offset_m);
        let w_t = self.weight_element(d_angle_deg, self.angle_tolerance, self.angle_offset_deg);
        (w_r * w_t).sqrt()
    }
}

/// One weighted hypothesis of the emitter position (world frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Particle {
    /// Hypothesised emitter position, metres.
    pub position: Point2,
    /// Normalised weight (the set sums to 1).
    pub weight: f64,
}

/// The filter output after one update.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EmitterEstimate {
    /// Weighted mean of the particles, world frame, metres.
    pub mean: Point2,
    /// Weighted covariance of the particle positions (x, y), m².
    #[serde(skip, default = "Matrix2::zeros")]
    pub covariance: Matrix2<f64>,
    /// The unfiltered estimate of this update (eq. 3–4 placed in the world with the robot pose).
    pub raw: Point2,
    /// Range and bearing of [`Self::mean`] from the robot pose of this update.
    pub filtered_range_bearing: RangeBearing,
    /// `N_eff = 1/Σw²` after the weight update, before any resampling.
    pub effective_sample_size: f64,
    /// Whether this update resampled.
    pub resampled: bool,
    /// Number of measurement updates so far, this one included.
    pub update_count: u64,
}

/// `N_eff = 1 / Σ wᵢ²` of normalised weights (eq. 12). Returns 0 for an empty or all-zero set.
#[must_use]
pub fn effective_sample_size(weights: &[f64]) -> f64 {
    let s: f64 = weights.iter().map(|w| w * w).sum();
    if s > 0.0 && s.is_finite() {
        1.0 / s
    } else {
        0.0
    }
}

/// Systematic (low-variance) resampling: `N` pointers `(u0 + i)/N`, `u0 ∈ [0, 1)`, walked along
/// the cumulative weights. Returns, for each new particle, the index of its parent. Weights are
/// normalised here, so they need not sum to 1; an empty, all-zero or non-finite set returns the
/// identity. Each parent `i` is copied `⌊N·wᵢ⌋` or `⌈N·wᵢ⌉` times (up to round-off at the
/// boundaries). The walk never indexes past the end, even when the cumulative sum ends below 1
/// after round-off.
#[must_use]
pub fn systematic_resample(weights: &[f64], u0: f64) -> Vec<usize> {
    let n = weights.len();
    let total: f64 = weights.iter().sum();
    if n == 0 || !positive_finite(total) || weights.iter().any(|w| w.is_nan() || *w < 0.0) {
        return (0..n).collect();
    }
    let u0 = if (0.0..1.0).contains(&u0) { u0 } else { 0.0 };
    let step = 1.0 / n as f64;
    let mut out = Vec::with_capacity(n);
    let mut parent = 0usize;
    let mut cumulative = weights.first().copied().unwrap_or(0.0) / total;
    for i in 0..n {
        let pointer = (u0 + i as f64) * step;
        while pointer >= cumulative && parent + 1 < n {
            parent += 1;
            cumulative += weights.get(parent).copied().unwrap_or(0.0) / total;
        }
        out.push(parent);
    }
    out
}

/// The seed's particle filter over one emitter position, with a seeded ChaCha8 RNG so runs are
/// reproducible.
#[derive(Debug, Clone)]
pub struct EmitterParticleFilter {
    config: ParticleFilterConfig,
    particles: Vec<Particle>,
    rng: ChaCha8Rng,
    updates: u64,
}

impl EmitterParticleFilter {
    /// Particles uniform over a disc of `init_radius_m` around the robot's start position (the
    /// seed initialises "based on the starting location of the robot").
    ///
    /// # Errors
    /// [`EmitterError::InvalidConfig`], or [`EmitterError::NonFinitePose`] for a bad start pose.
    pub fn new(
        config: ParticleFilterConfig,
        start: &Pose2,
        seed: u64,
    ) -> Result<Self, EmitterError> {
        check_pose(start)?;
        Self::around(
            config,
            Point2::new(start.x, start.y),
            config.init_radius_m,
            seed,
        )
    }

    /// Particles uniform over a disc of `radius_m` around `centre` (for a prior from elsewhere).
    ///
    /// # Errors
    /// [`EmitterError::InvalidConfig`] for a bad configuration, radius or centre.
    pub fn around(
        config: ParticleFilterConfig,
        centre: Point2,
        radius_m: f64,
        seed: u64,
    ) -> Result<Self, EmitterError> {
        config.validate()?;
        if !(centre.is_finite() && positive_finite(radius_m)) {
            return Err(EmitterError::InvalidConfig(
                "initial disc must be finite with radius > 0",
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = config.particle_count;
        let w = 1.0 / n as f64;
        let particles = (0..n)
            .map(|_| {
                let r = radius_m * rng.random::<f64>().sqrt();
                let a = rng.random::<f64>() * std::f64::consts::TAU;
                Particle {
                    position: Point2::new(centre.x + r * a.cos(), centre.y + r * a.sin()),
                    weight: w,
                }
            })
            .collect();
        Ok(Self {
            config,
            particles,
            rng,
            updates: 0,
        })
    }

    /// The configuration in use.
    #[must_use]
    pub fn config(&self) -> &ParticleFilterConfig {
        &self.config
    }

    /// The current particle set (weights normalised).
    #[must_use]
    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    /// One filter step: predict by `dt_s` seconds of random walk, weight against the measured
    /// range/bearing taken at robot pose `robot`, normalise, estimate, resample if needed.
    ///
    /// # Errors
    /// [`EmitterError::NonFinitePose`] or [`EmitterError::InvalidMeasurement`]; the particle set
    /// is left unchanged in that case.
    pub fn update(
        &mut self,
        robot: &Pose2,
        measured: &RangeBearing,
        dt_s: f64,
    ) -> Result<EmitterEstimate, EmitterError> {
        check_pose(robot)?;
        if !(measured.range_m.is_finite()
            && measured.range_m >= 0.0
            && measured.bearing_rad.is_finite())
        {
            return Err(EmitterError::InvalidMeasurement {
                range_m: measured.range_m,
                bearing_rad: measured.bearing_rad,
            });
        }
        self.predict(dt_s);
        let cfg = self.config;
        for p in &mut self.particles {
            p.weight *= cfg.likelihood(robot, &p.position, measured);
        }
        self.normalise();
        let weights: Vec<f64> = self.particles.iter().map(|p| p.weight).collect();
        let n_eff = effective_sample_size(&weights);
        let (mean, covariance) = self.mean_and_covariance();
        let resampled = n_eff < cfg.resample_ratio * self.particles.len() as f64;
        if resampled {
            self.resample(&weights);
        }
        self.updates += 1;
        let dx = mean.x - robot.x;
        let dy = mean.y - robot.y;
        Ok(EmitterEstimate {
            mean,
            covariance,
            raw: measured.to_world(robot),
            filtered_range_bearing: RangeBearing {
                range_m: dx.hypot(dy),
                bearing_rad: angle_diff(dy.atan2(dx), robot.theta),
            },
            effective_sample_size: n_eff,
            resampled,
            update_count: self.updates,
        })
    }

    /// Weighted mean and covariance of the current set. The covariance uses the unbiased
    /// weighted form `Σw(p−μ)(p−μ)ᵀ / (1 − Σw²)` when `Σw² < 1`.
    #[must_use]
    pub fn mean_and_covariance(&self) -> (Point2, Matrix2<f64>) {
        let (mut mx, mut my) = (0.0, 0.0);
        for p in &self.particles {
            mx += p.weight * p.position.x;
            my += p.weight * p.position.y;
        }
        let mut c = Matrix2::zeros();
        let mut sum_sq = 0.0;
        for p in &self.particles {
            let dx = p.position.x - mx;
            let dy = p.position.y - my;
            c[(0, 0)] += p.weight * dx * dx;
            c[(0, 1)] += p.weight * dx * dy;
            c[(1, 1)] += p.weight * dy * dy;
            sum_sq += p.weight * p.weight;
        }
        c[(1, 0)] = c[(0, 1)];
        if sum_sq < 1.0 {
            c /= 1.0 - sum_sq;
        }
        (Point2::new(mx, my), c)
    }

    fn predict(&mut self, dt_s: f64) {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            0.0
        };
        let sigma = self.config.process_noise_m_per_sqrt_s * dt.sqrt();
        self.jitter(sigma);
    }

    fn jitter(&mut self, sigma: f64) {
        if !positive_finite(sigma) {
            return;
        }
        if let Ok(normal) = Normal::new(0.0, sigma) {
            for p in &mut self.particles {
                p.position.x += normal.sample(&mut self.rng);
                p.position.y += normal.sample(&mut self.rng);
            }
        }
    }

    fn normalise(&mut self) {
        let total: f64 = self.particles.iter().map(|p| p.weight).sum();
        let n = self.particles.len() as f64;
        if total > 0.0 && total.is_finite() {
            for p in &mut self.particles {
                p.weight /= total;
            }
        } else {
            // Degenerate set (all weights underflowed): restart from uniform weights.
            for p in &mut self.particles {
                p.weight = 1.0 / n;
            }
        }
    }

    fn resample(&mut self, weights: &[f64]) {
        let u0 = self.rng.random::<f64>();
        let parents = systematic_resample(weights, u0);
        let w = 1.0 / self.particles.len() as f64;
        let new: Vec<Particle> = parents
            .iter()
            .filter_map(|&i| self.particles.get(i).copied())
            .map(|p| Particle {
                position: p.position,
                weight: w,
            })
            .collect();
        self.particles = new;
        let rough = self.config.roughening_m;
        self.jitter(rough);
    }
}

fn positive_finite(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn check_pose(p: &Pose2) -> Result<(), EmitterError> {
    if p.is_finite() {
        Ok(())
    } else {
        Err(EmitterError::NonFinitePose {
            x: p.x,
            y: p.y,
            theta: p.theta,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_element_follows_offset_and_clamps() {
        let c = ParticleFilterConfig::default();
        // Inside the offset: full weight.
        assert_eq!(c.weight_element(0.9, 0.1, 1.0), 1.0);
        // 1.2 m off: 0.1 / 0.2 = 0.5.
        assert!((c.weight_element(1.2, 0.1, 1.0) - 0.5).abs() < 1e-12);
        // Far off: floor.
        assert_eq!(c.weight_element(5.0, 0.1, 1.0), 0.1);
        // Angle: 15.02° → 0.01/0.02 = 0.5.
        assert!((c.weight_element(15.02, 0.01, 15.0) - 0.5).abs() < 1e-9);
        assert_eq!(c.weight_element(f64::NAN, 0.1, 1.0), 1.0);
    }

    #[test]
    fn likelihood_is_between_floor_and_one() {
        let c = ParticleFilterConfig::default();
        let robot = Pose2::new(0.0, 0.0, 0.0);
        let m = RangeBearing {
            range_m: 4.0,
            bearing_rad: 0.0,
        };
        assert_eq!(c.likelihood(&robot, &Point2::new(4.0, 0.0), &m), 1.0);
        // Wrong range (4 m off) and wrong angle: both elements at the floor.
        let behind = c.likelihood(&robot, &Point2::new(-8.0, 0.0), &m);
        assert!((behind - 0.1).abs() < 1e-12, "{behind}");
        // Right range, wrong angle: sqrt(1 · 0.1).
        let side = c.likelihood(&robot, &Point2::new(0.0, 4.0), &m);
        assert!((side - 0.1f64.sqrt()).abs() < 1e-12, "{side}");
    }

    #[test]
    fn n_eff_of_uniform_and_degenerate_sets() {
        assert!((effective_sample_size(&[0.25; 4]) - 4.0).abs() < 1e-12);
        assert!((effective_sample_size(&[1.0, 0.0, 0.0]) - 1.0).abs() < 1e-12);
        assert_eq!(effective_sample_size(&[]), 0.0);
    }

    #[test]
    fn bad_measurement_leaves_particles_untouched() {
        let mut f =
            EmitterParticleFilter::new(ParticleFilterConfig::default(), &Pose2::default(), 1)
                .unwrap();
        let before = f.particles().to_vec();
        let bad = RangeBearing {
            range_m: f64::NAN,
            bearing_rad: 0.0,
        };
        assert!(f.update(&Pose2::default(), &bad, 0.5).is_err());
        assert_eq!(f.particles(), &before[..]);
    }
}
