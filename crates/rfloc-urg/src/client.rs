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

/// A URG sensor behind a stream.
pub struct UrgClient<T> {
    io: T,
    decoder: ReplyDecoder,
    config: UrgConfig,
}

impl<T: AsyncRead + AsyncWrite + Unpin> UrgClient<T> {
    #[must_use]
    pub fn new(io: T, config: UrgConfig) -> Self {
        Self {
            io,
            decoder: ReplyDecoder::new(),
            config,
        }
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
