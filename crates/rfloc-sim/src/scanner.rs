//! 2-D laser range scanner and contact bumpers (seed 001, section 3: a Hokuyo URG-04LX-UG01
//! range finder for obstacle detection, contact sensors as fail-safe).
//!
//! Defaults follow the URG-04LX-UG01 data sheet figures: 240° field of view in 683 beams
//! (0.352° apart), 0.02–5.6 m range, σ = 0.01 m range noise (the sheet's ±30 mm accuracy
//! taken as 3σ). Beams are cast against every wall segment of the world; a beam that hits
//! nothing within `max_range` reports `max_range` and `hit = false`.

use rand::Rng;
use rfloc_pose::{angle_diff, Pose2};
use serde::{Deserialize, Serialize};

use crate::geometry::Point;
use crate::noise::gaussian;
use crate::world::World;

/// Scanner parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RangeScanner {
    pub beams: usize,
    /// Total field of view, degrees, centred on the heading.
    pub fov_deg: f64,
    pub min_range: f64,
    pub max_range: f64,
    pub noise_sigma: f64,
    /// Mounting offset ahead of the robot centre, metres.
    pub mount_offset: f64,
}

impl Default for RangeScanner {
    fn default() -> Self {
        Self {
            beams: 683,
            fov_deg: 240.0,
            min_range: 0.02,
            max_range: 5.6,
            noise_sigma: 0.01,
            mount_offset: 0.0,
        }
    }
}

/// One beam of a scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    /// Beam angle relative to the robot heading, radians.
    pub angle: f64,
    /// Measured range, metres.
    pub range: f64,
    /// False when nothing was hit within `max_range`.
    pub hit: bool,
}

impl RangeScanner {
    /// Angle of beam `i` relative to the heading.
    #[must_use]
    pub fn beam_angle(&self, i: usize) -> f64 {
        let fov = self.fov_deg.to_radians();
        if self.beams <= 1 {
            return 0.0;
        }
        -0.5 * fov + fov * i as f64 / (self.beams - 1) as f64
    }

    /// One scan from `robot`.
    pub fn scan<R: Rng + ?Sized>(&self, world: &World, robot: &Pose2, rng: &mut R) -> Vec<Beam> {
        let (ox, oy) = robot.transform_point(self.mount_offset, 0.0);
        let origin = Point::new(ox, oy);
        (0..self.beams)
            .map(|i| {
                let angle = self.beam_angle(i);
                match world.ray_cast(&origin, robot.theta + angle) {
                    Some(d) if d <= self.max_range => Beam {
                        angle,
                        range: (d + gaussian(rng, self.noise_sigma))
                            .clamp(self.min_range, self.max_range),
                        hit: true,
                    },
                    _ => Beam {
                        angle,
                        range: self.max_range,
                        hit: false,
                    },
                }
            })
            .collect()
    }
}

/// Contact state of the front and rear bumpers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BumperState {
    pub front: bool,
    pub rear: bool,
}

/// Bumpers on a round body: a wall closer than `body_radius + margin` ahead of (behind) the
/// centre presses the front (rear) bumper.
#[must_use]
pub fn bumpers(world: &World, robot: &Pose2, body_radius: f64, margin: f64) -> BumperState {
    let c = Point::new(robot.x, robot.y);
    let mut state = BumperState::default();
    for w in &world.walls {
        if w.distance_to_point(&c) <= body_radius + margin {
            let p = w.closest_point(&c);
            let rel = angle_diff((p.y - c.y).atan2(p.x - c.x), robot.theta);
            if rel.abs() <= std::f64::consts::FRAC_PI_2 {
                state.front = true;
            } else {
                state.rear = true;
            }
        }
    }
    state
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use std::path::Path;

    fn room() -> World {
        World::from_toml_str("[area]\nmin=[0.0,0.0]\nmax=[4.0,3.0]\n", Path::new("room")).unwrap()
    }

    #[test]
    fn noiseless_scan_matches_known_walls() {
        let s = RangeScanner {
            noise_sigma: 0.0,
            beams: 241,
            ..RangeScanner::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let scan = s.scan(&room(), &Pose2::new(1.0, 1.0, 0.0), &mut rng);
        let centre = &scan[120];
        assert!(centre.angle.abs() < 1e-12 && (centre.range - 3.0).abs() < 1e-12 && centre.hit);
        // 90° left: wall y = 3 is 2 m away; 90° right: wall y = 0 is 1 m away.
        let left = scan
            .iter()
            .find(|b| (b.angle - std::f64::consts::FRAC_PI_2).abs() < 1e-9)
            .unwrap();
        let right = scan
            .iter()
            .find(|b| (b.angle + std::f64::consts::FRAC_PI_2).abs() < 1e-9)
            .unwrap();
        assert!((left.range - 2.0).abs() < 1e-9 && (right.range - 1.0).abs() < 1e-9);
        // 45° left: hits y = 3 at x = 3 → 2√2.
        let diag = scan
            .iter()
            .find(|b| (b.angle - std::f64::consts::FRAC_PI_4).abs() < 1e-9)
            .unwrap();
        assert!((diag.range - 2.0 * 2f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn out_of_range_beams_report_max() {
        let s = RangeScanner {
            noise_sigma: 0.0,
            max_range: 2.5,
            beams: 3,
            fov_deg: 180.0,
            ..RangeScanner::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let scan = s.scan(&room(), &Pose2::new(1.0, 1.0, 0.0), &mut rng);
        assert!(!scan[1].hit && (scan[1].range - 2.5).abs() < 1e-12);
        assert!(scan[0].hit && (scan[0].range - 1.0).abs() < 1e-12);
    }

    #[test]
    fn noisy_scan_is_seeded_and_spread_as_configured() {
        let s = RangeScanner::default();
        let a = s.scan(
            &room(),
            &Pose2::new(2.0, 1.5, 0.3),
            &mut ChaCha8Rng::seed_from_u64(4),
        );
        let b = s.scan(
            &room(),
            &Pose2::new(2.0, 1.5, 0.3),
            &mut ChaCha8Rng::seed_from_u64(4),
        );
        assert_eq!(a, b);
        let clean = RangeScanner {
            noise_sigma: 0.0,
            ..s
        }
        .scan(
            &room(),
            &Pose2::new(2.0, 1.5, 0.3),
            &mut ChaCha8Rng::seed_from_u64(4),
        );
        let var = a
            .iter()
            .zip(&clean)
            .map(|(n, c)| (n.range - c.range).powi(2))
            .sum::<f64>()
            / a.len() as f64;
        assert!((var.sqrt() - 0.01).abs() < 0.002, "{}", var.sqrt());
    }

    #[test]
    fn bumpers_front_and_rear() {
        let w = room();
        assert_eq!(
            bumpers(&w, &Pose2::new(3.79, 1.5, 0.0), 0.2, 0.02),
            BumperState {
                front: true,
                rear: false
            }
        );
        assert_eq!(
            bumpers(&w, &Pose2::new(3.79, 1.5, std::f64::consts::PI), 0.2, 0.02),
            BumperState {
                front: false,
                rear: true
            }
        );
        assert_eq!(
            bumpers(&w, &Pose2::new(2.0, 1.5, 0.0), 0.2, 0.02),
            BumperState::default()
        );
    }
}
