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
