//! An XBee coordinator in API mode, emulated over any byte stream: answers `ND` with one
//! response per beacon that hears it (then the end frame), local `DB`, the local registers a
//! host library reads when it opens a device (`HV`, `VR`, `SH`, `SL`, `MY`, `NI`, `CE`, `AP`,
//! `AO`, `NT`, `NO`, `N?`, `ID`, `CH`, `OP`, …) with the values of an XBee S2C module running
//! Zigbee or 802.15.4 firmware ([`Flavor`]), and remote AT (0x17: `DB`, `NI`, `SH`, `SL`, `MY`,
//! `HV`, `VR`, `CE`) to the beacons. Beacon RSSI comes from a supplied function, so a
//! simulator can put path loss and an antenna pattern behind it.
//!
//! Timing. Replies are scheduled on wall time (`response_spacing` between `ND` responses,
//! `remote_failure_delay`). The coordinator sends nothing unsolicited, so with a zero
//! `response_spacing` a whole `ND` round (and every local reply) is written while the request
//! is handled, inside the simulated instant of the request: a lock-step simulator that does not
//! move its clock while a round is in flight gets its replies at deterministic simulated times.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap};
use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

use crate::address::{Address16, Address64};
use crate::codec::{ApiMode, DecodeStats, FrameDecoder};
use crate::frame::{
    AtCommand, AtCommandName, AtResponse, Frame, RemoteAtCommand, RemoteAtResponse,
};
use crate::nd::{
    dbm_to_rssi_byte, DeviceType, NdLayout, Node, DIGI_MANUFACTURER_ID, DIGI_PROFILE_ID,
};

/// RSSI of beacon `index` (position in the emulator's beacon list) in dBm, `None` = not heard.
pub type RssiFn = Arc<dyn Fn(usize) -> Option<f64> + Send + Sync>;

/// Status bytes the emulator sends.
const STATUS_OK: u8 = 0;
const STATUS_ERROR: u8 = 1;
const STATUS_INVALID_COMMAND: u8 = 2;
const STATUS_INVALID_PARAMETER: u8 = 3;
const STATUS_TX_FAILURE: u8 = 4;

/// Local registers a host may write (the others answer a write with status 3).
const WRITABLE: [&[u8; 2]; 18] = [
    b"NI", b"AO", b"NO", b"CE", b"ID", b"CH", b"MY", b"DH", b"DL", b"SM", b"EE", b"PL", b"PM",
    b"SC", b"SD", b"NJ", b"MM", b"RR",
];

/// Commands that act rather than hold a value: write, apply, reset, discover-repeat.
const EXECUTE: [&[u8; 2]; 4] = [b"WR", b"AC", b"FR", b"RE"];

/// One emulated remote radio.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Beacon {
    /// 64-bit address.
    pub address: Address64,
    /// 16-bit network address (`MY`).
    pub network_address: Address16,
    /// Node identifier.
    pub ni: String,
}

impl Beacon {
    /// Beacon number `k`: NI `beacon{k}`, address `0013A200_4000_0000 + k`, MY `0x1000 + k`.
    pub fn numbered(k: u16) -> Beacon {
        Beacon {
            address: Address64(0x0013_A200_4000_0000 + u64::from(k)),
            network_address: Address16(0x1000_u16.wrapping_add(k)),
            ni: format!("beacon{k}"),
        }
    }
}

/// Which firmware the emulated S2C module runs; decides the `VR`/`HV` pair (from which a host
/// library such as digi-xbee tells the protocol) and the registers that exist.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Flavor {
    /// Zigbee firmware (`VR` 0x4060): 64-bit `ID`/`OP`, `OI`, `ZS`, `AI`; a coordinator
    /// (`CE` 1, `MY` 0x0000).
    #[default]
    Zigbee,
    /// 802.15.4 firmware (`VR` 0x2003): 16-bit `ID`, `MM`, `RR`, `A1`/`A2`; a coordinator
    /// (`CE` 1). Pair with [`NdLayout::Ieee802154`].
    Ieee802154,
}

impl Flavor {
    /// The firmware version (`VR`).
    pub fn firmware_version(self) -> u16 {
        match self {
            Flavor::Zigbee => 0x4060,
            Flavor::Ieee802154 => 0x2003,
        }
    }
}

/// Hardware version (`HV`) of the emulated module: 0x2E is the XBee S2C through-hole (XB24C
/// TH-DIP) in Digi's hardware table, the low byte a revision.
pub const S2C_HARDWARE_VERSION: u16 = 0x2E41;

/// Emulator settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EmulatorConfig {
    /// API mode to speak.
    pub mode: ApiMode,
    /// 64-bit address of the coordinator itself (`SH`/`SL`).
    pub own_address: Address64,
    /// Initial `NT` in 100 ms units (the emulator accepts 1..=255).
    pub nt_units: u8,
    /// Gap between successive `ND` responses (shrunk so that all fit within `NT`).
    pub response_spacing: Duration,
    /// Whether to send the empty `ND` response at the end of a round.
    pub send_end_frame: bool,
    /// Record layout of `ND` responses.
    pub nd_layout: NdLayout,
    /// Append the RSSI-of-last-hop byte to Zigbee/DigiMesh records (as with `NO & 0x04`).
    pub append_rssi: bool,
    /// Delay before answering a remote command to a beacon that is not heard (status 4).
    pub remote_failure_delay: Duration,
    /// Firmware of the emulated module (default Zigbee).
    pub flavor: Flavor,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            mode: ApiMode::Escaped,
            own_address: Address64(0x0013_A200_4000_FFFF),
            nt_units: 0x3C,
            response_spacing: Duration::from_millis(2),
            send_end_frame: true,
            nd_layout: NdLayout::ZigbeeOrDigiMesh,
            append_rssi: false,
            remote_failure_delay: Duration::from_millis(5),
            flavor: Flavor::Zigbee,
        }
    }
}

/// What one [`CoordinatorEmulator::serve`] call saw and did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EmulatorStats {
    /// Frames received and understood.
    pub requests: u64,
    /// `ND` rounds started.
    pub nd_rounds: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames received that the emulator does not answer.
    pub ignored_frames: u64,
    /// Framing counters of the emulator's decoder.
    pub decode: DecodeStats,
}

/// An emulated coordinator with a fixed set of beacons.
#[derive(Clone)]
pub struct CoordinatorEmulator {
    beacons: Vec<Beacon>,
    rssi: RssiFn,
    config: EmulatorConfig,
}

impl fmt::Debug for CoordinatorEmulator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CoordinatorEmulator")
            .field("beacons", &self.beacons)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

/// A frame due at a time; `heard` is the beacon whose packet it stands for (for local `DB`).
struct Scheduled {
    due: Instant,
    seq: u64,
    frame: Frame,
    heard: Option<usize>,
}

impl PartialEq for Scheduled {
    fn eq(&self, other: &Self) -> bool {
        (self.due, self.seq) == (other.due, other.seq)
    }
}
impl Eq for Scheduled {}
impl PartialOrd for Scheduled {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Scheduled {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (self.due, self.seq).cmp(&(other.due, other.seq))
    }
}

/// Per-connection state.
struct Session {
    nt_units: u8,
    /// Local registers other than `NT`, `DB`, `AP` and `N?`, by name.
    registers: BTreeMap<[u8; 2], Vec<u8>>,
    last_heard: Option<usize>,
    outbox: BinaryHeap<Reverse<Scheduled>>,
    seq: u64,
    stats: EmulatorStats,
}

impl Session {
    fn schedule(&mut self, due: Instant, frame: Frame, heard: Option<usize>) {
        self.seq += 1;
        self.outbox.push(Reverse(Scheduled {
            due,
            seq: self.seq,
            frame,
            heard,
        }));
    }
}

impl CoordinatorEmulator {
    /// An emulator for `beacons`; `rssi(i)` gives the RSSI of `beacons[i]` at the moment of
    /// the request.
    pub fn new(beacons: Vec<Beacon>, rssi: RssiFn, config: EmulatorConfig) -> Self {
        Self {
            beacons,
            rssi,
            config,
        }
    }

    /// The beacons.
    pub fn beacons(&self) -> &[Beacon] {
        &self.beacons
    }

    /// Serves one connection until the stream ends (EOF), then returns what happened.
    pub async fn serve<S>(&self, mut stream: S) -> std::io::Result<EmulatorStats>
    where
        S: AsyncRead + AsyncWrite + Unpin,
    {
        let span = tracing::info_span!("xbee-emulator", mode = ?self.config.mode);
        let mut decoder = FrameDecoder::new(self.config.mode);
        let mut session = Session {
            nt_units: self.config.nt_units,
            registers: self.local_registers(),
            last_heard: None,
            outbox: BinaryHeap::new(),
            seq: 0,
            stats: EmulatorStats::default(),
        };
        let mut buf = [0u8; 256];
        loop {
            let next_due = session
                .outbox
                .peek()
                .map(|Reverse(s)| s.due)
                .unwrap_or_else(|| Instant::now() + Duration::from_secs(3600));
            tokio::select! {
                read = stream.read(&mut buf) => {
                    let n = read?;
                    if n == 0 {
                        session.stats.decode = decoder.stats();
                        return Ok(session.stats);
                    }
                    decoder.push(buf.get(..n).unwrap_or(&[]));
                    while let Some(item) = decoder.next_frame() {
                        let Ok(data) = item else { continue };
                        match Frame::parse(&data) {
                            Ok(frame) => self.handle(frame, &mut session),
                            Err(e) => {
                                session.stats.ignored_frames += 1;
                                tracing::warn!(parent: &span, error = %e, "emulator: malformed request");
                            }
                        }
                    }
                }
                () = tokio::time::sleep_until(next_due) => {}
            }
            let now = Instant::now();
            while session.outbox.peek().is_some_and(|Reverse(s)| s.due <= now) {
                let Some(Reverse(item)) = session.outbox.pop() else {
                    break;
                };
                let bytes = item
                    .frame
                    .encode(self.config.mode)
                    .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
                stream.write_all(&bytes).await?;
                stream.flush().await?;
                session.stats.frames_sent += 1;
                if item.heard.is_some() {
                    session.last_heard = item.heard;
                }
            }
        }
    }

    fn handle(&self, frame: Frame, session: &mut Session) {
        match frame {
            Frame::AtCommand(c) => {
                session.stats.requests += 1;
                self.handle_at(c, session);
            }
            Frame::RemoteAtCommand(c) => {
                session.stats.requests += 1;
                self.handle_remote_at(c, session);
            }
            other => {
                session.stats.ignored_frames += 1;
                tracing::debug!(frame_type = other.frame_type(), "emulator: frame ignored");
            }
        }
    }

    fn handle_at(&self, c: AtCommand, session: &mut Session) {
        if c.frame_id == 0 {
            return;
        }
        let now = Instant::now();
        let reply = |status_byte: u8, data: Vec<u8>| {
            Frame::AtResponse(AtResponse {
                frame_id: c.frame_id,
                command: c.command,
                status_byte,
                data,
            })
        };
        let (status, data) = match c.command {
            AtCommandName::ND => {
                self.start_discovery(&c, session, now);
                return;
            }
            AtCommandName::NT => match c.parameter.as_slice() {
                [] => (STATUS_OK, vec![session.nt_units]),
                [units] if *units >= 1 => {
                    session.nt_units = *units;
                    (STATUS_OK, Vec::new())
                }
                _ => (STATUS_INVALID_PARAMETER, Vec::new()),
            },
            AtCommandName::DB => {
                let rssi = session
                    .last_heard
                    .and_then(|i| (self.rssi)(i))
                    .map_or(0, dbm_to_rssi_byte);
                (STATUS_OK, vec![rssi])
            }
            AtCommandName::AP => match c.parameter.as_slice() {
                [] => (STATUS_OK, vec![self.config.mode.ap_value()]),
                [v] if *v == self.config.mode.ap_value() => (STATUS_OK, Vec::new()),
                _ => (STATUS_INVALID_PARAMETER, Vec::new()),
            },
            AtCommandName(name) if &name == b"N?" => {
                // The longest an ND round can take, ms: the NT window.
                let ms = u16::from(session.nt_units) * 100;
                (STATUS_OK, ms.to_be_bytes().to_vec())
            }
            AtCommandName(name) if EXECUTE.contains(&&name) => (STATUS_OK, Vec::new()),
            AtCommandName(name) => match (session.registers.get_mut(&name), c.parameter.is_empty())
            {
                (Some(value), true) => (STATUS_OK, value.clone()),
                (Some(value), false) if WRITABLE.contains(&&name) => {
                    *value = c.parameter.clone();
                    (STATUS_OK, Vec::new())
                }
                (Some(_), false) => (STATUS_INVALID_PARAMETER, Vec::new()),
                (None, _) => (STATUS_INVALID_COMMAND, Vec::new()),
            },
        };
        session.schedule(now, reply(status, data), None);
    }

    /// The local registers of the emulated S2C module at power-up (values as an S2C reports
    /// them; see docs/protocols/xbee-api.md §emulator).
    fn local_registers(&self) -> BTreeMap<[u8; 2], Vec<u8>> {
        let own = self.config.own_address;
        let mut r: BTreeMap<[u8; 2], Vec<u8>> = BTreeMap::new();
        let mut set = |name: &[u8; 2], value: &[u8]| {
            r.insert(*name, value.to_vec());
        };
        set(b"HV", &S2C_HARDWARE_VERSION.to_be_bytes());
        set(b"VR", &self.config.flavor.firmware_version().to_be_bytes());
        set(b"SH", &own.high().to_be_bytes());
        set(b"SL", &own.low().to_be_bytes());
        set(b"NI", b"coordinator");
        set(b"CE", &[1]);
        set(b"AO", &[0]);
        set(b"NO", &[u8::from(self.config.append_rssi) << 2]);
        set(b"BD", &[3]); // 9600 baud
        set(b"SM", &[0]);
        set(b"EE", &[0]);
        set(b"PL", &[4]);
        set(b"PM", &[1]);
        set(b"DH", &[0]);
        set(b"DL", &[0]);
        set(b"SC", &0x7FFF_u16.to_be_bytes());
        set(b"SD", &[3]);
        set(b"%V", &3300_u16.to_be_bytes());
        set(b"TP", &[0x19]);
        set(b"DD", &0x0012_0000_u32.to_be_bytes());
        match self.config.flavor {
            Flavor::Zigbee => {
                set(b"MY", &[0, 0]);
                set(b"MP", &0xFFFE_u16.to_be_bytes());
                set(b"ID", &0x1234_u64.to_be_bytes());
                set(b"OP", &0x1234_u64.to_be_bytes());
                set(b"OI", &0x7A5C_u16.to_be_bytes());
                set(b"CH", &[0x0F]);
                set(b"ZS", &[0]);
                set(b"AI", &[0]);
                set(b"NP", &0x0054_u16.to_be_bytes());
                set(b"NJ", &[0xFF]);
            }
            Flavor::Ieee802154 => {
                set(b"MY", &[0, 0]);
                set(b"ID", &0x3332_u16.to_be_bytes());
                set(b"CH", &[0x0C]);
                set(b"MM", &[0]);
                set(b"RR", &[0]);
                set(b"A1", &[0]);
                set(b"A2", &[0]);
                set(b"AI", &[0]);
                set(b"NP", &0x0064_u16.to_be_bytes());
            }
        }
        r
    }

    fn start_discovery(&self, c: &AtCommand, session: &mut Session, now: Instant) {
        session.stats.nd_rounds += 1;
        let heard: Vec<(usize, &Beacon, f64)> = self
            .beacons
            .iter()
            .enumerate()
            .filter(|(_, b)| c.parameter.is_empty() || b.ni.as_bytes() == c.parameter.as_slice())
            .filter_map(|(i, b)| (self.rssi)(i).map(|dbm| (i, b, dbm)))
            .collect();
        let response = |data: Vec<u8>, status_byte: u8| {
            Frame::AtResponse(AtResponse {
                frame_id: c.frame_id,
                command: AtCommandName::ND,
                status_byte,
                data,
            })
        };
        if !c.parameter.is_empty() && heard.is_empty() {
            session.schedule(now, response(Vec::new(), STATUS_ERROR), None);
            return;
        }
        let window = Duration::from_millis(u64::from(session.nt_units) * 100);
        let slots = u32::try_from(heard.len() + 1).unwrap_or(u32::MAX);
        let spacing = self.config.response_spacing.min(window / slots);
        let mut due = now;
        for (i, beacon, dbm) in heard {
            due += spacing;
            let rssi_raw = match self.config.nd_layout {
                NdLayout::Ieee802154 => Some(dbm_to_rssi_byte(dbm)),
                NdLayout::ZigbeeOrDigiMesh => {
                    self.config.append_rssi.then(|| dbm_to_rssi_byte(dbm))
                }
            };
            let zigbee = self.config.nd_layout == NdLayout::ZigbeeOrDigiMesh;
            let node = Node {
                layout: self.config.nd_layout,
                network_address: beacon.network_address,
                address: beacon.address,
                ni: beacon.ni.clone(),
                parent: zigbee.then_some(Address16::UNKNOWN),
                device_type: zigbee.then_some(DeviceType::Router),
                status: zigbee.then_some(0),
                profile_id: zigbee.then_some(DIGI_PROFILE_ID),
                manufacturer_id: zigbee.then_some(DIGI_MANUFACTURER_ID),
                digi_device_type: None,
                rssi_raw,
            };
            session.schedule(due, response(node.to_record(), STATUS_OK), Some(i));
        }
        if self.config.send_end_frame {
            session.schedule(due + spacing, response(Vec::new(), STATUS_OK), None);
        }
    }

    fn handle_remote_at(&self, c: RemoteAtCommand, session: &mut Session) {
        if c.frame_id == 0 {
            return;
        }
        let now = Instant::now();
        let found = self
            .beacons
            .iter()
            .enumerate()
            .find(|(_, b)| b.address == c.destination)
            .and_then(|(i, b)| (self.rssi)(i).map(|dbm| (i, b, dbm)));
        let reply = |source16: Address16, status_byte: u8, data: Vec<u8>| {
            Frame::RemoteAtResponse(RemoteAtResponse {
                frame_id: c.frame_id,
                source: c.destination,
                source16,
                command: c.command,
                status_byte,
                data,
            })
        };
        let Some((i, beacon, dbm)) = found else {
            let frame = reply(Address16::UNKNOWN, STATUS_TX_FAILURE, Vec::new());
            session.schedule(now + self.config.remote_failure_delay, frame, None);
            return;
        };
        let (status, data) = match (c.command, c.parameter.is_empty()) {
            (AtCommandName::DB, true) => (STATUS_OK, vec![dbm_to_rssi_byte(dbm)]),
            (AtCommandName::NI, true) => (STATUS_OK, beacon.ni.as_bytes().to_vec()),
            (AtCommandName::SH, true) => (STATUS_OK, beacon.address.high().to_be_bytes().to_vec()),
            (AtCommandName::SL, true) => (STATUS_OK, beacon.address.low().to_be_bytes().to_vec()),
            (AtCommandName(n), true) if &n == b"MY" => {
                (STATUS_OK, beacon.network_address.0.to_be_bytes().to_vec())
            }
            (AtCommandName(n), true) if &n == b"HV" => {
                (STATUS_OK, S2C_HARDWARE_VERSION.to_be_bytes().to_vec())
            }
            (AtCommandName(n), true) if &n == b"VR" => (
                STATUS_OK,
                self.config.flavor.firmware_version().to_be_bytes().to_vec(),
            ),
            // The beacons are routers (Zigbee) or end devices (802.15.4): CE 0.
            (AtCommandName(n), true) if &n == b"CE" => (STATUS_OK, vec![0]),
            _ => (STATUS_INVALID_COMMAND, Vec::new()),
        };
        session.schedule(now, reply(beacon.network_address, status, data), Some(i));
    }
}
