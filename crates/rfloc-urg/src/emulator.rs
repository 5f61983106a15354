//! A URG sensor emulator over any byte stream, for tests, peers and the simulator: the SCIP 2.0
//! command set of a URG-04LX (`SCIP2.0`, `VV`, `PP`, `II`, `BM`, `QT`, `RS`, `TM0/1/2`,
//! `GD`/`GS`, `MD`/`MS` streaming) plus `%ST` (a SCIP 2.2 state query some hosts send first),
//! ranges from a function of the beam angle. See docs/protocols/hokuyo-scip.md §6 for what it
//! answers and how that differs from the sensor.

use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::MissedTickBehavior;

use crate::encoding::encode;
use crate::reply::Reply;
use crate::scan::UrgGeometry;

/// The range seen along a beam `angle` radians from straight ahead (counter-clockwise), metres;
/// `None` when nothing is in reach.
pub type RangeFn = Arc<dyn Fn(f64) -> Option<f64> + Send + Sync>;

/// Seconds on the emulator's clock (for the replies' time stamps).
pub type ClockFn = Arc<dyn Fn() -> f64 + Send + Sync>;

/// What `VV` and `PP` report besides the geometry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SensorIdentity {
    /// `VEND`.
    pub vendor: String,
    /// `PROD`.
    pub product: String,
    /// `FIRM`.
    pub firmware: String,
    /// `PROT`.
    pub protocol: String,
    /// `SERI`.
    pub serial: String,
    /// `MODL` (`PP`, `II`).
    pub model: String,
    /// `SCAN`: standard motor speed, rpm (600: one scan per 100 ms).
    pub scan_rpm: u32,
}

impl Default for SensorIdentity {
    /// A URG-04LX (the `PP` example of the specification; the `VV` texts in its format).
    fn default() -> Self {
        Self {
            vendor: "Hokuyo Automatic Co.,Ltd.".into(),
            product: "SOKUIKI Sensor URG-04LX".into(),
            firmware: "3.4.03(17/Dec./2007)".into(),
            protocol: "SCIP 2.0".into(),
            serial: "H0000001".into(),
            model: "URG-04LX(Hokuyo Automatic Co.,Ltd.)".into(),
            scan_rpm: 600,
        }
    }
}

/// Emulator settings.
#[derive(Clone, Default)]
pub struct EmulatorConfig {
    pub geometry: UrgGeometry,
    /// Time stamps from this clock (default: wall time since the emulator was made).
    pub clock: Option<ClockFn>,
    /// `VV`/`PP`/`II` texts (default: a URG-04LX).
    pub identity: SensorIdentity,
}

/// What one session saw.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct EmulatorStats {
    pub commands: u64,
    /// Scans sent (single `GD`/`GS` replies and `MD`/`MS` scan messages).
    pub scans: u64,
    pub unknown_commands: u64,
}

/// A running `MD`/`MS` request.
#[derive(Debug, Clone)]
struct Streaming {
    /// `MD`/`MS` + start, end, cluster and interval fields.
    head: Vec<u8>,
    /// `;string` as sent, or empty.
    tag: Vec<u8>,
    start: u16,
    end: u16,
    cluster: u16,
    width: usize,
    /// Scans skipped between two sent.
    interval: u8,
    /// Scans still to send; `None` = until `QT`.
    remaining: Option<u16>,
    /// Scan periods to wait before the next scan.
    wait: u8,
}

/// Per-connection sensor state.
#[derive(Debug, Default)]
struct Session {
    laser: bool,
    time_adjust: bool,
    streaming: Option<Streaming>,
    /// Added to the clock for time stamps (`RS` zeroes the timer).
    clock_offset_ms: f64,
    stats: EmulatorStats,
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

    /// One scan period of the motor (`60 / SCAN` s, 100 ms at 600 rpm).
    fn scan_period(&self) -> Duration {
        Duration::from_secs_f64(60.0 / f64::from(self.config.identity.scan_rpm.max(1)))
    }

    /// Answers commands on `stream` until it closes; the laser starts off. `MD`/`MS` scans are
    /// sent one scan period apart (times the interval) on wall time.
    ///
    /// # Errors
    /// Reading or writing the stream failed.
    pub async fn serve<S: AsyncRead + AsyncWrite + Unpin>(
        &self,
        mut stream: S,
    ) -> std::io::Result<EmulatorStats> {
        let mut session = Session::default();
        let mut pending: Vec<u8> = Vec::new();
        let mut buf = [0u8; 256];
        let mut ticker = tokio::time::interval(self.scan_period());
        ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                read = stream.read(&mut buf) => {
                    let n = read?;
                    if n == 0 {
                        return Ok(session.stats);
                    }
                    pending.extend_from_slice(buf.get(..n).unwrap_or_default());
                    let mut out = Vec::new();
                    while let Some(end) = pending.iter().position(|b| *b == b'\n' || *b == b'\r') {
                        let line: Vec<u8> = pending.drain(..=end).collect();
                        let line = line.get(..end).unwrap_or_default();
                        if line.is_empty() {
                            continue;
                        }
                        session.stats.commands += 1;
                        let was_streaming = session.streaming.is_some();
                        out.extend(self.answer(line, &mut session));
                        if !was_streaming && session.streaming.is_some() {
                            // The first scan is one measured after the request.
                            ticker.reset();
                        }
                    }
                    if pending.len() > 1024 {
                        pending.clear();
                    }
                    if !out.is_empty() {
                        stream.write_all(&out).await?;
                        stream.flush().await?;
                    }
                }
                _ = ticker.tick(), if session.streaming.is_some() => {
                    if let Some(bytes) = self.stream_tick(&mut session) {
                        stream.write_all(&bytes).await?;
                        stream.flush().await?;
                    }
                }
            }
        }
    }

    /// The reply to one command line (without its line end).
    fn answer(&self, line: &[u8], s: &mut Session) -> Vec<u8> {
        // `;` starts the optional string characters, echoed but not interpreted.
        let body = line
            .iter()
            .position(|b| *b == b';')
            .and_then(|i| line.get(..i))
            .unwrap_or(line);
        let status = |st: &[u8; 2]| Reply::status_only(line, *st).to_bytes();
        match body {
            // Already speaking SCIP 2.0: the sensor answers the switch with `0E`.
            b"SCIP2.0" => status(b"0E"),
            b"VV" => self.info(line, &self.version_fields()),
            b"PP" => self.info(line, &self.parameter_fields()),
            b"II" => {
                let fields = self.state_fields(s);
                self.info(line, &fields)
            }
            b"%ST" => {
                let state = match (&s.streaming, s.time_adjust, s.laser) {
                    (Some(_), _, _) => "004",
                    (None, true, _) => "002",
                    (None, false, true) => "003",
                    (None, false, false) => "000",
                };
                let mut r = Reply::status_only(line, *b"00");
                r.lines = vec![with_sum(state)];
                r.to_bytes()
            }
            b"BM" => {
                if s.time_adjust {
                    return status(b"10");
                }
                let st = if s.laser { b"02" } else { b"00" };
                s.laser = true;
                status(st)
            }
            b"QT" => {
                s.laser = false;
                s.streaming = None;
                status(b"00")
            }
            b"RS" => {
                s.laser = false;
                s.streaming = None;
                s.time_adjust = false;
                s.clock_offset_ms = -self.now_ms();
                status(b"00")
            }
            b"TM0" => {
                let st = if s.time_adjust { b"02" } else { b"00" };
                s.time_adjust = true;
                s.laser = false;
                s.streaming = None;
                status(st)
            }
            b"TM1" => {
                if !s.time_adjust {
                    return status(b"04");
                }
                let mut r = Reply::status_only(line, *b"00");
                r.lines = vec![with_sum_bytes(&encode(self.stamp(s), 4))];
                r.to_bytes()
            }
            b"TM2" => {
                let st = if s.time_adjust { b"00" } else { b"03" };
                s.time_adjust = false;
                status(st)
            }
            _ if body.starts_with(b"TM") => status(b"01"),
            _ if body.starts_with(b"GD") || body.starts_with(b"GS") => self.single(line, body, s),
            _ if body.starts_with(b"MD") || body.starts_with(b"MS") => {
                self.start_streaming(line, body, s)
            }
            _ => {
                s.stats.unknown_commands += 1;
                status(b"0D")
            }
        }
    }

    fn info(&self, echo: &[u8], fields: &[(&str, String)]) -> Vec<u8> {
        Reply::information(echo, fields).to_bytes()
    }

    fn version_fields(&self) -> Vec<(&'static str, String)> {
        let id = &self.config.identity;
        vec![
            ("VEND", id.vendor.clone()),
            ("PROD", id.product.clone()),
            ("FIRM", id.firmware.clone()),
            ("PROT", id.protocol.clone()),
            ("SERI", id.serial.clone()),
        ]
    }

    fn parameter_fields(&self) -> Vec<(&'static str, String)> {
        let g = &self.config.geometry;
        vec![
            ("MODL", self.config.identity.model.clone()),
            ("DMIN", g.min_mm.to_string()),
            ("DMAX", g.max_mm.to_string()),
            ("ARES", g.steps_per_rev.to_string()),
            ("AMIN", g.first_step.to_string()),
            ("AMAX", g.last_step.to_string()),
            ("AFRT", g.front_step.to_string()),
            ("SCAN", self.config.identity.scan_rpm.to_string()),
        ]
    }

    fn state_fields(&self, s: &Session) -> Vec<(&'static str, String)> {
        let stamp = String::from_utf8_lossy(&encode(self.stamp(s), 4)).into_owned();
        vec![
            ("MODL", self.config.identity.model.clone()),
            ("LASR", if s.laser { "ON" } else { "OFF" }.to_string()),
            (
                "SCSP",
                format!("Initial({}[rpm])", self.config.identity.scan_rpm),
            ),
            ("MESM", "Measuring in normal mode".to_string()),
            ("SBPS", "USB only".to_string()),
            ("TIME", stamp),
            ("STAT", "Sensor works well.".to_string()),
        ]
    }

    fn now_ms(&self) -> f64 {
        self.config
            .clock
            .as_ref()
            .map_or_else(|| self.started.elapsed().as_secs_f64(), |c| c())
            * 1000.0
    }

    /// The 24-bit millisecond time stamp.
    fn stamp(&self, s: &Session) -> u32 {
        ((self.now_ms() + s.clock_offset_ms).max(0.0) as u64 % (1 << 24)) as u32
    }

    /// Start, end and cluster of a `GD`/`GS`/`MD`/`MS` body, or the status refusing them.
    fn steps(&self, body: &[u8]) -> Result<(u16, u16, u16), [u8; 2]> {
        let g = &self.config.geometry;
        let (start, end, cluster) = match (
            number(body, 2..6),
            number(body, 6..10),
            number(body, 10..12),
        ) {
            (None, _, _) => return Err(*b"01"),
            (_, None, _) => return Err(*b"02"),
            (_, _, None) => return Err(*b"03"),
            (Some(s), Some(e), Some(c)) => (s, e, c.max(1)),
        };
        if end > g.last_step || start < g.first_step {
            return Err(*b"04");
        }
        if end < start {
            return Err(*b"05");
        }
        Ok((start, end, cluster))
    }

    fn single(&self, line: &[u8], body: &[u8], s: &mut Session) -> Vec<u8> {
        if body.len() != 12 {
            let st = if body.len() < 12 { b"0C" } else { b"0D" };
            return Reply::status_only(line, *st).to_bytes();
        }
        let (start, end, cluster) = match self.steps(body) {
            Ok(v) => v,
            Err(st) => return Reply::status_only(line, st).to_bytes(),
        };
        if !s.laser {
            return Reply::status_only(line, *b"10").to_bytes();
        }
        s.stats.scans += 1;
        let width = if body.starts_with(b"GS") { 2 } else { 3 };
        let ranges = self.cluster_ranges(start, end, cluster, width);
        Reply::distance_encoded(line, *b"00", self.stamp(s), &ranges, width).to_bytes()
    }

    fn start_streaming(&self, line: &[u8], body: &[u8], s: &mut Session) -> Vec<u8> {
        if body.len() != 15 {
            let st = if body.len() < 15 { b"0C" } else { b"0D" };
            return Reply::status_only(line, *st).to_bytes();
        }
        let (start, end, cluster) = match self.steps(body) {
            Ok(v) => v,
            Err(st) => return Reply::status_only(line, st).to_bytes(),
        };
        let Some(interval) = number(body, 12..13) else {
            return Reply::status_only(line, *b"06").to_bytes();
        };
        let Some(scans) = number(body, 13..15) else {
            return Reply::status_only(line, *b"07").to_bytes();
        };
        if s.time_adjust {
            return Reply::status_only(line, *b"10").to_bytes();
        }
        // The laser goes on for the measurement (REF §8.1).
        s.laser = true;
        s.streaming = Some(Streaming {
            head: body.get(..13).unwrap_or_default().to_vec(),
            tag: line.get(body.len()..).unwrap_or_default().to_vec(),
            start,
            end,
            cluster,
            width: if body.starts_with(b"MS") { 2 } else { 3 },
            interval: u8::try_from(interval).unwrap_or(9),
            remaining: (scans > 0).then_some(scans),
            wait: 0,
        });
        Reply::status_only(line, *b"00").to_bytes()
    }

    /// One scan period of a running `MD`/`MS`: the scan message when one is due.
    fn stream_tick(&self, s: &mut Session) -> Option<Vec<u8>> {
        let stamp = self.stamp(s);
        let st = s.streaming.as_mut()?;
        if st.wait > 0 {
            st.wait -= 1;
            return None;
        }
        st.wait = st.interval;
        let left = match &mut st.remaining {
            Some(n) => {
                *n = n.saturating_sub(1);
                *n
            }
            None => 0,
        };
        let mut echo = st.head.clone();
        echo.extend_from_slice(format!("{:02}", left % 100).as_bytes());
        echo.extend_from_slice(&st.tag);
        let ranges = self.cluster_ranges(st.start, st.end, st.cluster, st.width);
        let bytes = Reply::distance_encoded(&echo, *b"99", stamp, &ranges, st.width).to_bytes();
        if st.remaining == Some(0) {
            // The laser goes off after the last requested scan (REF §8.1).
            s.streaming = None;
            s.laser = false;
        }
        s.stats.scans += 1;
        Some(bytes)
    }

    /// One value per cluster (the smallest), each limited to what `width` characters carry.
    fn cluster_ranges(&self, start: u16, end: u16, cluster: u16, width: usize) -> Vec<u32> {
        let cap = if width == 2 { 0xFFF } else { 0x3_FFFF };
        let mut ranges = Vec::new();
        let mut step = start;
        while step <= end {
            let last = step.saturating_add(cluster - 1).min(end);
            let value = (step..=last)
                .map(|st| self.range_mm(f64::from(st)))
                .min()
                .unwrap_or(0);
            ranges.push(value.min(cap));
            step = last + 1;
        }
        ranges
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

/// A decimal field of a command body.
fn number(body: &[u8], r: std::ops::Range<usize>) -> Option<u16> {
    let field = body.get(r)?;
    if !field.iter().all(u8::is_ascii_digit) {
        return None;
    }
    std::str::from_utf8(field).ok()?.parse().ok()
}

/// A text line with its check sum.
fn with_sum(text: &str) -> Vec<u8> {
    with_sum_bytes(text.as_bytes())
}

fn with_sum_bytes(text: &[u8]) -> Vec<u8> {
    let mut l = text.to_vec();
    l.push(crate::encoding::check_sum(text));
    l
}

#[cfg(test)]
mod tests {
    use super::*;

    fn emulator() -> UrgEmulator {
        let clock: ClockFn = Arc::new(|| 16_000.0);
        UrgEmulator::new(
            Arc::new(|_| Some(1.0)),
            EmulatorConfig {
                clock: Some(clock),
                ..EmulatorConfig::default()
            },
        )
    }

    fn ask(e: &UrgEmulator, s: &mut Session, line: &str) -> String {
        String::from_utf8(e.answer(line.as_bytes(), s)).unwrap()
    }

    #[test]
    fn information_replies_are_the_urg_04lx_s() {
        let e = emulator();
        let mut s = Session::default();
        assert_eq!(ask(&e, &mut s, "SCIP2.0"), "SCIP2.0\n0Ee\n\n");
        assert_eq!(
            ask(&e, &mut s, "PP"),
            "PP\n00P\nMODL:URG-04LX(Hokuyo Automatic Co.,Ltd.);N\nDMIN:20;4\nDMAX:5600;_\n\
             ARES:1024;\\\nAMIN:44;7\nAMAX:725;o\nAFRT:384;6\nSCAN:600;e\n\n"
        );
        let vv = ask(&e, &mut s, "VV;a1");
        assert!(
            vv.starts_with("VV;a1\n00P\nVEND:Hokuyo Automatic Co.,Ltd.;"),
            "{vv}"
        );
        assert!(vv.contains("\nPROT:SCIP 2.0;"), "{vv}");
        assert!(ask(&e, &mut s, "II").contains("\nLASR:OFF;"));
        assert_eq!(ask(&e, &mut s, "%ST"), "%ST\n00P\n000@\n\n");
        assert_eq!(ask(&e, &mut s, "XX"), "XX\n0Dd\n\n");
    }

    #[test]
    fn time_adjustment_mode() {
        let e = emulator();
        let mut s = Session::default();
        assert_eq!(ask(&e, &mut s, "TM1"), "TM1\n04T\n\n");
        assert_eq!(ask(&e, &mut s, "TM0"), "TM0\n00P\n\n");
        assert_eq!(ask(&e, &mut s, "%ST"), "%ST\n00P\n002B\n\n");
        // The clock reads 16 000 s: 16 000 000 ms → `m2@0` (REF §6's example), its sum `?`.
        assert_eq!(ask(&e, &mut s, "TM1"), "TM1\n00P\nm2@0?\n\n");
        assert_eq!(ask(&e, &mut s, "TM0"), "TM0\n02R\n\n");
        assert_eq!(ask(&e, &mut s, "TM2"), "TM2\n00P\n\n");
        assert_eq!(ask(&e, &mut s, "TM2"), "TM2\n03S\n\n");
        assert_eq!(ask(&e, &mut s, "TM9"), "TM9\n01Q\n\n");
        // RS zeroes the timer.
        assert_eq!(ask(&e, &mut s, "RS"), "RS\n00P\n\n");
        ask(&e, &mut s, "TM0");
        assert_eq!(ask(&e, &mut s, "TM1"), "TM1\n00P\n00000\n\n");
    }

    #[test]
    fn gs_and_gd_encodings() {
        let e = emulator();
        let mut s = Session::default();
        assert_eq!(ask(&e, &mut s, "GS0384038501"), "GS0384038501\n10Q\n\n");
        ask(&e, &mut s, "BM");
        // 1000 mm: `?X` in two characters, `0?X` in three; time stamp 16 000 000 ms.
        assert_eq!(
            ask(&e, &mut s, "GS0384038501"),
            "GS0384038501\n00P\nm2@0?\n?X?X^\n\n"
        );
        assert_eq!(
            ask(&e, &mut s, "GD0384038502"),
            "GD0384038502\n00P\nm2@0?\n0?X7\n\n"
        );
        assert_eq!(ask(&e, &mut s, "GD0384038"), "GD0384038\n0Cc\n\n");
        assert_eq!(ask(&e, &mut s, "GD0044072601"), "GD0044072601\n04T\n\n");
    }

    #[test]
    fn md_streams_the_requested_scans_then_turns_the_laser_off() {
        let e = emulator();
        let mut s = Session::default();
        assert_eq!(
            ask(&e, &mut s, "MD0384038501102;x"),
            "MD0384038501102;x\n00P\n\n"
        );
        assert_eq!(ask(&e, &mut s, "%ST"), "%ST\n00P\n004D\n\n");
        let first = String::from_utf8(e.stream_tick(&mut s).unwrap()).unwrap();
        assert_eq!(first, "MD0384038501101;x\n99b\nm2@0?\n0?X0?X>\n\n");
        assert!(e.stream_tick(&mut s).is_none(), "interval 1 skips a scan");
        let last = String::from_utf8(e.stream_tick(&mut s).unwrap()).unwrap();
        assert!(last.starts_with("MD0384038501100;x\n99b\n"), "{last}");
        assert!(s.streaming.is_none() && !s.laser);
        // MS0 streams until QT.
        ask(&e, &mut s, "MS0384038401000");
        for _ in 0..5 {
            let m = String::from_utf8(e.stream_tick(&mut s).unwrap()).unwrap();
            assert!(m.starts_with("MS0384038401000\n99b\n"), "{m}");
        }
        assert_eq!(ask(&e, &mut s, "QT"), "QT\n00P\n\n");
        assert!(e.stream_tick(&mut s).is_none());
        assert_eq!(
            ask(&e, &mut s, "MD03840385011x1"),
            "MD03840385011x1\n07W\n\n"
        );
    }
}
