//! All sensor models of a scenario with one independent, seeded random stream per sensor, in
//! the shapes the device emulators are fed with. Independent streams mean that reading one
//! sensor more or less often never changes what another sensor reports.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;

use crate::emitter::{AntennaRss, EmitterModel, FadingField};
use crate::hf::HfModel;
use crate::scanner::{bumpers, Beam, BumperState, RangeScanner};
use crate::scenario::Scenario;
use crate::uhf::UhfModel;
use crate::world::World;
use crate::xbee::{RangeBearingNoise, XbeeModel};

/// Sensor models plus their random streams for one trial.
#[derive(Debug, Clone)]
pub struct SensorSuite {
    pub uhf: UhfModel,
    pub hf: HfModel,
    pub xbee: XbeeModel,
    pub xbee_range_bearing: RangeBearingNoise,
    pub emitter: EmitterModel,
    pub scanner: RangeScanner,
    rng_uhf: ChaCha8Rng,
    rng_hf: ChaCha8Rng,
    rng_xbee: ChaCha8Rng,
    rng_emitter: ChaCha8Rng,
    rng_scanner: ChaCha8Rng,
    /// Shadowing per beacon for the current sweep (drawn on first use after
    /// [`SensorSuite::begin_xbee_sweep`]).
    xbee_shadow: Vec<Option<f64>>,
    /// Spatial multipath per emitter antenna (zero fields when the model has it off).
    emitter_fading: [FadingField; 4],
}

fn stream(seed: u64, k: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(k);
    r
}

impl SensorSuite {
    /// The scenario's models, streams seeded from trial `trial`'s seed.
    #[must_use]
    pub fn for_trial(scenario: &Scenario, trial: usize) -> Self {
        let seed = scenario.trial_seed(trial);
        let emitter = scenario.emitter_model();
        let emitter_fading = emitter.fading_fields(&mut stream(seed, 6));
        Self {
            uhf: scenario.uhf_model(),
            hf: scenario.hf_model(),
            xbee: scenario.xbee_model(),
            xbee_range_bearing: scenario.xbee_range_bearing(),
            emitter,
            scanner: scenario.scanner(),
            rng_uhf: stream(seed, 1),
            rng_hf: stream(seed, 2),
            rng_xbee: stream(seed, 3),
            rng_emitter: stream(seed, 4),
            rng_scanner: stream(seed, 5),
            xbee_shadow: Vec::new(),
            emitter_fading,
        }
    }

    /// UHF inventory from the robot's antenna: `(EPC, RSS)` pairs (Alien `t` tag list).
    pub fn uhf_inventory(&mut self, world: &World, robot: &Pose2) -> Vec<(String, f64)> {
        let antenna = self.uhf.antenna_pose(robot);
        self.uhf
            .visible_tags(&antenna, &world.uhf_tags, &mut self.rng_uhf)
            .into_iter()
            .map(|r| (r.epc, r.rss))
            .collect()
    }

    /// HF tags under the antenna: `(UID, RSSI 0–7)` pairs, nearest first (KTS scan lines).
    pub fn hf_scan(&mut self, world: &World, robot: &Pose2) -> Vec<(u64, u8)> {
        let antenna = self.hf.antenna_position(robot);
        self.hf
            .tags_under_antenna(antenna, &world.hf_tags, &mut self.rng_hf)
            .into_iter()
            .map(|r| (r.uid, r.rssi))
            .collect()
    }

    /// Starts a new reflector sweep: the next reading of each beacon draws a fresh shadowing
    /// value, which then holds until the next call (seed 003 sweeps at a standstill, so slow
    /// fading is common to one sweep and must not move its arg-max).
    pub fn begin_xbee_sweep(&mut self) {
        self.xbee_shadow.clear();
    }

    /// RSSI (dBm) of beacon `index` with the reflector at `stepper_angle` (radians from the
    /// heading); `None` for an unknown beacon or below sensitivity. Shadowing is held per
    /// beacon between [`SensorSuite::begin_xbee_sweep`] calls; fast fading is drawn per call.
    pub fn xbee_rssi(
        &mut self,
        world: &World,
        robot: &Pose2,
        stepper_angle: f64,
        index: usize,
    ) -> Option<f64> {
        let b = world.beacons.get(index)?;
        if self.xbee_shadow.len() <= index {
            self.xbee_shadow.resize(index + 1, None);
        }
        let shadow = match self.xbee_shadow.get(index).copied().flatten() {
            Some(v) => v,
            None => {
                let v = self.xbee.draw_shadow(&mut self.rng_xbee);
                if let Some(slot) = self.xbee_shadow.get_mut(index) {
                    *slot = Some(v);
                }
                v
            }
        };
        self.xbee.reading_with_shadow(
            robot,
            stepper_angle,
            &b.position,
            shadow,
            &mut self.rng_xbee,
        )
    }

    /// Table 3.1-style noisy `(range, bearing)` of beacon `index`.
    pub fn xbee_range_bearing(
        &mut self,
        world: &World,
        robot: &Pose2,
        index: usize,
    ) -> Option<(f64, f64)> {
        let b = world.beacons.get(index)?;
        Some(
            self.xbee_range_bearing
                .sample(robot, &b.position, &mut self.rng_xbee),
        )
    }

    /// RSS at the four emitter antennas; all `None` when the world has no emitter.
    pub fn emitter_rss(&mut self, world: &World, robot: &Pose2) -> AntennaRss {
        match &world.emitter {
            Some(e) => self.emitter.sample_with_fading(
                world,
                robot,
                e,
                &self.emitter_fading,
                &mut self.rng_emitter,
            ),
            None => [None; 4],
        }
    }

    /// One laser scan.
    pub fn laser_scan(&mut self, world: &World, robot: &Pose2) -> Vec<Beam> {
        self.scanner.scan(world, robot, &mut self.rng_scanner)
    }

    /// Bumper contacts for a body of `radius` (1 cm contact margin).
    #[must_use]
    pub fn bumpers(&self, world: &World, robot: &Pose2, radius: f64) -> BumperState {
        bumpers(world, robot, radius, 0.01)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const S: &str = r#"
name = "t"
pipeline = "snapshot"
duration_s = 1.0
dt_s = 0.1
trials = 2
seed = 9
[robot]
start = { x = 1.0, y = 1.0 }
[goal]
x = 2.0
y = 2.0
tolerance_m = 0.4
[world]
area = { min = [0.0, 0.0], max = [4.0, 4.0] }
uhf_tags = { random = { count = 200, seed = 3 } }
hf_grid = { origin = [0.5, 0.5], pitch = 0.1, rows = 10, cols = 10 }
xbee_beacons = [{ x = 3.0, y = 3.0, address = "1", ni = "beacon1" }]
emitter = { x = 3.0, y = 1.0 }
"#;

    #[test]
    fn streams_are_independent_and_seeded() {
        let s = Scenario::from_toml_str(S, Path::new("s.toml")).unwrap();
        let pose = Pose2::new(1.0, 1.0, 0.3);
        let mut a = SensorSuite::for_trial(&s, 0);
        let mut b = SensorSuite::for_trial(&s, 0);
        // Extra draws on b's HF and emitter streams must not change b's UHF reads.
        let _ = b.hf_scan(&s.world, &pose);
        let _ = b.emitter_rss(&s.world, &pose);
        let ua = a.uhf_inventory(&s.world, &pose);
        assert!(!ua.is_empty());
        assert_eq!(ua, b.uhf_inventory(&s.world, &pose));
        assert_eq!(
            a.hf_scan(&s.world, &pose).len(),
            b.hf_scan(&s.world, &pose).len()
        );
        let mut c = SensorSuite::for_trial(&s, 1);
        assert_ne!(ua, c.uhf_inventory(&s.world, &pose));
        assert!(a.xbee_rssi(&s.world, &pose, 0.0, 0).is_some());
        assert!(a.xbee_rssi(&s.world, &pose, 0.0, 1).is_none());
        // Within one sweep the shadowing is held: with fast fading off, repeated readings
        // at one angle are equal; a new sweep draws a new value.
        let mut q = SensorSuite::for_trial(&s, 0);
        q.xbee.fast_sigma_db = 0.0;
        q.xbee.integer_dbm = false;
        let r1 = q.xbee_rssi(&s.world, &pose, 0.0, 0);
        assert_eq!(r1, q.xbee_rssi(&s.world, &pose, 0.0, 0));
        q.begin_xbee_sweep();
        assert_ne!(r1, q.xbee_rssi(&s.world, &pose, 0.0, 0));
        assert!(a.emitter_rss(&s.world, &pose).iter().all(Option::is_some));
        assert_eq!(a.laser_scan(&s.world, &pose).len(), 683);
    }
}
