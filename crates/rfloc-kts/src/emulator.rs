//! A device emulator: answers AT commands and, while scanning, reports the tags of a floor
//! grid that lie under an antenna whose position a closure supplies.
//!
//! RSSI follows seed 002's own emulator (Appendix A) through [`crate::rssi_table`]; the
//! auxiliary channel is the main value moved by −1, 0 or +1 (seeded RNG), clamped to 0..7, as
//! in the `a/b` pairs of the reference captures. A tag that was in range on the previous scan
//! and is not now is reported once as `SCAN:-UID=…`.
//!
//! Scans happen every `scan_period / time_scale` of wall time, or, in lock-step mode
//! ([`KtsEmulator::lock_step`]), only when the simulator asks through a [`ScanControl`]: each
//! request names how many bytes the emulator must have read (and answered) before it scans,
//! so a command the host wrote before the request is always in force for that scan.

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::framing::{FramedLine, LineFramer};
use crate::rssi_table::rssi_at_distance;
use crate::uid::Uid;

/// How grid tags get their UIDs (row-major order, x fastest).
#[derive(Debug, Clone, PartialEq)]
pub enum UidScheme {
    /// `base + index`, printed as 16 hex digits (`base` must be a valid ISO 15693 UID).
    Sequential { base: u64 },
    /// One UID per tag, row-major; tags beyond the list are left out.
    Explicit(Vec<Uid>),
}

/// A rectangular grid of floor tags.
#[derive(Debug, Clone, PartialEq)]
pub struct TagGrid {
    /// Position of the tag at row 0, column 0 (metres).
    pub origin: (f64, f64),
    /// Distance between neighbouring tags (metres).
    pub pitch: f64,
    pub rows: usize,
    pub cols: usize,
    pub uids: UidScheme,
}

impl TagGrid {
    /// Seed 002's test field (§7.3, Table 9): 3×3 tags at 100 mm pitch from (0, 0), IDs
    /// `…AE4 689 47A / 586 785 ADC / BF4 691 78D` by rows of increasing y. The UID prefix
    /// `E00401503A5BD` is the one in Table 7.
    #[must_use]
    pub fn seed002_test_field() -> Self {
        let ids = [
            "AE4", "689", "47A", "586", "785", "ADC", "BF4", "691", "78D",
        ];
        let uids = ids
            .iter()
            .filter_map(|s| Uid::parse(&format!("E00401503A5BD{s}")).ok())
            .collect();
        Self {
            origin: (0.0, 0.0),
            pitch: 0.1,
            rows: 3,
            cols: 3,
            uids: UidScheme::Explicit(uids),
        }
    }

    /// Every tag with its position (metres).
    #[must_use]
    pub fn tags(&self) -> Vec<(Uid, f64, f64)> {
        let mut out = Vec::with_capacity(self.rows * self.cols);
        for r in 0..self.rows {
            for c in 0..self.cols {
                let i = r * self.cols + c;
                let uid = match &self.uids {
                    UidScheme::Sequential { base } => base
                        .checked_add(i as u64)
                        .and_then(|v| Uid::from_u64(v).ok()),
                    UidScheme::Explicit(list) => list.get(i).cloned(),
                };
                if let Some(uid) = uid {
                    #[allow(clippy::cast_precision_loss)]
                    let (x, y) = (
                        self.origin.0 + c as f64 * self.pitch,
                        self.origin.1 + r as f64 * self.pitch,
                    );
                    out.push((uid, x, y));
                }
            }
        }
        out
    }
}

/// Supplies the antenna centre (metres) in the grid's frame.
pub type AntennaPosition = Arc<dyn Fn() -> (f64, f64) + Send + Sync>;

/// Emulator settings.
#[derive(Clone)]
pub struct EmulatorConfig {
    pub grid: TagGrid,
    pub antenna: AntennaPosition,
    /// Time between scan reports (seed 002 §7.2: readings every 100 ms).
    pub scan_period: Duration,
    /// Speed-up: the scan period is divided by this (2.0 = twice real time).
    pub time_scale: f64,
    /// Probability that an in-range tag is missed on one scan.
    pub miss_probability: f64,
    /// RNG seed (misses and auxiliary RSSI).
    pub seed: u64,
    /// Identification lines answered to `ATI` (the emulator's own, not the module's).
    pub ident: Vec<String>,
    /// The RSSI (0–7) of a tag at a distance (metres) from the antenna centre, `None` beyond
    /// the read range; called once per tag in range per scan (a simulator's noisy model).
    /// `None`: seed 002's emulator table ([`crate::rssi_table`]), noise-free.
    pub rssi: Option<RssiFn>,
    /// Where each tag really lies relative to its grid position (metres), row-major like
    /// [`TagGrid::tags`]; missing entries are exact. Placement error of a real floor.
    pub tag_offsets: Vec<(f64, f64)>,
}

/// A reader's RSSI as a function of the antenna–tag distance (metres).
pub type RssiFn = Arc<dyn Fn(f64) -> Option<u8> + Send + Sync>;

impl std::fmt::Debug for EmulatorConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmulatorConfig")
            .field("grid", &self.grid)
            .field("scan_period", &self.scan_period)
            .field("time_scale", &self.time_scale)
            .field("miss_probability", &self.miss_probability)
            .field("seed", &self.seed)
            .field("rssi", &self.rssi.as_ref().map(|_| "custom"))
            .field("tag_offsets", &self.tag_offsets.len())
            .finish_non_exhaustive()
    }
}

impl EmulatorConfig {
    /// Defaults around a grid and an antenna: 100 ms period, real time, no misses, seed 0.
    #[must_use]
    pub fn new(grid: TagGrid, antenna: AntennaPosition) -> Self {
        Self {
            grid,
            antenna,
            scan_period: Duration::from_millis(100),
            time_scale: 1.0,
            miss_probability: 0.0,
            seed: 0,
            ident: vec![
                "rfloc KTS RFIDM1356 emulator".to_string(),
                "S/N 0000000001".to_string(),
            ],
            rssi: None,
            tag_offsets: Vec::new(),
        }
    }
}

/// What one lock-step scan did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ScanStep {
    /// `SCAN:` lines written (0 when not scanning or nothing in range).
    pub lines: usize,
    /// Bytes the emulator has read so far.
    pub rx_bytes: u64,
    /// Bytes the emulator has written so far.
    pub tx_bytes: u64,
}

#[derive(Debug)]
struct ScanRequest {
    after_rx_bytes: u64,
    /// Scan, or only report the counters (see [`ScanControl::settle`]).
    scan: bool,
    done: oneshot::Sender<ScanStep>,
}

/// Drives a lock-step emulator (see [`KtsEmulator::lock_step`]). Cheap to clone.
#[derive(Debug, Clone)]
pub struct ScanControl {
    tx: mpsc::Sender<ScanRequest>,
}

impl ScanControl {
    /// One scan period: once the emulator has read at least `after_rx_bytes` bytes and answered
    /// every command in them, it scans (if scanning is on) and writes the report; returns what
    /// it wrote. Pass the number of bytes the host has written so far.
    ///
    /// # Errors
    /// `NotConnected` when the emulator is not serving (or stopped before the scan).
    pub async fn scan(&self, after_rx_bytes: u64) -> std::io::Result<ScanStep> {
        self.request(after_rx_bytes, true).await
    }

    /// As [`ScanControl::scan`] without the scan: returns the counters once the emulator has
    /// read `after_rx_bytes` bytes and answered them (so `tx_bytes` includes every reply).
    ///
    /// # Errors
    /// As [`ScanControl::scan`].
    pub async fn settle(&self, after_rx_bytes: u64) -> std::io::Result<ScanStep> {
        self.request(after_rx_bytes, false).await
    }

    async fn request(&self, after_rx_bytes: u64, scan: bool) -> std::io::Result<ScanStep> {
        let gone = || std::io::Error::new(std::io::ErrorKind::NotConnected, "emulator stopped");
        let (done, rx) = oneshot::channel();
        self.tx
            .send(ScanRequest {
                after_rx_bytes,
                scan,
                done,
            })
            .await
            .map_err(|_| gone())?;
        rx.await.map_err(|_| gone())
    }
}

/// Waits for the next scan request; never resolves without a receiver.
async fn next_scan(steps: &mut Option<mpsc::Receiver<ScanRequest>>) -> Option<ScanRequest> {
    match steps {
        Some(rx) => rx.recv().await,
        None => std::future::pending().await,
    }
}

/// The emulated reader.
#[derive(Debug)]
pub struct KtsEmulator {
    config: EmulatorConfig,
    tags: Vec<(Uid, f64, f64)>,
    rng: ChaCha8Rng,
    scanning: bool,
    echo: bool,
    in_field: BTreeSet<Uid>,
    /// Lock-step mode: scan requests.
    steps: Option<mpsc::Receiver<ScanRequest>>,
    rx_bytes: u64,
    tx_bytes: u64,
}

impl KtsEmulator {
    #[must_use]
    pub fn new(config: EmulatorConfig) -> Self {
        let tags = config
            .grid
            .tags()
            .into_iter()
            .enumerate()
            .map(|(i, (uid, x, y))| {
                let (dx, dy) = config.tag_offsets.get(i).copied().unwrap_or((0.0, 0.0));
                (uid, x + dx, y + dy)
            })
            .collect();
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        Self {
            config,
            tags,
            rng,
            scanning: false,
            echo: false,
            in_field: BTreeSet::new(),
            steps: None,
            rx_bytes: 0,
            tx_bytes: 0,
        }
    }

    /// Switches to lock-step mode: scans happen only through the returned control (and its
    /// clones), never on wall time; `time_scale` and `scan_period` are then not used.
    #[must_use]
    pub fn lock_step(&mut self) -> ScanControl {
        let (tx, rx) = mpsc::channel(4);
        self.steps = Some(rx);
        ScanControl { tx }
    }

    /// Serves `io` in a new task.
    pub fn spawn<T>(self, io: T) -> JoinHandle<std::io::Result<()>>
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    {
        let mut reader = self;
        tokio::spawn(
            async move { reader.serve(io).await }.instrument(tracing::info_span!("kts-emulator")),
        )
    }

    /// Serves `io` until it closes.
    ///
    /// # Errors
    /// I/O errors of the stream.
    pub async fn serve<T>(&mut self, io: T) -> std::io::Result<()>
    where
        T: AsyncRead + AsyncWrite + Unpin + Send,
    {
        // The reader outlives the link (a client may connect again, to the same reader in the
        // same mode); so does its lock-step control.
        let mut steps = self.steps.take();
        let served = self.serve_link(io, &mut steps).await;
        self.steps = steps;
        served
    }

    async fn serve_link<T>(
        &mut self,
        io: T,
        steps: &mut Option<mpsc::Receiver<ScanRequest>>,
    ) -> std::io::Result<()>
    where
        T: AsyncRead + AsyncWrite + Unpin + Send,
    {
        let (mut rd, mut wr) = tokio::io::split(io);
        let mut framer = LineFramer::new();
        let mut buf = [0u8; 256];
        let scale = if self.config.time_scale.is_finite() && self.config.time_scale > 0.0 {
            self.config.time_scale
        } else {
            1.0
        };
        let period = self
            .config
            .scan_period
            .div_f64(scale)
            .max(Duration::from_micros(100));
        let mut ticker = tokio::time::interval(period);
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let wall_clock = steps.is_none();
        let mut pending: Option<ScanRequest> = None;
        loop {
            if pending
                .as_ref()
                .is_some_and(|p| self.rx_bytes >= p.after_rx_bytes)
            {
                if let Some(req) = pending.take() {
                    let lines = if req.scan && self.scanning {
                        let report = self.scan_report();
                        self.write_out(&mut wr, &report).await?;
                        report.lines().count()
                    } else {
                        0
                    };
                    let _ = req.done.send(ScanStep {
                        lines,
                        rx_bytes: self.rx_bytes,
                        tx_bytes: self.tx_bytes,
                    });
                }
                continue;
            }
            // Biased: a command already received is answered before a scan due at once.
            tokio::select! {
                biased;
                n = rd.read(&mut buf) => {
                    let n = n?;
                    if n == 0 {
                        return Ok(());
                    }
                    for line in framer.push(buf.get(..n).unwrap_or_default()) {
                        let reply = match line {
                            FramedLine::Line(b) => self.answer(&String::from_utf8_lossy(&b)),
                            FramedLine::Overlong(_) => "ERROR\r\n".to_string(),
                        };
                        self.write_out(&mut wr, &reply).await?;
                    }
                    self.rx_bytes += n as u64;
                }
                req = next_scan(steps), if !wall_clock && pending.is_none() => match req {
                    Some(req) => pending = Some(req),
                    None => *steps = None,
                },
                _ = ticker.tick(), if wall_clock && self.scanning => {
                    let report = self.scan_report();
                    self.write_out(&mut wr, &report).await?;
                }
            }
        }
    }

    async fn write_out<W: AsyncWrite + Unpin>(
        &mut self,
        wr: &mut W,
        text: &str,
    ) -> std::io::Result<()> {
        if !text.is_empty() {
            self.tx_bytes += text.len() as u64;
            wr.write_all(text.as_bytes()).await?;
            wr.flush().await?;
        }
        Ok(())
    }

    /// The reply to one command line.
    fn answer(&mut self, line: &str) -> String {
        let cmd = line.trim();
        let mut out = String::new();
        if self.echo {
            out.push_str(cmd);
            out.push_str("\r\n");
        }
        let upper = cmd.to_ascii_uppercase();
        let ok = match upper.as_str() {
            "AT" => true,
            "ATI" => {
                for l in &self.config.ident {
                    out.push_str(l);
                    out.push_str("\r\n");
                }
                true
            }
            "ATE0" => {
                self.echo = false;
                true
            }
            "ATE1" => {
                self.echo = true;
                true
            }
            _ => match upper.strip_prefix("AT+SCAN=") {
                Some("0" | "OFF") => {
                    self.scanning = false;
                    self.in_field.clear();
                    true
                }
                Some(mode) if mode.split(',').any(|m| m.trim() == "AC") => {
                    self.scanning = true;
                    true
                }
                _ => false,
            },
        };
        out.push_str(if ok { "OK\r\n" } else { "ERROR\r\n" });
        out
    }

    /// One scan: `SCAN:+UID` for tags in range (minus misses), `SCAN:-UID` for tags that left.
    fn scan_report(&mut self) -> String {
        let (ax, ay) = (self.config.antenna)();
        let mut out = String::new();
        let mut now_in = BTreeSet::new();
        for (uid, x, y) in &self.tags {
            let d_m = ((x - ax).powi(2) + (y - ay).powi(2)).sqrt();
            let main = match &self.config.rssi {
                Some(f) => f(d_m),
                None => rssi_at_distance(d_m * 100.0),
            };
            let Some(main) = main else {
                continue;
            };
            now_in.insert(uid.clone());
            if self.rng.random::<f64>() < self.config.miss_probability {
                continue;
            }
            let aux = (i32::from(main) + self.rng.random_range(-1..=1)).clamp(0, 7);
            out.push_str(&format!("SCAN:+UID={uid},+RSSI={main}/{aux}\r\n"));
        }
        for gone in self.in_field.difference(&now_in) {
            out.push_str(&format!("SCAN:-UID={gone}\r\n"));
        }
        self.in_field = now_in;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    fn emulator(antenna: Arc<Mutex<(f64, f64)>>, miss: f64) -> KtsEmulator {
        let a = Arc::clone(&antenna);
        let mut cfg = EmulatorConfig::new(
            TagGrid::seed002_test_field(),
            Arc::new(move || *a.lock().unwrap()),
        );
        cfg.miss_probability = miss;
        cfg.seed = 7;
        KtsEmulator::new(cfg)
    }

    #[test]
    fn table9_layout() {
        let tags = TagGrid::seed002_test_field().tags();
        assert_eq!(tags.len(), 9);
        // Seed 002 Table 9: …AE4 at (0, 0), …ADC at (200, 100) mm, …78D at (200, 200) mm.
        let find = |s: &str| {
            tags.iter()
                .find(|(u, _, _)| u.to_string().ends_with(s))
                .map(|(_, x, y)| (*x, *y))
        };
        assert_eq!(find("AE4"), Some((0.0, 0.0)));
        let (x, y) = find("ADC").unwrap();
        assert!((x - 0.2).abs() < 1e-12 && (y - 0.1).abs() < 1e-12);
        let (x, y) = find("78D").unwrap();
        assert!((x - 0.2).abs() < 1e-12 && (y - 0.2).abs() < 1e-12);
    }

    #[test]
    fn sequential_uids() {
        let g = TagGrid {
            origin: (1.0, 2.0),
            pitch: 0.1,
            rows: 2,
            cols: 3,
            uids: UidScheme::Sequential {
                base: 0xE004_0150_3A5B_D000,
            },
        };
        let tags = g.tags();
        assert_eq!(tags.len(), 6);
        assert_eq!(tags[5].0.to_string(), "E00401503A5BD005");
        assert!((tags[5].1 - 1.2).abs() < 1e-12 && (tags[5].2 - 2.1).abs() < 1e-12);
    }

    #[test]
    fn commands_and_scan_reports() {
        let antenna = Arc::new(Mutex::new((0.1, 0.2)));
        let mut emu = emulator(Arc::clone(&antenna), 0.0);
        assert_eq!(emu.answer("AT"), "OK\r\n");
        assert_eq!(emu.answer("AT+Nope"), "ERROR\r\n");
        assert_eq!(emu.answer("AT+Scan=AC,RSSI"), "OK\r\n");
        assert!(emu.scanning);
        let report = emu.scan_report();
        // Over …691 at (100, 200) mm: RSSI 7 there; …BF4, …78D, …785 at 10 cm read 0.
        assert!(
            report.contains("SCAN:+UID=E00401503A5BD691,+RSSI=7/"),
            "{report}"
        );
        assert_eq!(report.lines().count(), 4, "{report}");
        *antenna.lock().unwrap() = (1.0, 1.0);
        let report = emu.scan_report();
        assert_eq!(report.matches("SCAN:-UID=").count(), 4, "{report}");
        assert_eq!(emu.answer("AT+Scan=0"), "OK\r\n");
        assert!(!emu.scanning);
        assert_eq!(emu.answer("ATE1"), "OK\r\n");
        assert_eq!(emu.answer("AT"), "AT\r\nOK\r\n");
    }

    #[test]
    fn misses_follow_the_probability() {
        let antenna = Arc::new(Mutex::new((0.1, 0.2)));
        let mut emu = emulator(antenna, 0.3);
        let seen: usize = (0..500)
            .map(|_| emu.scan_report().matches("SCAN:+UID").count())
            .sum();
        let rate = seen as f64 / 2000.0;
        assert!((rate - 0.7).abs() < 0.05, "seen rate {rate}");
    }
}
