//! Alien ALR-9900 UHF RFID reader over its text command protocol (TCP port 23): a sans-IO
//! codec, an async client, a reconnecting session and a reader emulator.
//!
//! - [`ReplyFramer`] splits the byte stream into NUL-terminated frames and prompts;
//!   [`parse_reply`] classifies a reply; [`TagListFormat`] parses TagLists in the Text, Terse,
//!   XML and Custom formats ([`CustomFormat`] compiles a `TagListCustomFormat`). No I/O.
//! - [`AlienClient`] logs in (prompt-suppressed or interactive), runs `get`/`set`, applies a
//!   [`ReaderSetup`] and reads [`Snapshot`]s.
//! - [`AlienSession`] reconnects through a connector closure with back-off and re-applies the
//!   setup; it and the client implement [`SnapshotReader`], the trait the daemon uses.
//! - [`Transcript`] reads a recorded session back: commands paired with their replies, and
//!   the TagList format followed through the session ([`FormatTracker`]). No I/O.
//! - [`ReaderEmulator`] serves the protocol on any stream or a TCP listener, answering `t` from a
//!   supplied tag field.
//!
//! See `docs/protocols/alien-alr9900.md` for the protocol as implemented and its sources.
#![forbid(unsafe_code)]
#![deny(clippy::indexing_slicing)]

mod client;
mod custom_format;
#[cfg(feature = "emulator")]
mod emulator;
mod error;
mod format_tracker;
mod framing;
mod reader_time;
mod redact;
mod reply;
mod session;
mod setup;
mod snapshot;
mod taglist;
mod transcript;

pub use client::{AlienClient, AlienConfig, AlienStats, EchoState, LineEnding, PromptMode};
pub use custom_format::{CustomFormat, CustomFormatError, FieldKind};
#[cfg(feature = "emulator")]
pub use emulator::{EchoMode, EmulatorOptions, ReaderEmulator, TagField};
pub use error::{AlienError, SessionEnd};
pub use format_tracker::FormatTracker;
pub use framing::{Frame, Prompt, ReplyFramer, MAX_FRAME_LEN};
pub use reader_time::{civil_from_unix, format_reader_time, unix_from_civil, ReaderTime};
pub use reply::{parse_reply, session_end, Reply};
pub use session::{AlienSession, Backoff, Connector};
pub use setup::{ReaderSetup, SetupCommand, PROJECT_CUSTOM_FORMAT, SEED000_CUSTOM_FORMAT};
pub use snapshot::{RssiMeaning, Snapshot, SnapshotReader};
pub use taglist::{parse_tag_id, MalformedTagLine, TagId, TagListFormat, TagRead};
pub use transcript::{Exchange, Transcript};
