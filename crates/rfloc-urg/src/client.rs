//! An async SCIP 2.0 client over any byte stream: laser on, one `GD` scan at a time, laser off.

use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use crate::command::Command;
use crate::error::ScipError;
use crate::reply::{DecodeStats, Reply, ReplyDecoder};
use crate::scan::{Scan, UrgGeometry};

/// Client settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UrgConfig {
    /// The sensor's geometry (which steps to ask for, how to read them).
    pub geometry: UrgGeometry,
    /// Adjacent steps merged into one value (1 = every step).
    pub cluster: u8,
    /// How long one reply may take.
    pub reply_timeout: Duration,
}

impl Default for UrgConfig {
    fn default() -> Self {
        Self {
            geometry: UrgGeometry::default(),
            cluster: 1,
            reply_timeout: Duration::from_secs(1),
        }
    }
}

/// What the sensor told about itself in the handshake ([`UrgClient::connect`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SensorInfo {
    /// The `VV` fields (`VEND`, `PROD`, `FIRM`, `PROT`, `SERI`), empty when `VV` failed.
    pub version: Vec<(String, String)>,
    /// The `PP` fields, empty when `PP` failed.
    pub parameters: Vec<(String, String)>,
    /// The geometry read from `PP`; `None` when `PP` failed or lacked a field (the client
    /// then keeps its configured geometry).
    pub geometry: Option<UrgGeometry>,
}

impl SensorInfo {
    /// A `VV` or `PP` field.
    #[must_use]
    pub fn field(&self, key: &str) -> Option<&str> {
        self.version
            .iter()
            .chain(&self.parameters)
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// The geometry in `PP` fields: `ARES`, `AFRT`, `AMIN`, `AMAX`, `DMIN`, `DMAX` all present,
/// numeric and consistent (`AMIN ≤ AMAX < ARES`, `DMIN < DMAX`).
#[must_use]
pub fn geometry_from_parameters(fields: &[(String, String)]) -> Option<UrgGeometry> {
    let get = |k: &str| -> Option<u32> {
        fields
            .iter()
            .find(|(key, _)| key == k)
            .and_then(|(_, v)| v.trim().parse().ok())
    };
    let step = |k: &str| get(k).and_then(|v| u16::try_from(v).ok());
    let g = UrgGeometry {
        steps_per_rev: step("ARES")?,
        front_step: step("AFRT")?,
        first_step: step("AMIN")?,
        last_step: step("AMAX")?,
        min_mm: get("DMIN")?,
        max_mm: get("DMAX")?,
    };
    (g.first_step <= g.last_step && g.last_step < g.steps_per_rev && g.min_mm < g.max_mm)
        .then_some(g)
}

/// A URG sensor behind a stream.
pub struct UrgClient<T> {
    io: T,
    decoder: ReplyDecoder,
    config: UrgConfig,
}

impl<T: AsyncRead + AsyncWrite + Unpin> UrgClient<T> {
    /// A client that uses the configured geometry as it is (no handshake).
    #[must_use]
    pub fn new(io: T, config: UrgConfig) -> Self {
        Self {
            io,
            decoder: ReplyDecoder::new(),
            config,
        }
    }

    /// A client that first asks the sensor what it is: `SCIP2.0` (status `00`, or `0E` from a
    /// sensor already speaking SCIP 2.0), `VV` and `PP`. The geometry `PP` reports replaces
    /// the configured one; when `PP` fails or is incomplete the configured geometry stays
    /// (a warning is logged). Only link failures are errors.
    ///
    /// # Errors
    /// [`ScipError::Io`] and [`ScipError::Closed`]; time-outs and refusals are not.
    pub async fn connect(io: T, config: UrgConfig) -> Result<(Self, SensorInfo), ScipError> {
        let mut client = Self::new(io, config);
        let info = client.identify().await?;
        Ok((client, info))
    }

    /// The handshake of [`UrgClient::connect`] on an existing client.
    ///
    /// # Errors
    /// As [`UrgClient::connect`].
    pub async fn identify(&mut self) -> Result<SensorInfo, ScipError> {
        let mut info = SensorInfo::default();
        match self.exchange(Command::Scip2).await {
            Ok(r) if matches!(&r.status, b"00" | b"0E") => {}
            Ok(r) => {
                tracing::warn!(status = ?String::from_utf8_lossy(&r.status), "SCIP2.0 refused")
            }
            Err(e) => Self::fatal_or_warn(e, "SCIP2.0")?,
        }
        match self.info(Command::Version).await {
            Ok(v) => info.version = v,
            Err(e) => Self::fatal_or_warn(e, "VV")?,
        }
        match self.info(Command::Parameters).await {
            Ok(p) => {
                info.geometry = geometry_from_parameters(&p);
                info.parameters = p;
            }
            Err(e) => Self::fatal_or_warn(e, "PP")?,
        }
        match info.geometry {
            Some(g) => self.config.geometry = g,
            None => tracing::warn!(
                geometry = ?self.config.geometry,
                "no usable PP geometry; keeping the configured one"
            ),
        }
        Ok(info)
    }

    /// Link failures end the handshake; anything else is logged and skipped.
    fn fatal_or_warn(e: ScipError, what: &str) -> Result<(), ScipError> {
        match e {
            ScipError::Io(_) | ScipError::Closed => Err(e),
            other => {
                tracing::warn!(command = what, error = %other, "URG handshake step failed");
                Ok(())
            }
        }
    }

    /// The `KEY:value` fields of an information command's reply.
    async fn info(&mut self, command: Command) -> Result<Vec<(String, String)>, ScipError> {
        let r = self.exchange(command).await?;
        if !r.ok() {
            return Err(ScipError::Status {
                echo: r.echo,
                status: r.status,
            });
        }
        r.info()
    }

    /// Reads `PP` and, when it carries a usable geometry, uses it from now on; otherwise the
    /// geometry in use stays. Returns the geometry in use afterwards.
    ///
    /// # Errors
    /// Link failures only.
    pub async fn read_parameters(&mut self) -> Result<UrgGeometry, ScipError> {
        match self.info(Command::Parameters).await {
            Ok(p) => match geometry_from_parameters(&p) {
                Some(g) => self.config.geometry = g,
                None => tracing::warn!("PP without a usable geometry; keeping the configured one"),
            },
            Err(e) => Self::fatal_or_warn(e, "PP")?,
        }
        Ok(self.config.geometry)
    }

    /// The geometry the client scans with: the one `PP` reported, or the configured one.
    #[must_use]
    pub fn geometry(&self) -> UrgGeometry {
        self.config.geometry
    }

    /// Switches the laser on (`BM`); a sensor whose laser is already on answers status `02`,
    /// which counts as success.
    ///
    /// # Errors
    /// Link failures, time-outs and other statuses.
    pub async fn laser_on(&mut self) -> Result<(), ScipError> {
        let r = self.exchange(Command::BeamOn).await?;
        match &r.status {
            b"00" | b"02" => Ok(()),
            _ => Err(ScipError::Status {
                echo: r.echo,
                status: r.status,
            }),
        }
    }

    /// Switches the laser off (`QT`).
    ///
    /// # Errors
    /// Link failures, time-outs and error statuses.
    pub async fn laser_off(&mut self) -> Result<(), ScipError> {
        let r = self.exchange(Command::Quit).await?;
        if r.ok() {
            Ok(())
        } else {
            Err(ScipError::Status {
                echo: r.echo,
                status: r.status,
            })
        }
    }

    /// The latest scan over the geometry's measured steps (`GD`).
    ///
    /// # Errors
    /// Link failures, time-outs, error statuses (`10`: laser off) and malformed data.
    pub async fn scan(&mut self) -> Result<Scan, ScipError> {
        let g = self.config.geometry;
        let r = self
            .exchange(Command::GetDistance {
                start: g.first_step,
                end: g.last_step,
                cluster: self.config.cluster,
            })
            .await?;
        Scan::from_reply(&r)
    }

    /// The client's settings.
    #[must_use]
    pub fn config(&self) -> &UrgConfig {
        &self.config
    }

    /// Decoder counters (replies, dropped replies and bytes).
    #[must_use]
    pub fn stats(&self) -> DecodeStats {
        self.decoder.stats()
    }

    /// Sends `command` and waits for the reply that echoes it. Replies to other commands (a
    /// late answer to an earlier, timed-out request) are skipped; damaged replies are dropped
    /// by the decoder and waiting goes on.
    async fn exchange(&mut self, command: Command) -> Result<Reply, ScipError> {
        self.io
            .write_all(&command.to_bytes())
            .await
            .map_err(|e| ScipError::Io(e.to_string()))?;
        self.io
            .flush()
            .await
            .map_err(|e| ScipError::Io(e.to_string()))?;
        let expected = command.echo();
        let limit = self.config.reply_timeout;
        let wait = async {
            let mut buf = [0u8; 1024];
            loop {
                while let Some(reply) = self.decoder.next_reply() {
                    match reply {
                        Ok(r) if r.echo == expected => return Ok(r),
                        Ok(r) => {
                            tracing::debug!(echo = ?String::from_utf8_lossy(&r.echo), "reply to another command skipped");
                        }
                        Err(_) => {}
                    }
                }
                let n = self
                    .io
                    .read(&mut buf)
                    .await
                    .map_err(|e| ScipError::Io(e.to_string()))?;
                if n == 0 {
                    return Err(ScipError::Closed);
                }
                self.decoder.push(buf.get(..n).unwrap_or_default());
            }
        };
        tokio::time::timeout(limit, wait)
            .await
            .map_err(|_| ScipError::Timeout(limit))?
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encoding::check_sum;
    use rfloc_transport::MockTransport;

    fn gd_reply(echo: &[u8], ranges: &[u32]) -> Vec<u8> {
        Reply::distance(echo, 42, ranges).to_bytes()
    }

    fn three_step_config() -> UrgConfig {
        UrgConfig {
            geometry: UrgGeometry {
                first_step: 383,
                last_step: 385,
                ..UrgGeometry::default()
            },
            ..UrgConfig::default()
        }
    }

    #[tokio::test]
    async fn a_late_reply_to_another_command_is_skipped() {
        // The BM answer arrives only after the GD request: the client skips it and takes the
        // GD answer that follows.
        let io = MockTransport::builder()
            .expect_write(b"GD0383038501\n")
            .reply(b"BM\n00P\n\n")
            .reply(gd_reply(b"GD0383038501", &[1000, 2000, 3000]))
            .build();
        let mut client = UrgClient::new(io, three_step_config());
        let scan = client.scan().await.unwrap();
        assert_eq!(scan.ranges_mm, vec![1000, 2000, 3000]);
        assert_eq!(scan.timestamp_ms, 42);
    }

    #[tokio::test]
    async fn a_damaged_reply_is_dropped_and_no_scan_is_made_up() {
        let mut bad = gd_reply(b"GD0383038501", &[1000, 2000, 3000]);
        let at = bad.len() - 4;
        bad[at] ^= 1;
        let io = MockTransport::builder()
            .expect_write(b"GD0383038501\n")
            .reply(bad)
            .build();
        let mut client = UrgClient::new(
            io,
            UrgConfig {
                reply_timeout: Duration::from_millis(50),
                ..three_step_config()
            },
        );
        // The mock ends after its script: the wait ends with the link, not with a scan.
        assert!(matches!(
            client.scan().await,
            Err(ScipError::Closed | ScipError::Timeout(_))
        ));
        assert_eq!(client.stats().bad_replies, 1);
    }

    #[tokio::test]
    async fn handshake_reads_pp_byte_for_byte() {
        let io = MockTransport::builder()
            .expect_write(b"SCIP2.0\n")
            .reply(b"SCIP2.0\n0Ee\n\n")
            .expect_write(b"VV\n")
            .reply(b"VV\n00P\nPROT:SCIP 2.0;N\n\n")
            .expect_write(b"PP\n")
            .reply(
                b"PP\n00P\nDMIN:20;4\nDMAX:4000;X\nARES:1024;\\\nAMIN:44;7\nAMAX:725;o\nAFRT:384;6\nSCAN:600;e\n\n",
            )
            .build();
        let (client, info) = UrgClient::connect(io, UrgConfig::default()).await.unwrap();
        let g = UrgGeometry {
            max_mm: 4000,
            ..UrgGeometry::default()
        };
        assert_eq!(info.geometry, Some(g));
        assert_eq!(client.geometry(), g);
        assert_eq!(info.field("PROT"), Some("SCIP 2.0"));
    }

    #[tokio::test]
    async fn a_refused_pp_keeps_the_configured_geometry() {
        // A SCIP 1.1-only answer to everything: undefined command `0D`.
        let io = MockTransport::builder()
            .expect_write(b"SCIP2.0\n")
            .reply(b"SCIP2.0\n00P\n\n")
            .expect_write(b"VV\n")
            .reply(b"VV\n0Dd\n\n")
            .expect_write(b"PP\n")
            .reply(b"PP\n0Dd\n\n")
            .build();
        let (client, info) = UrgClient::connect(io, UrgConfig::default()).await.unwrap();
        assert_eq!(info.geometry, None);
        assert!(info.version.is_empty() && info.parameters.is_empty());
        assert_eq!(client.geometry(), UrgGeometry::default());
    }

    #[tokio::test]
    async fn laser_on_accepts_already_on_and_refuses_trouble() {
        let io = MockTransport::builder()
            .expect_write(b"BM\n")
            .reply(b"BM\n02R\n\n")
            .expect_write(b"BM\n")
            .reply([b"BM\n50".as_slice(), &[check_sum(b"50")], b"\n\n"].concat())
            .build();
        let mut client = UrgClient::new(io, UrgConfig::default());
        client.laser_on().await.unwrap();
        assert!(matches!(
            client.laser_on().await,
            Err(ScipError::Status { status, .. }) if &status == b"50"
        ));
    }
}
