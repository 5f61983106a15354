//! Async XBee client over any byte stream: AT and remote AT commands with frame-ID bookkeeping,
//! node discovery (`ND`) and RSSI queries (`DB`).

use std::collections::VecDeque;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

use crate::address::{Address16, Address64};
use crate::codec::{
    ApiMode, DecodeStats, EncodeError, FrameDecoder, HexBytes, DEFAULT_MAX_FRAME_DATA,
};
use crate::frame::{
    AtCommand, AtCommandName, AtResponse, AtStatus, Frame, RemoteAtCommand, RemoteAtResponse,
};
use crate::nd::{rssi_byte_to_dbm, NdError, NdLayoutHint, Node};

/// How many unsolicited frames (modem status, receive packets, …) are kept for
/// [`XBeeClient::take_unsolicited`] before the oldest is dropped.
pub const UNSOLICITED_CAPACITY: usize = 64;

/// Where [`XBeeClient::node_rssi`] takes a beacon's RSSI from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum RssiSource {
    /// Remote `DB` (0x17 → 0x97): what the beacon measured on the coordinator's request
    /// (transmit side of the coordinator's antenna).
    #[default]
    RemoteDb,
    /// A remote `DB` to make the beacon answer, then local `DB`: what the coordinator measured on
    /// the beacon's 0x97 reply (receive side of the coordinator's antenna). Any other packet
    /// received between the two commands would overwrite the local value.
    LocalDbAfterRemote,
}

/// Client settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClientConfig {
    /// The radio's `AP` mode.
    pub mode: ApiMode,
    /// How long to wait for the response to a local AT command.
    pub response_timeout: Duration,
    /// How long to wait for the 0x97 response to a remote AT command.
    pub remote_timeout: Duration,
    /// The radio's `NT` (discovery window). [`XBeeClient::set_node_discovery_timeout`] keeps it
    /// in step with the radio.
    pub node_discovery_timeout: Duration,
    /// Extra time after `NT` before discovery gives up waiting for the end frame.
    pub discovery_margin: Duration,
    /// Which `ND` record layout to expect.
    pub nd_layout: NdLayoutHint,
    /// Largest length field the decoder accepts.
    pub max_frame_data: usize,
    /// Where [`XBeeClient::node_rssi`] takes RSSI from.
    pub rssi_source: RssiSource,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            mode: ApiMode::Escaped,
            response_timeout: Duration::from_secs(1),
            remote_timeout: Duration::from_secs(5),
            node_discovery_timeout: Duration::from_millis(6000),
            discovery_margin: Duration::from_millis(1000),
            nd_layout: NdLayoutHint::Auto,
            max_frame_data: DEFAULT_MAX_FRAME_DATA,
            rssi_source: RssiSource::RemoteDb,
        }
    }
}

/// Errors of the client.
#[derive(Debug, thiserror::Error)]
pub enum XBeeError {
    /// The stream failed.
    #[error("xbee i/o: {0}")]
    Io(#[from] std::io::Error),
    /// The stream ended.
    #[error("xbee stream closed")]
    Closed,
    /// No response in time.
    #[error("xbee: no response to {command} within {waited:?}")]
    Timeout {
        /// The command that went unanswered.
        command: AtCommandName,
        /// How long the client waited.
        waited: Duration,
    },
    /// The radio answered with a non-OK status.
    #[error("xbee: {command} returned {status:?} (status byte {status_byte:02X})")]
    Status {
        /// The command.
        command: AtCommandName,
        /// Decoded status.
        status: AtStatus,
        /// Status byte as received.
        status_byte: u8,
    },
    /// A response value had an unexpected size.
    #[error("xbee: unexpected value for {command}: {}", HexBytes(.data))]
    BadValue {
        /// The command.
        command: AtCommandName,
        /// The value received.
        data: Vec<u8>,
    },
    /// A requested setting is outside what the radio can hold.
    #[error("xbee: {0}")]
    InvalidSetting(String),
    /// A frame could not be encoded.
    #[error("xbee: {0}")]
    Encode(#[from] EncodeError),
}

/// How a discovery round ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum DiscoveryEnd {
    /// The radio sent the empty `ND` response.
    EndFrame,
    /// `NT` plus the margin passed without an end frame.
    Timeout,
}

/// Result of one `ND` round.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeDiscovery {
    /// Nodes that answered, in arrival order.
    pub nodes: Vec<Node>,
    /// How the round ended.
    pub end: DiscoveryEnd,
    /// Records that could not be parsed (also counted in [`ClientStats::bad_nd_records`]).
    #[serde(skip)]
    pub rejected: Vec<NdError>,
}

/// Counters of the client, on top of the decoder's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClientStats {
    /// Framing counters.
    pub decode: DecodeStats,
    /// Frames with a good checksum whose fields did not fit their type.
    pub malformed_frames: u64,
    /// Responses whose frame ID matched no outstanding request.
    pub stray_responses: u64,
    /// `ND` records that could not be parsed.
    pub bad_nd_records: u64,
    /// Unsolicited frames dropped because the queue was full.
    pub unsolicited_dropped: u64,
}

/// An XBee radio in API mode behind any byte stream (serial port, pty, TCP, replay).
///
/// Every frame written is followed by a flush. Responses are matched by frame ID; IDs run
/// 1..=255 and wrap, skipping 0 (which would suppress the response).
#[derive(Debug)]
pub struct XBeeClient<T> {
    io: T,
    config: ClientConfig,
    decoder: FrameDecoder,
    next_frame_id: u8,
    nt_units_set: Option<u8>,
    unsolicited: VecDeque<Frame>,
    stats: ClientStats,
    span: tracing::Span,
}

impl<T> XBeeClient<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    /// Wraps `io` with `config`.
    pub fn new(io: T, config: ClientConfig) -> Self {
        let decoder = FrameDecoder::with_max_frame_data(config.mode, config.max_frame_data);
        let span = tracing::info_span!("xbee", mode = ?config.mode);
        Self {
            io,
            config,
            decoder,
            next_frame_id: 1,
            nt_units_set: None,
            unsolicited: VecDeque::new(),
            stats: ClientStats::default(),
            span,
        }
    }

    /// The settings in use.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Counters so far.
    pub fn stats(&self) -> ClientStats {
        ClientStats {
            decode: self.decoder.stats(),
            ..self.stats
        }
    }

    /// Unsolicited frames received while waiting for responses (oldest first).
    pub fn take_unsolicited(&mut self) -> Vec<Frame> {
        self.unsolicited.drain(..).collect()
    }

    /// Gives the stream back.
    pub fn into_inner(self) -> T {
        self.io
    }

    /// The next frame ID (1..=255, wrapping past 0).
    pub fn allocate_frame_id(&mut self) -> u8 {
        let id = self.next_frame_id;
        self.next_frame_id = id.checked_add(1).unwrap_or(1);
        id
    }

    /// Writes one frame and flushes.
    pub async fn send_frame(&mut self, frame: &Frame) -> Result<(), XBeeError> {
        let bytes = frame.encode(self.config.mode)?;
        tracing::trace!(parent: &self.span, bytes = %HexBytes(&bytes), "xbee tx");
        self.io.write_all(&bytes).await?;
        self.io.flush().await?;
        Ok(())
    }

    /// The next frame received before `deadline`, or `None` at the deadline.
    pub async fn recv_frame(&mut self, deadline: Instant) -> Result<Option<Frame>, XBeeError> {
        let mut buf = [0u8; 256];
        loop {
            while let Some(item) = self.decoder.next_frame() {
                let Ok(data) = item else { continue };
                match Frame::parse(&data) {
                    Ok(frame) => return Ok(Some(frame)),
                    Err(e) => {
                        self.stats.malformed_frames += 1;
                        tracing::warn!(parent: &self.span, error = %e, "xbee: malformed frame dropped");
                    }
                }
            }
            let n = match tokio::time::timeout_at(deadline, self.io.read(&mut buf)).await {
                Err(_elapsed) => return Ok(None),
                Ok(read) => read?,
            };
            if n == 0 {
                return Err(XBeeError::Closed);
            }
            let chunk = buf.get(..n).unwrap_or(&[]);
            tracing::trace!(parent: &self.span, bytes = %HexBytes(chunk), "xbee rx");
            self.decoder.push(chunk);
        }
    }

    /// Files a frame that was not the one being waited for.
    fn set_aside(&mut self, frame: Frame) {
        match frame {
            Frame::AtResponse(_) | Frame::RemoteAtResponse(_) | Frame::TransmitStatus(_) => {
                self.stats.stray_responses += 1;
                tracing::debug!(parent: &self.span, ?frame, "xbee: stray response ignored");
            }
            other => {
                if self.unsolicited.len() >= UNSOLICITED_CAPACITY {
                    self.unsolicited.pop_front();
                    self.stats.unsolicited_dropped += 1;
                    tracing::warn!(parent: &self.span, "xbee: unsolicited queue full, oldest frame dropped");
                }
                self.unsolicited.push_back(other);
            }
        }
    }

    /// Sends a local AT command and returns its response, whatever the status.
    pub async fn at_command(
        &mut self,
        command: AtCommandName,
        parameter: &[u8],
    ) -> Result<AtResponse, XBeeError> {
        let frame_id = self.allocate_frame_id();
        self.send_frame(&Frame::AtCommand(AtCommand {
            frame_id,
            command,
            parameter: parameter.to_vec(),
            queued: false,
        }))
        .await?;
        let waited = self.config.response_timeout;
        let deadline = Instant::now() + waited;
        while let Some(frame) = self.recv_frame(deadline).await? {
            match frame {
                Frame::AtResponse(r) if r.frame_id == frame_id && r.command == command => {
                    return Ok(r)
                }
                other => self.set_aside(other),
            }
        }
        Err(XBeeError::Timeout { command, waited })
    }

    /// Sends a local AT command and fails unless the status is OK; returns the value.
    pub async fn at_command_ok(
        &mut self,
        command: AtCommandName,
        parameter: &[u8],
    ) -> Result<Vec<u8>, XBeeError> {
        let r = self.at_command(command, parameter).await?;
        match r.status() {
            AtStatus::Ok => Ok(r.data),
            status => Err(XBeeError::Status {
                command,
                status,
                status_byte: r.status_byte,
            }),
        }
    }

    /// Sends an AT command to a remote radio (0x17) and returns its 0x97 response, whatever
    /// the status.
    pub async fn remote_at_command(
        &mut self,
        destination: Address64,
        command: AtCommandName,
        parameter: &[u8],
    ) -> Result<RemoteAtResponse, XBeeError> {
        let frame_id = self.allocate_frame_id();
        self.send_frame(&Frame::RemoteAtCommand(RemoteAtCommand {
            frame_id,
            destination,
            destination16: Address16::UNKNOWN,
            options: 0,
            command,
            parameter: parameter.to_vec(),
        }))
        .await?;
        let waited = self.config.remote_timeout;
        let deadline = Instant::now() + waited;
        while let Some(frame) = self.recv_frame(deadline).await? {
            match frame {
                Frame::RemoteAtResponse(r)
                    if r.frame_id == frame_id
                        && r.command == command
                        && r.source == destination =>
                {
                    return Ok(r)
                }
                other => self.set_aside(other),
            }
        }
        Err(XBeeError::Timeout { command, waited })
    }

    /// Sets `NT` on the radio (rounded up to 100 ms units, 1..=255) and uses it for discovery.
    pub async fn set_node_discovery_timeout(&mut self, nt: Duration) -> Result<(), XBeeError> {
        let units = nt.as_millis().div_ceil(100);
        let units = u8::try_from(units)
            .ok()
            .filter(|u| *u >= 1)
            .ok_or_else(|| {
                XBeeError::InvalidSetting(format!("NT {nt:?} outside 100 ms..=25.5 s"))
            })?;
        self.at_command_ok(AtCommandName::NT, &[units]).await?;
        self.nt_units_set = Some(units);
        self.config.node_discovery_timeout = Duration::from_millis(u64::from(units) * 100);
        Ok(())
    }

    /// Sets `NT` if it differs from the last value set, then runs [`XBeeClient::discover`].
    pub async fn discover_with_timeout(
        &mut self,
        nt: Duration,
    ) -> Result<NodeDiscovery, XBeeError> {
        let units = nt.as_millis().div_ceil(100);
        if self.nt_units_set.map(u128::from) != Some(units) {
            self.set_node_discovery_timeout(nt).await?;
        }
        self.discover().await
    }

    /// Sends `ND` and collects the responses until the empty end frame or until `NT` plus the
    /// margin has passed.
    pub async fn discover(&mut self) -> Result<NodeDiscovery, XBeeError> {
        let command = AtCommandName::ND;
        let frame_id = self.allocate_frame_id();
        self.send_frame(&Frame::AtCommand(AtCommand {
            frame_id,
            command,
            parameter: Vec::new(),
            queued: false,
        }))
        .await?;
        let deadline =
            Instant::now() + self.config.node_discovery_timeout + self.config.discovery_margin;
        let mut nodes = Vec::new();
        let mut rejected = Vec::new();
        while let Some(frame) = self.recv_frame(deadline).await? {
            let r = match frame {
                Frame::AtResponse(r) if r.frame_id == frame_id && r.command == command => r,
                other => {
                    self.set_aside(other);
                    continue;
                }
            };
            if r.status() != AtStatus::Ok {
                return Err(XBeeError::Status {
                    command,
                    status: r.status(),
                    status_byte: r.status_byte,
                });
            }
            if r.data.is_empty() {
                return Ok(NodeDiscovery {
                    nodes,
                    end: DiscoveryEnd::EndFrame,
                    rejected,
                });
            }
            match Node::parse(&r.data, self.config.nd_layout) {
                Ok(node) => {
                    tracing::debug!(parent: &self.span, address = %node.address, ni = %node.ni, "xbee: node discovered");
                    nodes.push(node);
                }
                Err(e) => {
                    self.stats.bad_nd_records += 1;
                    tracing::warn!(parent: &self.span, error = %e, "xbee: ND record rejected");
                    rejected.push(e);
                }
            }
        }
        Ok(NodeDiscovery {
            nodes,
            end: DiscoveryEnd::Timeout,
            rejected,
        })
    }

    /// Local `DB`: RSSI of the last packet the radio received, in dBm (`None` if it reports 0,
    /// i.e. nothing received).
    pub async fn local_rssi(&mut self) -> Result<Option<f64>, XBeeError> {
        let data = self.at_command_ok(AtCommandName::DB, &[]).await?;
        db_value_to_dbm(AtCommandName::DB, &data)
    }

    /// Remote `DB` (0x17 → 0x97): the RSSI the remote measured on the request it just
    /// received, in dBm. `None` when the remote did not answer (status 4) or reports 0.
    pub async fn remote_rssi(&mut self, node: Address64) -> Result<Option<f64>, XBeeError> {
        let r = self.remote_at_command(node, AtCommandName::DB, &[]).await?;
        match r.status() {
            AtStatus::Ok => db_value_to_dbm(AtCommandName::DB, &r.data),
            AtStatus::TxFailure => Ok(None),
            status => Err(XBeeError::Status {
                command: AtCommandName::DB,
                status,
                status_byte: r.status_byte,
            }),
        }
    }
}

impl<T> XBeeClient<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    /// RSSI of the link to `node` in dBm from the configured [`RssiSource`]; `None` when the
    /// beacon did not answer or the radio reports 0.
    pub async fn node_rssi(&mut self, node: Address64) -> Result<Option<f64>, XBeeError> {
        match self.config.rssi_source {
            RssiSource::RemoteDb => self.remote_rssi(node).await,
            RssiSource::LocalDbAfterRemote => match self.remote_rssi(node).await? {
                None => Ok(None),
                Some(_) => self.local_rssi().await,
            },
        }
    }
}

/// Reads a `DB` value (big-endian unsigned, "positive number = −dBm").
fn db_value_to_dbm(command: AtCommandName, data: &[u8]) -> Result<Option<f64>, XBeeError> {
    match data {
        [] | [0] => Ok(None),
        [b] => Ok(Some(rssi_byte_to_dbm(*b))),
        _ => Err(XBeeError::BadValue {
            command,
            data: data.to_vec(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::encode_frame;
    use crate::frame::ModemStatus;
    use tokio::io::{duplex, DuplexStream};

    fn client(io: DuplexStream) -> XBeeClient<DuplexStream> {
        XBeeClient::new(
            io,
            ClientConfig {
                response_timeout: Duration::from_millis(200),
                ..ClientConfig::default()
            },
        )
    }

    fn wire(frame: &Frame) -> Vec<u8> {
        frame.encode(ApiMode::Escaped).unwrap()
    }

    /// Reads one request frame from the device side.
    async fn read_request(device: &mut DuplexStream) -> Frame {
        let mut decoder = FrameDecoder::new(ApiMode::Escaped);
        let mut buf = [0u8; 64];
        loop {
            if let Some(Ok(data)) = decoder.next_frame() {
                return Frame::parse(&data).unwrap();
            }
            let n = device.read(&mut buf).await.unwrap();
            decoder.push(&buf[..n]);
        }
    }

    #[tokio::test]
    async fn response_found_among_noise_stray_and_unsolicited_frames() {
        let (host, mut device) = duplex(1024);
        let mut client = client(host);
        let peer = tokio::spawn(async move {
            let Frame::AtCommand(request) = read_request(&mut device).await else {
                panic!("expected an AT command")
            };
            let mut out = vec![0x00, 0x13, 0x55]; // line noise
            out.extend(wire(&Frame::ModemStatus(ModemStatus { status: 6 })));
            out.extend(wire(&Frame::AtResponse(AtResponse {
                frame_id: request.frame_id.wrapping_add(7),
                command: AtCommandName::DB,
                status_byte: 0,
                data: vec![0x40],
            })));
            out.extend(encode_frame(&[0x88, 0x01], ApiMode::Escaped).unwrap()); // too short
            out.extend(wire(&Frame::AtResponse(AtResponse {
                frame_id: request.frame_id,
                command: AtCommandName::DB,
                status_byte: 0,
                data: vec![0x50],
            })));
            device.write_all(&out).await.unwrap();
            device
        });
        assert_eq!(client.local_rssi().await.unwrap(), Some(-80.0));
        let stats = client.stats();
        assert_eq!(stats.decode.dropped_bytes, 3);
        assert_eq!((stats.stray_responses, stats.malformed_frames), (1, 1));
        assert_eq!(
            client.take_unsolicited(),
            vec![Frame::ModemStatus(ModemStatus { status: 6 })]
        );
        drop(peer.await.unwrap());
    }

    #[tokio::test]
    async fn silent_device_times_out_and_closed_stream_is_reported() {
        let (host, device) = duplex(1024);
        let mut client = client(host);
        let err = client.at_command(AtCommandName::NT, &[]).await.unwrap_err();
        assert!(
            matches!(
                err,
                XBeeError::Timeout {
                    command: AtCommandName::NT,
                    ..
                }
            ),
            "{err}"
        );
        drop(device);
        let err = client.at_command(AtCommandName::NT, &[]).await.unwrap_err();
        assert!(matches!(err, XBeeError::Closed | XBeeError::Io(_)), "{err}");
    }

    #[tokio::test]
    async fn nd_error_status_is_an_error_and_db_of_two_bytes_is_rejected() {
        let (host, mut device) = duplex(1024);
        let mut client = client(host);
        let peer = tokio::spawn(async move {
            for (status_byte, data) in [(1u8, vec![]), (0, vec![0x00, 0x50])] {
                let request = read_request(&mut device).await;
                let Frame::AtCommand(c) = request else {
                    panic!("expected an AT command")
                };
                let reply = Frame::AtResponse(AtResponse {
                    frame_id: c.frame_id,
                    command: c.command,
                    status_byte,
                    data,
                });
                device.write_all(&wire(&reply)).await.unwrap();
            }
            device
        });
        let err = client.discover().await.unwrap_err();
        assert!(
            matches!(
                err,
                XBeeError::Status {
                    status: AtStatus::Error,
                    ..
                }
            ),
            "{err}"
        );
        let err = client.local_rssi().await.unwrap_err();
        assert!(matches!(err, XBeeError::BadValue { .. }), "{err}");
        drop(peer.await.unwrap());
    }

    #[test]
    fn frame_ids_skip_zero() {
        let (host, _device) = duplex(16);
        let mut client = client(host);
        let ids: Vec<u8> = (0..512).map(|_| client.allocate_frame_id()).collect();
        assert!(!ids.contains(&0));
        assert_eq!(ids[254], 255);
        assert_eq!(ids[255], 1);
    }
}
