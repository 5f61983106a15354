//! Continuous-pose particle filter over the fine fingerprint map.
//!
//! The seed's future work (section 8) asks for a particle filter to stop the cycling between
//! neighbouring states. [`TrackFilter`] keeps particles in `(x, y, θ)`:
//! - **prediction** by the robot's odometry increment between two snapshots (robot frame), with
//!   noise proportional to the increment;
//! - **update** with a snapshot through the fingerprint map (every exploration snapshot with the
//!   pose the robot believed it had, from odometry): the `k` most similar fingerprints weigh
//!   `exp(−(d − d_min)/τ)` and each spreads a Gaussian kernel around its pose, so a particle's
//!   likelihood is `floor + Σ_i w_i · K(p − p_i)`;
//! - **sensor resetting**: a small fraction of particles is redrawn around the best-matching
//!   fingerprints at every update (all of them at the first), so a wrong lock can recover;
//! - systematic resampling when the effective sample size drops below half.
//!
//! The estimate is a local mean around the heaviest 0.3 m cell of the particle cloud (three
//! mean-shift steps), so two separated modes are not averaged into a point between them.

use rand::Rng;
use rfloc_pose::{angle_diff, wrap_angle, Pose2};
use serde::{Deserialize, Serialize};

use crate::distance::{IndexedSnapshot, SnapshotDistance, TagIndex};
use crate::snapshot::Snapshot;
use crate::tagmap::TagMap;

/// Every exploration snapshot with its pose: the fine localisation database.
#[derive(Debug, Clone, Default)]
pub struct FingerprintMap {
    distance: SnapshotDistance,
    tags: TagIndex,
    prints: Vec<IndexedSnapshot>,
    poses: Vec<Pose2>,
}

impl FingerprintMap {
    /// A map of the non-empty snapshots among `samples`.
    #[must_use]
    pub fn new<'a>(
        samples: impl IntoIterator<Item = (&'a Snapshot, Pose2)>,
        distance: SnapshotDistance,
    ) -> Self {
        let mut map = Self {
            distance,
            ..Self::default()
        };
        for (s, p) in samples {
            if s.is_empty() {
                continue;
            }
            let indexed = map.tags.index(s);
            map.prints.push(indexed);
            map.poses.push(p);
        }
        map
    }

    /// Number of fingerprints.
    #[must_use]
    pub fn len(&self) -> usize {
        self.prints.len()
    }

    /// True when the map holds no fingerprint.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.prints.is_empty()
    }

    /// Poses of the fingerprints.
    #[must_use]
    pub fn poses(&self) -> &[Pose2] {
        &self.poses
    }

    /// The `k` fingerprints most similar to `snapshot`, as `(pose, weight)` with weight
    /// `exp(−(d − d_min)/τ)` (the best one weighs 1), dropping those below `e^−8`.
    #[must_use]
    pub fn matches(&self, snapshot: &Snapshot, k: usize, tau: f64) -> Vec<(Pose2, f64)> {
        if snapshot.is_empty() || self.prints.is_empty() {
            return Vec::new();
        }
        let q = self.tags.index_query(snapshot);
        let mut d: Vec<(f64, usize)> = self
            .prints
            .iter()
            .enumerate()
            .map(|(i, p)| (self.distance.between_indexed(&q, p), i))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let dmin = d.first().map_or(0.0, |x| x.0);
        let tau = tau.max(1e-9);
        d.iter()
            .take(k.max(1))
            .map(|(di, i)| ((-(di - dmin) / tau).exp(), *i))
            .filter(|(w, _)| *w > (-8.0_f64).exp())
            .filter_map(|(w, i)| self.poses.get(i).map(|p| (*p, w)))
            .collect()
    }
}

/// Particle filter parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackConfig {
    /// Number of particles.
    pub particles: usize,
    /// Fingerprints that vote in one update.
    pub neighbours: usize,
    /// Snapshot-dissimilarity temperature τ of the fingerprint weights.
    pub tau: f64,
    /// Kernel σ around a fingerprint's position, metres.
    pub sigma_xy: f64,
    /// Kernel σ around a fingerprint's heading, radians.
    pub sigma_theta: f64,
    /// Likelihood floor relative to the best fingerprint's kernel peak (outlier snapshots).
    pub floor: f64,
    /// Largest fraction of particles redrawn around the best fingerprints at one update. The
    /// fraction drawn is `max(0, 1 − w_fast/w_slow)` (augmented MCL: only when the particles
    /// explain the snapshots worse than they used to), capped by this.
    pub reset_fraction: f64,
    /// Smoothing factors of the short- and long-term mean likelihood (augmented MCL).
    pub alpha_fast: f64,
    pub alpha_slow: f64,
    /// Odometry noise: σ of translation per metre moved and a constant, metres.
    pub odo_trans_rel: f64,
    pub odo_trans_abs: f64,
    /// Odometry noise: σ of rotation per radian turned and a constant, radians.
    pub odo_rot_rel: f64,
    pub odo_rot_abs: f64,
    /// Radius of the local mean that gives the estimate, metres.
    pub estimate_radius: f64,
}

impl Default for TrackConfig {
    fn default() -> Self {
        Self {
            particles: 1500,
            neighbours: 40,
            tau: 0.05,
            sigma_xy: 0.2,
            sigma_theta: 0.35,
            floor: 0.3,
            reset_fraction: 0.02,
            alpha_fast: 0.5,
            alpha_slow: 0.05,
            odo_trans_rel: 0.1,
            odo_trans_abs: 0.01,
            odo_rot_rel: 0.1,
            odo_rot_abs: 0.02,
            estimate_radius: 0.5,
        }
    }
}

/// The filter's pose estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackEstimate {
    /// Local mean pose around the heaviest part of the cloud.
    pub pose: Pose2,
    /// Weighted RMS distance of the particles within the estimate radius from the estimate, m.
    pub spread: f64,
    /// Fraction of the weight within the estimate radius (1 = one tight mode).
    pub mass: f64,
    /// Weighted covariance over `(x, y, θ)` of the particles within the estimate radius.
    pub covariance: nalgebra::Matrix3<f64>,
}

/// Particle filter over `(x, y, θ)` with odometry prediction and fingerprint updates.
#[derive(Debug, Clone)]
pub struct TrackFilter {
    config: TrackConfig,
    poses: Vec<Pose2>,
    weights: Vec<f64>,
    initialised: bool,
    w_fast: f64,
    w_slow: f64,
}

/// One standard normal draw (Box–Muller).
fn normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl TrackFilter {
    /// A filter with no particles yet: the first update with tags draws them from the
    /// fingerprints that match (global localisation).
    #[must_use]
    pub fn new(config: TrackConfig) -> Self {
        Self {
            config,
            poses: Vec::new(),
            weights: Vec::new(),
            initialised: false,
            w_fast: 0.0,
            w_slow: 0.0,
        }
    }

    /// True once a snapshot with tags has placed the particles.
    #[must_use]
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// The particles and their weights (weights sum to 1).
    #[must_use]
    pub fn particles(&self) -> (&[Pose2], &[f64]) {
        (&self.poses, &self.weights)
    }

    /// Moves every particle by the odometry increment `delta` (robot frame) plus noise.
    pub fn predict<R: Rng + ?Sized>(&mut self, delta: &Pose2, rng: &mut R) {
        let c = &self.config;
        let dist = delta.x.hypot(delta.y);
        let st = c.odo_trans_abs + c.odo_trans_rel * dist;
        let sr = c.odo_rot_abs + c.odo_rot_rel * delta.theta.abs() + 0.05 * dist;
        for p in &mut self.poses {
            let noisy = Pose2::new(
                delta.x + st * normal(rng),
                delta.y + st * normal(rng),
                delta.theta + sr * normal(rng),
            );
            *p = p.compose(&noisy);
        }
    }

    /// Draws a pose around one of the matched fingerprints (weighted).
    fn draw_near<R: Rng + ?Sized>(&self, matches: &[(Pose2, f64)], rng: &mut R) -> Option<Pose2> {
        let total: f64 = matches.iter().map(|m| m.1).sum();
        if total <= 0.0 {
            return None;
        }
        let mut u = rng.random::<f64>() * total;
        let mut chosen = matches.first()?.0;
        for (p, w) in matches {
            chosen = *p;
            if u < *w {
                break;
            }
            u -= w;
        }
        let c = &self.config;
        Some(Pose2::new(
            chosen.x + c.sigma_xy * normal(rng),
            chosen.y + c.sigma_xy * normal(rng),
            chosen.theta + c.sigma_theta * normal(rng),
        ))
    }

    /// Global localisation: every particle drawn around the matched fingerprints, uniform
    /// weights.
    fn draw_all<R: Rng + ?Sized>(&mut self, matches: &[(Pose2, f64)], rng: &mut R) {
        let n = self.config.particles.max(1);
        self.poses = (0..n)
            .filter_map(|_| self.draw_near(matches, rng))
            .collect();
        let m = self.poses.len().max(1) as f64;
        self.weights = vec![1.0 / m; self.poses.len()];
        self.initialised = !self.poses.is_empty();
    }

    /// Particles to redraw near the matches (augmented MCL): the fraction by which the
    /// short-term mean likelihood fell below the long-term one, capped by `reset_fraction`.
    fn resets(&self) -> usize {
        let deficit = if self.w_slow > 0.0 {
            (1.0 - self.w_fast / self.w_slow).max(0.0)
        } else {
            0.0
        };
        let fraction = deficit.min(self.config.reset_fraction.clamp(0.0, 1.0));
        (fraction * self.poses.len() as f64).round() as usize
    }

    /// Weighs the particles by a snapshot; an empty snapshot (no tags) changes nothing.
    pub fn update<R: Rng + ?Sized>(
        &mut self,
        map: &FingerprintMap,
        snapshot: &Snapshot,
        rng: &mut R,
    ) {
        let c = self.config;
        let matches = map.matches(snapshot, c.neighbours, c.tau);
        if matches.is_empty() {
            return;
        }
        if !self.initialised || self.poses.is_empty() {
            self.draw_all(&matches, rng);
        }
        let inv_xy = 0.5 / (c.sigma_xy * c.sigma_xy).max(1e-12);
        let inv_th = 0.5 / (c.sigma_theta * c.sigma_theta).max(1e-12);
        let peak: f64 = matches.iter().map(|m| m.1).fold(0.0, f64::max);
        let floor = c.floor * peak;
        let mut explained = 0.0;
        for (p, w) in self.poses.iter().zip(self.weights.iter_mut()) {
            let mut l = floor;
            for (q, wq) in &matches {
                let dx = p.x - q.x;
                let dy = p.y - q.y;
                let e = (dx * dx + dy * dy) * inv_xy;
                if e > 12.0 {
                    continue;
                }
                let dth = angle_diff(p.theta, q.theta);
                l += wq * (-(e + dth * dth * inv_th)).exp();
            }
            explained += *w * l / peak.max(1e-300);
            *w *= l;
        }
        self.finish_update(explained, rng);
        // Sensor resetting: redraw a few particles near the matches when the cloud explains
        // the snapshots worse than it used to.
        let n = self.poses.len();
        for _ in 0..self.resets() {
            let i = rng.random_range(0..n.max(1));
            if let (Some(fresh), Some(slot)) =
                (self.draw_near(&matches, rng), self.poses.get_mut(i))
            {
                *slot = fresh;
            }
        }
    }

    /// Weighs the particles by a snapshot through the learned tag map ([`TagMap`]: each
    /// particle scored by the reader's model against the mapped tag positions). The
    /// fingerprints still propose poses: all particles at the first update (global
    /// localisation), and before each update a fraction of them when the cloud explains the
    /// snapshots worse than it used to (augmented MCL on the per-tag likelihood). An empty
    /// snapshot, or one without a mapped tag, changes nothing.
    pub fn update_with_map<R: Rng + ?Sized>(
        &mut self,
        tags: &TagMap,
        proposals: &FingerprintMap,
        snapshot: &Snapshot,
        rng: &mut R,
    ) {
        let c = self.config;
        let obs = tags.observe(snapshot);
        if obs.mapped == 0 {
            return;
        }
        let matches = proposals.matches(snapshot, c.neighbours, c.tau);
        if !self.initialised || self.poses.is_empty() {
            if matches.is_empty() {
                return;
            }
            self.draw_all(&matches, rng);
        } else if !matches.is_empty() {
            let n = self.poses.len();
            let k = self.resets();
            let uniform = 1.0 / n.max(1) as f64;
            for _ in 0..k {
                let i = rng.random_range(0..n.max(1));
                if let Some(fresh) = self.draw_near(&matches, rng) {
                    if let (Some(slot), Some(w)) = (self.poses.get_mut(i), self.weights.get_mut(i))
                    {
                        *slot = fresh;
                        *w = uniform;
                    }
                }
            }
            normalise(&mut self.weights);
        }
        let scores: Vec<(f64, usize)> = self
            .poses
            .iter()
            .map(|p| tags.log_likelihood(p, &obs))
            .collect();
        let best = scores.iter().map(|s| s.0).fold(f64::NEG_INFINITY, f64::max);
        if !best.is_finite() {
            return;
        }
        // How well the cloud explains the snapshot: weighted per-term likelihood.
        let mut explained = 0.0;
        for (w, (ll, terms)) in self.weights.iter_mut().zip(&scores) {
            explained += *w * (ll / (*terms).max(1) as f64).exp();
            *w *= (ll - best).exp();
        }
        self.finish_update(explained, rng);
    }

    /// After the weights were multiplied by a snapshot's likelihood: the short- and long-term
    /// averages of how well the cloud explained it (`explained`), normalisation, and
    /// resampling when the effective sample size is below half.
    fn finish_update<R: Rng + ?Sized>(&mut self, explained: f64, rng: &mut R) {
        let c = &self.config;
        if self.w_slow <= 0.0 {
            self.w_slow = explained;
            self.w_fast = explained;
        } else {
            self.w_slow += c.alpha_slow * (explained - self.w_slow);
            self.w_fast += c.alpha_fast * (explained - self.w_fast);
        }
        if !normalise(&mut self.weights) {
            let m = self.weights.len().max(1) as f64;
            self.weights.iter_mut().for_each(|w| *w = 1.0 / m);
        }
        let ess = 1.0 / self.weights.iter().map(|w| w * w).sum::<f64>().max(1e-300);
        if ess < 0.5 * self.weights.len() as f64 {
            self.resample(rng);
        }
    }

    /// Systematic resampling; weights become uniform.
    fn resample<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let n = self.poses.len();
        if n == 0 {
            return;
        }
        let step = 1.0 / n as f64;
        let mut u = rng.random::<f64>() * step;
        let mut cum = self.weights.first().copied().unwrap_or(0.0);
        let mut i = 0usize;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            while u > cum && i + 1 < n {
                i += 1;
                cum += self.weights.get(i).copied().unwrap_or(0.0);
            }
            if let Some(p) = self.poses.get(i) {
                out.push(*p);
            }
            u += step;
        }
        self.poses = out;
        self.weights = vec![step; self.poses.len()];
    }

    /// The estimate; `None` before the first snapshot with tags.
    #[must_use]
    pub fn estimate(&self) -> Option<TrackEstimate> {
        if self.poses.is_empty() {
            return None;
        }
        // Heaviest 0.3 m cell.
        const CELL: f64 = 0.3;
        let mut cells: std::collections::HashMap<(i64, i64), f64> =
            std::collections::HashMap::new();
        for (p, w) in self.poses.iter().zip(&self.weights) {
            let key = ((p.x / CELL).floor() as i64, (p.y / CELL).floor() as i64);
            *cells.entry(key).or_insert(0.0) += w;
        }
        // The cell whose 3×3 neighbourhood is heaviest (a diffuse mode beats a tight speck).
        let around = |k: &(i64, i64)| -> f64 {
            let mut sum = 0.0;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    sum += cells.get(&(k.0 + dx, k.1 + dy)).copied().unwrap_or(0.0);
                }
            }
            sum
        };
        let best = cells
            .keys()
            .map(|k| (*k, around(k)))
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
            .map(|(k, _)| k)?;
        let mut cx = (best.0 as f64 + 0.5) * CELL;
        let mut cy = (best.1 as f64 + 0.5) * CELL;
        let r2 = self.config.estimate_radius.max(CELL).powi(2);
        let mut result = None;
        for _ in 0..3 {
            let (mut sw, mut sx, mut sy, mut ss, mut sc) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (p, w) in self.poses.iter().zip(&self.weights) {
                if (p.x - cx).powi(2) + (p.y - cy).powi(2) <= r2 {
                    sw += w;
                    sx += w * p.x;
                    sy += w * p.y;
                    ss += w * p.theta.sin();
                    sc += w * p.theta.cos();
                }
            }
            if sw <= 0.0 {
                break;
            }
            cx = sx / sw;
            cy = sy / sw;
            result = Some((sw, wrap_angle(ss.atan2(sc))));
        }
        let (mass, theta) = result?;
        let mut var = 0.0;
        let mut cov = nalgebra::Matrix3::<f64>::zeros();
        for (p, w) in self.poses.iter().zip(&self.weights) {
            let d2 = (p.x - cx).powi(2) + (p.y - cy).powi(2);
            if d2 <= r2 {
                var += w * d2;
                let e = nalgebra::Vector3::new(p.x - cx, p.y - cy, angle_diff(p.theta, theta));
                cov += *w * e * e.transpose();
            }
        }
        Some(TrackEstimate {
            pose: Pose2::new(cx, cy, theta),
            spread: (var / mass).sqrt(),
            mass,
            covariance: cov / mass,
        })
    }
}

/// Normalises in place; false when the sum is not positive and finite.
fn normalise(v: &mut [f64]) -> bool {
    let s: f64 = v.iter().sum();
    if s > 0.0 && s.is_finite() {
        v.iter_mut().for_each(|x| *x /= s);
        true
    } else {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tag::TagId;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A snapshot that identifies a 0.5 m cell and its heading quadrant.
    fn snap(x: f64, y: f64, theta: f64) -> Snapshot {
        let cx = (x / 0.5).floor() as i64;
        let cy = (y / 0.5).floor() as i64;
        let q = (wrap_angle(theta) / std::f64::consts::FRAC_PI_2).round() as i64;
        let id = ((cx * 31 + cy) * 7 + q).rem_euclid(250) as u8;
        Snapshot::from_reads([
            (TagId::new(vec![id]), 3000.0),
            (TagId::new(vec![cx as u8, 0]), 2000.0),
        ])
    }

    #[test]
    fn tracks_a_path_with_odometry_after_global_initialisation() {
        // Fingerprints on a 0.25 m grid, four headings.
        let mut samples = Vec::new();
        for ix in 0..16 {
            for iy in 0..16 {
                for q in 0..4 {
                    let p = Pose2::new(
                        0.125 + 0.25 * f64::from(ix),
                        0.125 + 0.25 * f64::from(iy),
                        f64::from(q) * std::f64::consts::FRAC_PI_2,
                    );
                    samples.push((snap(p.x, p.y, p.theta), p));
                }
            }
        }
        let map = FingerprintMap::new(
            samples.iter().map(|(s, p)| (s, *p)),
            SnapshotDistance::RssL1,
        );
        assert_eq!(map.len(), 1024);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut f = TrackFilter::new(TrackConfig::default());
        assert!(f.estimate().is_none());
        let mut truth = Pose2::new(0.6, 1.0, 0.0);
        let step = Pose2::new(0.1, 0.0, 0.08);
        let mut errors = Vec::new();
        for k in 0..30 {
            if k > 0 {
                truth = truth.compose(&step);
                f.predict(&step, &mut rng);
            }
            f.update(&map, &snap(truth.x, truth.y, truth.theta), &mut rng);
            let e = f.estimate().unwrap();
            errors.push(e.pose.distance(&truth));
        }
        let late: f64 = errors.iter().skip(10).sum::<f64>() / 20.0;
        // The snapshot alone only knows the 0.5 m cell (≈0.2 m RMS within it); odometry over
        // the path narrows it.
        assert!(late < 0.2, "late mean error {late}: {errors:?}");
        let (poses, weights) = f.particles();
        assert_eq!(poses.len(), weights.len());
        assert!((weights.iter().sum::<f64>() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn empty_snapshot_changes_nothing_and_resampling_keeps_count() {
        let a = Snapshot::from_reads([(TagId::new(vec![1]), 3000.0)]);
        let map = FingerprintMap::new([(&a, Pose2::new(1.0, 1.0, 0.0))], SnapshotDistance::RssL1);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut f = TrackFilter::new(TrackConfig {
            particles: 200,
            ..TrackConfig::default()
        });
        f.update(&map, &Snapshot::new(), &mut rng);
        assert!(!f.is_initialised());
        f.update(&map, &a, &mut rng);
        assert!(f.is_initialised());
        assert_eq!(f.particles().0.len(), 200);
        let e = f.estimate().unwrap();
        assert!(e.pose.distance(&Pose2::new(1.0, 1.0, 0.0)) < 0.1, "{e:?}");
        assert!(e.mass > 0.9);
        f.resample(&mut rng);
        assert_eq!(f.particles().0.len(), 200);
    }
}
