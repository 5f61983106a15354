//! Throughput of the frame codec: decoding and encoding escaped `ND` responses.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use rfloc_xbee::{
    Address16, Address64, ApiMode, AtCommandName, AtResponse, DeviceType, Frame, FrameDecoder,
    NdLayout, NdLayoutHint, Node,
};

fn nd_response(k: u64) -> Frame {
    let node = Node {
        layout: NdLayout::ZigbeeOrDigiMesh,
        network_address: Address16(0x1234),
        address: Address64(0x0013_A200_407D_1100 + k),
        ni: format!("beacon{k}"),
        parent: Some(Address16::UNKNOWN),
        device_type: Some(DeviceType::Router),
        status: Some(0),
        profile_id: Some(0xC105),
        manufacturer_id: Some(0x101E),
        digi_device_type: None,
        rssi_raw: Some(0x38),
    };
    Frame::AtResponse(AtResponse {
        frame_id: 1,
        command: AtCommandName::ND,
        status_byte: 0,
        data: node.to_record(),
    })
}

fn codec(c: &mut Criterion) {
    let frames: Vec<Frame> = (0..1000).map(nd_response).collect();
    let mut group = c.benchmark_group("codec");
    for mode in [ApiMode::Unescaped, ApiMode::Escaped] {
        let wire: Vec<u8> = frames
            .iter()
            .flat_map(|f| f.encode(mode).unwrap())
            .collect();
        group.throughput(Throughput::Bytes(wire.len() as u64));
        group.bench_with_input(
            BenchmarkId::new("decode_parse", format!("{mode:?}")),
            &wire,
            |b, wire| {
                b.iter(|| {
                    let mut decoder = FrameDecoder::new(mode);
                    let mut nodes = 0;
                    for chunk in wire.chunks(64) {
                        decoder.push(chunk);
                        while let Some(Ok(data)) = decoder.next_frame() {
                            if let Ok(Frame::AtResponse(r)) = Frame::parse(&data) {
                                nodes +=
                                    usize::from(Node::parse(&r.data, NdLayoutHint::Auto).is_ok());
                            }
                        }
                    }
                    assert_eq!(nodes, 1000);
                });
            },
        );
        group.bench_with_input(
            BenchmarkId::new("encode", format!("{mode:?}")),
            &frames,
            |b, frames| {
                b.iter(|| {
                    frames
                        .iter()
                        .map(|f| f.encode(mode).unwrap().len())
                        .sum::<usize>()
                });
            },
        );
    }
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
