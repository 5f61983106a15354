//! The first SIP's XPOS/YPOS is a signed 15-bit position: a robot that backed off before the
//! client connected starts at a small negative x, not 32.7 m away; later SIPs are wrapped
//! increments.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use proptest::prelude::*;
use rfloc_aria::{ConversionFactors, FrameDecoder, MotorSip, OdometryTracker, ServerPacket};

/// docs/protocols/pioneer-aria.md Example G with XPOS `F5 7F` (0x7FF5 = −11 mm in 15 bits),
/// YPOS 0 and THPOS 0; the check sum recomputed for the changed bytes.
const FIRST_SIP_X_MINUS_11MM: [u8; 43] = [
    0xFA, 0xFB, 0x28, 0x33, 0xF5, 0x7F, 0x00, 0x00, 0x00, 0x00, 0xC8, 0x00, 0xC8, 0x00, 0x7D, 0x00,
    0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x02, 0x00, 0x88, 0x13, 0x01, 0xB0, 0x04, 0x00, 0x00, 0x00,
    0xFF, 0x00, 0x7D, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x7B, 0x0D,
];

fn decode_sips(bytes: &[u8]) -> Vec<MotorSip> {
    let mut d = FrameDecoder::new();
    d.push(bytes);
    let mut out = Vec::new();
    while let Some(f) = d.next_frame() {
        if let ServerPacket::Motor(sip) = ServerPacket::from_frame(f.unwrap()).unwrap() {
            out.push(sip);
        }
    }
    out
}

/// The wire bytes of a SIP at `x_mm` (wrapped into 15 bits as the robot does), y = 0.
fn sip_bytes_at(template: &MotorSip, x_mm: i64) -> Vec<u8> {
    let mut s = template.clone();
    s.x_raw = u16::try_from(x_mm.rem_euclid(0x8000)).unwrap();
    s.to_frame().encode().unwrap()
}

#[test]
fn first_sip_behind_the_origin_reads_negative() {
    let sips = decode_sips(&FIRST_SIP_X_MINUS_11MM);
    assert_eq!(sips.len(), 1);
    assert_eq!(sips[0].x_raw, 0x7FF5);
    let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
    let s = t.update(&sips[0]);
    assert!((s.pose.x - -0.011).abs() < 1e-12, "x = {} m", s.pose.x);
    assert_eq!(s.pose.y, 0.0);
}

#[test]
fn drive_from_minus_11mm_through_both_wraps() {
    // Forward at 200 mm per SIP from −11 mm to 40 m: the raw counter wraps at 0x7FFF → 0 right
    // away and again at 32.768 m; the odometry follows the distance driven.
    let template = decode_sips(&FIRST_SIP_X_MINUS_11MM).remove(0);
    let mut wire = Vec::new();
    let mut x = -11_i64;
    let mut expected = Vec::new();
    while x <= 40_000 {
        wire.extend(sip_bytes_at(&template, x));
        expected.push(x);
        x += 200;
    }
    let sips = decode_sips(&wire);
    assert_eq!(sips.len(), expected.len());
    let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
    for (sip, x_mm) in sips.iter().zip(&expected) {
        let s = t.update(sip);
        assert!(
            (s.pose.x * 1000.0 - *x_mm as f64).abs() < 1e-6,
            "expected {x_mm} mm, got {} m",
            s.pose.x
        );
    }
}

proptest! {
    /// Any start within ±16.383 m and any walk of steps below the 4096-unit wrap rule is
    /// followed exactly.
    #[test]
    fn signed_start_and_wrapped_steps(
        start in -0x3FFF_i64..=0x3FFF,
        steps in proptest::collection::vec(-4000_i64..=4000, 1..60),
    ) {
        let template = decode_sips(&FIRST_SIP_X_MINUS_11MM).remove(0);
        let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
        let mut x = start;
        let first = t.update(&decode_sips(&sip_bytes_at(&template, x)).remove(0));
        prop_assert!((first.pose.x * 1000.0 - x as f64).abs() < 1e-6);
        for d in steps {
            x += d;
            let s = t.update(&decode_sips(&sip_bytes_at(&template, x)).remove(0));
            prop_assert!((s.pose.x * 1000.0 - x as f64).abs() < 1e-6);
        }
    }
}
