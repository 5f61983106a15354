//! rfloc's daemon as a library: the robot file, the driver registry, device supervision, the
//! estimator thread, the pose stream, systemd notification and replay. It holds no emulator and
//! no simulator: a robot file with a `[simulation]` section runs through the [`simulation`]
//! seam, which a lab crate implements.
#![forbid(unsafe_code)]

pub mod config;
pub mod daemon;
pub mod devices;
pub mod estimator;
pub mod events;
pub mod fleet;
pub mod message;
pub mod notify;
pub mod pipeline;
pub mod replay;
pub mod server;
pub mod simulation;
pub mod time;
pub mod viz;
