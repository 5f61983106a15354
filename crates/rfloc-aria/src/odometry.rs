//! Raw SIP fields → continuous odometry in metres and radians (docs §6).

use rfloc_pose::{wrap_angle, Pose2};

use crate::sip::{MotorSip, StallBumpers};

/// Conversion factors for one robot model (docs §6.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConversionFactors {
    /// Millimetres per XPOS/YPOS unit.
    pub dist_conv: f64,
    /// Radians per THPOS unit.
    pub angle_conv: f64,
    /// mm/s per wheel velocity unit.
    pub vel_conv: f64,
    /// rad/s per unit of (R − L)/2, used when the SIP has no ROTVEL field.
    pub diff_conv: f64,
    /// mm/s per VEL2 byte unit.
    pub vel2_divisor: f64,
    /// mm per sonar range unit.
    pub range_conv: f64,
}

impl ConversionFactors {
    /// `p3dx-sh` (ARCOS, SH controller): DistConvFactor 1.0.
    pub const P3DX_SH: ConversionFactors = ConversionFactors {
        dist_conv: 1.0,
        angle_conv: 0.001534,
        vel_conv: 1.0,
        diff_conv: 0.0056,
        vel2_divisor: 20.0,
        range_conv: 1.0,
    };
    /// `p3dx` (older H8 controller and MobileSim's default model): DistConvFactor 0.485.
    pub const P3DX: ConversionFactors = ConversionFactors {
        dist_conv: 0.485,
        ..Self::P3DX_SH
    };

    /// The factors for a SYNC2 subclass string, chosen as ARIA does (case-insensitive):
    /// `p3dx` → 0.485 mm/unit, anything else → the SH factors.
    #[must_use]
    pub fn for_subclass(subclass: &str) -> Self {
        if subclass.eq_ignore_ascii_case("p3dx") {
            Self::P3DX
        } else {
            if !subclass.eq_ignore_ascii_case("p3dx-sh") {
                tracing::warn!(
                    subclass,
                    "unknown ARIA robot subclass, using p3dx-sh factors"
                );
            }
            Self::P3DX_SH
        }
    }
}

impl Default for ConversionFactors {
    fn default() -> Self {
        Self::P3DX_SH
    }
}

/// Largest XPOS/YPOS change per SIP treated as real motion; larger jumps are a 15-bit wrap
/// (ARIA's 0x1000 rule, docs §6.3).
const WRAP_THRESHOLD: i32 = 0x1000;
/// XPOS/YPOS period.
const WRAP_PERIOD: i32 = 0x8000;

/// One odometry sample derived from a motor SIP.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometrySample {
    /// Pose in metres and radians in the client's odometry frame.
    pub pose: Pose2,
    /// Forward velocity, m/s.
    pub v: f64,
    /// Rotational velocity, rad/s (counter-clockwise positive).
    pub w: f64,
    /// Stall and bumper bits.
    pub stall_bumpers: StallBumpers,
    /// Battery voltage, volts.
    pub battery_v: f64,
    /// Motors enabled flag.
    pub motors_enabled: bool,
}

/// Turns the 15-bit XPOS/YPOS counters into continuous odometry.
///
/// The robot's own frame (its XPOS/YPOS/THPOS) is tracked as an unwrapped "encoder pose"; the
/// published pose is `transform ⊕ encoder pose`. The transform is the identity at start and after
/// [`OdometryTracker::reset_origin`]; after [`OdometryTracker::rebase`] (a reconnect) it is chosen
/// so the published pose continues where it stopped, whatever the robot reports then.
#[derive(Debug, Clone)]
pub struct OdometryTracker {
    factors: ConversionFactors,
    last_raw: Option<(i32, i32)>,
    enc_x: i64,
    enc_y: i64,
    transform: Pose2,
    continue_from: Option<Pose2>,
    last_pose: Pose2,
}

impl OdometryTracker {
    /// A tracker whose first SIP defines the pose (as ARIA does: the robot's reported position).
    #[must_use]
    pub fn new(factors: ConversionFactors) -> Self {
        Self {
            factors,
            last_raw: None,
            enc_x: 0,
            enc_y: 0,
            transform: Pose2::default(),
            continue_from: None,
            last_pose: Pose2::default(),
        }
    }

    /// The conversion factors in use.
    #[must_use]
    pub fn factors(&self) -> ConversionFactors {
        self.factors
    }

    /// Changes the conversion factors (after a new SYNC2 reply) and rebases.
    pub fn set_factors(&mut self, factors: ConversionFactors) {
        self.factors = factors;
        self.rebase();
    }

    /// The last published pose.
    #[must_use]
    pub fn pose(&self) -> Pose2 {
        self.last_pose
    }

    /// Forget the robot's counters but keep the published pose continuous: the next SIP is
    /// mapped onto the last pose (used after a reconnect).
    pub fn rebase(&mut self) {
        if self.last_raw.is_some() || self.continue_from.is_some() {
            self.continue_from = Some(self.last_pose);
        }
        self.last_raw = None;
    }

    /// After SETO: the robot's origin is reset and so is the published pose.
    pub fn reset_origin(&mut self) {
        self.last_raw = None;
        self.continue_from = None;
        self.transform = Pose2::default();
        self.last_pose = Pose2::default();
    }

    fn encoder_pose(&self, th_raw: i16) -> Pose2 {
        Pose2::new(
            self.enc_x as f64 * self.factors.dist_conv / 1000.0,
            self.enc_y as f64 * self.factors.dist_conv / 1000.0,
            wrap_angle(f64::from(th_raw) * self.factors.angle_conv),
        )
    }

    /// Consumes one motor SIP.
    pub fn update(&mut self, sip: &MotorSip) -> OdometrySample {
        let x = i32::from(sip.x_raw & 0x7FFF);
        let y = i32::from(sip.y_raw & 0x7FFF);
        match self.last_raw {
            None => {
                // The counters start at the robot's origin: a robot that backed off before the
                // first SIP reports e.g. 0x7FF5, which is −11 units, not +32757.
                self.enc_x = i64::from(signed15(x));
                self.enc_y = i64::from(signed15(y));
            }
            Some((lx, ly)) => {
                self.enc_x += i64::from(unwrap_delta(x - lx));
                self.enc_y += i64::from(unwrap_delta(y - ly));
            }
        }
        self.last_raw = Some((x, y));
        let enc = self.encoder_pose(sip.th_raw);
        if let Some(target) = self.continue_from.take() {
            // transform ⊕ enc = target  ⇒  transform = target ⊕ enc⁻¹
            let enc_inv = Pose2::default().relative_to(&enc);
            self.transform = target.compose(&enc_inv);
        }
        let pose = self.transform.compose(&enc);
        self.last_pose = pose;
        let f = &self.factors;
        let left = f64::from(sip.left_vel) * f.vel_conv;
        let right = f64::from(sip.right_vel) * f.vel_conv;
        let w = match sip.tail.rot_vel {
            Some(rv) => (f64::from(rv) / 10.0).to_radians(),
            None => (right - left) / 2.0 * f.diff_conv,
        };
        let battery_v = match sip.tail.battery_x10 {
            Some(b) => f64::from(b) / 10.0,
            None => f64::from(sip.battery_dv) / 10.0,
        };
        OdometrySample {
            pose,
            v: (left + right) / 2.0 / 1000.0,
            w,
            stall_bumpers: sip.stall_bumpers,
            battery_v,
            motors_enabled: sip.motors_enabled(),
        }
    }
}

/// A 15-bit XPOS/YPOS counter read as a signed (two's complement) 15-bit position: 0x4000 and
/// above are negative (0x7FFF = −1).
#[must_use]
pub fn signed15(raw: i32) -> i32 {
    let v = raw & 0x7FFF;
    if v >= 0x4000 {
        v - WRAP_PERIOD
    } else {
        v
    }
}

/// A 15-bit counter difference mapped to the motion it stands for (ARIA's rule, docs §6.3).
#[must_use]
pub fn unwrap_delta(d: i32) -> i32 {
    if d > WRAP_THRESHOLD {
        d - WRAP_PERIOD
    } else if d < -WRAP_THRESHOLD {
        d + WRAP_PERIOD
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sip::SipTail;

    fn sip(x: u16, y: u16, th: i16) -> MotorSip {
        MotorSip {
            moving: false,
            x_raw: x,
            y_raw: y,
            th_raw: th,
            left_vel: 100,
            right_vel: 300,
            battery_dv: 125,
            stall_bumpers: StallBumpers(0),
            control: 0,
            flags: 1,
            compass: 0,
            sonar: vec![],
            grip_state: 0,
            an_port: 0,
            analog: 0,
            digin: 0,
            digout: 0,
            tail: SipTail::default(),
        }
    }

    #[test]
    fn wrap_example_from_reference() {
        // docs §8 Example G: lastX = 32700, x = 100 → qx = 168 units.
        assert_eq!(unwrap_delta(100 - 32700), 168);
        assert_eq!(unwrap_delta(32700 - 100), -168);
        assert_eq!(unwrap_delta(4096), 4096);
    }

    #[test]
    fn crossing_the_wrap_is_continuous() {
        let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
        let a = t.update(&sip(32700, 0, 0));
        let b = t.update(&sip(100, 0, 0));
        assert!((b.pose.x - a.pose.x - 0.168).abs() < 1e-12);
        // High bit is ignored (15-bit field).
        let c = t.update(&sip(0x8000 | 150, 0, 0));
        assert!((c.pose.x - b.pose.x - 0.050).abs() < 1e-12);
    }

    #[test]
    fn conversions_use_factors() {
        let mut t = OdometryTracker::new(ConversionFactors::for_subclass("P3DX"));
        let s = t.update(&sip(1000, 2000, 1024));
        assert!((s.pose.x - 0.485).abs() < 1e-12);
        assert!((s.pose.y - 0.970).abs() < 1e-12);
        assert!((s.pose.theta - 1024.0 * 0.001534).abs() < 1e-12);
        assert!((s.v - 0.2).abs() < 1e-12);
        // No ROTVEL: (R − L)/2 · DiffConv = 100 · 0.0056.
        assert!((s.w - 0.56).abs() < 1e-12);
        assert!((s.battery_v - 12.5).abs() < 1e-12);
    }

    #[test]
    fn rebase_keeps_pose_continuous() {
        let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
        t.update(&sip(1000, 0, 0));
        let before = t.update(&sip(1500, 0, 1024)).pose;
        t.rebase();
        // The robot restarted from zero.
        let after = t.update(&sip(0, 0, 0)).pose;
        assert!(after.distance(&before) < 1e-12);
        assert!((after.theta - before.theta).abs() < 1e-12);
        // Moving "forward" in the robot's new frame moves along the old heading (≈ +y).
        let moved = t.update(&sip(100, 0, 0)).pose;
        assert!((moved.y - before.y - 0.1).abs() < 1e-3);
        assert!((moved.x - before.x).abs() < 1e-3);
    }

    #[test]
    fn first_position_is_a_signed_15_bit_value() {
        assert_eq!(signed15(0x7FF5), -11);
        assert_eq!(signed15(0x3FFF), 0x3FFF);
        assert_eq!(signed15(0x4000), -0x4000);
        assert_eq!(signed15(0x8000 | 5), 5);
        // XPOS bytes F5 7F (the robot backed off 11 mm before the first SIP), YPOS 0C 00.
        let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
        let first = t.update(&sip(
            u16::from_le_bytes([0xF5, 0x7F]),
            u16::from_le_bytes([0x0C, 0x00]),
            0,
        ));
        assert!((first.pose.x + 0.011).abs() < 1e-12, "x = {}", first.pose.x);
        assert!((first.pose.y - 0.012).abs() < 1e-12);
        // Forward through zero and on: increments, not absolute values.
        let next = t.update(&sip(0x0005, 0x000C, 0));
        assert!((next.pose.x - 0.005).abs() < 1e-12);
    }

    #[test]
    fn reset_origin_starts_from_robot_report() {
        let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
        t.update(&sip(1000, 0, 0));
        t.reset_origin();
        let s = t.update(&sip(0, 0, 0));
        assert_eq!(s.pose, Pose2::default());
    }
}
