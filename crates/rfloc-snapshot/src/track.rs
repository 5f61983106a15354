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

use crate::distance::{postings, IndexedSnapshot, Shared, SnapshotDistance, TagIndex};
use crate::readtable::ROUND_MAGIC;
use crate::snapshot::Snapshot;
use crate::tagmap::{LikelihoodScratch, TagMap};

/// Every exploration snapshot with its pose: the fine localisation database.
#[derive(Debug, Clone, Default)]
pub struct FingerprintMap {
    distance: SnapshotDistance,
    tags: TagIndex,
    prints: Vec<IndexedSnapshot>,
    poses: Vec<Pose2>,
    /// For each interned tag, the fingerprints that read it (inverted index).
    postings: Vec<Vec<(u32, f64)>>,
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
        map.postings = postings(&map.prints, map.tags.len());
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
    /// `exp(−(d − d_min)/τ)` (the best one weighs 1), dropping those below `e^−8`. Ties keep
    /// the fingerprints' order. Only fingerprints sharing a tag with the snapshot are compared
    /// (through the inverted index); the others are at dissimilarity 1.
    #[must_use]
    pub fn matches(&self, snapshot: &Snapshot, k: usize, tau: f64) -> Vec<(Pose2, f64)> {
        if snapshot.is_empty() || self.prints.is_empty() {
            return Vec::new();
        }
        let q = self.tags.index_query(snapshot);
        let mut shared: Vec<(u32, Shared)> = Vec::new();
        // Position in `shared` of each fingerprint met so far.
        let mut slot = vec![u32::MAX; self.prints.len()];
        for (t, rq) in q.pairs() {
            let Some(p) = self.postings.get(t as usize) else {
                continue;
            };
            for &(i, rp) in p {
                let Some(at) = slot.get_mut(i as usize) else {
                    continue;
                };
                if *at == u32::MAX {
                    *at = shared.len() as u32;
                    shared.push((i, Shared::default()));
                }
                if let Some((_, s)) = shared.get_mut(*at as usize) {
                    s.add(rq, rp);
                }
            }
        }
        let mut d: Vec<(f64, usize)> = shared
            .iter()
            .filter_map(|(i, s)| {
                let p = self.prints.get(*i as usize)?;
                Some((self.distance.with_shared(&q, p, *s), *i as usize))
            })
            .collect();
        let k = k.max(1);
        // Fewer than k share a tag: the rest are the first fingerprints sharing none (d = 1).
        if d.len() < k {
            let missing = k - d.len();
            d.extend(
                slot.iter()
                    .enumerate()
                    .filter(|(_, s)| **s == u32::MAX)
                    .take(missing)
                    .filter_map(|(i, _)| {
                        let p = self.prints.get(i)?;
                        Some((self.distance.with_shared(&q, p, Shared::default()), i))
                    }),
            );
        }
        let order = |a: &(f64, usize), b: &(f64, usize)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        if d.len() > k {
            d.select_nth_unstable_by(k - 1, order);
            d.truncate(k);
        }
        d.sort_by(order);
        let dmin = d.first().map_or(0.0, |x| x.0);
        let tau = tau.max(1e-9);
        d.iter()
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
#[derive(Debug)]
pub struct TrackFilter {
    config: TrackConfig,
    poses: Vec<Pose2>,
    weights: Vec<f64>,
    initialised: bool,
    w_fast: f64,
    w_slow: f64,
    /// Work buffers of the tag-map likelihood.
    scratch: LikelihoodScratch,
    scores: Vec<(f64, f64)>,
    /// The particles drawn by resampling (swapped with `poses`).
    drawn: Vec<Pose2>,
}

/// A clone has the same state; its work buffers start empty (they hold nothing between
/// updates, and copying them would double what a clone copies).
impl Clone for TrackFilter {
    fn clone(&self) -> Self {
        Self {
            config: self.config,
            poses: self.poses.clone(),
            weights: self.weights.clone(),
            initialised: self.initialised,
            w_fast: self.w_fast,
            w_slow: self.w_slow,
            scratch: LikelihoodScratch::default(),
            scores: Vec::new(),
            drawn: Vec::new(),
        }
    }

    /// Takes `source`'s state and keeps this filter's work buffers and allocations.
    fn clone_from(&mut self, source: &Self) {
        self.config = source.config;
        self.poses.clone_from(&source.poses);
        self.weights.clone_from(&source.weights);
        self.initialised = source.initialised;
        self.w_fast = source.w_fast;
        self.w_slow = source.w_slow;
    }
}

/// One standard normal draw (ziggurat).
fn normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, rng)
}

/// `p ⊕ (dx, dy, dθ)` with `sin`/`cos` from [`sincos`].
#[inline]
fn compose(p: &Pose2, dx: f64, dy: f64, dth: f64) -> Pose2 {
    let (s, c) = sincos(p.theta);
    Pose2::new(p.x + c * dx - s * dy, p.y + s * dx + c * dy, p.theta + dth)
}

/// `eˣ` without the library call, branch-free so that loops over particles vectorise: `x`
/// reduced by `k·ln 2` to `|r| ≤ ½ ln 2`, `eʳ` by its Taylor polynomial to degree 13
/// (truncation below 1e−17 relative), `2ᵏ` built from its bits. Relative error a few units in
/// the last place (below 1e−15, see the test) for `−707 ≤ x ≤ 709.7`; below −707 it returns
/// 0 (the library's value there is below 1e−307), above ∞, and NaN for NaN.
#[inline]
#[must_use]
pub(crate) fn exp(x: f64) -> f64 {
    // ln 2 split (fdlibm's `ln2HI`, `ln2LO`): the high part has 32 significant bits.
    const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
    let xc = x.clamp(-707.0, 709.8);
    // k = round(x / ln 2); 1.5·2⁵² + k holds k in its low mantissa bits.
    let kb = xc * std::f64::consts::LOG2_E + ROUND_MAGIC;
    let k = kb - ROUND_MAGIC;
    // `k · LN2_HI` is exact (|k| ≤ 1024).
    let r = (xc - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 6_227_020_800.0;
    for c in [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // 2^(k − 1) (k ≥ −1020 here), times 2 after the product so that k = 1024 still works.
    let bits = kb
        .to_bits()
        .wrapping_sub(ROUND_MAGIC.to_bits())
        .wrapping_add(1022)
        << 52;
    let y = p * f64::from_bits(bits) * 2.0;
    let y = if x < -707.0 { 0.0 } else { y };
    let y = if x > 709.8 { f64::INFINITY } else { y };
    if x.is_nan() {
        x
    } else {
        y
    }
}

/// [`wrap_angle`] without the library's `fmod` (which does not vectorise) and without a
/// branch (so that loops over particles vectorise): bit-identical for `|a| < 2π` (`fmod`
/// returns such an `a` unchanged, and `rem_euclid` then adds 2π to a negative one); up to
/// `|a| < 2⁵¹`, `a` less the nearest multiple of 2π, within `|a|·2⁻⁵²` of it (particle headings
/// are not wrapped by the motion model); beyond, where a heading has no fractional part left,
/// some angle in `[−π, π]`; NaN for a NaN or an infinity.
#[inline]
fn wrap_small(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let r = if a.abs() < TAU {
        a
    } else {
        a - crate::readtable::round_f64(a * (1.0 / TAU)) * TAU
    };
    let r = if r < 0.0 { r + TAU } else { r };
    let r = if r > PI { r - TAU } else { r };
    if r.abs() <= PI || r.is_nan() {
        r
    } else {
        r.clamp(-PI, PI)
    }
}

/// `sin θ`, `cos θ` by polynomials after reduction to `[−π/4, π/4]` (error below 1e−13;
/// cheaper than the library's correctly rounded pair).
#[inline]
pub(crate) fn sincos(theta: f64) -> (f64, f64) {
    let q = crate::readtable::round_f64(theta * std::f64::consts::FRAC_2_PI);
    let r = theta - q * std::f64::consts::FRAC_PI_2;
    let r2 = r * r;
    let s = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0
                    + r2 * (-1.0 / 5040.0
                        + r2 * (1.0 / 362_880.0
                            + r2 * (-1.0 / 39_916_800.0 + r2 * (1.0 / 6_227_020_800.0)))))));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0
                + r2 * (-1.0 / 720.0
                    + r2 * (1.0 / 40_320.0
                        + r2 * (-1.0 / 3_628_800.0
                            + r2 * (1.0 / 479_001_600.0 + r2 * (-1.0 / 87_178_291_200.0)))))));
    crate::readtable::to_quadrant(q, s, c)
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
            scratch: LikelihoodScratch::default(),
            scores: Vec::new(),
            drawn: Vec::new(),
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
            let (dx, dy, dth) = (
                delta.x + st * normal(rng),
                delta.y + st * normal(rng),
                delta.theta + sr * normal(rng),
            );
            *p = compose(p, dx, dy, dth);
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
        if !self.initialised || self.poses.is_empty() {
            let matches = proposals.matches(snapshot, c.neighbours, c.tau);
            if matches.is_empty() {
                return;
            }
            self.draw_all(&matches, rng);
        } else {
            // The fingerprints are only consulted when particles are to be redrawn.
            let k = self.resets();
            let matches = if k > 0 {
                proposals.matches(snapshot, c.neighbours, c.tau)
            } else {
                Vec::new()
            };
            if !matches.is_empty() {
                let n = self.poses.len();
                let uniform = 1.0 / n.max(1) as f64;
                for _ in 0..k {
                    let i = rng.random_range(0..n.max(1));
                    if let Some(fresh) = self.draw_near(&matches, rng) {
                        if let (Some(slot), Some(w)) =
                            (self.poses.get_mut(i), self.weights.get_mut(i))
                        {
                            *slot = fresh;
                            *w = uniform;
                        }
                    }
                }
                normalise(&mut self.weights);
            }
        }
        let mut scores = std::mem::take(&mut self.scores);
        tags.log_likelihoods(&self.poses, &obs, &mut self.scratch, &mut scores);
        let best = crate::simd::lane_max(&scores, |s| s.0);
        if !best.is_finite() {
            self.scores = scores;
            return;
        }
        // How well the cloud explains the snapshot: weighted per-term likelihood.
        // Both exponentials first (a loop that vectorises), then the sum (`simd::lane_sums`).
        crate::simd::widest(
            #[inline(always)]
            || {
                for (ll, terms) in &mut scores {
                    (*ll, *terms) = (exp(*ll / terms.max(1.0)), exp(*ll - best));
                }
            },
        );
        let [explained] = crate::simd::lane_sums(&self.weights, &scores, |w, s| [w * s.0]);
        for (w, (_, relative)) in self.weights.iter_mut().zip(&scores) {
            *w *= relative;
        }
        self.scores = scores;
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
        let [square] = crate::simd::lane_sums(&self.weights, &self.weights, |&w, _| [w * w]);
        let ess = 1.0 / square.max(1e-300);
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
        let out = &mut self.drawn;
        out.clear();
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
        std::mem::swap(&mut self.poses, &mut self.drawn);
        self.weights.clear();
        self.weights.resize(self.poses.len(), step);
    }

    /// The estimate; `None` before the first snapshot with tags.
    #[must_use]
    pub fn estimate(&self) -> Option<TrackEstimate> {
        if self.poses.is_empty() {
            return None;
        }
        // Heaviest 0.3 m cell.
        const CELL: f64 = 0.3;
        // The particles as columns (the sums below load them as whole vectors), in a plain
        // loop over slices (a `collect` would call a fold that is not inlined into the wider
        // instructions' variant).
        let n = self.poses.len();
        let (mut xs, mut ys, mut ts) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        crate::simd::widest(
            #[inline(always)]
            || {
                for (((x, y), t), p) in xs.iter_mut().zip(&mut ys).zip(&mut ts).zip(&self.poses) {
                    (*x, *y, *t) = (p.x, p.y, p.theta);
                }
            },
        );
        let cells = CellWeights::new(&xs, &ys, &self.weights, CELL);
        // The cell whose 3×3 neighbourhood is heaviest (a diffuse mode beats a tight speck);
        // ties go to the smallest cell.
        let best = cells
            .occupied()
            .map(|k| (k, cells.around(k)))
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
            .map(|(k, _)| k)?;
        let mut cx = (best.0 as f64 + 0.5) * CELL;
        let mut cy = (best.1 as f64 + 0.5) * CELL;
        let r2 = self.config.estimate_radius.max(CELL).powi(2);
        // Three mean-shift steps; the heading and mass come from the last step's window.
        let mut window = None;
        // Sums over the particles in interleaved partial sums (`simd::lane_sums_columns`:
        // they vectorise); a particle outside the window adds exact zeros (finite poses).
        let w = &self.weights[..];
        for _ in 0..3 {
            let [sw, sx, sy] = crate::simd::lane_sums_columns([&xs, &ys, w], |[x, y, w]| {
                let (dx, dy) = (x - cx, y - cy);
                let w = if dx * dx + dy * dy <= r2 { w } else { 0.0 };
                [w, w * x, w * y]
            });
            if sw <= 0.0 {
                break;
            }
            window = Some((cx, cy, sw));
            cx = sx / sw;
            cy = sy / sw;
        }
        let (wx, wy, mass) = window?;
        let [ss, sc] = crate::simd::lane_sums_columns([&xs, &ys, &ts, w], |[x, y, t, w]| {
            let (dx, dy) = (x - wx, y - wy);
            let w = if dx * dx + dy * dy <= r2 { w } else { 0.0 };
            let (s, c) = sincos(t);
            [w * s, w * c]
        });
        let theta = wrap_angle(ss.atan2(sc));
        let [var, xx, xy, xt, yy, yt, tt] =
            crate::simd::lane_sums_columns([&xs, &ys, &ts, w], |[x, y, t, w]| {
                let (ex, ey) = (x - cx, y - cy);
                let d2 = ex * ex + ey * ey;
                let w = if d2 <= r2 { w } else { 0.0 };
                let et = wrap_small(t - theta);
                [
                    w * d2,
                    w * ex * ex,
                    w * ex * ey,
                    w * ex * et,
                    w * ey * ey,
                    w * ey * et,
                    w * et * et,
                ]
            });
        let cov = nalgebra::Matrix3::new(xx, xy, xt, xy, yy, yt, xt, yt, tt);
        Some(TrackEstimate {
            pose: Pose2::new(cx, cy, theta),
            spread: (var / mass).sqrt(),
            mass,
            covariance: cov / mass,
        })
    }
}

/// Particle weight per 0.3 m cell: a dense grid over the cloud's bounding box when it is small,
/// a hash map otherwise.
enum CellWeights {
    Dense {
        x0: i64,
        y0: i64,
        nx: i64,
        ny: i64,
        w: Vec<f64>,
    },
    Sparse(std::collections::HashMap<(i64, i64), f64>),
}

impl CellWeights {
    /// The weights of the particles at `(x, y)`, summed per cell of side `cell` (cell
    /// `(⌊x/cell⌋, ⌊y/cell⌋)`; in four interleaved partial sums).
    fn new(xs: &[f64], ys: &[f64], weights: &[f64], cell: f64) -> Self {
        let n = xs.len().min(ys.len()).min(weights.len());
        let (xs, ys, weights) = (&xs[..n], &ys[..n], &weights[..n]);
        // Cell coordinates as whole floats (conversions to integers do not vectorise).
        let key = |v: f64| crate::readtable::floor_f64(v / cell);
        // The bounding box (`lane_max`: vectorised; keys that are not a number are left out).
        let (x0, x1) = (
            -crate::simd::lane_max(xs, |&x| -key(x)),
            crate::simd::lane_max(xs, |&x| key(x)),
        );
        let (y0, y1) = (
            -crate::simd::lane_max(ys, |&y| -key(y)),
            crate::simd::lane_max(ys, |&y| key(y)),
        );
        let (nx, ny) = (x1 - x0 + 1.0, y1 - y0 + 1.0);
        if x0 <= x1 && nx <= 256.0 && ny <= 256.0 {
            // Each particle's cell index (a whole number below 2¹⁶, exact in its float's low
            // mantissa bits after adding 2⁵²: no float-to-integer conversion, so the loop
            // vectorises), and its weight; a particle whose key is not finite goes to cell 0
            // with weight 0, which adds nothing.
            const TWO_52: f64 = 4_503_599_627_370_496.0;
            let mut index = vec![0_u64; n];
            let mut mass = vec![0.0; n];
            crate::simd::widest(
                #[inline(always)]
                || {
                    for (((i, m), (&x, &y)), &v) in index
                        .iter_mut()
                        .zip(&mut mass)
                        .zip(xs.iter().zip(ys))
                        .zip(weights)
                    {
                        let (x, y) = (key(x), key(y));
                        let finite = x.is_finite() && y.is_finite();
                        let f = (y - y0) * nx + (x - x0);
                        (*i, *m) = if finite {
                            ((f + TWO_52).to_bits() & 0xFFFF_FFFF, v)
                        } else {
                            (0, 0.0)
                        };
                    }
                },
            );
            let (nx, ny) = (nx as usize, ny as usize);
            // Four interleaved histograms (particle `j` into the `j mod 4`-th), added at the
            // end: consecutive particles in one cell (runs of resampled copies) do not wait
            // for each other's sums.
            let cells = nx * ny;
            let mut parts = vec![0.0; 4 * cells];
            for (j, (&i, &v)) in index.iter().zip(&mass).enumerate() {
                if let Some(c) = parts.get_mut((j % 4) * cells + i as usize) {
                    *c += v;
                }
            }
            let (a, rest) = parts.split_at(cells);
            let (b, rest) = rest.split_at(cells);
            let (c, d) = rest.split_at(cells);
            let w = (0..cells).map(|i| (a[i] + b[i]) + (c[i] + d[i])).collect();
            Self::Dense {
                x0: x0 as i64,
                y0: y0 as i64,
                nx: nx as i64,
                ny: ny as i64,
                w,
            }
        } else {
            let mut cells = std::collections::HashMap::new();
            for ((&x, &y), &v) in xs.iter().zip(ys).zip(weights) {
                *cells.entry((key(x) as i64, key(y) as i64)).or_insert(0.0) += v;
            }
            Self::Sparse(cells)
        }
    }

    fn get(&self, k: (i64, i64)) -> f64 {
        match self {
            Self::Dense { x0, y0, nx, ny, w } => {
                let (x, y) = (k.0 - x0, k.1 - y0);
                if x < 0 || y < 0 || x >= *nx || y >= *ny {
                    0.0
                } else {
                    w.get((y * nx + x) as usize).copied().unwrap_or(0.0)
                }
            }
            Self::Sparse(m) => m.get(&k).copied().unwrap_or(0.0),
        }
    }

    /// Cells holding particles (weight may be zero).
    fn occupied(&self) -> Box<dyn Iterator<Item = (i64, i64)> + '_> {
        match self {
            Self::Dense { x0, y0, nx, w, .. } => Box::new(
                w.iter()
                    .enumerate()
                    .filter(|(_, v)| **v > 0.0)
                    .map(move |(i, _)| (x0 + i as i64 % nx, y0 + i as i64 / nx)),
            ),
            Self::Sparse(m) => Box::new(m.keys().copied()),
        }
    }

    fn around(&self, k: (i64, i64)) -> f64 {
        let mut sum = 0.0;
        for dx in -1..=1 {
            for dy in -1..=1 {
                sum += self.get((k.0 + dx, k.1 + dy));
            }
        }
        sum
    }
}

/// Normalises in place; false when the sum is not positive and finite.
fn normalise(v: &mut [f64]) -> bool {
    let [s] = crate::simd::lane_sums(v, v, |&x, _| [x]);
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

    /// The filter on a tag map, run once with its loops in the widest instructions this CPU has
    /// and once in the baseline ones: the same particles, weights and estimates, bit for bit.
    #[test]
    fn widest_instructions_give_the_same_bits_as_the_baseline() {
        use crate::tagmap::{MappedTag, ReadModel, TagMap, TagMapConfig};
        let model = ReadModel::seed000(1000.0, 2);
        let tags: Vec<MappedTag> = (0..400)
            .map(|i| MappedTag {
                id: TagId::new(vec![(i >> 8) as u8, (i & 0xff) as u8]),
                x: 0.125 + 0.25 * f64::from(i % 20),
                y: 0.125 + 0.25 * f64::from(i / 20),
                sigma: 0.05,
                reads: 1,
            })
            .collect();
        let map = TagMap::from_tags(model.clone(), TagMapConfig::default(), tags.clone());
        let snapshot_at = |pose: &Pose2| {
            let a = model.antenna(pose);
            Snapshot::from_reads(tags.iter().filter_map(|t| {
                let m = model.mean_rss_from(&a, t.x, t.y);
                (m >= model.threshold).then(|| (t.id.clone(), m))
            }))
        };
        let samples: Vec<(Snapshot, Pose2)> = (0..64)
            .map(|i| {
                let p = Pose2::new(
                    0.5 + 0.5 * f64::from(i % 8),
                    0.5 + 0.5 * f64::from(i / 8),
                    0.4 * f64::from(i),
                );
                (snapshot_at(&p), p)
            })
            .collect();
        let prints = FingerprintMap::new(
            samples.iter().map(|(s, p)| (s, *p)),
            SnapshotDistance::RssL1,
        );
        let run = || {
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            let mut f = TrackFilter::new(TrackConfig {
                particles: 300,
                ..TrackConfig::default()
            });
            let mut truth = Pose2::new(1.2, 1.5, 0.3);
            let step = Pose2::new(0.08, 0.0, 0.05);
            let mut out = Vec::new();
            for _ in 0..12 {
                truth = truth.compose(&step);
                f.predict(&step, &mut rng);
                let snapshot = snapshot_at(&truth);
                assert!(snapshot.len() >= 10, "{} tags read", snapshot.len());
                f.update_with_map(&map, &prints, &snapshot, &mut rng);
                let e = f.estimate().unwrap();
                out.extend([e.pose.x, e.pose.y, e.pose.theta, e.spread, e.mass]);
                out.extend(e.covariance.iter().copied());
                let (poses, weights) = f.particles();
                out.extend(poses.iter().flat_map(|p| [p.x, p.y, p.theta]));
                out.extend(weights.iter().copied());
            }
            out.into_iter().map(f64::to_bits).collect::<Vec<u64>>()
        };
        let widest = run();
        let baseline = crate::simd::on_baseline(run);
        assert_eq!(widest.len(), baseline.len());
        assert!(widest == baseline, "the variants differ");
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

    /// The inverted index gives the same matches as comparing with every fingerprint.
    #[test]
    fn matches_equal_a_full_scan() {
        let mut samples = Vec::new();
        for ix in 0..12 {
            for iy in 0..12 {
                let p = Pose2::new(0.2 * f64::from(ix), 0.2 * f64::from(iy), 0.3);
                samples.push((snap(p.x, p.y, p.theta), p));
            }
        }
        for distance in [
            SnapshotDistance::RssL1,
            SnapshotDistance::SeedScore { id_weight: 0.6 },
        ] {
            let map = FingerprintMap::new(samples.iter().map(|(s, p)| (s, *p)), distance);
            for (q, _) in samples.iter().step_by(7) {
                for k in [1, 5, 40, 400] {
                    let fast = map.matches(q, k, 0.05);
                    // Full scan: every fingerprint, stable sort by distance.
                    let mut all: Vec<(f64, usize)> = samples
                        .iter()
                        .enumerate()
                        .map(|(i, (s, _))| (distance.between(q, s), i))
                        .collect();
                    all.sort_by(|a, b| a.0.total_cmp(&b.0));
                    let dmin = all[0].0;
                    let slow: Vec<(Pose2, f64)> = all
                        .iter()
                        .take(k)
                        .map(|(d, i)| (samples[*i].1, (-(d - dmin) / 0.05).exp()))
                        .filter(|(_, w)| *w > (-8.0_f64).exp())
                        .collect();
                    assert_eq!(fast.len(), slow.len(), "k {k}");
                    for (a, b) in fast.iter().zip(&slow) {
                        assert_eq!(a.0, b.0);
                        assert!((a.1 - b.1).abs() < 1e-9);
                    }
                }
            }
        }
    }

    #[test]
    fn fast_exp_matches_the_library() {
        let mut worst = 0.0_f64;
        let mut x = -707.0;
        while x < 709.7 {
            for d in [0.0, 1e-9, 0.123_456_789, 0.5 * std::f64::consts::LN_2] {
                let e = (x + d).exp();
                worst = worst.max((exp(x + d) - e).abs() / e);
            }
            x += 0.0137;
        }
        assert!(worst < 1e-15, "{worst}");
        for x in [0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 709.78] {
            assert!((exp(x) - x.exp()).abs() <= 1e-15 * x.exp(), "{x}");
        }
        assert_eq!(exp(-708.0), 0.0);
        assert_eq!(exp(-1e9), 0.0);
        assert_eq!(exp(710.0), f64::INFINITY);
        assert_eq!(exp(f64::INFINITY), f64::INFINITY);
        assert_eq!(exp(f64::NEG_INFINITY), 0.0);
        assert!(exp(f64::NAN).is_nan());
    }

    /// Cell weights: summed per cell; a key that is not a number adds nothing and does not
    /// widen the box; an infinite key sends every weight to the sparse map.
    #[test]
    fn cell_weights_sum_per_cell_and_skip_keys_that_are_not_numbers() {
        let kx = [2.0, 3.0, 2.0, f64::NAN, -1.0];
        let ky = [5.0, 5.0, 5.0, 5.0, 7.0];
        let w = [0.25, 0.125, 0.5, 1.0, 0.0625];
        let cells = CellWeights::new(&kx, &ky, &w, 1.0);
        assert!(matches!(cells, CellWeights::Dense { nx: 5, ny: 3, .. }));
        assert_eq!(cells.get((2, 5)), 0.75);
        assert_eq!(cells.get((3, 5)), 0.125);
        assert_eq!(cells.get((-1, 7)), 0.0625);
        assert_eq!(cells.get((0, 0)), 0.0);
        let mut occupied: Vec<_> = cells.occupied().collect();
        occupied.sort_unstable();
        assert_eq!(occupied, [(-1, 7), (2, 5), (3, 5)]);
        let far = CellWeights::new(&[0.0, f64::INFINITY], &[0.0, 0.0], &[0.5, 0.5], 1.0);
        assert!(matches!(far, CellWeights::Sparse(_)));
        assert_eq!(far.get((0, 0)), 0.5);
    }

    #[test]
    fn wrap_small_is_wrap_angle() {
        // Bit-identical within one turn.
        for i in -2318..=2318 {
            let a = f64::from(i) * 0.002_71;
            assert_eq!(wrap_small(a).to_bits(), wrap_angle(a).to_bits(), "{a}");
        }
        for a in [0.0, -0.0, std::f64::consts::PI, -std::f64::consts::PI] {
            assert_eq!(wrap_small(a).to_bits(), wrap_angle(a).to_bits(), "{a}");
        }
        assert!(wrap_small(f64::NAN).is_nan() && wrap_small(f64::INFINITY).is_nan());
        // Far out: a heading with no fractional part left still wraps into [−π, π].
        for a in [1e7, -3.3e9, 2.0e15, 1e300, -1e300] {
            let w = wrap_small(a);
            assert!(w.abs() <= std::f64::consts::PI, "{a}: {w}");
        }
        // Beyond, within rounding of the same angle, and in (−π, π].
        for i in -200_000..200_000 {
            let a = f64::from(i) * 0.002_713 + 0.5 * f64::from(i % 7);
            let (w, reference) = (wrap_small(a), wrap_angle(a));
            let d = (w - reference).abs();
            let d = d.min((d - std::f64::consts::TAU).abs());
            assert!(d <= 1e-15 * a.abs().max(1.0), "{a}: {w} vs {reference}");
            assert!(
                w > -std::f64::consts::PI && w <= std::f64::consts::PI,
                "{a}: {w}"
            );
        }
    }

    #[test]
    fn fast_sincos_matches_the_library() {
        for i in -3000..3000 {
            let th = f64::from(i) * 0.01171;
            let (s, c) = sincos(th);
            assert!(
                (s - th.sin()).abs() < 1e-13 && (c - th.cos()).abs() < 1e-13,
                "{th}"
            );
        }
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
