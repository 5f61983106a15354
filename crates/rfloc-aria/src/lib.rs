//! Native Pioneer P3-DX serial protocol (P2OS/AROS/ARCOS, as spoken by ARIA): a sans-IO codec,
//! an async client with watchdog keep-alive and reconnection, and a robot emulator.
//!
//! Layers:
//! - [`frame`]: packet framing, checksum and a resynchronising decoder;
//! - [`command`]: client commands and their argument encoding, with clamping;
//! - [`sip`]: server information packets (motor SIP, SYNC2 identity, CONFIG);
//! - [`odometry`]: raw SIP fields to continuous odometry in metres and radians;
//! - [`client`]: [`AriaClient`], the async driver, and the [`MobileBase`] trait;
//! - [`emulator`]: [`RobotEmulator`], a differential-drive robot serving the protocol.
//!
//! The protocol facts used here are listed with their sources in `docs/protocols/pioneer-aria.md`.
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

pub mod client;
pub mod command;
#[cfg(feature = "emulator")]
pub mod emulator;
pub mod frame;
mod mock_base;
pub mod odometry;
pub mod sip;
pub mod sonar;

pub use client::{
    AriaClient, ClientConfig, ClientError, ClientStats, ConnectFuture, LinkState, MobileBase,
    Odometry, SCALED_CLOSE_LINGER_FLOOR, SCALED_LINK_TIMEOUT_FLOOR, SCALED_SYNC_TIMEOUT_FLOOR,
};
pub use command::{Arg, ArgError, Command, CommandError, CommandLimits, LinkPhase};
#[cfg(feature = "emulator")]
pub use emulator::{
    EmulatorConfig, EmulatorError, EmulatorHandle, EmulatorState, MotionHook, RobotEmulator,
    SonarHook, StepControl, WheelSlip,
};
pub use frame::{checksum, EncodeError, Frame, FrameDecoder, FrameError};
pub use mock_base::{MockBase, MockBaseCall};
pub use odometry::{ConversionFactors, OdometrySample, OdometryTracker};
pub use sip::{
    ConfigMore, ConfigPacket, MotorSip, RobotIdentity, ServerPacket, SipError, SipTail,
    SonarReading, StallBumpers,
};
pub use sonar::{p3dx_discs, SonarDisc, SonarRing, NO_ECHO_M};
