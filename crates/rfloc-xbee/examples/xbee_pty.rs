//! Serves the coordinator emulator on a pseudo-terminal for a peer host library:
//!
//! ```text
//! cargo run -p rfloc-xbee --features emulator --example xbee_pty -- [1|2] [zigbee|802.15.4] [LINK]
//! ```
//!
//! API mode (default 2) and firmware flavour (default zigbee; 802.15.4 also switches the ND
//! layout). Three beacons (`beacon1`..`beacon3` at −40, −55 and −70 dBm) answer. Prints
//! `PTY <slave path>` once the emulator serves, makes `LINK` a symlink to it when given, and
//! serves until killed.
#![allow(clippy::print_stdout)]

use std::io::Write;
use std::sync::Arc;

use rfloc_xbee::{ApiMode, Beacon, CoordinatorEmulator, EmulatorConfig, Flavor, NdLayout};
use tokio_serial::{SerialPort, SerialStream};

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = match args.first().map(String::as_str) {
        Some("1") => ApiMode::Unescaped,
        _ => ApiMode::Escaped,
    };
    let flavor = match args.get(1).map(String::as_str) {
        Some("802.15.4") => Flavor::Ieee802154,
        _ => Flavor::Zigbee,
    };
    let (master, slave) = SerialStream::pair()?;
    let path = slave.name().ok_or("the pty has no slave path")?;
    if let Some(link) = args.get(2) {
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(&path, link)?;
    }
    let emulator = peer_emulator(mode, flavor);
    println!("PTY {path}");
    std::io::stdout().flush()?;
    // The slave stays open here, so the master never reads end-of-file between clients.
    let _slave = slave;
    emulator.serve(master).await?;
    Ok(())
}

fn peer_emulator(mode: ApiMode, flavor: Flavor) -> CoordinatorEmulator {
    let rssi = [-40.0, -55.0, -70.0];
    CoordinatorEmulator::new(
        (1..=3).map(Beacon::numbered).collect(),
        Arc::new(move |i| rssi.get(i).copied()),
        EmulatorConfig {
            mode,
            flavor,
            nd_layout: match flavor {
                Flavor::Zigbee => NdLayout::ZigbeeOrDigiMesh,
                Flavor::Ieee802154 => NdLayout::Ieee802154,
            },
            ..EmulatorConfig::default()
        },
    )
}
