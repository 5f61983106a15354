//! Filter configuration. Defaults follow the XBee EKF-SLAM reference (seed 003, Table 3.1 and
//! eq. 2.7) where it gives a value; the rest are documented choices.

use serde::{Deserialize, Serialize};

/// Noise on commanded velocities, used by [`crate::EkfSlam::predict_velocity`].
/// Units: m/s and rad/s (standard deviations of the velocity actually achieved).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VelocityNoise {
    /// σ_v in m/s (seed 003 Table 3.1: 0.0119).
    pub sigma_v: f64,
    /// σ_ω in rad/s (seed 003 Table 3.1: 0.0012).
    pub sigma_omega: f64,
}

impl Default for VelocityNoise {
    fn default() -> Self {
        Self {
            sigma_v: 0.0119,
            sigma_omega: 0.0012,
        }
    }
}

/// Noise on odometry increments, used by [`crate::EkfSlam::predict_odometry`].
///
/// For an increment `(dx, dy, dθ)` in the robot frame with length `d = hypot(dx, dy)`:
/// `σ_x = σ_y = trans_per_m·d + floor_m` and `σ_θ = rot_per_rad·|dθ| + rot_per_m·d + floor_rad`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OdometryNoise {
    /// Translation error per metre travelled (dimensionless).
    pub trans_per_m: f64,
    /// Heading error per radian turned (dimensionless).
    pub rot_per_rad: f64,
    /// Heading error per metre travelled (rad/m).
    pub rot_per_m: f64,
    /// Translation standard deviation added to every increment (m).
    pub floor_m: f64,
    /// Heading standard deviation added to every increment (rad).
    pub floor_rad: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        Self {
            trans_per_m: 0.02,
            rot_per_rad: 0.02,
            rot_per_m: 0.01,
            floor_m: 1e-4,
            floor_rad: 1e-4,
        }
    }
}

/// Log-distance path-loss model `RSSI(d) = p_ref_dbm − 10·η·log10(d / 1 m)` (seed 003 eq. 2.7).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PathLoss {
    /// Received power at 1 m, dBm (seed 003: −29).
    pub p_ref_dbm: f64,
    /// Path-loss exponent η (seed 003: 2).
    pub eta: f64,
}

impl Default for PathLoss {
    fn default() -> Self {
        Self {
            p_ref_dbm: -29.0,
            eta: 2.0,
        }
    }
}

impl PathLoss {
    /// Expected RSSI in dBm at distance `d` metres.
    #[must_use]
    pub fn rssi_at(&self, d: f64) -> f64 {
        self.p_ref_dbm - 10.0 * self.eta * d.log10()
    }

    /// Distance (m) at which the model gives `rssi_dbm` (the median distance under log-normal noise).
    #[must_use]
    pub fn distance_for(&self, rssi_dbm: f64) -> f64 {
        10f64.powf((self.p_ref_dbm - rssi_dbm) / (10.0 * self.eta))
    }

    /// `d ln(d̂) / d RSSI` magnitude: `ln 10 / (10 η)`.
    #[must_use]
    pub fn ln_distance_per_db(&self) -> f64 {
        std::f64::consts::LN_10 / (10.0 * self.eta)
    }
}

/// How an RSSI reading ([`crate::RangeReading::RssiDbm`]) enters the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RssiHandling {
    /// Use the RSSI itself as the measurement, `h = P_ref − 10η log10(d)`, with its variance in
    /// dB². Unbiased and homoscedastic in dB (preferred).
    #[default]
    PathLossMeasurement,
    /// Convert to a range `d̂ = 10^((P_ref − RSSI)/(10η))` with variance `(d̂·σ_ln)²`,
    /// `σ_ln = σ_dB·ln10/(10η)` (what the reference did; biased high by `exp(σ_ln²/2)`).
    ConvertToRange,
}

/// Which covariance update is used after each measurement. Both cost O(n²·m).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceUpdate {
    /// Joseph form `(I−KH)P(I−KH)ᵀ + KRKᵀ`, expanded as `P − KMᵀ − MKᵀ + KSKᵀ` with `M = PHᵀ`.
    #[default]
    Joseph,
    /// Cholesky downdate `P − W Wᵀ`, `W = M L⁻ᵀ`, `S = L Lᵀ`.
    Cholesky,
}

/// Mahalanobis gate on the normalised innovation squared (NIS).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Gate {
    /// Reject a 1-D measurement when NIS exceeds this (default 10.83 = χ²₁ 99.9 %).
    pub chi2_1dof: f64,
    /// Reject a 2-D measurement when NIS exceeds this (default 13.82 = χ²₂ 99.9 %).
    pub chi2_2dof: f64,
    /// When false, nothing is rejected (NIS is still reported).
    pub enabled: bool,
}

impl Default for Gate {
    fn default() -> Self {
        Self {
            chi2_1dof: 10.828,
            chi2_2dof: 13.816,
            enabled: true,
        }
    }
}

/// Delayed initialisation of beacons seen without a usable range+bearing pair (range-only,
/// RSSI-only or bearing-only readings): views are collected and the beacon is triangulated once
/// the views constrain it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DelayedInit {
    /// Minimum number of views before a triangulation is attempted.
    pub min_views: usize,
    /// Views kept per pending beacon (the oldest is dropped beyond this).
    pub max_views: usize,
    /// Minimum distance (m) between the extreme robot positions of the views.
    pub min_baseline_m: f64,
    /// Accept the triangulated position only if the largest standard deviation of its 2×2
    /// covariance is at most this (m).
    pub max_std_m: f64,
    /// Once a pending beacon has at least this many views, also accept a triangulation whose
    /// largest σ is at most `max_relative_std` times its distance from the mean view position:
    /// far beacons seen from a short baseline never reach `max_std_m`, but their views then
    /// define a unimodal, well-conditioned estimate, which enters the map with its full
    /// covariance and is refined by every later sweep. 0 turns this off.
    pub relax_after_views: usize,
    /// Relative σ bound of `relax_after_views` (dimensionless).
    pub max_relative_std: f64,
    /// Keep a copy of the robot pose of every view in the filter state (one per update batch
    /// that stores a view), correlated with everything else and refined by later updates, until
    /// no pending view refers to it. The triangulated beacon then enters the map with its exact
    /// first-order cross-covariances to those poses, so views from a well-known pose (e.g. near
    /// the start) keep their weight. When false, the views' poses are taken as exact and the
    /// beacon is attached to the current pose.
    pub view_poses_in_state: bool,
    /// Also delay observations that carry both a range (or RSSI) and a bearing: collect them as
    /// views and triangulate, instead of adding the beacon at once by the inverse model.
    pub delay_range_bearing: bool,
}

impl Default for DelayedInit {
    fn default() -> Self {
        Self {
            min_views: 3,
            max_views: 30,
            min_baseline_m: 0.5,
            max_std_m: 1.5,
            relax_after_views: 0,
            max_relative_std: 0.25,
            view_poses_in_state: true,
            delay_range_bearing: false,
        }
    }
}

/// Full EKF-SLAM configuration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EkfSlamConfig {
    /// Velocity-command noise for [`crate::EkfSlam::predict_velocity`].
    pub velocity_noise: VelocityNoise,
    /// Odometry-increment noise for [`crate::EkfSlam::predict_odometry`].
    pub odometry_noise: OdometryNoise,
    /// Distance between the drive wheels, m (seed 003 Table 3.1: 0.331). Used by
    /// [`crate::twist_from_wheel_speeds`]; the filter itself works on (v, ω).
    pub wheelbase_m: f64,
    /// Path-loss model for RSSI readings.
    pub path_loss: PathLoss,
    /// How RSSI readings are used.
    pub rssi_handling: RssiHandling,
    /// Covariance update form.
    pub covariance_update: CovarianceUpdate,
    /// Innovation gate.
    pub gate: Gate,
    /// Delayed initialisation settings.
    pub delayed_init: DelayedInit,
    /// Predicted distances below this (m) make an observation unusable (singular Jacobians).
    pub min_distance_m: f64,
}

impl Default for EkfSlamConfig {
    fn default() -> Self {
        Self {
            velocity_noise: VelocityNoise::default(),
            odometry_noise: OdometryNoise::default(),
            wheelbase_m: 0.331,
            path_loss: PathLoss::default(),
            rssi_handling: RssiHandling::default(),
            covariance_update: CovarianceUpdate::default(),
            gate: Gate::default(),
            delayed_init: DelayedInit::default(),
            min_distance_m: 0.05,
        }
    }
}

/// Converts wheel speeds (m/s) of a differential drive into `(v, ω)`.
#[must_use]
pub fn twist_from_wheel_speeds(left: f64, right: f64, wheelbase_m: f64) -> (f64, f64) {
    ((left + right) / 2.0, (right - left) / wheelbase_m)
}
