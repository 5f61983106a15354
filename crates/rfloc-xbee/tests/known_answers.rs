//! Known-answer tests: byte literals from the project's XBee API reference (cited by section;
//! see `docs/protocols/xbee-api.md`) decoded, parsed and re-encoded.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
use rfloc_xbee::{
    Address16, Address64, ApiMode, AtCommandName, AtStatus, DeviceType, Frame, FrameDecoder,
    NdLayout, NdLayoutHint, Node,
};

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

/// Decodes exactly one frame from `wire`, checks it re-encodes to `wire`, returns it.
fn one_frame(wire: &str, mode: ApiMode) -> Frame {
    let wire = hex(wire);
    let mut decoder = FrameDecoder::new(mode);
    decoder.push(&wire);
    let data = decoder
        .next_frame()
        .expect("a frame")
        .expect("a valid frame");
    assert!(decoder.next_frame().is_none());
    assert_eq!(decoder.stats().dropped_bytes, 0);
    let frame = Frame::parse(&data).unwrap();
    assert_eq!(frame.encode(mode).unwrap(), wire, "re-encoding differs");
    frame
}

// §3 0x08 and §8 example 1 (Digi 90000976_K p.100): ND with frame ID 1.
#[test]
fn at_command_nd() {
    let Frame::AtCommand(c) = one_frame("7E 00 04 08 01 4E 44 64", ApiMode::Unescaped) else {
        panic!("not an AT command")
    };
    assert_eq!(
        (c.frame_id, c.command, c.queued),
        (1, AtCommandName::ND, false)
    );
    assert!(c.parameter.is_empty());
    // §8 example 1: no special byte, AP=2 form identical.
    one_frame("7E 00 04 08 01 4E 44 64", ApiMode::Escaped);
}

// §3 0x08 (p.103): NJ query with frame ID 0x52.
#[test]
fn at_command_nj() {
    let Frame::AtCommand(c) = one_frame("7E 00 04 08 52 4E 4A 0D", ApiMode::Unescaped) else {
        panic!("not an AT command")
    };
    assert_eq!((c.frame_id, c.command), (0x52, AtCommandName(*b"NJ")));
}

// §3 0x09 (p.103): queue BD=7.
#[test]
fn at_command_queued_bd() {
    let Frame::AtCommand(c) = one_frame("7E 00 05 09 01 42 44 07 68", ApiMode::Unescaped) else {
        panic!("not an AT command")
    };
    assert!(c.queued);
    assert_eq!(
        (c.frame_id, c.command, c.parameter),
        (1, AtCommandName(*b"BD"), vec![7])
    );
}

// §3 0x17 (p.108): remote BH=1 with apply changes; and (p.100) D1=3 to the coordinator.
#[test]
fn remote_at_command() {
    let Frame::RemoteAtCommand(c) = one_frame(
        "7E 00 10 17 01 00 13 A2 00 40 40 11 22 FF FE 02 42 48 01 F5",
        ApiMode::Unescaped,
    ) else {
        panic!("not a remote AT command")
    };
    assert_eq!(c.destination, Address64(0x0013_A200_4040_1122));
    assert_eq!((c.destination16, c.options), (Address16(0xFFFE), 0x02));
    assert_eq!((c.command, c.parameter), (AtCommandName(*b"BH"), vec![1]));

    let Frame::RemoteAtCommand(c) = one_frame(
        "7E 00 10 17 01 00 00 00 00 00 00 00 00 FF FE 02 44 31 03 70",
        ApiMode::Unescaped,
    ) else {
        panic!("not a remote AT command")
    };
    assert_eq!(c.destination, Address64::COORDINATOR);
    assert_eq!((c.command, c.parameter), (AtCommandName(*b"D1"), vec![3]));
}

// §6: remote DB request and response (derived in the reference, verified there with digi-xbee).
#[test]
fn remote_db_request_and_response() {
    let Frame::RemoteAtCommand(c) = one_frame(
        "7E 00 0F 17 02 00 13 A2 00 40 A1 B2 C3 FF FE 00 44 42 58",
        ApiMode::Unescaped,
    ) else {
        panic!("not a remote AT command")
    };
    assert_eq!((c.frame_id, c.command), (2, AtCommandName::DB));
    let Frame::RemoteAtResponse(r) = one_frame(
        "7E 00 10 97 02 00 13 A2 00 40 A1 B2 C3 12 34 44 42 00 50 3F",
        ApiMode::Unescaped,
    ) else {
        panic!("not a remote AT response")
    };
    assert_eq!(
        (r.source, r.source16),
        (Address64(0x0013_A200_40A1_B2C3), Address16(0x1234))
    );
    assert_eq!((r.status(), r.data), (AtStatus::Ok, vec![0x50]));
}

// §3 0x88 (p.110): BD set, OK.
#[test]
fn at_response_bd() {
    let Frame::AtResponse(r) = one_frame("7E 00 05 88 01 42 44 00 F0", ApiMode::Unescaped) else {
        panic!("not an AT response")
    };
    assert_eq!(
        (r.frame_id, r.command, r.status()),
        (1, AtCommandName(*b"BD"), AtStatus::Ok)
    );
    assert!(r.data.is_empty());
}

// §6: local DB query (id 3) and its response with DB = 0x50 (−80 dBm).
#[test]
fn local_db() {
    let Frame::AtCommand(c) = one_frame("7E 00 04 08 03 44 42 6E", ApiMode::Unescaped) else {
        panic!("not an AT command")
    };
    assert_eq!((c.frame_id, c.command), (3, AtCommandName::DB));
    let Frame::AtResponse(r) = one_frame("7E 00 06 88 03 44 42 00 50 9E", ApiMode::Unescaped)
    else {
        panic!("not an AT response")
    };
    assert_eq!(r.data, vec![0x50]);
    assert_eq!(rfloc_xbee::nd::rssi_byte_to_dbm(0x50), -80.0);
}

// §3 0x88 / §7.2: the status byte is read as status & 0x0F (0x45 is "unknown" in digi-xbee).
#[test]
fn at_status_low_nibble() {
    assert_eq!(AtStatus::from_byte(0x45), AtStatus::Other(5));
    assert_eq!(AtStatus::from_byte(0x44), AtStatus::TxFailure);
    assert_eq!(AtStatus::from_byte(0x40), AtStatus::Ok);
    assert_eq!(AtStatus::from_byte(0x0B), AtStatus::NoSecureSession);
}

// §3 0x97 (p.118): SL query response; §8 escaping edge case: its length 0x13 is escaped in AP=2.
#[test]
fn remote_at_response_sl() {
    let wire = "7E 00 13 97 55 00 13 A2 00 40 52 2B AA 7D 84 53 4C 00 40 52 2B AA F0";
    let Frame::RemoteAtResponse(r) = one_frame(wire, ApiMode::Unescaped) else {
        panic!("not a remote AT response")
    };
    assert_eq!(
        (r.frame_id, r.source),
        (0x55, Address64(0x0013_A200_4052_2BAA))
    );
    assert_eq!(
        (r.source16, r.command),
        (Address16(0x7D84), AtCommandName::SL)
    );
    assert_eq!(
        (r.status(), r.data.clone()),
        (AtStatus::Ok, hex("40 52 2B AA"))
    );
    let escaped = Frame::RemoteAtResponse(r).encode(ApiMode::Escaped).unwrap();
    assert_eq!(escaped[..10], hex("7E 00 7D 33 97 55 00 7D 33 A2")[..]);
    assert!(escaped.windows(3).any(|w| w == [0xAA, 0x7D, 0x5D]));
}

// §6: a failed remote DB ends `… 44 42 04 C1` (Digi forum example), status 4.
#[test]
fn remote_db_failure_status() {
    let Frame::RemoteAtResponse(r) =
        Frame::parse(&hex("97 01 00 13 A2 00 40 A1 B2 C3 FF FE 44 42 04")).unwrap()
    else {
        panic!("not a remote AT response")
    };
    assert_eq!(r.status(), AtStatus::TxFailure);
    let wire = Frame::RemoteAtResponse(r)
        .encode(ApiMode::Unescaped)
        .unwrap();
    assert_eq!(
        *wire.last().unwrap(),
        rfloc_xbee::checksum(&wire[3..wire.len() - 1])
    );
}

// §3 0x8A (p.110): coordinator started.
#[test]
fn modem_status() {
    let Frame::ModemStatus(s) = one_frame("7E 00 02 8A 06 6F", ApiMode::Unescaped) else {
        panic!("not a modem status")
    };
    assert_eq!(s.status, 6);
}

// §3 0x10 (p.104) and its AP=2 form (p.105): the checksum 0x13 is escaped.
#[test]
fn transmit_request() {
    let raw = "7E 00 16 10 01 00 13 A2 00 40 0A 01 27 FF FE 00 00 54 78 44 61 74 61 30 41 13";
    let Frame::TransmitRequest(t) = one_frame(raw, ApiMode::Unescaped) else {
        panic!("not a transmit request")
    };
    assert_eq!(
        (t.frame_id, t.destination),
        (1, Address64(0x0013_A200_400A_0127))
    );
    assert_eq!(
        (t.destination16, t.broadcast_radius, t.options),
        (Address16(0xFFFE), 0, 0)
    );
    assert_eq!(t.data, b"TxData0A".to_vec());
    let escaped =
        "7E 00 16 10 01 00 7D 33 A2 00 40 0A 01 27 FF FE 00 00 54 78 44 61 74 61 30 41 7D 33";
    assert_eq!(
        one_frame(escaped, ApiMode::Escaped),
        Frame::TransmitRequest(t)
    );
}

// §3 0x8B (p.111).
#[test]
fn transmit_status() {
    let Frame::TransmitStatus(s) =
        one_frame("7E 00 07 8B 01 7D 84 00 00 01 71", ApiMode::Unescaped)
    else {
        panic!("not a transmit status")
    };
    assert_eq!((s.frame_id, s.destination16), (1, Address16(0x7D84)));
    assert_eq!(
        (s.retry_count, s.delivery_status, s.discovery_status),
        (0, 0, 1)
    );
}

// §3 0x90 (p.112) with the reference's erratum applied (length 0x12, not 0x11).
#[test]
fn receive_packet() {
    let wire = "7E 00 12 90 00 13 A2 00 40 52 2B AA 7D 84 01 52 78 44 61 74 61 0D";
    let Frame::ReceivePacket(r) = one_frame(wire, ApiMode::Unescaped) else {
        panic!("not a receive packet")
    };
    assert_eq!(
        (r.source, r.source16, r.options),
        (Address64(0x0013_A200_4052_2BAA), Address16(0x7D84), 1)
    );
    assert_eq!(r.data, b"RxData".to_vec());
    // The manual's printed length 0x11 does not match its data: the decoder rejects it.
    let mut d = FrameDecoder::new(ApiMode::Unescaped);
    d.push(&hex(
        "7E 00 11 90 00 13 A2 00 40 52 2B AA 7D 84 01 52 78 44 61 74 61 0D",
    ));
    let items: Vec<_> = std::iter::from_fn(|| d.next_frame()).collect();
    assert!(items.iter().all(|i| i.is_err()), "{items:?}");
    assert_eq!(d.stats().bad_checksums, 1);
}

// §3 0x91 (p.113).
#[test]
fn explicit_receive() {
    let wire =
        "7E 00 18 91 00 13 A2 00 40 52 2B AA 7D 84 E0 E0 22 11 C1 05 02 52 78 44 61 74 61 52";
    let Frame::ExplicitReceive(r) = one_frame(wire, ApiMode::Unescaped) else {
        panic!("not an explicit receive")
    };
    assert_eq!((r.source_endpoint, r.destination_endpoint), (0xE0, 0xE0));
    assert_eq!(
        (r.cluster_id, r.profile_id, r.options),
        (0x2211, 0xC105, 0x02)
    );
    assert_eq!(r.data, b"RxData".to_vec());
}

// §3 0x95 (p.117-118): node identification with NI " " (0x20).
#[test]
fn node_identification() {
    let wire = "7E 00 20 95 00 13 A2 00 40 52 2B AA 7D 84 02 7D 84 00 13 A2 00 40 52 2B AA 20 00 FF FE 01 01 C1 05 10 1E 1B";
    let Frame::NodeIdentification(n) = one_frame(wire, ApiMode::Unescaped) else {
        panic!("not a node identification")
    };
    assert_eq!(
        (n.sender, n.sender16, n.options),
        (Address64(0x0013_A200_4052_2BAA), Address16(0x7D84), 2)
    );
    let node = n.node().unwrap();
    assert_eq!(
        (node.network_address, node.address),
        (Address16(0x7D84), Address64(0x0013_A200_4052_2BAA))
    );
    assert_eq!(
        (node.ni.as_str(), node.parent, node.device_type),
        (" ", Some(Address16(0xFFFE)), Some(DeviceType::Router))
    );
    assert_eq!(node.status, Some(1)); // source event: pushbutton
}

// Unknown types are kept as raw (§1: firmware may add frame types).
#[test]
fn unknown_frame_kept() {
    let frame = Frame::parse(&hex("A1 01 02 03")).unwrap();
    assert_eq!(
        frame,
        Frame::Unknown {
            frame_type: 0xA1,
            data: vec![1, 2, 3]
        }
    );
    assert_eq!(frame.to_frame_data(), hex("A1 01 02 03"));
}

fn nd_node(wire: &str, mode: ApiMode) -> Node {
    let Frame::AtResponse(r) = one_frame(wire, mode) else {
        panic!("not an AT response")
    };
    assert_eq!(
        (r.frame_id, r.command, r.status()),
        (1, AtCommandName::ND, AtStatus::Ok)
    );
    Node::parse(&r.data, NdLayoutHint::Auto).unwrap()
}

fn assert_beacon1(node: &Node) {
    assert_eq!(node.layout, NdLayout::ZigbeeOrDigiMesh);
    assert_eq!(node.network_address, Address16(0x1234));
    assert_eq!(node.address, Address64(0x0013_A200_40A1_B2C3));
    assert_eq!(node.ni, "beacon1");
    assert_eq!(node.parent, Some(Address16(0xFFFE)));
    assert_eq!(node.device_type, Some(DeviceType::Router));
    assert_eq!(
        (node.status, node.profile_id, node.manufacturer_id),
        (Some(0), Some(0xC105), Some(0x101E))
    );
}

// §8 example 2: Zigbee ND response, no optional tail.
#[test]
fn nd_example_2() {
    let node = nd_node("7E 00 1F 88 01 4E 44 00 12 34 00 13 A2 00 40 A1 B2 C3 62 65 61 63 6F 6E 31 00 FF FE 01 00 C1 05 10 1E 08", ApiMode::Unescaped);
    assert_beacon1(&node);
    assert_eq!((node.digi_device_type, node.rssi_raw), (None, None));
}

// §8 example 2b: trailing RSSI byte 0x38 = −56 dBm.
#[test]
fn nd_example_2b_rssi() {
    let node = nd_node("7E 00 20 88 01 4E 44 00 12 34 00 13 A2 00 40 A1 B2 C3 62 65 61 63 6F 6E 31 00 FF FE 01 00 C1 05 10 1E 38 D0", ApiMode::Unescaped);
    assert_beacon1(&node);
    assert_eq!(
        (node.digi_device_type, node.rssi_raw, node.rssi_dbm()),
        (None, Some(0x38), Some(-56.0))
    );
}

// §8 example 2c: DD 00 03 00 00 appended.
#[test]
fn nd_example_2c_dd() {
    let node = nd_node("7E 00 23 88 01 4E 44 00 12 34 00 13 A2 00 40 A1 B2 C3 62 65 61 63 6F 6E 31 00 FF FE 01 00 C1 05 10 1E 00 03 00 00 05", ApiMode::Unescaped);
    assert_beacon1(&node);
    assert_eq!(
        (node.digi_device_type, node.rssi_raw),
        (Some(0x0003_0000), None)
    );
}

// §8 example 3: example 2 in AP=2 (SH's 0x13 escaped).
#[test]
fn nd_example_3_escaped() {
    let node = nd_node("7E 00 1F 88 01 4E 44 00 12 34 00 7D 33 A2 00 40 A1 B2 C3 62 65 61 63 6F 6E 31 00 FF FE 01 00 C1 05 10 1E 08", ApiMode::Escaped);
    assert_beacon1(&node);
}

// §8 example 4: SL 407D1142 in AP=1 and AP=2.
#[test]
fn nd_example_4() {
    let raw = nd_node("7E 00 1F 88 01 4E 44 00 12 34 00 13 A2 00 40 7D 11 42 62 65 61 63 6F 6E 31 00 FF FE 01 00 C1 05 10 1E 4E", ApiMode::Unescaped);
    let esc = nd_node("7E 00 1F 88 01 4E 44 00 12 34 00 7D 33 A2 00 40 7D 5D 7D 31 42 62 65 61 63 6F 6E 31 00 FF FE 01 00 C1 05 10 1E 4E", ApiMode::Escaped);
    assert_eq!(raw, esc);
    assert_eq!(raw.address, Address64(0x0013_A200_407D_1142));
}

// §8 example 5: the empty ND response that ends discovery.
#[test]
fn nd_example_5_end() {
    let Frame::AtResponse(r) = one_frame("7E 00 05 88 01 4E 44 00 E4", ApiMode::Unescaped) else {
        panic!("not an AT response")
    };
    assert_eq!((r.command, r.status()), (AtCommandName::ND, AtStatus::Ok));
    assert!(r.data.is_empty());
}

// §4.1: real Zigbee capture (xbee-api#3), an end device with parent 0x0000, no DB byte.
#[test]
fn nd_zigbee_capture_end_device() {
    let node = Node::parse(
        &hex("08 53 00 13 A2 00 40 5C EF D5 53 45 4E 53 4F 52 31 00 00 00 02 00 C1 05 10 1E"),
        NdLayoutHint::Auto,
    )
    .unwrap();
    assert_eq!(
        (node.network_address, node.address),
        (Address16(0x0853), Address64(0x0013_A200_405C_EFD5))
    );
    assert_eq!(
        (node.ni.as_str(), node.parent, node.device_type),
        ("SENSOR1", Some(Address16(0)), Some(DeviceType::EndDevice))
    );
}

// §5.2: real DigiMesh capture (Digi forum), NI " NODE3", MY = parent = 0xFFFE.
#[test]
fn nd_digimesh_capture() {
    let node = nd_node_id2("7E 00 1E 88 02 4E 44 00 FF FE 00 13 A2 00 40 FC DD 56 20 4E 4F 44 45 33 00 FF FE 01 00 C1 05 10 1E 57");
    assert_eq!(
        (node.network_address, node.address),
        (Address16(0xFFFE), Address64(0x0013_A200_40FC_DD56))
    );
    assert_eq!(
        (node.ni.as_str(), node.device_type),
        (" NODE3", Some(DeviceType::Router))
    );
    // §5.2: third-party DigiMesh record with NO=0x04, trailing RSSI 0x38.
    let node = Node::parse(
        &hex("FF FE 00 13 A2 00 40 E4 4B A9 20 00 FF FE 01 00 C1 05 10 1E 38"),
        NdLayoutHint::Auto,
    )
    .unwrap();
    assert_eq!((node.ni.as_str(), node.rssi_dbm()), (" ", Some(-56.0)));
}

fn nd_node_id2(wire: &str) -> Node {
    let Frame::AtResponse(r) = one_frame(wire, ApiMode::Unescaped) else {
        panic!("not an AT response")
    };
    assert_eq!((r.frame_id, r.command), (2, AtCommandName::ND));
    Node::parse(&r.data, NdLayoutHint::Auto).unwrap()
}

// §5.1: 802.15.4 record, DB byte 0x58 (−88 dBm) after SL, nothing after NI's NUL.
#[test]
fn nd_802154() {
    let record = hex("12 34 00 13 A2 00 40 A1 B2 C3 58 62 65 61 63 6F 6E 31 00");
    for hint in [NdLayoutHint::Auto, NdLayoutHint::Ieee802154] {
        let node = Node::parse(&record, hint).unwrap();
        assert_eq!(node.layout, NdLayout::Ieee802154);
        assert_eq!(
            (node.ni.as_str(), node.rssi_dbm()),
            ("beacon1", Some(-88.0))
        );
        assert_eq!((node.parent, node.device_type), (None, None));
        assert_eq!(node.to_record(), record);
    }
    assert!(Node::parse(&record, NdLayoutHint::ZigbeeOrDigiMesh).is_err());
}

// §4.1: a tail of 2 bytes after MANUFACTURER_ID is none of 0/1/4/5: rejected with the bytes.
#[test]
fn nd_bad_tail_rejected() {
    let record = hex("12 34 00 13 A2 00 40 A1 B2 C3 62 00 FF FE 01 00 C1 05 10 1E AA BB");
    let err = Node::parse(&record, NdLayoutHint::ZigbeeOrDigiMesh).unwrap_err();
    assert_eq!(
        err,
        rfloc_xbee::NdError::UnexpectedTail {
            tail_len: 2,
            record: record.clone()
        }
    );
    // No NUL after byte 10 at all: neither layout fits.
    assert!(matches!(
        Node::parse(&record[..11], NdLayoutHint::Auto),
        Err(rfloc_xbee::NdError::MissingNiTerminator { .. })
    ));
    // 802.15.4 with an empty NI (DB 0x62, then the NUL) is valid.
    assert_eq!(
        Node::parse(&record[..12], NdLayoutHint::Auto)
            .unwrap()
            .rssi_raw,
        Some(0x62)
    );
    assert!(Node::parse(&[], NdLayoutHint::Auto).is_err());
}
