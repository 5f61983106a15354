//! Tracking on the tag grid while driving: a particle filter over `(x, y, θ)` that moves
//! particles with noisy odometry increments and weights them by the RSSI likelihood of the
//! reported tags (and, optionally, the miss likelihood of nearby tags that were not reported).

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rfloc_pose::{angle_diff, wrap_angle, EstimateMode, Pose2, PoseEstimate};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::grid::TagGrid;
use crate::init::pool_reports;
use crate::reading::TagReading;
use crate::rssi::{LikelihoodTable, RssiModel};

/// Tracker settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GridTrackerConfig {
    /// Number of particles.
    pub particles: usize,
    /// Antenna position in the robot frame, m.
    pub antenna_offset_m: (f64, f64),
    /// Odometry translation noise per metre travelled (σ, dimensionless).
    pub trans_noise_per_m: f64,
    /// Odometry heading noise per radian turned (σ, dimensionless).
    pub rot_noise_per_rad: f64,
    /// Odometry heading noise per metre travelled (σ, rad/m).
    pub rot_noise_per_m: f64,
    /// Translation noise added to every increment (σ, m).
    pub floor_m: f64,
    /// Heading noise added to every increment (σ, rad).
    pub floor_rad: f64,
    /// Use nearby tags that were not reported.
    pub use_non_detections: bool,
    /// Resample when the effective sample size falls below this fraction of the particles.
    pub resample_threshold: f64,
    /// RNG seed (the tracker is deterministic for a given seed and input).
    pub seed: u64,
}

impl Default for GridTrackerConfig {
    fn default() -> Self {
        Self {
            particles: 500,
            antenna_offset_m: (-0.10, 0.0),
            trans_noise_per_m: 0.05,
            rot_noise_per_rad: 0.05,
            rot_noise_per_m: 0.1,
            floor_m: 0.0005,
            floor_rad: 0.002,
            use_non_detections: true,
            resample_threshold: 0.5,
            seed: 1,
        }
    }
}

/// Tracker errors.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrackerError {
    /// An input was NaN or infinite.
    #[error("non-finite {0}")]
    NonFinite(&'static str),
    /// The configuration or start covariance cannot work.
    #[error("invalid: {0}")]
    Invalid(String),
}

/// What one [`GridTracker::update`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerUpdate {
    /// Distinct known tags in the reports.
    pub known_tags: usize,
    /// Reports of UIDs not in the grid (ignored).
    pub unknown_reports: usize,
    /// Effective sample size after weighting (before any resampling).
    pub effective_sample_size: f64,
    /// Whether the particles were resampled.
    pub resampled: bool,
}

/// Particle filter on the tag grid.
#[derive(Debug, Clone)]
pub struct GridTracker {
    grid: TagGrid,
    table: LikelihoodTable,
    config: GridTrackerConfig,
    particles: Vec<Vector3<f64>>,
    log_w: Vec<f64>,
    rng: ChaCha8Rng,
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

impl GridTracker {
    /// Starts with particles drawn from N(`start`, `covariance`) (e.g. an
    /// [`crate::InitialPose`]'s pose and covariance).
    pub fn new(
        grid: TagGrid,
        model: &RssiModel,
        config: GridTrackerConfig,
        start: Pose2,
        covariance: Matrix3<f64>,
    ) -> Result<Self, TrackerError> {
        if config.particles == 0 {
            return Err(TrackerError::Invalid("zero particles".into()));
        }
        if !start.is_finite() || covariance.iter().any(|v| !v.is_finite()) {
            return Err(TrackerError::NonFinite("start pose or covariance"));
        }
        let sym = (covariance + covariance.transpose()) / 2.0 + Matrix3::identity() * 1e-12;
        let l = sym
            .cholesky()
            .ok_or_else(|| TrackerError::Invalid("start covariance not positive definite".into()))?
            .l();
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let particles = (0..config.particles)
            .map(|_| {
                let z = Vector3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
                let d = l * z;
                Vector3::new(start.x + d.x, start.y + d.y, wrap_angle(start.theta + d.z))
            })
            .collect();
        Ok(Self {
            grid,
            table: LikelihoodTable::new(model, 0.0, 0.0002),
            config,
            log_w: vec![0.0; config.particles],
            particles,
            rng,
        })
    }

    /// Moves every particle by the odometry increment `delta` (robot frame at the previous
    /// reading) plus sampled noise.
    pub fn predict(&mut self, delta: Pose2) -> Result<(), TrackerError> {
        if !delta.is_finite() {
            return Err(TrackerError::NonFinite("odometry increment"));
        }
        let c = self.config;
        let len = delta.x.hypot(delta.y);
        let s_xy = c.trans_noise_per_m * len + c.floor_m;
        let s_th = c.rot_noise_per_rad * delta.theta.abs() + c.rot_noise_per_m * len + c.floor_rad;
        for p in &mut self.particles {
            let dx = delta.x + s_xy * normal(&mut self.rng);
            let dy = delta.y + s_xy * normal(&mut self.rng);
            let dth = delta.theta + s_th * normal(&mut self.rng);
            let (s, co) = p.z.sin_cos();
            *p = Vector3::new(
                p.x + co * dx - s * dy,
                p.y + s * dx + co * dy,
                wrap_angle(p.z + dth),
            );
        }
        Ok(())
    }

    /// Weights the particles with one scan's reports. An empty scan changes nothing (a scan in
    /// which the reader reported nothing is treated as missing, not as evidence).
    pub fn update(&mut self, readings: &[TagReading]) -> TrackerUpdate {
        let (pooled, unknown, _invalid) = pool_reports(&self.grid, readings);
        let n = self.particles.len();
        if pooled.is_empty() {
            return TrackerUpdate {
                known_tags: 0,
                unknown_reports: unknown,
                effective_sample_size: self.ess(),
                resampled: false,
            };
        }
        let (ax, ay) = self.config.antenna_offset_m;
        let reach = self.table.reach_m;
        for (p, lw) in self.particles.iter().zip(self.log_w.iter_mut()) {
            let (s, co) = p.z.sin_cos();
            let (qx, qy) = (p.x + co * ax - s * ay, p.y + s * ax + co * ay);
            let mut l = 0.0;
            for (_, (tx, ty), w) in &pooled {
                l += self.table.log_report(w, (tx - qx).hypot(ty - qy));
            }
            if self.config.use_non_detections {
                for (uid, tx, ty) in self.grid.tags_within(qx, qy, reach) {
                    if !pooled.iter().any(|(u, _, _)| *u == uid) {
                        l += self.table.log_miss((tx - qx).hypot(ty - qy));
                    }
                }
            }
            *lw += l;
        }
        let max = self.log_w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        for lw in &mut self.log_w {
            *lw -= max;
        }
        let ess = self.ess();
        #[allow(clippy::cast_precision_loss)]
        let resampled = ess < self.config.resample_threshold * n as f64;
        if resampled {
            self.resample();
        }
        TrackerUpdate {
            known_tags: pooled.len(),
            unknown_reports: unknown,
            effective_sample_size: ess,
            resampled,
        }
    }

    fn weights(&self) -> Vec<f64> {
        let w: Vec<f64> = self.log_w.iter().map(|l| l.exp()).collect();
        let s: f64 = w.iter().sum();
        #[allow(clippy::cast_precision_loss)]
        let n = w.len() as f64;
        if s > 0.0 && s.is_finite() {
            w.into_iter().map(|v| v / s).collect()
        } else {
            vec![1.0 / n; w.len()]
        }
    }

    fn ess(&self) -> f64 {
        1.0 / self.weights().iter().map(|w| w * w).sum::<f64>()
    }

    /// Systematic (low-variance) resampling.
    fn resample(&mut self) {
        let w = self.weights();
        let n = w.len();
        #[allow(clippy::cast_precision_loss)]
        let step = 1.0 / n as f64;
        let mut u = self.rng.random::<f64>() * step;
        let mut out = Vec::with_capacity(n);
        let mut c = w.first().copied().unwrap_or(0.0);
        let mut i = 0;
        for _ in 0..n {
            while u > c && i + 1 < n {
                i += 1;
                c += w.get(i).copied().unwrap_or(0.0);
            }
            if let Some(p) = self.particles.get(i) {
                out.push(*p);
            }
            u += step;
        }
        self.particles = out;
        self.log_w = vec![0.0; n];
    }

    /// Weighted mean pose (circular mean heading) and covariance.
    #[must_use]
    pub fn estimate(&self) -> (Pose2, Matrix3<f64>) {
        let w = self.weights();
        let (mut x, mut y, mut s, mut c) = (0.0, 0.0, 0.0, 0.0);
        for (p, wi) in self.particles.iter().zip(&w) {
            x += wi * p.x;
            y += wi * p.y;
            s += wi * p.z.sin();
            c += wi * p.z.cos();
        }
        let th = s.atan2(c);
        let mut cov = Matrix3::zeros();
        for (p, wi) in self.particles.iter().zip(&w) {
            let d = Vector3::new(p.x - x, p.y - y, angle_diff(p.z, th));
            cov += *wi * d * d.transpose();
        }
        (Pose2::new(x, y, th), cov)
    }

    /// The estimate as a [`PoseEstimate`] stamped `time`.
    #[must_use]
    pub fn pose_estimate(&self, time: f64) -> PoseEstimate {
        let (pose, covariance) = self.estimate();
        PoseEstimate {
            time,
            pose,
            covariance,
            mode: EstimateMode::Fix,
            source: "hfgrid-tracker".into(),
        }
    }
}
