//! The emulator's local and remote AT registers, byte for byte (AP=1): what a host library
//! reads when it opens a device (`HV`, `VR`, `CE`, `MY`, `N?`, `ID`), writes, refusals, and
//! remote AT to a beacon.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::sync::Arc;
use std::time::Duration;

use rfloc_xbee::{ApiMode, Beacon, CoordinatorEmulator, EmulatorConfig, Flavor};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

fn start(flavor: Flavor) -> DuplexStream {
    let (host, device) = tokio::io::duplex(4096);
    let emulator = CoordinatorEmulator::new(
        vec![Beacon::numbered(1)],
        Arc::new(|_| Some(-40.0)),
        EmulatorConfig {
            mode: ApiMode::Unescaped,
            flavor,
            ..EmulatorConfig::default()
        },
    );
    tokio::spawn(async move { emulator.serve(device).await });
    host
}

async fn exchange(host: &mut DuplexStream, request: &str, reply: &str) {
    host.write_all(&hex(request)).await.unwrap();
    let want = hex(reply);
    let mut got = vec![0u8; want.len()];
    tokio::time::timeout(Duration::from_secs(2), host.read_exact(&mut got))
        .await
        .expect("no reply")
        .unwrap();
    assert_eq!(got, want, "reply to {request}");
}

#[tokio::test]
async fn zigbee_s2c_registers() {
    let mut h = start(Flavor::Zigbee);
    exchange(
        &mut h,
        "7E 00 04 08 01 48 56 58",
        "7E 00 07 88 01 48 56 00 2E 41 69",
    )
    .await; // HV
    exchange(
        &mut h,
        "7E 00 04 08 02 56 52 4D",
        "7E 00 07 88 02 56 52 00 40 60 2D",
    )
    .await; // VR
    exchange(
        &mut h,
        "7E 00 04 08 03 43 45 6C",
        "7E 00 06 88 03 43 45 00 01 EB",
    )
    .await; // CE
    exchange(
        &mut h,
        "7E 00 04 08 04 4E 3F 66",
        "7E 00 07 88 04 4E 3F 00 17 70 5F",
    )
    .await; // N?
    exchange(
        &mut h,
        "7E 00 04 08 05 4D 59 4C",
        "7E 00 07 88 05 4D 59 00 00 00 CC",
    )
    .await; // MY
    exchange(
        &mut h,
        "7E 00 04 08 0A 49 44 60",
        "7E 00 0D 88 0A 49 44 00 00 00 00 00 00 00 12 34 9A",
    )
    .await; // ID: 64-bit PAN
    exchange(
        &mut h,
        "7E 00 09 08 06 4E 49 72 6F 62 6F 74 34",
        "7E 00 05 88 06 4E 49 00 DA",
    )
    .await; // NI robot
    exchange(
        &mut h,
        "7E 00 04 08 07 4E 49 59",
        "7E 00 0A 88 07 4E 49 00 72 6F 62 6F 74 B3",
    )
    .await; // NI
    exchange(
        &mut h,
        "7E 00 05 08 08 48 56 01 50",
        "7E 00 05 88 08 48 56 03 CE",
    )
    .await; // HV is read-only
    exchange(
        &mut h,
        "7E 00 04 08 09 58 58 3E",
        "7E 00 05 88 09 58 58 02 BC",
    )
    .await; // XX unknown
    exchange(
        &mut h,
        "7E 00 04 08 0B 57 52 43",
        "7E 00 05 88 0B 57 52 00 C3",
    )
    .await; // WR
            // Remote MY of beacon 1 (0x1001).
    exchange(
        &mut h,
        "7E 00 0F 17 0C 00 13 A2 00 40 00 00 01 FF FE 02 4D 59 41",
        "7E 00 11 97 0C 00 13 A2 00 40 00 00 01 10 01 4D 59 00 10 01 9E",
    )
    .await;
}

#[tokio::test]
async fn ieee802154_s2c_registers() {
    let mut h = start(Flavor::Ieee802154);
    exchange(
        &mut h,
        "7E 00 04 08 01 48 56 58",
        "7E 00 07 88 01 48 56 00 2E 41 69",
    )
    .await; // HV
    exchange(
        &mut h,
        "7E 00 04 08 02 56 52 4D",
        "7E 00 07 88 02 56 52 00 20 03 AA",
    )
    .await; // VR
    exchange(
        &mut h,
        "7E 00 04 08 03 43 45 6C",
        "7E 00 06 88 03 43 45 00 01 EB",
    )
    .await; // CE
    exchange(
        &mut h,
        "7E 00 04 08 0A 49 44 60",
        "7E 00 07 88 0A 49 44 00 33 32 7B",
    )
    .await; // ID
}
