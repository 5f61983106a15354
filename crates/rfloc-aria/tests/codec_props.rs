//! Property tests of the codec: encode → decode round trips and resynchronisation.

use proptest::prelude::*;
use rfloc_aria::{
    Command, CommandLimits, Frame, FrameDecoder, LinkPhase, MotorSip, ServerPacket, SipTail,
    SonarReading, StallBumpers,
};

fn open_command() -> impl Strategy<Value = Command> {
    prop_oneof![
        Just(Command::Pulse),
        Just(Command::Open),
        Just(Command::Close),
        any::<bool>().prop_map(Command::Enable),
        (-2200i16..=2200).prop_map(Command::Vel),
        (-500i16..=500).prop_map(Command::Rvel),
        (any::<i8>(), any::<i8>()).prop_map(|(left, right)| Command::Vel2 { left, right }),
        (0i16..360).prop_map(Command::Head),
        (-i16::MAX..=i16::MAX).prop_map(Command::Dhead),
        (0i16..=2200).prop_map(Command::SetV),
        (0i16..=500).prop_map(Command::SetRv),
        (-i16::MAX..=i16::MAX).prop_map(Command::SetA),
        (-i16::MAX..=i16::MAX).prop_map(Command::SetRa),
        Just(Command::Stop),
        Just(Command::EStop),
        any::<bool>().prop_map(Command::Sonar),
        Just(Command::SetO),
        Just(Command::Config),
    ]
}

fn motor_sip() -> impl Strategy<Value = MotorSip> {
    let head = (
        any::<bool>(),
        any::<u16>(),
        any::<u16>(),
        any::<i16>(),
        any::<i16>(),
        any::<i16>(),
        any::<u8>(),
        any::<u16>(),
        any::<i16>(),
        any::<u16>(),
        any::<u8>(),
    );
    let sonar = proptest::collection::vec(
        (any::<u8>(), any::<u16>()).prop_map(|(number, range)| SonarReading { number, range }),
        0..20,
    );
    let io = any::<[u8; 5]>();
    let tail = (
        0usize..=4,
        any::<u16>(),
        any::<u8>(),
        any::<i16>(),
        any::<u16>(),
        proptest::collection::vec(any::<u8>(), 0..8),
    )
        .prop_map(|(k, b, c, r, f, rest)| SipTail {
            battery_x10: (k >= 1).then_some(b),
            charge_state: (k >= 2).then_some(c),
            rot_vel: (k >= 3).then_some(r),
            fault_flags: (k >= 4).then_some(f),
            rest: if k == 4 { rest } else { Vec::new() },
        });
    (head, sonar, io, tail).prop_map(|(h, sonar, io, tail)| MotorSip {
        moving: h.0,
        x_raw: h.1,
        y_raw: h.2,
        th_raw: h.3,
        left_vel: h.4,
        right_vel: h.5,
        battery_dv: h.6,
        stall_bumpers: StallBumpers(h.7),
        control: h.8,
        flags: h.9,
        compass: h.10,
        sonar,
        grip_state: io[0],
        an_port: io[1],
        analog: io[2],
        digin: io[3],
        digout: io[4],
        tail,
    })
}

fn decode_all(d: &mut FrameDecoder) -> Vec<Frame> {
    let mut out = Vec::new();
    while let Some(r) = d.next_frame() {
        if let Ok(f) = r {
            out.push(f);
        }
    }
    out
}

proptest! {
    #[test]
    fn command_round_trip(cmd in open_command()) {
        let bytes = cmd.encode(&CommandLimits::P3DX).unwrap();
        let mut d = FrameDecoder::new();
        d.push(&bytes);
        let frames = decode_all(&mut d);
        prop_assert_eq!(frames.len(), 1);
        let back = Command::from_frame(&frames[0], LinkPhase::Open).unwrap();
        prop_assert_eq!(back, cmd);
        prop_assert_eq!(d.dropped_bytes(), 0);
    }

    #[test]
    fn any_i16_velocity_is_clamped_into_limits(v in any::<i16>()) {
        let bytes = Command::Vel(v).encode(&CommandLimits::P3DX).unwrap();
        let mut d = FrameDecoder::new();
        d.push(&bytes);
        let f = decode_all(&mut d).remove(0);
        let Command::Vel(sent) = Command::from_frame(&f, LinkPhase::Open).unwrap() else {
            panic!("not VEL");
        };
        prop_assert!(sent.abs() <= 2200);
        prop_assert_eq!(sent, v.clamp(-2200, 2200));
    }

    #[test]
    fn sip_round_trip(sip in motor_sip()) {
        let bytes = sip.to_frame().encode().unwrap();
        let mut d = FrameDecoder::new();
        d.push(&bytes);
        let frames = decode_all(&mut d);
        prop_assert_eq!(frames.len(), 1);
        let back = ServerPacket::from_frame(frames[0].clone()).unwrap();
        prop_assert_eq!(back, ServerPacket::Motor(sip));
    }

    /// Garbage (without 0xFA, so it cannot fake a header) between frames is dropped, counted, and
    /// every frame is still found, however the stream is split into reads.
    #[test]
    fn resync_after_garbage(
        frames in proptest::collection::vec(
            (any::<u8>(), proptest::collection::vec(any::<u8>(), 0..40))
                .prop_map(|(id, p)| Frame::new(id, p)),
            1..8),
        garbage in proptest::collection::vec(
            proptest::collection::vec(any::<u8>().prop_filter("no header byte", |b| *b != 0xFA), 0..12),
            8),
        split in 1usize..17,
    ) {
        let mut stream = Vec::new();
        let mut garbage_len = 0u64;
        for (f, g) in frames.iter().zip(garbage.iter()) {
            stream.extend_from_slice(g);
            garbage_len += g.len() as u64;
            stream.extend_from_slice(&f.encode().unwrap());
        }
        let mut d = FrameDecoder::new();
        let mut got = Vec::new();
        for chunk in stream.chunks(split) {
            d.push(chunk);
            got.extend(decode_all(&mut d));
        }
        prop_assert_eq!(got, frames);
        prop_assert_eq!(d.dropped_bytes(), garbage_len);
    }

    /// Any byte soup: no panic, and every byte is accounted for (frame, dropped or pending).
    #[test]
    fn arbitrary_bytes_are_accounted_for(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let mut d = FrameDecoder::new();
        d.push(&bytes);
        let frames = decode_all(&mut d);
        let framed: u64 = frames.iter().map(|f| f.payload.len() as u64 + 6).sum();
        prop_assert_eq!(framed + d.dropped_bytes() + d.pending() as u64, bytes.len() as u64);
    }

    /// A corrupted byte in one frame loses at most that frame — when no payload contains the
    /// header bytes `FA FB`. The protocol has no escaping: a corrupted frame whose payload holds
    /// `FA FB n` looks like the start of an n-byte frame and can swallow the frames after it
    /// (they stay pending until enough bytes arrive). That limit is the protocol's, and is
    /// documented in the crate README.
    #[test]
    fn corruption_loses_only_the_hit_frame(
        payloads in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 1..30), 3..6),
        which in 0usize..3,
        pos in 3usize..30,
        flip in 1u8..=255,
    ) {
        prop_assume!(payloads.iter().all(|p| !p.windows(2).any(|w| w == [0xFA, 0xFB])));
        let frames: Vec<Frame> = payloads.into_iter().map(|p| Frame::new(0x32, p)).collect();
        let mut stream = Vec::new();
        let mut start = 0;
        for (i, f) in frames.iter().enumerate() {
            if i == which { start = stream.len(); }
            stream.extend_from_slice(&f.encode().unwrap());
        }
        let len = frames[which].payload.len() + 6;
        let at = start + pos.min(len - 1);
        stream[at] ^= flip;
        let mut d = FrameDecoder::new();
        d.push(&stream);
        let got = decode_all(&mut d);
        for (i, f) in frames.iter().enumerate() {
            if i != which {
                prop_assert!(got.contains(f), "frame {} lost", i);
            }
        }
    }
}
