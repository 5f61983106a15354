//! The Pioneer's sonar ring: where each disc sits on the body, and the latest range of each as
//! the SIPs report them (a few discs per SIP, the ring in turn).
//!
//! Disc geometry of a P3-DX (ARIA's `p3dx` robot parameters, `SonarUnit` lines: x, y in mm
//! from the centre of rotation, heading in degrees, counter-clockwise): eight front discs at
//! 90, 50, 30, 10, −10, −30, −50, −90° and eight rear discs mirrored, each seeing a cone of
//! about 15° out to about 5 m.

use rfloc_pose::Pose2;

use crate::odometry::ConversionFactors;
use crate::sip::MotorSip;

/// One sonar disc on the body: its position (metres, robot frame) and heading (radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarDisc {
    pub x_m: f64,
    pub y_m: f64,
    pub heading_rad: f64,
}

impl SonarDisc {
    /// The disc's pose in the robot frame.
    #[must_use]
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.x_m, self.y_m, self.heading_rad)
    }

    /// The echo point of a range `range_m`, in the robot frame.
    #[must_use]
    pub fn echo_point(&self, range_m: f64) -> (f64, f64) {
        (
            self.x_m + range_m * self.heading_rad.cos(),
            self.y_m + range_m * self.heading_rad.sin(),
        )
    }
}

/// `SonarUnit` x (mm), y (mm), heading (degrees) of a P3-DX, disc 0 to 15.
const P3DX_UNITS: [(i16, i16, i16); 16] = [
    (69, 136, 90),
    (114, 119, 50),
    (148, 78, 30),
    (166, 27, 10),
    (166, -27, -10),
    (148, -78, -30),
    (114, -119, -50),
    (69, -136, -90),
    (-157, -136, -90),
    (-203, -119, -130),
    (-237, -78, -150),
    (-255, -27, -170),
    (-255, 27, 170),
    (-237, 78, 150),
    (-203, 119, 130),
    (-157, 136, 90),
];

/// The sixteen discs of a P3-DX, numbered as the SIPs number them.
#[must_use]
pub fn p3dx_discs() -> [SonarDisc; 16] {
    P3DX_UNITS.map(|(x, y, deg)| SonarDisc {
        x_m: f64::from(x) / 1000.0,
        y_m: f64::from(y) / 1000.0,
        heading_rad: f64::from(deg).to_radians(),
    })
}

/// Ranges at or above this are "no echo" (the discs reach about 5 m).
pub const NO_ECHO_M: f64 = 5.0;

/// The latest range of every disc of a P3-DX ring (its sixteen front and rear discs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarRing {
    /// Latest range of each disc, metres, by disc number (the discs are the P3-DX's).
    ranges: [Option<f64>; 16],
    /// Discs the last [`SonarRing::update`] set (bit per disc number).
    pub updated: u16,
    /// Readings for disc numbers the ring does not have (counted, not stored).
    pub unknown_discs: u64,
}

impl Default for SonarRing {
    fn default() -> Self {
        Self::p3dx()
    }
}

impl SonarRing {
    /// A P3-DX ring with no readings yet.
    #[must_use]
    pub fn p3dx() -> Self {
        Self {
            ranges: [None; 16],
            updated: 0,
            unknown_discs: 0,
        }
    }

    /// Takes the sonar readings of one SIP (raw units × `factors.range_conv` = mm); true when
    /// any disc was updated.
    pub fn update(&mut self, sip: &MotorSip, factors: &ConversionFactors) -> bool {
        self.updated = 0;
        for r in &sip.sonar {
            match self.ranges.get_mut(usize::from(r.number)) {
                Some(slot) => {
                    *slot = Some(f64::from(r.range) * factors.range_conv / 1000.0);
                    self.updated |= 1 << r.number;
                }
                None => self.unknown_discs += 1,
            }
        }
        self.updated != 0
    }

    /// Each disc with a reading: the disc and its latest range, metres.
    pub fn readings(&self) -> impl Iterator<Item = (SonarDisc, f64)> + '_ {
        p3dx_discs()
            .into_iter()
            .zip(&self.ranges)
            .filter_map(|(d, r)| r.map(|r| (d, r)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sip::SonarReading;

    #[test]
    fn the_ring_is_symmetric_front_to_back_and_left_to_right() {
        let d = p3dx_discs();
        for i in 0..8 {
            // Front disc i and its left/right mirror 7 − i.
            let (a, b) = (d[i], d[7 - i]);
            assert!((a.x_m - b.x_m).abs() < 1e-12 && (a.y_m + b.y_m).abs() < 1e-12);
            assert!((a.heading_rad + b.heading_rad).abs() < 1e-12);
            assert!(a.x_m > 0.0 && d[8 + i].x_m < 0.0, "front then rear");
        }
        assert!((d[3].heading_rad - 10f64.to_radians()).abs() < 1e-12);
        let (x, y) = d[0].echo_point(1.0);
        assert!((x - 0.069).abs() < 1e-9 && (y - 1.136).abs() < 1e-9);
    }

    #[test]
    fn readings_are_kept_per_disc_and_unknown_discs_counted() {
        let mut ring = SonarRing::p3dx();
        let mut sip = MotorSip {
            sonar: vec![
                SonarReading {
                    number: 3,
                    range: 1200,
                },
                SonarReading {
                    number: 20,
                    range: 500,
                },
            ],
            ..MotorSip::default()
        };
        assert!(ring.update(&sip, &ConversionFactors::P3DX_SH));
        let got: Vec<(f64, f64)> = ring.readings().map(|(d, r)| (d.heading_rad, r)).collect();
        assert_eq!(got.len(), 1);
        assert_eq!(ring.updated, 1 << 3);
        assert!((got[0].1 - 1.2).abs() < 1e-12);
        assert_eq!(ring.unknown_discs, 1);
        sip.sonar.clear();
        assert!(!ring.update(&sip, &ConversionFactors::P3DX_SH));
        assert_eq!(
            (ring.updated, ring.readings().count()),
            (0, 1),
            "kept, not updated"
        );
    }
}
