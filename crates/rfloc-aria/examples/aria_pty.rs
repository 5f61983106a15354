//! Serves the Pioneer emulator on a pseudo-terminal for a peer client (ARIA, P2OS):
//!
//! ```text
//! cargo run -p rfloc-aria --features emulator --example aria_pty -- [LINK]
//! ```
//!
//! A `p3dx-sh` at the origin in real time. Prints `PTY <slave path>` once it serves, makes
//! `LINK` a symlink to it when given, and serves until killed; a client that goes away leaves
//! the robot open, as a real controller does, and the next one must CLOSE and handshake.
#![allow(clippy::print_stdout)]

use std::io::Write;

use rfloc_aria::{EmulatorConfig, RobotEmulator};
use tokio_serial::{SerialPort, SerialStream};

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (master, slave) = SerialStream::pair()?;
    let path = slave.name().ok_or("the pty has no slave path")?;
    if let Some(link) = std::env::args().nth(1) {
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&path, &link)?;
    }
    let mut robot = RobotEmulator::new(EmulatorConfig::default());
    println!("PTY {path}");
    std::io::stdout().flush()?;
    // The slave stays open here, so the master never reads end-of-file between clients.
    let _slave = slave;
    robot.serve(master).await?;
    Ok(())
}
