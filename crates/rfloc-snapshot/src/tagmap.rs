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
use std::sync::Arc;

use rfloc_pose::{normal_cdf, Pose2};
use serde::{Deserialize, Serialize};

use crate::readpass::{add_reads, ReadMode, ReadScratch, Reads};
use crate::readtable::{sincos_f32, AntennaLanes, FieldScratch, MissField, PoseLanes, ReadTable};
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

/// Tags of one snapshot against the map: the mapped tags that were read, with their RSS.
#[derive(Debug, Clone, Default)]
pub struct MapObservation {
    /// `(index into TagMap::tags, RSS)` of each mapped tag read.
    reads: Vec<(usize, f64)>,
    /// Tags read that are not in the map.
    pub unmapped: usize,
    /// Mapped tags read.
    pub mapped: usize,
}

/// Poses scored together by [`TagMap::log_likelihoods`] (their buffers fit the first-level
/// cache).
const BLOCK: usize = 256;

/// Work buffers of [`TagMap::log_likelihoods`] (kept between calls to avoid allocating).
#[derive(Debug, Clone, Default)]
pub struct LikelihoodScratch {
    /// Per pose of a block: the antenna's pose and its heading's cosine and sine.
    antenna: AntennaLanes,
    poses: PoseLanes,
    acc: Vec<f32>,
    terms: Vec<f32>,
    reads: ReadScratch,
    field: FieldScratch,
    /// The read tags relative to the first pose: `(x, y, RSS)`.
    tags: Vec<(f32, f32, f32)>,
}

/// Learned tag positions, with the reader model tabulated for fast scoring.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TagMap {
    pub model: ReadModel,
    pub config: TagMapConfig,
    pub tags: Vec<MappedTag>,
    #[serde(skip)]
    index: HashMap<TagId, usize>,
    /// The model's table and the miss field of these tags (shared by clones; built by
    /// [`TagMap::rebuild_index`]).
    #[serde(skip)]
    field: Option<Arc<MissField>>,
}

/// One read (or miss) of a tag during mapping: the antenna pose (position, cos and sin of the
/// heading) and the snapshot's RSS.
#[derive(Debug, Clone, Copy)]
struct Sighting {
    x: f64,
    y: f64,
    cos: f64,
    sin: f64,
    rss: Option<f64>,
}

impl Sighting {
    fn new(a: &Pose2, rss: Option<f64>) -> Self {
        let (sin, cos) = a.theta.sin_cos();
        Self {
            x: a.x,
            y: a.y,
            cos,
            sin,
            rss,
        }
    }
}

impl TagMap {
    /// Maps every tag read in at least `config.min_reads` of `samples` (snapshot, robot pose).
    #[must_use]
    pub fn learn<'a>(
        samples: impl IntoIterator<Item = (&'a Snapshot, Pose2)>,
        model: ReadModel,
        config: TagMapConfig,
    ) -> Self {
        let samples: Vec<(&Snapshot, Pose2)> = samples.into_iter().collect();
        let poses: Vec<Pose2> = samples.iter().map(|(_, p)| *p).collect();
        let snapshots: Vec<&Snapshot> = samples.iter().map(|(s, _)| *s).collect();
        let mapper = Mapper::new(&snapshots, model, config);
        mapper.map(&poses, None)
    }

    /// A map of already placed tags (the index and tables are built).
    #[must_use]
    pub fn from_tags(model: ReadModel, config: TagMapConfig, tags: Vec<MappedTag>) -> Self {
        let mut map = Self {
            model,
            config,
            tags,
            index: HashMap::new(),
            field: None,
        };
        map.rebuild_index();
        map
    }

    /// Rebuilds the lookup tables (after deserialising, or after changing `tags`, `model` or
    /// `config.floor`). The miss field's tiles are computed lazily, on first use.
    pub fn rebuild_index(&mut self) {
        let table = ReadTable::new(&self.model, self.config.floor);
        self.rebuild_with(table);
    }

    /// [`TagMap::rebuild_index`] with a table already built for this model and floor.
    fn rebuild_with(&mut self, table: ReadTable) {
        self.index = self
            .tags
            .iter()
            .enumerate()
            .map(|(i, t)| (t.id.clone(), i))
            .collect();
        let positions: Vec<(f64, f64)> = self.tags.iter().map(|t| (t.x, t.y)).collect();
        self.field = Some(Arc::new(MissField::new(table, &positions)));
    }

    /// Computes the whole miss field now instead of tile by tile on first use (a live robot
    /// may prefer to pay this at start).
    pub fn precompute_field(&self) {
        if let Some(f) = &self.field {
            f.compute_all();
        }
    }

    /// Tiles of the miss field computed so far, and in all.
    #[must_use]
    pub fn field_tiles(&self) -> (usize, usize) {
        self.field
            .as_ref()
            .map_or((0, 0), |f| (f.computed_tiles(), f.tile_count()))
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
        let mut obs = MapObservation::default();
        for (id, rss) in snapshot.iter() {
            match self.index.get(id) {
                Some(&i) => {
                    obs.reads.push((i, rss));
                    obs.mapped += 1;
                }
                None => obs.unmapped += 1,
            }
        }
        obs
    }

    /// σ of a read tag's RSS about the model's mean at the pose (read noise and map error).
    fn read_sigma(&self) -> f64 {
        self.model
            .snapshot_sigma()
            .hypot(self.config.map_sigma)
            .max(1e-9)
    }

    /// Log-likelihood of the observation from robot pose `pose` (see the module
    /// documentation), already divided by the temperature, and the number of terms (tags in
    /// view plus read tags out of view; the field's count is interpolated, hence rounded).
    #[must_use]
    pub fn log_likelihood(&self, pose: &Pose2, obs: &MapObservation) -> (f64, usize) {
        let mut out = Vec::with_capacity(1);
        self.log_likelihoods(
            std::slice::from_ref(pose),
            obs,
            &mut LikelihoodScratch::default(),
            &mut out,
        );
        let (ll, terms) = out.first().copied().unwrap_or((0.0, 0.0));
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        (ll, terms.round().max(0.0) as usize)
    }

    /// The log-likelihood by direct summation over every mapped tag in view, with the model
    /// evaluated exactly (no table, no field): the reference [`TagMap::log_likelihoods`]
    /// approximates. Returns the value divided by the temperature and the number of terms.
    #[must_use]
    pub fn log_likelihood_exact(&self, pose: &Pose2, obs: &MapObservation) -> (f64, f64) {
        let antenna = self.model.antenna(pose);
        let sigma = self.read_sigma();
        let floor = self.config.floor;
        let reach = self.model.reach();
        let mut read = vec![false; self.tags.len()];
        let (mut ll, mut terms) = (0.0, 0.0);
        for &(i, r) in &obs.reads {
            let Some(t) = self.tags.get(i) else { continue };
            if let Some(flag) = read.get_mut(i) {
                *flag = true;
            }
            let m = self.model.mean_rss_from(&antenna, t.x, t.y);
            let z = (r - m) / sigma;
            ll += (-0.5 * z * z).max(-floor);
            terms += 1.0;
        }
        let (sin, cos) = antenna.theta.sin_cos();
        for (t, _) in self.tags.iter().zip(&read).filter(|(_, r)| !**r) {
            let (wx, wy) = (t.x - antenna.x, t.y - antenna.y);
            let x = cos * wx + sin * wy;
            if x < 0.0 || wx.hypot(wy) > reach {
                continue;
            }
            let m = self.model.mean_rss(x, -sin * wx + cos * wy);
            ll += crate::readtable::miss_term(&self.model, floor, m);
            terms += 1.0;
        }
        (ll / self.config.temperature.max(1e-9), terms)
    }

    /// [`TagMap::log_likelihood_exact`] of the read tags only.
    #[must_use]
    pub fn read_log_likelihood_exact(&self, pose: &Pose2, obs: &MapObservation) -> (f64, f64) {
        let antenna = self.model.antenna(pose);
        let sigma = self.read_sigma();
        let (mut ll, mut terms) = (0.0, 0.0);
        for &(i, r) in &obs.reads {
            let Some(t) = self.tags.get(i) else { continue };
            let z = (r - self.model.mean_rss_from(&antenna, t.x, t.y)) / sigma;
            ll += (-0.5 * z * z).max(-self.config.floor);
            terms += 1.0;
        }
        (ll / self.config.temperature.max(1e-9), terms)
    }

    /// Log-likelihoods (divided by the temperature) and term counts of many robot poses for
    /// one observation, appended to `out` after clearing it. Uses the tabulated model and the
    /// miss field: per pose, one field look-up plus one table look-up per read tag. Falls back
    /// to [`TagMap::log_likelihood_exact`] when the tables are missing or were built for
    /// another model or floor (call [`TagMap::rebuild_index`] after changing them).
    ///
    /// The read tags' means and miss terms come from the table packed in 32 bits per cell:
    /// one look-up per pair of pose and read tag (16 at a time with AVX-512). Packing rounds a
    /// mean by at most 1/16382 of the table's range of means and a miss term by at most
    /// `floor / 65534`; [`TagMap::log_likelihoods_unpacked`] takes them as tabulated.
    pub fn log_likelihoods(
        &self,
        poses: &[Pose2],
        obs: &MapObservation,
        scratch: &mut LikelihoodScratch,
        out: &mut Vec<(f64, f64)>,
    ) {
        self.score(poses, obs, scratch, out, ReadMode::Packed);
    }

    /// As [`TagMap::log_likelihoods`] with the table's means and miss terms as tabulated (not
    /// packed): what the joint learning of map and trajectory scores by, whose factors come
    /// from the likelihood's shape over small steps.
    pub fn log_likelihoods_unpacked(
        &self,
        poses: &[Pose2],
        obs: &MapObservation,
        scratch: &mut LikelihoodScratch,
        out: &mut Vec<(f64, f64)>,
    ) {
        self.score(poses, obs, scratch, out, ReadMode::Full);
    }

    /// As [`TagMap::log_likelihoods`] with the read tags' terms only (no miss terms): what the
    /// joint learning of map and trajectory uses to place a pose, where it does not depend on
    /// the miss field of a map that changes every round.
    pub fn read_log_likelihoods(
        &self,
        poses: &[Pose2],
        obs: &MapObservation,
        scratch: &mut LikelihoodScratch,
        out: &mut Vec<(f64, f64)>,
    ) {
        self.score(poses, obs, scratch, out, ReadMode::ReadsOnly);
    }

    fn score(
        &self,
        poses: &[Pose2],
        obs: &MapObservation,
        scratch: &mut LikelihoodScratch,
        out: &mut Vec<(f64, f64)>,
        mode: ReadMode,
    ) {
        let reads_only = mode == ReadMode::ReadsOnly;
        out.clear();
        let Some(field) = self
            .field
            .as_ref()
            .filter(|f| f.table().is_for(&self.model, self.config.floor))
        else {
            out.extend(poses.iter().map(|p| {
                if reads_only {
                    self.read_log_likelihood_exact(p, obs)
                } else {
                    self.log_likelihood_exact(p, obs)
                }
            }));
            return;
        };
        let table = field.table();
        let LikelihoodScratch {
            antenna,
            poses: lanes,
            acc,
            terms,
            reads,
            field: field_scratch,
            tags,
        } = scratch;
        let (ox, oy) = poses.first().map_or((0.0, 0.0), |p| (p.x, p.y));
        let off = self.model.antenna_offset;
        #[allow(clippy::cast_possible_truncation)]
        let (inv_sigma, floor) = ((1.0 / self.read_sigma()) as f32, self.config.floor as f32);
        #[allow(clippy::cast_possible_truncation)]
        tags.clear();
        tags.extend(obs.reads.iter().filter_map(|&(ti, r)| {
            let t = self.tags.get(ti)?;
            Some(((t.x - ox) as f32, (t.y - oy) as f32, r as f32))
        }));
        let inv_t = 1.0 / self.config.temperature.max(1e-9);
        // Blocks of poses small enough that their buffers stay in the first-level cache while
        // every read tag passes over them.
        for block in poses.chunks(BLOCK) {
            let m = block.len();
            lanes.reset(m);
            for v in [&mut *acc, &mut *terms] {
                v.clear();
                v.resize(lanes.c.len(), 0.0);
            }
            // Antenna poses, and as lanes (relative to the first pose, in single precision,
            // pre-rotated and scaled to table cells): loops that vectorise.
            crate::simd::widest(
                #[inline(always)]
                || {
                    // Plain loops over slices (an `extend` would call a fold that is not
                    // inlined here, so not compiled for the wider instructions).
                    antenna.reset(m);
                    let AntennaLanes {
                        x,
                        y,
                        theta,
                        cos,
                        sin,
                    } = antenna;
                    let (x, y, theta) = (&mut x[..m], &mut y[..m], &mut theta[..m]);
                    let (cos, sin) = (&mut cos[..m], &mut sin[..m]);
                    for (i, p) in block.iter().enumerate().take(m) {
                        let (s, c) = sincos_f32(p.theta);
                        x[i] = p.x + f64::from(c) * off;
                        y[i] = p.y + f64::from(s) * off;
                        theta[i] = p.theta;
                        (cos[i], sin[i]) = (c, s);
                    }
                    let (pc, ps) = (&mut lanes.c[..m], &mut lanes.s[..m]);
                    let (pu, pv) = (&mut lanes.u[..m], &mut lanes.v[..m]);
                    for i in 0..m {
                        [pc[i], ps[i], pu[i], pv[i]] =
                            PoseLanes::lane(x[i] - ox, y[i] - oy, cos[i], sin[i]);
                    }
                },
            );
            // The field at each antenna pose.
            if !reads_only {
                field.sample_many(antenna, field_scratch, &mut acc[..m], &mut terms[..m]);
            }
            let read_tags = Reads {
                tags,
                inv_sigma,
                floor,
                mode,
            };
            add_reads(table, &read_tags, lanes, reads, acc, terms);
            out.extend(
                acc.iter()
                    .zip(terms.iter())
                    .take(m)
                    .map(|(a, k)| (f64::from(*a) * inv_t, f64::from(*k))),
            );
        }
    }
}
/// The survey's snapshots (tags interned) and antenna poses with their spatial index, as every
/// tag's search sees them; maps tags for a given set of poses.
pub(crate) struct Mapper<'a> {
    model: ReadModel,
    config: TagMapConfig,
    table: ReadTable,
    /// Tag IDs, and for each the snapshots that read it with the RSS.
    ids: Vec<&'a TagId>,
    reads: Vec<Vec<(usize, f64)>>,
}

/// The antenna poses of one mapping pass, bucketed.
pub(crate) struct PoseIndex {
    antennas: Vec<Pose2>,
    grid: HashMap<(i64, i64), Vec<usize>>,
    cell: f64,
}

impl PoseIndex {
    fn new(antennas: Vec<Pose2>, cell: f64) -> Self {
        let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (i, a) in antennas.iter().enumerate() {
            grid.entry(cell_of(a.x, a.y, cell)).or_default().push(i);
        }
        Self {
            antennas,
            grid,
            cell,
        }
    }
}

impl<'a> Mapper<'a> {
    pub(crate) fn new(snapshots: &[&'a Snapshot], model: ReadModel, config: TagMapConfig) -> Self {
        let mut by_id: BTreeMap<&'a TagId, Vec<(usize, f64)>> = BTreeMap::new();
        for (i, s) in snapshots.iter().enumerate() {
            for (id, rss) in s.iter() {
                by_id.entry(id).or_default().push((i, rss));
            }
        }
        let table = ReadTable::new(&model, config.floor);
        let (ids, reads) = by_id
            .into_iter()
            .filter(|(_, seen)| seen.len() >= config.min_reads.max(1))
            .unzip();
        Self {
            model,
            config,
            table,
            ids,
            reads,
        }
    }

    /// Places every tag for the robot poses `poses` (one per snapshot); with `previous` (the
    /// positions of the last pass, by tag), tags are searched around them only.
    pub(crate) fn map(&self, poses: &[Pose2], previous: Option<&[Option<(f64, f64)>]>) -> TagMap {
        let index = self.index(poses);
        let located: Vec<Option<MappedTag>> = (0..self.ids.len())
            .map(|k| {
                let start = previous.and_then(|p| p.get(k).copied().flatten());
                self.locate_tag(k, &index, start)
            })
            .collect();
        self.build(&located)
    }

    /// Number of tags read often enough over the whole survey.
    pub(crate) fn tag_count(&self) -> usize {
        self.ids.len()
    }

    /// Snapshots (indices) that read tag `k`, in order.
    pub(crate) fn reads_of(&self, k: usize) -> &[(usize, f64)] {
        self.reads.get(k).map_or(&[], Vec::as_slice)
    }

    /// The antenna poses of `poses` (the first `poses.len()` snapshots), bucketed.
    pub(crate) fn index(&self, poses: &[Pose2]) -> PoseIndex {
        let antennas: Vec<Pose2> = poses.iter().map(|p| self.model.antenna(p)).collect();
        PoseIndex::new(antennas, self.table.reach.max(0.5))
    }

    /// Places tag `k` from the snapshots `index` covers (its reads among them must reach
    /// `min_reads`), around `start` when given.
    pub(crate) fn locate_tag(
        &self,
        k: usize,
        index: &PoseIndex,
        start: Option<(f64, f64)>,
    ) -> Option<MappedTag> {
        let id = self.ids.get(k)?;
        let all = self.reads.get(k)?;
        let seen = all
            .get(..all.partition_point(|(i, _)| *i < index.antennas.len()))
            .unwrap_or(&[]);
        if seen.len() < self.config.min_reads.max(1) {
            return None;
        }
        self.locate(id, seen, index, start)
    }

    /// The map of the located tags.
    pub(crate) fn build(&self, located: &[Option<MappedTag>]) -> TagMap {
        self.build_from(located.iter().flatten().cloned())
    }

    /// The map of these tags (sharing the mapper's table).
    pub(crate) fn build_from(&self, tags: impl Iterator<Item = MappedTag>) -> TagMap {
        let mut map = TagMap {
            model: self.model.clone(),
            config: self.config,
            tags: tags.collect(),
            index: HashMap::new(),
            field: None,
        };
        map.rebuild_with(self.table.clone());
        map
    }

    /// Log-likelihood of a tag at `(x, y)` given its sightings (reads and misses).
    fn tag_log_likelihood(&self, x: f64, y: f64, sightings: &[Sighting], sigma: f64) -> f64 {
        let floor = self.config.floor;
        let mut ll = 0.0;
        for s in sightings {
            let (wx, wy) = (x - s.x, y - s.y);
            let (m, miss) = self
                .table
                .at(s.cos * wx + s.sin * wy, -s.sin * wx + s.cos * wy);
            ll += match s.rss {
                Some(r) => {
                    let z = (r - m) / sigma;
                    (-0.5 * z * z).max(-floor)
                }
                // A miss from where the tag could not be read says nothing (the table's 0).
                None => miss,
            };
        }
        ll
    }

    /// Places one tag: first guess from its reads (or `start`), coarse then fine grid search of
    /// the likelihood, σ from the likelihood's spread over the fine grid.
    fn locate(
        &self,
        id: &TagId,
        seen: &[(usize, f64)],
        survey: &PoseIndex,
        start: Option<(f64, f64)>,
    ) -> Option<MappedTag> {
        let c = &self.config;
        let model = &self.model;
        let reach = self.table.reach;
        let (gx, gy) = match start {
            Some(p) => p,
            None => {
                // First guess: each read puts the tag on the boresight at the on-axis
                // distance of its RSS.
                let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
                for (i, rss) in seen {
                    let a = survey.antennas.get(*i)?;
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
                (sx / sw, sy / sw)
            }
        };
        // A second pass only refines around the last position.
        let radius = if start.is_some() {
            2.0 * c.coarse_step
        } else {
            c.search_radius
        };
        // Sightings: the reads, and the misses from every antenna pose within reach of the
        // window.
        let read_at: HashMap<usize, f64> = seen.iter().copied().collect();
        let (cx, cy) = cell_of(gx, gy, survey.cell);
        #[allow(clippy::cast_possible_truncation)]
        let span = ((radius + reach) / survey.cell).ceil() as i64;
        let mut sightings: Vec<Sighting> = Vec::new();
        for dx in -span..=span {
            for dy in -span..=span {
                let Some(members) = survey.grid.get(&(cx + dx, cy + dy)) else {
                    continue;
                };
                for &i in members {
                    let Some(a) = survey.antennas.get(i) else {
                        continue;
                    };
                    let near = (a.x - gx).hypot(a.y - gy) <= radius + reach;
                    match read_at.get(&i) {
                        Some(r) => sightings.push(Sighting::new(a, Some(*r))),
                        None if near => sightings.push(Sighting::new(a, None)),
                        None => {}
                    }
                }
            }
        }
        let sigma = model.snapshot_sigma().hypot(0.5 * c.map_sigma).max(1e-9);
        let search = |x0: f64, y0: f64, half: f64, step: f64| -> Vec<(f64, f64, f64)> {
            #[allow(clippy::cast_possible_truncation)]
            let n = (half / step).round().clamp(0.0, 1000.0) as i64;
            let mut out = Vec::new();
            for ix in -n..=n {
                for iy in -n..=n {
                    #[allow(clippy::cast_precision_loss)]
                    let (x, y) = (x0 + ix as f64 * step, y0 + iy as f64 * step);
                    out.push((x, y, self.tag_log_likelihood(x, y, &sightings, sigma)));
                }
            }
            out
        };
        let best_of = |v: &[(f64, f64, f64)]| v.iter().copied().max_by(|a, b| a.2.total_cmp(&b.2));
        let coarse = search(gx, gy, radius, c.coarse_step.max(1e-3));
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
}

fn cell_of(x: f64, y: f64, cell: f64) -> (i64, i64) {
    #[allow(clippy::cast_possible_truncation)]
    ((x / cell).floor() as i64, (y / cell).floor() as i64)
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
        // The tabulated likelihood (field and table) against direct summation with the exact
        // model, at poses around the truth: close, and it ranks them the same way.
        let mut pairs = Vec::new();
        for k in 0..60 {
            let p = Pose2::new(
                1.5 + 0.02 * f64::from(k % 8) * 6.0,
                1.5 + 0.1 * f64::from(k / 8),
                0.7 + 0.05 * f64::from(k % 5) - 0.1,
            );
            pairs.push((
                map.log_likelihood(&p, &obs).0,
                map.log_likelihood_exact(&p, &obs).0,
            ));
        }
        let spread = pairs.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max)
            - pairs.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let worst = pairs.iter().map(|p| (p.0 - p.1).abs()).fold(0.0, f64::max);
        assert!(worst < 0.1 * spread.max(1.0), "worst {worst} of {spread}");
        // Reloaded from JSON the map scores the same.
        let mut back: TagMap = serde_json::from_str(&serde_json::to_string(&map).unwrap()).unwrap();
        back.rebuild_index();
        assert_eq!(back.len(), map.len());
        assert!((back.log_likelihood(&truth, &obs).0 - best).abs() < 1e-9);
    }
}
