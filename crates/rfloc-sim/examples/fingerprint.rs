//! Prints each scenario file's fingerprint (`Scenario::fingerprint`), the value
//! `rfloc_sim::published` records for the seeds' own files.
//!
//! `cargo run -p rfloc-sim --example fingerprint -- scenarios/seed*.toml`

use std::path::Path;

fn main() -> std::process::ExitCode {
    let mut code = std::process::ExitCode::SUCCESS;
    for arg in std::env::args().skip(1) {
        match rfloc_sim::Scenario::load(Path::new(&arg)) {
            Ok(s) => println!("{} {:#018x}", s.spec.name, s.fingerprint()),
            Err(e) => {
                eprintln!("{e}");
                code = std::process::ExitCode::FAILURE;
            }
        }
    }
    code
}
