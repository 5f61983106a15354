//! A map of tag positions learned from the exploration snapshots, and the snapshot likelihood
//! of a pose under the reader's propagation model.
//!
//! The seed localises by matching a snapshot against stored ones, so its accuracy is bounded by
//! how densely exploration covered `(x, y, θ)`: with a directional antenna, two snapshots a few
//! centimetres apart but 30° apart in heading share few tags. The robot knows more than the
//! stored snapshots, though: where it was (odometry) when it read each tag, and how the reader's
//! RSS falls with distance and angle (the seed's own fit, eq. 3.19/3.22–3.23). [`TagMap::learn`]
//! puts every tag seen often enough at the position that best explains its reads **and its
//! misses** along the exploration path (a coarse-to-fine grid search of the log-likelihood
//! below, with the spread of the likelihood as the position's σ). [`TagMap::log_likelihood`]
//! then scores any pose against a snapshot, between the stored ones:
//!
//! - a mapped tag that was read with RSS `r`: `log N(r; m, σ²)` with `m` the model's mean RSS
//!   from the pose and `σ² = σ_read²/n + σ_map²` (`n` reads averaged per snapshot; `σ_map` covers
//!   the tag's position error and the model's fit error);
//! - a mapped tag in view that was not read: `log(1 − P_read(m))`, with
//!   `P_read(m) = (1 − dropout)·Φ((m − threshold)/σ)`;
//! - each term is floored at `−floor` (an unmapped reflection, a moved tag or a wrong map entry
//!   costs at most that), and tags read but not in the map do not count.
//!
//! Units: metres, radians, RSS in reader units.

use std::collections::{BTreeMap, HashMap};

use rfloc_pose::{normal_cdf, Pose2};
use serde::{Deserialize, Serialize};

use crate::snapshot::Snapshot;
use crate::tag::TagId;

/// The reader's mean response and detection, as the robot believes it (calibrated offline; the
/// default is seed 000's fit with its simulation threshold).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadModel {
    /// `c_k` of `RSS(d) = Σ_k c_k e^{−k d}` on the antenna axis (k = 1, 2, …).
    pub coeffs: Vec<f64>,
    /// Behind the antenna the distance counts this many times (eq. 3.23's `a`).
    pub behind_attenuation: f64,
    /// Reads below this RSS are not reported.
    pub threshold: f64,
    /// σ of one read's RSS about the model.
    pub read_sigma: f64,
    /// Probability that a readable tag is missed in one read.
    pub dropout: f64,
    /// Reads averaged into one snapshot.
    pub reads_per_snapshot: usize,
    /// Antenna position along the robot's x axis, metres.
    pub antenna_offset: f64,
    /// The model reads a tag at distance `d` as the fit does at `d / distance_scale` (1: the
    /// fit itself). A miscalibrated robot (a simulation's `[mismatch] scale`) has another value.
    #[serde(default = "unit_scale")]
    pub distance_scale: f64,
}

fn unit_scale() -> f64 {
    1.0
}

impl ReadModel {
    /// Seed 000's propagation fit (Table 3.2: 2235, 17144, −12101), behind attenuation 50,
    /// simulation threshold 1000, σ 239 per read, 5 % dropout, `reads` reads per snapshot.
    #[must_use]
    pub fn seed000(threshold: f64, reads: usize) -> Self {
        Self {
            coeffs: vec![2235.0, 17144.0, -12101.0],
            behind_attenuation: 50.0,
            threshold,
            read_sigma: 239.0,
            dropout: 0.05,
            reads_per_snapshot: reads.max(1),
            antenna_offset: 0.0,
            distance_scale: 1.0,
        }
    }

    /// Mean RSS of a tag at `(x, y)` in the antenna frame (x along the boresight).
    #[must_use]
    pub fn mean_rss(&self, x: f64, y: f64) -> f64 {
        let d = x.hypot(y);
        let cos = if d > 0.0 { (x / d).abs() } else { 1.0 };
        let d = if self.distance_scale > 0.0 {
            d / self.distance_scale
        } else {
            d
        };
        let scaled = if x >= 0.0 {
            d
        } else {
            self.behind_attenuation * d
        };
        let mut e = 1.0;
        let step = (-scaled).exp();
        let mut sum = 0.0;
        for c in &self.coeffs {
            e *= step;
            sum += c * e;
        }
        sum.max(0.0) * cos
    }

    /// Mean RSS of a tag at world `(x, y)` seen from the antenna pose `antenna`.
    #[must_use]
    pub fn mean_rss_from(&self, antenna: &Pose2, x: f64, y: f64) -> f64 {
        let (sin, cos) = antenna.theta.sin_cos();
        let (wx, wy) = (x - antenna.x, y - antenna.y);
        self.mean_rss(cos * wx + sin * wy, -sin * wx + cos * wy)
    }

    /// The antenna's pose for a robot pose.
    #[must_use]
    pub fn antenna(&self, robot: &Pose2) -> Pose2 {
        robot.compose(&Pose2::new(self.antenna_offset, 0.0, 0.0))
    }

    /// σ of a snapshot's (averaged) RSS about the model, without map error.
    #[must_use]
    pub fn snapshot_sigma(&self) -> f64 {
        #[allow(clippy::cast_precision_loss)]
        let n = self.reads_per_snapshot.max(1) as f64;
        self.read_sigma / n.sqrt()
    }

    /// Probability that a tag of mean RSS `mean` is in a snapshot.
    #[must_use]
    pub fn read_probability(&self, mean: f64) -> f64 {
        let s = self.snapshot_sigma().max(1e-9);
        // A snapshot keeps the tags of its largest read: one success in n tries.
        let one = (1.0 - self.dropout) * normal_cdf((mean - self.threshold) / s);
        #[allow(clippy::cast_possible_wrap, clippy::cast_possible_truncation)]
        let n = self.reads_per_snapshot.clamp(1, 16) as i32;
        1.0 - (1.0 - one).powi(n)
    }

    /// On-axis distance beyond which the mean RSS stays below the threshold, metres (the reach).
    #[must_use]
    pub fn reach(&self) -> f64 {
        let mut d = 0.0;
        while d < 10.0 && self.mean_rss(d, 0.0) >= self.threshold {
            d += 0.01;
        }
        d
    }
}

/// Settings of tag mapping and scoring.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagMapConfig {
    /// A tag is mapped once read in at least this many snapshots.
    pub min_reads: usize,
    /// Half-width of the coarse search window around the reads' first guess, metres.
    pub search_radius: f64,
    /// Coarse and fine grid steps of the position search, metres.
    pub coarse_step: f64,
    pub fine_step: f64,
    /// σ added to the snapshot's RSS σ for map and model error, reader units.
    pub map_sigma: f64,
    /// Floor of one tag's log-likelihood term.
    pub floor: f64,
    /// Log-likelihoods are divided by this (reads of neighbouring tags share map errors).
    pub temperature: f64,
}

impl Default for TagMapConfig {
    fn default() -> Self {
        Self {
            min_reads: 3,
            search_radius: 0.8,
            coarse_step: 0.1,
            fine_step: 0.02,
            map_sigma: 200.0,
            floor: 6.0,
            temperature: 2.0,
        }
    }
}

/// One mapped tag.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MappedTag {
    pub id: TagId,
    pub x: f64,
    pub y: f64,
    /// σ of the position (likelihood spread over the search grid), metres.
    pub sigma: f64,
    /// Snapshots that read it during mapping.
    pub reads: usize,
}

/// Tags of one snapshot against the map: the RSS of each mapped tag that was read.
#[derive(Debug, Clone, Default)]
pub struct MapObservation {
    /// Indexed like [`TagMap::tags`]; `None` = not read.
    rss: Vec<Option<f64>>,
    /// Tags read that are not in the map.
    pub unmapped: usize,
    /// Mapped tags read.
    pub mapped: usize,
}

/// Learned tag positions with a spatial index.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TagMap {
    pub model: ReadModel,
    pub config: TagMapConfig,
    pub tags: Vec<MappedTag>,
    #[serde(skip)]
    index: BTreeMap<TagId, usize>,
    #[serde(skip)]
    grid: HashMap<(i64, i64), Vec<usize>>,
    #[serde(skip)]
    cell: f64,
}

/// One read (or miss) of a tag during mapping: the antenna pose and the snapshot's RSS.
type Sighting = (Pose2, Option<f64>);

impl TagMap {
    /// Maps every tag read in at least `config.min_reads` of `samples` (snapshot, robot pose).
    #[must_use]
    pub fn learn<'a>(
        samples: impl IntoIterator<Item = (&'a Snapshot, Pose2)>,
        model: ReadModel,
        config: TagMapConfig,
    ) -> Self {
        let samples: Vec<(&Snapshot, Pose2)> = samples.into_iter().collect();
        let antennas: Vec<Pose2> = samples.iter().map(|(_, p)| model.antenna(p)).collect();
        let reach = model.reach();
        // Spatial index of the antenna poses for the misses.
        let pose_cell = reach.max(0.5);
        let mut pose_grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (i, a) in antennas.iter().enumerate() {
            pose_grid
                .entry(cell_of(a.x, a.y, pose_cell))
                .or_default()
                .push(i);
        }
        let mut reads: BTreeMap<&TagId, Vec<(usize, f64)>> = BTreeMap::new();
        for (i, (s, _)) in samples.iter().enumerate() {
            for (id, rss) in s.iter() {
                reads.entry(id).or_default().push((i, rss));
            }
        }
        let mut tags = Vec::new();
        for (id, seen) in reads {
            if seen.len() < config.min_reads.max(1) {
                continue;
            }
            let index = SurveyIndex {
                antennas: &antennas,
                grid: &pose_grid,
                cell: pose_cell,
                reach,
            };
            if let Some(t) = locate(id, &seen, &index, &model, &config) {
                tags.push(t);
            }
        }
        let mut map = Self {
            model,
            config,
            tags,
            index: BTreeMap::new(),
            grid: HashMap::new(),
            cell: 1.0,
        };
        map.rebuild_index();
        map
    }

    /// Rebuilds the lookup tables (after deserialising).
    pub fn rebuild_index(&mut self) {
        self.cell = self.model.reach().max(0.5);
        self.index = self
            .tags
            .iter()
            .enumerate()
            .map(|(i, t)| (t.id.clone(), i))
            .collect();
        self.grid.clear();
        for (i, t) in self.tags.iter().enumerate() {
            self.grid
                .entry(cell_of(t.x, t.y, self.cell))
                .or_default()
                .push(i);
        }
    }

    /// Number of mapped tags.
    #[must_use]
    pub fn len(&self) -> usize {
        self.tags.len()
    }

    /// True when no tag is mapped.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.tags.is_empty()
    }

    /// The mapped tag with this ID.
    #[must_use]
    pub fn get(&self, id: &TagId) -> Option<&MappedTag> {
        self.index.get(id).and_then(|i| self.tags.get(*i))
    }

    /// The snapshot's tags against the map.
    #[must_use]
    pub fn observe(&self, snapshot: &Snapshot) -> MapObservation {
        let mut obs = MapObservation {
            rss: vec![None; self.tags.len()],
            ..MapObservation::default()
        };
        for (id, rss) in snapshot.iter() {
            match self.index.get(id).and_then(|i| obs.rss.get_mut(*i)) {
                Some(slot) => {
                    *slot = Some(rss);
                    obs.mapped += 1;
                }
                None => obs.unmapped += 1,
            }
        }
        obs
    }

    /// Log-likelihood of the observation from robot pose `pose` (see the module
    /// documentation), already divided by the temperature, and the number of terms.
    #[must_use]
    pub fn log_likelihood(&self, pose: &Pose2, obs: &MapObservation) -> (f64, usize) {
        let antenna = self.model.antenna(pose);
        let sigma = self.model.snapshot_sigma().hypot(self.config.map_sigma);
        let reach = self.cell;
        let (cx, cy) = cell_of(antenna.x, antenna.y, self.cell);
        let (sin, cos) = antenna.theta.sin_cos();
        let mut ll = 0.0;
        let mut terms = 0usize;
        let mut read_seen = 0usize;
        for dx in -1..=1 {
            for dy in -1..=1 {
                let Some(members) = self.grid.get(&(cx + dx, cy + dy)) else {
                    continue;
                };
                for &i in members {
                    let Some(t) = self.tags.get(i) else { continue };
                    let rss = obs.rss.get(i).copied().flatten();
                    let (wx, wy) = (t.x - antenna.x, t.y - antenna.y);
                    if rss.is_none() && (wx * wx + wy * wy > reach * reach) {
                        continue;
                    }
                    // Into the antenna frame.
                    let x = cos * wx + sin * wy;
                    if rss.is_none() && x < 0.0 {
                        // Behind the antenna: never read, and not read.
                        continue;
                    }
                    let y = -sin * wx + cos * wy;
                    let m = self.model.mean_rss(x, y);
                    let term = match rss {
                        Some(r) => {
                            read_seen += 1;
                            let z = (r - m) / sigma;
                            -0.5 * z * z
                        }
                        None => (1.0 - self.model.read_probability(m)).max(1e-300).ln(),
                    };
                    ll += term.max(-self.config.floor);
                    terms += 1;
                }
            }
        }
        // Tags read but too far from this pose to be in the cells above: each at the floor.
        let missing = obs.mapped.saturating_sub(read_seen);
        #[allow(clippy::cast_precision_loss)]
        {
            ll -= missing as f64 * self.config.floor;
        }
        terms += missing;
        (ll / self.config.temperature.max(1e-9), terms)
    }
}

fn cell_of(x: f64, y: f64, cell: f64) -> (i64, i64) {
    #[allow(clippy::cast_possible_truncation)]
    ((x / cell).floor() as i64, (y / cell).floor() as i64)
}

/// Log-likelihood of a tag at `(x, y)` given its sightings (reads and misses).
fn tag_log_likelihood(
    x: f64,
    y: f64,
    sightings: &[Sighting],
    model: &ReadModel,
    c: &TagMapConfig,
    reach: f64,
) -> f64 {
    let sigma = model.snapshot_sigma().hypot(0.5 * c.map_sigma);
    let mut ll = 0.0;
    for (a, rss) in sightings {
        let (sin, cos) = a.theta.sin_cos();
        let (wx, wy) = (x - a.x, y - a.y);
        let ax = cos * wx + sin * wy;
        if rss.is_none() && (ax < 0.0 || wx * wx + wy * wy > reach * reach) {
            // A miss from where the tag could not be read says nothing.
            continue;
        }
        let m = model.mean_rss(ax, -sin * wx + cos * wy);
        let term = match rss {
            Some(r) => {
                let z = (r - m) / sigma;
                -0.5 * z * z
            }
            None => (1.0 - model.read_probability(m)).max(1e-300).ln(),
        };
        ll += term.max(-c.floor);
    }
    ll
}

/// The survey's antenna poses with their spatial index, as every tag's search sees them.
struct SurveyIndex<'a> {
    antennas: &'a [Pose2],
    grid: &'a HashMap<(i64, i64), Vec<usize>>,
    /// Cell size of `grid`, metres.
    cell: f64,
    /// The model's reach, metres.
    reach: f64,
}

/// Places one tag: first guess from its reads, coarse then fine grid search of the likelihood,
/// σ from the likelihood's spread over the fine grid.
fn locate(
    id: &TagId,
    seen: &[(usize, f64)],
    survey: &SurveyIndex<'_>,
    model: &ReadModel,
    c: &TagMapConfig,
) -> Option<MappedTag> {
    let (antennas, pose_grid, pose_cell, reach) =
        (survey.antennas, survey.grid, survey.cell, survey.reach);
    // First guess: each read puts the tag on the boresight at the on-axis distance of its RSS.
    let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
    for (i, rss) in seen {
        let a = antennas.get(*i)?;
        let mut d = 0.0;
        while d < 5.0 && model.mean_rss(d, 0.0) > *rss {
            d += 0.02;
        }
        // Off-axis tags read weaker than on the axis: the true distance is shorter.
        let d = 0.7 * d;
        let w = rss.max(1.0);
        sx += w * (a.x + d * a.theta.cos());
        sy += w * (a.y + d * a.theta.sin());
        sw += w;
    }
    if sw <= 0.0 {
        return None;
    }
    let (gx, gy) = (sx / sw, sy / sw);
    // Sightings: the reads, and the misses from every antenna pose within reach of the window.
    let read_at: HashMap<usize, f64> = seen.iter().copied().collect();
    let (cx, cy) = cell_of(gx, gy, pose_cell);
    #[allow(clippy::cast_possible_truncation)]
    let span = ((c.search_radius + reach) / pose_cell).ceil() as i64;
    let mut sightings: Vec<Sighting> = Vec::new();
    for dx in -span..=span {
        for dy in -span..=span {
            let Some(members) = pose_grid.get(&(cx + dx, cy + dy)) else {
                continue;
            };
            for &i in members {
                let Some(a) = antennas.get(i) else { continue };
                let near = (a.x - gx).hypot(a.y - gy) <= c.search_radius + reach;
                match read_at.get(&i) {
                    Some(r) => sightings.push((*a, Some(*r))),
                    None if near => sightings.push((*a, None)),
                    None => {}
                }
            }
        }
    }
    let search = |x0: f64, y0: f64, half: f64, step: f64| -> Vec<(f64, f64, f64)> {
        #[allow(clippy::cast_possible_truncation)]
        let n = (half / step).round().clamp(0.0, 1000.0) as i64;
        let mut out = Vec::new();
        for ix in -n..=n {
            for iy in -n..=n {
                #[allow(clippy::cast_precision_loss)]
                let (x, y) = (x0 + ix as f64 * step, y0 + iy as f64 * step);
                out.push((x, y, tag_log_likelihood(x, y, &sightings, model, c, reach)));
            }
        }
        out
    };
    let best_of = |v: &[(f64, f64, f64)]| v.iter().copied().max_by(|a, b| a.2.total_cmp(&b.2));
    let coarse = search(gx, gy, c.search_radius, c.coarse_step.max(1e-3));
    let (bx, by, _) = best_of(&coarse)?;
    let fine = search(bx, by, c.coarse_step, c.fine_step.max(1e-4));
    let (fx, fy, fl) = best_of(&fine)?;
    // Spread: likelihood-weighted second moment over the fine window (at least a grid step).
    let (mut w, mut m2) = (0.0, 0.0);
    for (x, y, l) in &fine {
        let p = (l - fl).exp();
        w += p;
        m2 += p * ((x - fx).powi(2) + (y - fy).powi(2));
    }
    let sigma = if w > 0.0 {
        (m2 / w / 2.0).sqrt()
    } else {
        c.coarse_step
    }
    .max(c.fine_step);
    Some(MappedTag {
        id: id.clone(),
        x: fx,
        y: fy,
        sigma,
        reads: seen.len(),
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
        let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
        let u2: f64 = rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Snapshot of `tags` from `pose` under `model` with its noise (one read per snapshot).
    fn read(
        model: &ReadModel,
        tags: &[(f64, f64)],
        pose: &Pose2,
        rng: &mut ChaCha8Rng,
    ) -> Snapshot {
        let a = model.antenna(pose);
        let mut s = Snapshot::new();
        for (i, (x, y)) in tags.iter().enumerate() {
            let m = model.mean_rss_from(&a, *x, *y);
            let r = m + model.read_sigma * gaussian(rng);
            if r >= model.threshold && rng.random::<f64>() >= model.dropout {
                s.insert(TagId::new(vec![(i >> 8) as u8, (i & 0xff) as u8]), r);
            }
        }
        s
    }

    #[test]
    fn a_distance_scale_reads_every_tag_as_scale_times_as_far() {
        let fit = ReadModel::seed000(1000.0, 1);
        let long = ReadModel {
            distance_scale: 1.15,
            ..fit.clone()
        };
        for (x, y) in [(0.3, 0.0), (0.5, 0.4), (-0.2, 0.1), (1.0, -0.7)] {
            let want = fit.mean_rss(x, y);
            let got = long.mean_rss(1.15 * x, 1.15 * y);
            assert!((got - want).abs() < 1e-9 * want.max(1.0), "{got} vs {want}");
        }
        // A tag map written before the field existed reads as the fit itself.
        let mut json = serde_json::to_value(&fit).unwrap();
        json.as_object_mut().unwrap().remove("distance_scale");
        let old: ReadModel = serde_json::from_value(json).unwrap();
        assert_eq!(old, fit);
    }

    #[test]
    fn seed_model_values() {
        let m = ReadModel::seed000(1000.0, 1);
        // Eq. 3.19 at 0.2 m: 6680.7; at 60° off axis half of it; behind: nearly nothing.
        assert!((m.mean_rss(0.2, 0.0) - 6680.7).abs() < 0.1);
        let off = m.mean_rss(0.2 * 0.5, 0.2 * 0.75_f64.sqrt());
        assert!((off - 3340.35).abs() < 0.1, "{off}");
        assert!(m.mean_rss(-0.2, 0.0) < 1.0);
        // Reach at the 1000 threshold: 1.6–1.7 m.
        assert!((1.6..=1.7).contains(&m.reach()), "{}", m.reach());
        // A tag well inside the reach is read almost surely; one far below the threshold never.
        assert!(m.read_probability(3000.0) > 0.94);
        assert!(m.read_probability(200.0) < 1e-3);
    }

    #[test]
    fn maps_tags_from_a_noisy_walk_and_scores_the_true_pose_best() {
        let model = ReadModel::seed000(1000.0, 1);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let tags: Vec<(f64, f64)> = (0..120)
            .map(|_| (rng.random::<f64>() * 4.0, rng.random::<f64>() * 4.0))
            .collect();
        // A walk over the area with all headings.
        let poses: Vec<Pose2> = (0..600)
            .map(|_| {
                Pose2::new(
                    0.3 + 3.4 * rng.random::<f64>(),
                    0.3 + 3.4 * rng.random::<f64>(),
                    std::f64::consts::TAU * rng.random::<f64>(),
                )
            })
            .collect();
        let snaps: Vec<Snapshot> = poses
            .iter()
            .map(|p| read(&model, &tags, p, &mut rng))
            .collect();
        let map = TagMap::learn(
            snaps.iter().zip(poses.iter().copied()),
            model.clone(),
            TagMapConfig::default(),
        );
        assert!(map.len() > 100, "{} tags mapped", map.len());
        let mut errors: Vec<f64> = map
            .tags
            .iter()
            .map(|t| {
                let i = usize::from(t.id.0[0]) << 8 | usize::from(t.id.0[1]);
                let (x, y) = tags[i];
                (t.x - x).hypot(t.y - y)
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 0.08, "median tag error {median} m");
        // The true pose scores better than poses 0.2 m or 30° away.
        let truth = Pose2::new(2.0, 2.0, 0.7);
        let obs = map.observe(&read(&model, &tags, &truth, &mut rng));
        let at = |p: &Pose2| map.log_likelihood(p, &obs).0;
        let best = at(&truth);
        for other in [
            Pose2::new(2.2, 2.0, 0.7),
            Pose2::new(2.0, 1.8, 0.7),
            Pose2::new(2.0, 2.0, 0.7 + 0.52),
            Pose2::new(2.0, 2.0, 0.7 - 0.52),
        ] {
            assert!(at(&other) < best, "{other:?}: {} vs {best}", at(&other));
        }
        // Reloaded from JSON the map scores the same.
        let mut back: TagMap = serde_json::from_str(&serde_json::to_string(&map).unwrap()).unwrap();
        back.rebuild_index();
        assert_eq!(back.len(), map.len());
        assert!((back.log_likelihood(&truth, &obs).0 - best).abs() < 1e-9);
    }
}
