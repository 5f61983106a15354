//! A URG sensor emulator over any byte stream, for tests and the simulator: `BM`, `QT` and
//! `GD` as SCIP 2.0 specifies them, ranges from a function of the beam angle.

use std::sync::Arc;
use std::time::Instant;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use crate::reply::Reply;
use crate::scan::UrgGeometry;

/// The range seen along a beam `angle` radians from straight ahead (counter-clockwise), metres;
/// `None` when nothing is in reach.
pub type RangeFn = Arc<dyn Fn(f64) -> Option<f64> + Send + Sync>;

/// Seconds on the emulator's clock (for the replies' time stamps).
pub type ClockFn = Arc<dyn Fn() -> f64 + Send + Sync>;

/// Emulator settings.
#[derive(Clone, Default)]
pub struct EmulatorConfig {
    pub geometry: UrgGeometry,
    /// Time stamps from this clock (default: wall time since the emulator was made).
    pub clock: Option<ClockFn>,
}

/// What one session saw.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct EmulatorStats {
    pub commands: u64,
    pub scans: u64,
    pub unknown_commands: u64,
}

/// The emulated sensor.
pub struct UrgEmulator {
    ranges: RangeFn,
    config: EmulatorConfig,
    started: Instant,
}

impl UrgEmulator {
    #[must_use]
    pub fn new(ranges: RangeFn, config: EmulatorConfig) -> Self {
        Self {
            ranges,
            config,
            started: Instant::now(),
        }
    }

    /// Answers commands on `stream` until it closes; the laser starts off.
    ///
    /// # Errors
    /// Reading or writing the stream failed.
    pub async fn serve<S: AsyncRead + AsyncWrite + Unpin>(
        &self,
        mut stream: S,
    ) -> std::io::Result<EmulatorStats> {
        let mut stats = EmulatorStats::default();
        let mut laser = false;
        let mut pending: Vec<u8> = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            let n = stream.read(&mut buf).await?;
            if n == 0 {
                return Ok(stats);
            }
            pending.extend_from_slice(buf.get(..n).unwrap_or_default());
            while let Some(end) = pending.iter().position(|b| *b == b'\n' || *b == b'\r') {
                let line: Vec<u8> = pending.drain(..=end).collect();
                let line = line.get(..end).unwrap_or_default();
                if line.is_empty() {
                    continue;
                }
                stats.commands += 1;
                let reply = self.answer(line, &mut laser, &mut stats);
                stream.write_all(&reply).await?;
                stream.flush().await?;
            }
            if pending.len() > 1024 {
                pending.clear();
            }
        }
    }

    fn answer(&self, line: &[u8], laser: &mut bool, stats: &mut EmulatorStats) -> Vec<u8> {
        match line {
            b"BM" => {
                let status = if *laser { b"02" } else { b"00" };
                *laser = true;
                status_reply(line, status)
            }
            b"QT" => {
                *laser = false;
                status_reply(line, b"00")
            }
            _ if line.starts_with(b"GD") => {
                stats.scans += 1;
                self.distance(line, *laser)
            }
            _ => {
                stats.unknown_commands += 1;
                status_reply(line, b"0D")
            }
        }
    }

    fn distance(&self, line: &[u8], laser: bool) -> Vec<u8> {
        let g = &self.config.geometry;
        let number = |r: std::ops::Range<usize>| -> Option<u16> {
            std::str::from_utf8(line.get(r)?).ok()?.parse().ok()
        };
        let (start, end, cluster) = match (number(2..6), number(6..10), number(10..12)) {
            (None, _, _) => return status_reply(line, b"01"),
            (_, None, _) => return status_reply(line, b"02"),
            (_, _, None) => return status_reply(line, b"03"),
            (Some(s), Some(e), Some(c)) => (s, e, c.max(1)),
        };
        if end > g.last_step || start < g.first_step {
            return status_reply(line, b"04");
        }
        if end < start {
            return status_reply(line, b"05");
        }
        if !laser {
            return status_reply(line, b"10");
        }
        let now_s = self
            .config
            .clock
            .as_ref()
            .map_or_else(|| self.started.elapsed().as_secs_f64(), |c| c());
        let stamp = ((now_s * 1000.0).max(0.0) as u64 % (1 << 24)) as u32;
        let mut ranges = Vec::new();
        let mut step = start;
        while step <= end {
            let last = (step + cluster - 1).min(end);
            let value = (step..=last)
                .map(|s| self.range_mm(f64::from(s)))
                .min()
                .unwrap_or(0);
            ranges.push(value);
            step = last + 1;
        }
        Reply::distance(line, stamp, &ranges).to_bytes()
    }

    /// The range of `step` in mm; 0 (the URG-04LX's "no echo in range" code) when nothing is
    /// in reach.
    fn range_mm(&self, step: f64) -> u32 {
        let g = &self.config.geometry;
        match (self.ranges)(g.angle(step)) {
            Some(m) if m.is_finite() => {
                let mm = (m * 1000.0).round();
                if mm >= f64::from(g.min_mm) && mm <= f64::from(g.max_mm) {
                    mm as u32
                } else {
                    0
                }
            }
            _ => 0,
        }
    }
}

fn status_reply(echo: &[u8], status: &[u8; 2]) -> Vec<u8> {
    Reply {
        echo: echo.to_vec(),
        status: *status,
        timestamp_ms: None,
        data: Vec::new(),
    }
    .to_bytes()
}
