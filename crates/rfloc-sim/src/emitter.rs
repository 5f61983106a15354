//! RSS at four directional 915 MHz antennas on the robot (seed 001, section 4).
//!
//! The seed lost its equations (3)–(4) in extraction and gives no path-loss numbers, so the
//! model is built from what its text states and documented as assumptions:
//!
//! - four receivers behind reflectors at 90°: front, left, back, right of the heading
//!   (section 4.2, "two pairs … at a 90° offset");
//! - 915 MHz, λ = 0.3276 m (section 4.2); free-space loss at the 1 m reference distance
//!   `20·log10(4π/λ) = 31.7 dB`, then log-distance with exponent `n = 2`;
//! - reflector beam width from eq. (2), `HPBW = kλ/D` with k ≈ 70 and the 300 mm reflector:
//!   70 · 0.3276 / 0.3 ≈ 76°, back lobe −10 dB ([`ReflectorPattern`]);
//! - multipath: Gaussian σ = 4 dB per antenna per reading (section 4.4 calls the RSS "highly
//!   fluctuating" without a number; 4 dB is a typical indoor value) plus a fixed 6 dB loss
//!   for every wall the direct path crosses (no line of sight, section 4.2);
//! - −100 dBm sensitivity; at 0 dBm this gives a free-space reach far beyond the seed's
//!   "over 50 m";
//! - optional spatially correlated multipath ([`FadingField`], off by default): a seeded sum
//!   of plane waves at the carrier wavelength per antenna, so the fading pattern is fixed in
//!   space (standing still does not average it out; moving ~λ/2 decorrelates it).

use rand::Rng;
use rfloc_pose::{angle_diff, Pose2};
use serde::{Deserialize, Serialize};

use crate::geometry::Point;
use crate::noise::gaussian;
use crate::pattern::ReflectorPattern;
use crate::world::{Emitter, World};

/// Wavelength at 915 MHz, metres (seed 001 section 4.2).
pub const WAVELENGTH: f64 = 0.3276;
/// Boresight of the four antennas relative to the heading: front, left, back, right.
pub const ANTENNA_BORESIGHTS: [f64; 4] = [
    0.0,
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::PI,
    -std::f64::consts::FRAC_PI_2,
];

/// Parameters of the four-antenna RSS model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmitterModel {
    /// Loss at 1 m, dB.
    pub reference_loss_db: f64,
    /// Log-distance exponent.
    pub path_loss_exponent: f64,
    pub pattern: ReflectorPattern,
    /// σ of the per-antenna multipath term, dB.
    pub multipath_sigma_db: f64,
    /// Loss per wall crossed by the direct path, dB.
    pub wall_loss_db: f64,
    pub sensitivity_dbm: f64,
    /// σ of the spatially correlated multipath field, dB (0 = off).
    pub spatial_fading_sigma_db: f64,
}

impl Default for EmitterModel {
    fn default() -> Self {
        Self {
            reference_loss_db: 20.0 * (4.0 * std::f64::consts::PI / WAVELENGTH).log10(),
            path_loss_exponent: 2.0,
            // Eq. (2): HPBW = kλ/D in degrees with k = 70, D = 0.3 m → 76.4°.
            pattern: ReflectorPattern::from_hpbw(70.0 * WAVELENGTH / 0.3, -10.0),
            multipath_sigma_db: 4.0,
            wall_loss_db: 6.0,
            sensitivity_dbm: -100.0,
            spatial_fading_sigma_db: 0.0,
        }
    }
}

/// RSS at the four antennas `[front, left, back, right]`, dBm; `None` below sensitivity.
pub type AntennaRss = [Option<f64>; 4];

/// A seeded, spatially correlated fading field: `σ·√(2/K)·Σ cos(k·(x cos φᵢ + y sin φᵢ) + ψᵢ)`
/// over `K` plane waves with wavenumber `k = 2π/λ`, random directions φᵢ and phases ψᵢ. Its
/// mean is 0 and its variance σ² (over space and seeds); values decorrelate over about λ/2.
#[derive(Debug, Clone, PartialEq)]
pub struct FadingField {
    waves: Vec<(f64, f64, f64)>,
    amplitude: f64,
}

impl FadingField {
    /// A field of `components` plane waves at `wavelength` with standard deviation `sigma_db`.
    pub fn new<R: Rng + ?Sized>(
        sigma_db: f64,
        wavelength: f64,
        components: usize,
        rng: &mut R,
    ) -> Self {
        let k = 2.0 * std::f64::consts::PI / wavelength;
        let n = components.max(1);
        let waves = (0..n)
            .map(|_| {
                let phi = rng.random_range(0.0..2.0 * std::f64::consts::PI);
                let psi = rng.random_range(0.0..2.0 * std::f64::consts::PI);
                (k * phi.cos(), k * phi.sin(), psi)
            })
            .collect();
        Self {
            waves,
            amplitude: sigma_db * (2.0 / n as f64).sqrt(),
        }
    }

    /// Field value at `(x, y)`, dB.
    #[must_use]
    pub fn at(&self, x: f64, y: f64) -> f64 {
        self.amplitude
            * self
                .waves
                .iter()
                .map(|(kx, ky, psi)| (kx * x + ky * y + psi).cos())
                .sum::<f64>()
    }
}

impl EmitterModel {
    /// Mean RSS at each antenna (no multipath), dBm.
    #[must_use]
    pub fn mean_rss(&self, world: &World, robot: &Pose2, emitter: &Emitter) -> [f64; 4] {
        let here = Point::new(robot.x, robot.y);
        let d = here.distance(&emitter.position).max(0.05);
        let walls = world.walls_crossed(&here, &emitter.position) as f64;
        let base = emitter.power_dbm
            - self.reference_loss_db
            - 10.0 * self.path_loss_exponent * d.log10()
            - walls * self.wall_loss_db;
        let bearing = (emitter.position.y - robot.y).atan2(emitter.position.x - robot.x);
        ANTENNA_BORESIGHTS
            .map(|b| base + self.pattern.gain_db(angle_diff(bearing, robot.theta + b)))
    }

    /// One field per antenna for [`EmitterModel::sample_with_fading`] (16 plane waves each).
    pub fn fading_fields<R: Rng + ?Sized>(&self, rng: &mut R) -> [FadingField; 4] {
        std::array::from_fn(|_| FadingField::new(self.spatial_fading_sigma_db, WAVELENGTH, 16, rng))
    }

    /// One reading with the per-antenna spatial fading `fields` added to the i.i.d. multipath.
    pub fn sample_with_fading<R: Rng + ?Sized>(
        &self,
        world: &World,
        robot: &Pose2,
        emitter: &Emitter,
        fields: &[FadingField; 4],
        rng: &mut R,
    ) -> AntennaRss {
        let mean = self.mean_rss(world, robot, emitter);
        std::array::from_fn(|i| {
            let fade = fields.get(i).map_or(0.0, |f| f.at(robot.x, robot.y));
            let z = mean.get(i).copied().unwrap_or(f64::NEG_INFINITY)
                + fade
                + gaussian(rng, self.multipath_sigma_db);
            (z >= self.sensitivity_dbm).then_some(z)
        })
    }

    /// One reading of the four antennas.
    pub fn sample<R: Rng + ?Sized>(
        &self,
        world: &World,
        robot: &Pose2,
        emitter: &Emitter,
        rng: &mut R,
    ) -> AntennaRss {
        self.mean_rss(world, robot, emitter).map(|m| {
            let z = m + gaussian(rng, self.multipath_sigma_db);
            (z >= self.sensitivity_dbm).then_some(z)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn world(extra: &str) -> World {
        World::from_toml_str(
            &format!("[area]\nmin=[-10.0,-10.0]\nmax=[10.0,10.0]\n{extra}"),
            Path::new("w"),
        )
        .unwrap()
    }

    #[test]
    fn strongest_antenna_faces_the_emitter_and_pairs_differ() {
        let w = world("");
        let m = EmitterModel::default();
        let e = Emitter {
            position: Point::new(0.0, 4.0),
            power_dbm: 0.0,
        };
        let rss = m.mean_rss(&w, &Pose2::new(0.0, 0.0, 0.0), &e);
        // Emitter on the left: left antenna strongest, right weakest by the back lobe.
        assert!(rss[1] > rss[0] && rss[1] > rss[2] && rss[1] > rss[3]);
        assert!((rss[1] - rss[3] - 10.0).abs() < 1e-9);
        // 4 m, 0 dBm, on boresight: −20·log10(4π/λ) − 20·log10(4) = −31.68 − 12.04 dB.
        assert!((rss[1] + 31.68 + 12.04).abs() < 0.01, "{}", rss[1]);
        let hp = m.pattern.hpbw_deg();
        assert!((hp - 76.44).abs() < 0.2, "hpbw {hp}");
    }

    #[test]
    fn fading_field_has_its_sigma_and_is_spatially_smooth() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut sum, mut sq, mut n) = (0.0, 0.0, 0.0);
        let mut max_step: f64 = 0.0;
        for seed in 0..50 {
            let f = FadingField::new(
                3.0,
                WAVELENGTH,
                16,
                &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed),
            );
            for _ in 0..40 {
                let (x, y) = (rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0));
                let v = f.at(x, y);
                sum += v;
                sq += v * v;
                n += 1.0;
                max_step = max_step.max((f.at(x + 0.005, y) - v).abs());
            }
        }
        let mean = sum / n;
        let sd = (sq / n - mean * mean).sqrt();
        assert!(
            mean.abs() < 0.3 && (sd - 3.0).abs() < 0.3,
            "mean {mean} sd {sd}"
        );
        // 5 mm (λ/65) moves the field by at most a fraction of σ.
        assert!(max_step < 1.5, "{max_step}");
        let a = FadingField::new(
            3.0,
            WAVELENGTH,
            16,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
        );
        let b = FadingField::new(
            3.0,
            WAVELENGTH,
            16,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
        );
        assert_eq!(a, b);
        // With i.i.d. noise off, the faded reading is the mean plus the field value.
        let m = EmitterModel {
            multipath_sigma_db: 0.0,
            spatial_fading_sigma_db: 3.0,
            ..EmitterModel::default()
        };
        let fields = m.fading_fields(&mut rand_chacha::ChaCha8Rng::seed_from_u64(2));
        let w = world("");
        let e = Emitter {
            position: Point::new(3.0, 0.0),
            power_dbm: 0.0,
        };
        let p = Pose2::new(0.3, 0.2, 0.0);
        let got = m.sample_with_fading(
            &w,
            &p,
            &e,
            &fields,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(0),
        );
        let mean_rss = m.mean_rss(&w, &p, &e);
        for i in 0..4 {
            assert!((got[i].unwrap() - mean_rss[i] - fields[i].at(0.3, 0.2)).abs() < 1e-9);
        }
    }

    #[test]
    fn walls_attenuate_and_reach_exceeds_50_m() {
        let m = EmitterModel::default();
        let e = Emitter {
            position: Point::new(4.0, 0.0),
            power_dbm: 0.0,
        };
        let open = m.mean_rss(&world(""), &Pose2::default(), &e);
        let walled = m.mean_rss(
            &world("[[walls]]\npoints = [[2.0, -1.0], [2.0, 1.0]]\n"),
            &Pose2::default(),
            &e,
        );
        assert!((open[0] - walled[0] - 6.0).abs() < 1e-9);
        let far = Emitter {
            position: Point::new(9.0, 0.0),
            power_dbm: 0.0,
        };
        let big = World::from_toml_str(
            "[area]\nmin=[-60.0,-60.0]\nmax=[60.0,60.0]\n",
            Path::new("w"),
        )
        .unwrap();
        let at50 = m.mean_rss(&big, &Pose2::new(-41.0, 0.0, 0.0), &far);
        assert!(at50[0] > m.sensitivity_dbm + 3.0 * m.multipath_sigma_db);
    }
}
