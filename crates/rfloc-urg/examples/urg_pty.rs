//! Serves the URG emulator on a pseudo-terminal for a peer host library:
//!
//! ```text
//! cargo run -p rfloc-urg --features emulator --example urg_pty -- [LINK]
//! ```
//!
//! The emulated URG-04LX sees a wall 2 m ahead across ±60°. Prints `PTY <slave path>` once it
//! serves, makes `LINK` a symlink to it when given, and serves until killed.
#![allow(clippy::print_stdout)]

use std::io::Write;
use std::sync::Arc;

use rfloc_urg::{EmulatorConfig, UrgEmulator};
use tokio_serial::{SerialPort, SerialStream};

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (master, slave) = SerialStream::pair()?;
    let path = slave.name().ok_or("the pty has no slave path")?;
    if let Some(link) = std::env::args().nth(1) {
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&path, &link)?;
    }
    let wall = |angle: f64| (angle.abs() < 60f64.to_radians()).then(|| 2.0 / angle.cos());
    let emulator = UrgEmulator::new(Arc::new(wall), EmulatorConfig::default());
    println!("PTY {path}");
    std::io::stdout().flush()?;
    // The slave stays open here, so the master never reads end-of-file between clients.
    let _slave = slave;
    emulator.serve(master).await?;
    Ok(())
}
