//! RSSI ↔ distance for the HF reader (values 0–7), as a likelihood over the antenna–tag
//! distance for each RSSI value. The blind spot (RSSI 0 both at 10–14 cm and at 4.7–5 cm,
//! seed 002 Table 4 and its emulator table) is kept as a multi-modal likelihood rather than
//! resolved by picking one distance.

pub use rfloc_pose::normal_cdf;
use serde::{Deserialize, Serialize};

/// Largest RSSI value the reader reports.
pub const MAX_RSSI: u8 = 7;

/// One distance band `(lo_m, hi_m]` in which the reader reports `rssi`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RssiBand {
    /// Lower distance bound, m (exclusive).
    pub lo_m: f64,
    /// Upper distance bound, m (inclusive).
    pub hi_m: f64,
    /// Reported RSSI.
    pub rssi: u8,
}

/// Piecewise RSSI model with soft band edges and a detection probability.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RssiModel {
    /// Bands covering `(0, max_range]`.
    pub bands: Vec<RssiBand>,
    /// Standard deviation of the band edges, m (how uncertain each edge distance is).
    pub edge_sigma_m: f64,
    /// Probability that a tag inside the reading range is reported in one stop/scan.
    pub p_detect: f64,
    /// Probability that a reported value is arbitrary (spread over the 8 values).
    pub p_outlier: f64,
    /// Height of the antenna above the tags, m (distance = hypot(horizontal, height)).
    pub antenna_height_m: f64,
}

/// The emulator table of seed 002 (appendix 11.1, arrays `r2`/`r4`, cm → m, `r1` = 14 cm):
/// RSSI rises 0→5 from 14 cm to 6 cm, falls back to 0 at 4.7–5 cm (the blind spot), then
/// rises to 7 below 2.75 cm.
const BLIND_SPOT_EDGES_CM: [(f64, u8); 18] = [
    (14.0, 0),
    (9.75, 1),
    (9.0, 2),
    (8.0, 3),
    (7.0, 4),
    (6.0, 5),
    (5.8, 4),
    (5.5, 3),
    (5.3, 2),
    (5.1, 1),
    (5.0, 0),
    (4.7, 1),
    (4.5, 2),
    (4.3, 3),
    (4.2, 4),
    (4.0, 5),
    (3.5, 6),
    (2.75, 7),
];

/// Monotonic table ("ideal RSSI"): the maximal-distance row of seed 002 Table 4.
const IDEAL_EDGES_CM: [(f64, u8); 8] = [
    (14.0, 0),
    (9.8, 1),
    (9.0, 2),
    (8.0, 3),
    (7.0, 4),
    (6.0, 5),
    (3.5, 6),
    (2.8, 7),
];

fn bands_from_edges(edges: &[(f64, u8)]) -> Vec<RssiBand> {
    let mut out = Vec::with_capacity(edges.len());
    for (i, &(hi_cm, rssi)) in edges.iter().enumerate() {
        let lo_cm = edges.get(i + 1).map_or(0.0, |e| e.0);
        out.push(RssiBand {
            lo_m: lo_cm / 100.0,
            hi_m: hi_cm / 100.0,
            rssi,
        });
    }
    out
}

impl RssiModel {
    /// The seed's measured relation with the blind spot (emulator table), 3 mm edge σ.
    #[must_use]
    pub fn seed002_blind_spot() -> Self {
        Self {
            bands: bands_from_edges(&BLIND_SPOT_EDGES_CM),
            edge_sigma_m: 0.003,
            p_detect: 0.9,
            p_outlier: 0.02,
            antenna_height_m: 0.0,
        }
    }

    /// A monotonic relation (no blind spot), 3 mm edge σ.
    #[must_use]
    pub fn seed002_ideal() -> Self {
        Self {
            bands: bands_from_edges(&IDEAL_EDGES_CM),
            ..Self::seed002_blind_spot()
        }
    }

    /// The same model with every band edge (distance) multiplied by `k`: a reader whose
    /// RSSI-to-distance calibration is `k` times the true one.
    #[must_use]
    pub fn scaled(&self, k: f64) -> Self {
        let mut out = self.clone();
        if k.is_finite() && k > 0.0 {
            for b in &mut out.bands {
                b.lo_m *= k;
                b.hi_m *= k;
            }
        }
        out
    }

    /// Largest distance at which a tag can be read, m.
    #[must_use]
    pub fn max_range_m(&self) -> f64 {
        self.bands.iter().map(|b| b.hi_m).fold(0.0, f64::max)
    }

    fn distance(&self, horizontal_m: f64) -> f64 {
        horizontal_m.hypot(self.antenna_height_m)
    }

    /// The RSSI the noise-free model reports at horizontal distance `d` (m), `None` out of range.
    #[must_use]
    pub fn rssi_for_distance(&self, horizontal_m: f64) -> Option<u8> {
        let d = self.distance(horizontal_m);
        self.bands
            .iter()
            .find(|b| d > b.lo_m && d <= b.hi_m)
            .map(|b| b.rssi)
            .or_else(|| {
                // d == 0 belongs to the closest band.
                (d == 0.0)
                    .then(|| self.bands.iter().find(|b| b.lo_m == 0.0).map(|b| b.rssi))
                    .flatten()
            })
    }

    /// Probability that the tag is reported at all at horizontal distance `d`.
    #[must_use]
    pub fn detection_probability(&self, horizontal_m: f64) -> f64 {
        let d = self.distance(horizontal_m);
        self.p_detect * normal_cdf((self.max_range_m() - d) / self.edge_sigma_m.max(1e-6))
    }

    /// `P(RSSI = rssi | reported, d)`: band membership with Gaussian-blurred edges, mixed with a
    /// uniform outlier probability.
    #[must_use]
    pub fn value_probability(&self, rssi: u8, horizontal_m: f64) -> f64 {
        let d = self.distance(horizontal_m);
        let s = self.edge_sigma_m.max(1e-6);
        let mut p = 0.0;
        let mut total = 0.0;
        for b in &self.bands {
            let m = normal_cdf((d - b.lo_m) / s) - normal_cdf((d - b.hi_m) / s);
            total += m;
            if b.rssi == rssi {
                p += m;
            }
        }
        let inband = if total > 1e-12 { p / total } else { 0.0 };
        (1.0 - self.p_outlier) * inband + self.p_outlier / f64::from(MAX_RSSI + 1)
    }

    /// Likelihood of "reported with value `rssi`" at horizontal distance `d`.
    #[must_use]
    pub fn likelihood(&self, rssi: u8, horizontal_m: f64) -> f64 {
        self.detection_probability(horizontal_m) * self.value_probability(rssi, horizontal_m)
    }

    /// Likelihood of "not reported" at horizontal distance `d`.
    #[must_use]
    pub fn miss_likelihood(&self, horizontal_m: f64) -> f64 {
        1.0 - self.detection_probability(horizontal_m)
    }
}

/// Log-likelihoods tabulated over distance for fast evaluation.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LikelihoodTable {
    step: f64,
    /// `value[r][i]`: P(report r | d = i·step) (detection included).
    value: Vec<Vec<f64>>,
    /// log P(no report | d).
    log_miss: Vec<f64>,
    /// Beyond the table: distance at which everything is constant.
    pub reach_m: f64,
}

/// Floor on probabilities before taking logs (keeps one bad read from vetoing a pose).
const P_FLOOR: f64 = 1e-6;

impl LikelihoodTable {
    /// Tabulates `model` with band edges blurred to at least `min_sigma_m` (search tempering).
    pub fn new(model: &RssiModel, min_sigma_m: f64, step: f64) -> Self {
        let mut m = model.clone();
        m.edge_sigma_m = m.edge_sigma_m.max(min_sigma_m);
        let reach = m.max_range_m() + 5.0 * m.edge_sigma_m;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (reach / step).ceil() as usize + 2;
        #[allow(clippy::cast_precision_loss)]
        let d = |i: usize| i as f64 * step;
        let value = (0..=MAX_RSSI)
            .map(|r| (0..n).map(|i| m.likelihood(r, d(i))).collect())
            .collect();
        let log_miss = (0..n)
            .map(|i| m.miss_likelihood(d(i)).max(P_FLOOR).ln())
            .collect();
        Self {
            step,
            value,
            log_miss,
            reach_m: reach,
        }
    }

    fn index(&self, d: f64) -> usize {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let i = (d / self.step).round().max(0.0) as usize;
        i.min(self.log_miss.len().saturating_sub(1))
    }

    /// Mixture log-likelihood of a tag reported with the value histogram `weights[r]` (sum 1).
    pub fn log_report(&self, weights: &[f64; 8], d: f64) -> f64 {
        let i = self.index(d);
        let mut p = 0.0;
        for (r, w) in weights.iter().enumerate() {
            if *w > 0.0 {
                p += w * self
                    .value
                    .get(r)
                    .and_then(|v| v.get(i))
                    .copied()
                    .unwrap_or(0.0);
            }
        }
        p.max(P_FLOOR).ln()
    }

    /// `log_report(weights, d)` tabulated over distance, for repeated evaluation.
    pub fn report_curve(&self, weights: &[f64; 8]) -> Vec<f64> {
        #[allow(clippy::cast_precision_loss)]
        let curve = (0..self.log_miss.len())
            .map(|i| self.log_report(weights, i as f64 * self.step))
            .collect();
        curve
    }

    /// Looks up a curve from [`Self::report_curve`] at distance `d`.
    pub fn at(&self, curve: &[f64], d: f64) -> f64 {
        curve
            .get(self.index(d))
            .or_else(|| curve.last())
            .copied()
            .unwrap_or(0.0)
    }

    /// Log-likelihood of a tag not reported.
    pub fn log_miss(&self, d: f64) -> f64 {
        self.log_miss.get(self.index(d)).copied().unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blind_spot_table_reproduces_the_seed_emulator() {
        let m = RssiModel::seed002_blind_spot();
        // Distances in cm → RSSI as the emulator's find(r2 > d) / r4(end) gives them.
        for (cm, r) in [
            (12.0, 0),
            (9.5, 1),
            (8.5, 2),
            (7.5, 3),
            (6.5, 4),
            (5.9, 5),
            (5.6, 4),
            (5.4, 3),
            (5.2, 2),
            (5.05, 1),
            (4.8, 0),
            (4.6, 1),
            (4.4, 2),
            (4.25, 3),
            (4.1, 4),
            (3.8, 5),
            (3.0, 6),
            (1.0, 7),
            (0.0, 7),
        ] {
            assert_eq!(m.rssi_for_distance(cm / 100.0), Some(r), "{cm} cm");
        }
        assert_eq!(m.rssi_for_distance(0.141), None);
    }

    #[test]
    fn rssi_zero_is_bimodal_under_the_blind_spot_model() {
        let m = RssiModel::seed002_blind_spot();
        let near = m.likelihood(0, 0.0485);
        let far = m.likelihood(0, 0.12);
        let between = m.likelihood(0, 0.07);
        assert!(near > 0.3 && far > 0.5, "{near} {far}");
        assert!(between < 0.05, "{between}");
        let ideal = RssiModel::seed002_ideal();
        assert!(ideal.likelihood(0, 0.0485) < 0.05);
    }

    #[test]
    fn value_probabilities_sum_to_one() {
        let m = RssiModel::seed002_blind_spot();
        for d in [0.0, 0.02, 0.05, 0.09, 0.13] {
            let s: f64 = (0..=MAX_RSSI).map(|r| m.value_probability(r, d)).sum();
            assert!((s - 1.0).abs() < 1e-9, "{d}: {s}");
        }
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_cdf(1.959_964) - 0.975).abs() < 1e-6);
    }
}
