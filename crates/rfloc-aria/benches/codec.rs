//! Throughput of the SIP path: framing + motor SIP parsing + odometry update, and command
//! encoding.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rfloc_aria::{
    Command, CommandLimits, ConversionFactors, FrameDecoder, MotorSip, OdometryTracker,
    ServerPacket, SipTail, SonarReading, StallBumpers,
};

fn sip(k: u16) -> Vec<u8> {
    MotorSip {
        moving: true,
        x_raw: k.wrapping_mul(37) & 0x7FFF,
        y_raw: k.wrapping_mul(11) & 0x7FFF,
        th_raw: (k % 4096) as i16 - 2048,
        left_vel: 200,
        right_vel: 220,
        battery_dv: 125,
        stall_bumpers: StallBumpers(0),
        control: 0,
        flags: 0x1F,
        compass: 0,
        sonar: (0..4)
            .map(|n| SonarReading {
                number: n,
                range: 5000,
            })
            .collect(),
        grip_state: 0,
        an_port: 0,
        analog: 0,
        digin: 0,
        digout: 0,
        tail: SipTail {
            battery_x10: Some(125),
            charge_state: Some(0),
            rot_vel: Some(30),
            fault_flags: Some(0),
            rest: vec![],
        },
    }
    .to_frame()
    .encode()
    .unwrap()
}

fn bench(c: &mut Criterion) {
    let stream: Vec<u8> = (0..1000).flat_map(sip).collect();
    let mut g = c.benchmark_group("aria");
    g.throughput(Throughput::Bytes(stream.len() as u64));
    g.bench_function("decode_1000_sips_to_odometry", |b| {
        b.iter(|| {
            let mut d = FrameDecoder::new();
            let mut t = OdometryTracker::new(ConversionFactors::P3DX_SH);
            let mut n = 0u32;
            for chunk in stream.chunks(64) {
                d.push(chunk);
                while let Some(Ok(f)) = d.next_frame() {
                    if let Ok(ServerPacket::Motor(s)) = ServerPacket::from_frame(f) {
                        std::hint::black_box(t.update(&s));
                        n += 1;
                    }
                }
            }
            assert_eq!(n, 1000);
        });
    });
    g.throughput(Throughput::Elements(1));
    g.bench_function("encode_vel", |b| {
        b.iter(|| {
            std::hint::black_box(
                Command::Vel(std::hint::black_box(1234)).encode(&CommandLimits::P3DX),
            )
        });
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
