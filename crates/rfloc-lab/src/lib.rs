//! rfloc's lab: the device emulators attached to a robot file's devices (`rfloc run` with a
//! `[simulation]` section), and the seed scenario trials (`rfloc sim`). Nothing here runs on a
//! robot; the daemon reaches it only through `rfloc_daemon::simulation`.
#![forbid(unsafe_code)]

pub mod emulate;
pub mod scenario;
pub mod sim;
