//! `rfloc replay`: the daemon's pipeline on captured device logs.
//!
//! Each `.cap` in the folder is replayed through its real driver over a `ReplayIo` (stream mode,
//! as fast as possible) with the replay clock as the driver's clock, so every event carries its
//! recorded time. Events of all devices and the capture's `ev mark` records are merged by time
//! and fed to the pipeline; POSE lines go to stdout with times taken from the capture's
//! `started` header plus the recorded offset, so the output is the same on every run.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use rfloc_aria::{ConversionFactors, FrameDecoder, OdometryTracker, ServerPacket};
use rfloc_capture::{Capture, RecordKind};
use rfloc_kts::{KtsClient, KtsConfig};
use rfloc_transport::replay::{ReplayMode, Replayer};
use rfloc_transport::SharedClock;

use rfloc_xbee::{
    ApiMode, AtCommandName, AtStatus, Frame as XBeeFrame, FrameDecoder as XBeeFrameDecoder,
    NdLayoutHint, Node,
};

use crate::config::{
    AntennaSide, DriverConfig, EkfSlamSettings, EstimatorConfig, HfGridSettings, RobotConfig,
    SnapshotSettings, XbeeRole,
};
use crate::devices::{swept_beacons, SweepMark};
use crate::events::DeviceEvent;
use crate::message::{pose_json, target_json, PoseFormat};
use crate::pipeline;

/// Replays every capture in `dir` through the pipeline and prints POSE lines.
pub async fn replay_dir(
    dir: PathBuf,
    pipeline_name: Option<String>,
    cfg: Option<RobotConfig>,
) -> anyhow::Result<()> {
    let lines = replay_lines(&dir, pipeline_name.as_deref(), cfg.as_ref()).await?;
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    for l in lines {
        if writeln!(out, "{l}").is_err() {
            break;
        }
    }
    Ok(())
}

/// The POSE lines a replay of `dir` produces.
pub async fn replay_lines(
    dir: &Path,
    pipeline_name: Option<&str>,
    cfg: Option<&RobotConfig>,
) -> anyhow::Result<Vec<String>> {
    let mut caps = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "cap") {
            let cap = Capture::from_path(&path)?;
            caps.push((path, cap));
        }
    }
    caps.sort_by(|a, b| a.0.cmp(&b.0));
    anyhow::ensure!(!caps.is_empty(), "no .cap files in {}", dir.display());

    let has = |device: &str| {
        caps.iter().any(|(_, c)| {
            c.header
                .device
                .as_deref()
                .is_some_and(|d| d.starts_with(device))
        })
    };
    let estimator = match (pipeline_name, cfg) {
        (_, Some(c)) => c.estimator.clone(),
        (Some("odometry"), None) => EstimatorConfig::Odometry,
        (Some("hfgrid"), None) => EstimatorConfig::Hfgrid(HfGridSettings::default()),
        (Some("ekfslam"), None) => EstimatorConfig::Ekfslam(EkfSlamSettings::default()),
        (Some("snapshot"), None) => EstimatorConfig::Snapshot(snapshot_settings(dir)),
        (Some(other), None) => {
            anyhow::bail!("unknown pipeline {other:?} (odometry, hfgrid, ekfslam, snapshot)")
        }
        (None, None) if has("kts") => EstimatorConfig::Hfgrid(HfGridSettings::default()),
        (None, None) if has("alien") => EstimatorConfig::Snapshot(snapshot_settings(dir)),
        (None, None) if has("xbee") => EstimatorConfig::Ekfslam(EkfSlamSettings::default()),
        (None, None) => EstimatorConfig::Odometry,
    };

    let mut events = Vec::new();
    let mut started = None;
    for (path, cap) in &caps {
        let name = path
            .file_stem()
            .map_or_else(|| "device".to_string(), |s| s.to_string_lossy().to_string());
        let device = cap.header.device.clone().unwrap_or_default();
        if started.is_none() {
            started = cap.header.started.as_deref().and_then(parse_rfc3339);
        }
        for (t, text) in cap.events() {
            if let Some(mark) = text.strip_prefix("mark ") {
                events.push(DeviceEvent::Mark {
                    device: name.clone(),
                    t,
                    text: mark.to_string(),
                });
            }
        }
        match device.as_str() {
            "kts-rfidm1356" => events.extend(replay_kts(&name, cap.clone()).await?),
            "pioneer-aria" => events.extend(replay_aria(&name, cap.clone()).await?),
            "alien-alr9900" => events.extend(replay_alien(&name, cap)),
            "hokuyo-urg" => {
                let offset = cfg.and_then(|c| {
                    c.devices.iter().find_map(|d| match &d.driver {
                        DriverConfig::Urg(u) if d.name == name => Some(u.mount_offset_m),
                        _ => None,
                    })
                });
                events.extend(replay_urg(&name, cap, offset.unwrap_or(0.0)));
            }
            "xbee-api1" | "xbee-api2" => {
                let mode = if device == "xbee-api1" {
                    ApiMode::Unescaped
                } else {
                    ApiMode::Escaped
                };
                // The robot file says which radios are emitter receivers (and behind which
                // reflector); the others sweep.
                let receiver = cfg.and_then(|c| {
                    c.devices.iter().find_map(|d| match &d.driver {
                        DriverConfig::Xbee(x)
                            if d.name == name && x.role == XbeeRole::EmitterReceiver =>
                        {
                            x.antenna
                        }
                        _ => None,
                    })
                });
                match receiver {
                    Some(antenna) => {
                        events.extend(replay_emitter_receiver(&name, cap, mode, antenna));
                    }
                    None => {
                        let scan = pipeline::scan_config(&estimator);
                        events.extend(replay_xbee_sweeps(&name, cap, mode, &scan));
                    }
                }
            }
            other => {
                tracing::warn!(device = other, file = %path.display(), "no replay driver for this device; skipped")
            }
        }
    }
    events.sort_by(|a, b| a.time().unwrap_or(0.0).total_cmp(&b.time().unwrap_or(0.0)));
    // The end of the recording is an event too: pipelines that wait for more input finish here.
    let end = events.last().and_then(DeviceEvent::time).unwrap_or(0.0);
    events.push(DeviceEvent::Mark {
        device: "replay".into(),
        t: end,
        text: "end".into(),
    });

    // Learned files: the robot file's state folder, or the session folder itself (a simulated
    // trial keeps its survey, tag map and database next to its captures).
    let state_dir = cfg.map_or(Some(dir), |c| c.state.dir.as_deref());
    let mut p = pipeline::build(&estimator, state_dir);
    let fmt = PoseFormat {
        frame_id: cfg.map_or_else(|| "map".into(), |c| c.robot.frame_id.clone()),
        child_frame_id: cfg.map_or_else(|| "base_link".into(), |c| c.robot.child_frame_id.clone()),
        precision: cfg.map_or(4, |c| c.pose.precision),
    };
    let epoch = started.unwrap_or(UNIX_EPOCH);
    let mut lines = Vec::new();
    for ev in &events {
        if let Some(est) = p.handle(ev) {
            let wall = epoch + Duration::from_secs_f64(est.time.max(0.0));
            match pose_json(&est, wall, &fmt) {
                Ok(l) => lines.push(l),
                Err(e) => tracing::warn!(error = %e, "estimate not printed"),
            }
        }
        for t in p.take_targets() {
            let wall = epoch + Duration::from_secs_f64(t.time.max(0.0));
            match target_json(&t, wall, &fmt) {
                Ok(l) => lines.push(l),
                Err(e) => tracing::warn!(error = %e, "target not printed"),
            }
        }
    }
    Ok(lines)
}

/// Snapshot settings for a session folder without a robot file: the tag map when the folder
/// holds `survey.json` and `tag-map.json`, the cluster database `snapshot-db.json` otherwise.
fn snapshot_settings(dir: &Path) -> SnapshotSettings {
    let both = dir.join("survey.json").exists() && dir.join("tag-map.json").exists();
    SnapshotSettings {
        survey: both.then(|| "survey.json".into()),
        tag_map: both.then(|| "tag-map.json".into()),
        ..SnapshotSettings::default()
    }
}

/// The reader's capture read back with the sans-IO transcript: every TagList reply is one
/// read at its recorded time; each `mark snapshot reads=N` (written by the device task after
/// each averaged snapshot) averages the last N reads into one snapshot event, as the task
/// did. A capture without such marks gives one snapshot per read.
fn replay_alien(name: &str, cap: &Capture) -> Vec<DeviceEvent> {
    let marked = cap.events().any(|(_, text)| {
        text.strip_prefix("mark ")
            .and_then(crate::devices::parse_snapshot_mark)
            .is_some()
    });
    let mut transcript = rfloc_alien::Transcript::new();
    let mut reads: Vec<(f64, Vec<(String, f64)>)> = Vec::new();
    let mut out = Vec::new();
    let snapshot = |t: f64, tags: Vec<(String, f64)>| DeviceEvent::UhfSnapshot {
        device: name.to_string(),
        t,
        tags,
    };
    for rec in &cap.records {
        match &rec.kind {
            RecordKind::Tx(b) => transcript.push_client(b),
            RecordKind::Rx(b) => {
                for ex in transcript.push_reader(rec.t(), b) {
                    let Some(tags) = transcript.tags(&ex) else {
                        continue;
                    };
                    let read: Vec<(String, f64)> = tags
                        .iter()
                        .filter_map(|t| t.rssi.map(|r| (t.id.to_string(), r)))
                        .collect();
                    if marked {
                        reads.push((ex.t, read));
                    } else {
                        out.push(snapshot(ex.t, crate::devices::average_reads(&[read])));
                    }
                }
            }
            RecordKind::Event(text) => {
                let Some(n) = text
                    .strip_prefix("mark ")
                    .and_then(crate::devices::parse_snapshot_mark)
                else {
                    continue;
                };
                let from = reads.len().saturating_sub(n);
                let group: Vec<(f64, Vec<(String, f64)>)> = reads.drain(from..).collect();
                reads.clear();
                if let Some((t, _)) = group.last() {
                    let polls: Vec<Vec<(String, f64)>> =
                        group.iter().map(|(_, r)| r.clone()).collect();
                    out.push(snapshot(*t, crate::devices::average_reads(&polls)));
                }
            }
        }
    }
    tracing::debug!(
        snapshots = out.len(),
        stray_frames = transcript.stray_frames,
        "alien replay done"
    );
    out
}

async fn replay_kts(name: &str, cap: Capture) -> anyhow::Result<Vec<DeviceEvent>> {
    let (io, mut handle) = Replayer::new(cap).mode(ReplayMode::Stream).start();
    let clock: SharedClock = handle.clock();
    let config = KtsConfig {
        silence_timeout: None,
        ..KtsConfig::default()
    };
    let mut client = KtsClient::spawn(io, config, clock);
    let mut rx = client.take_events().context("event stream already taken")?;
    let mut out = Vec::new();
    while let Some(ev) = rx.recv().await {
        out.extend(DeviceEvent::from_tag_event(name, &ev));
    }
    let report = handle.finished().await;
    tracing::debug!(?report, stats = ?client.stats(), "kts replay done");
    Ok(out)
}

/// The Pioneer streams SIPs faster than a watch channel can be observed during a fast replay,
/// so its capture is decoded with the driver's sans-IO core (frame decoder, SIP parser,
/// odometry tracker) record by record: every SIP gives one odometry event at its recorded time.
#[allow(clippy::unused_async)]
async fn replay_aria(name: &str, cap: Capture) -> anyhow::Result<Vec<DeviceEvent>> {
    let mut decoder = FrameDecoder::new();
    let mut tracker: Option<OdometryTracker> = None;
    let mut stalled = false;
    let mut bumpers = (false, false);
    let mut sonar = rfloc_aria::SonarRing::p3dx();
    let mut out = Vec::new();
    let mut skipped = 0u64;
    for rec in &cap.records {
        let RecordKind::Rx(bytes) = &rec.kind else {
            continue;
        };
        decoder.push(bytes);
        while let Some(frame) = decoder.next_frame() {
            let Ok(frame) = frame else {
                skipped += 1;
                continue;
            };
            match ServerPacket::from_frame(frame) {
                Ok(ServerPacket::Identity(id)) => {
                    tracker = Some(OdometryTracker::new(ConversionFactors::for_subclass(
                        &id.subclass,
                    )));
                }
                Ok(ServerPacket::Motor(sip)) => {
                    let t = tracker
                        .get_or_insert_with(|| OdometryTracker::new(ConversionFactors::P3DX_SH));
                    let s = t.update(&sip);
                    // As the device task with sonar on: the ring after every SIP with ranges.
                    let scan = sonar
                        .update(&sip, &t.factors())
                        .then(|| crate::devices::sonar_beams(&sonar));
                    out.push(DeviceEvent::Odometry {
                        device: name.to_string(),
                        t: rec.t(),
                        pose: s.pose,
                        v: s.v,
                        w: s.w,
                    });
                    if let Some(beams) = scan {
                        out.push(DeviceEvent::RangeScan {
                            device: name.to_string(),
                            t: rec.t(),
                            beams,
                        });
                    }
                    // As the device task: one event when a stall begins.
                    let stalled_now =
                        sip.stall_bumpers.left_stall() || sip.stall_bumpers.right_stall();
                    if stalled_now && !stalled {
                        out.push(DeviceEvent::WheelStall {
                            device: name.to_string(),
                            t: rec.t(),
                        });
                    }
                    stalled = stalled_now;
                    let bumpers_now = (
                        sip.stall_bumpers.front_bumpers() != 0,
                        sip.stall_bumpers.rear_bumpers() != 0,
                    );
                    if bumpers_now != bumpers {
                        bumpers = bumpers_now;
                        out.push(DeviceEvent::Bumpers {
                            device: name.to_string(),
                            t: rec.t(),
                            front: bumpers.0,
                            rear: bumpers.1,
                        });
                    }
                }
                Ok(_) => {}
                Err(_) => skipped += 1,
            }
        }
    }
    if skipped > 0 || decoder.dropped_bytes() > 0 {
        tracing::warn!(
            skipped,
            dropped = decoder.dropped_bytes(),
            "pioneer replay skipped damaged packets"
        );
    }
    Ok(out)
}

/// One sweep being rebuilt from a radio capture: the heading of its start mark and the
/// readings of each `ND` round (by frame ID), in request order.
struct SweepInProgress {
    heading_rad: f64,
    rounds: Vec<(u8, Vec<(u64, f64)>)>,
}

/// Rebuilds the XBee task's sweeps from its capture: the `ND` rounds between a `sweep start`
/// and a `sweep end` mark, paired in order with the antenna angles of the end mark, estimated
/// with the pipeline's sweep settings. Each sweep gives a [`DeviceEvent::Sweep`] at its end
/// mark's time; an abandoned sweep (no angles) gives its failure.
fn replay_xbee_sweeps(
    name: &str,
    cap: &Capture,
    mode: ApiMode,
    scan: &rfloc_bearing::ScanConfig,
) -> Vec<DeviceEvent> {
    let mut tx = XBeeFrameDecoder::new(mode);
    let mut rx = XBeeFrameDecoder::new(mode);
    let mut current: Option<SweepInProgress> = None;
    let mut out = Vec::new();
    let mut unusable = 0u64;
    for rec in &cap.records {
        match &rec.kind {
            RecordKind::Event(text) => {
                let Some(mark) = text.strip_prefix("mark ").and_then(SweepMark::parse) else {
                    continue;
                };
                match mark {
                    SweepMark::Start { heading_rad } => {
                        current = Some(SweepInProgress {
                            heading_rad,
                            rounds: Vec::new(),
                        });
                    }
                    SweepMark::End { antenna_rad } => {
                        let Some(sweep) = current.take() else {
                            unusable += 1;
                            continue;
                        };
                        out.push(DeviceEvent::Sweep {
                            device: name.to_string(),
                            t: rec.t(),
                            result: rebuilt_sweep(&sweep, &antenna_rad, scan),
                        });
                    }
                }
            }
            RecordKind::Tx(bytes) => {
                tx.push(bytes);
                while let Some(frame) = tx.next_frame() {
                    if let (Some(sweep), Ok(Ok(XBeeFrame::AtCommand(c)))) =
                        (current.as_mut(), frame.map(|f| XBeeFrame::parse(&f)))
                    {
                        if c.command == AtCommandName::ND {
                            sweep.rounds.push((c.frame_id, Vec::new()));
                        }
                    }
                }
            }
            RecordKind::Rx(bytes) => {
                rx.push(bytes);
                while let Some(frame) = rx.next_frame() {
                    let Ok(Ok(XBeeFrame::AtResponse(r))) = frame.map(|f| XBeeFrame::parse(&f))
                    else {
                        continue;
                    };
                    if r.command != AtCommandName::ND || r.data.is_empty() {
                        continue;
                    }
                    let Some(sweep) = current.as_mut() else {
                        continue;
                    };
                    let round = sweep
                        .rounds
                        .iter_mut()
                        .rev()
                        .find(|(id, _)| *id == r.frame_id);
                    match (round, Node::parse(&r.data, NdLayoutHint::Auto)) {
                        (Some((_, readings)), Ok(node)) => {
                            if let Some(dbm) = node.rssi_dbm() {
                                readings.push((node.address.0, dbm));
                            }
                        }
                        _ => unusable += 1,
                    }
                }
            }
        }
    }
    let dropped = tx.stats().dropped_bytes + rx.stats().dropped_bytes;
    if unusable > 0 || dropped > 0 {
        tracing::warn!(
            unusable,
            dropped,
            "radio replay skipped records it could not place in a sweep"
        );
    }
    out
}

/// Rebuilds an emitter receiver's polls from its capture: each local `DB` response is one
/// [`DeviceEvent::EmitterRss`] at the time its bytes were read, and a remote `DB` the emitter
/// did not answer (status 4) is one reading of `None`, as the device task reports them.
fn replay_emitter_receiver(
    name: &str,
    cap: &Capture,
    mode: ApiMode,
    antenna: AntennaSide,
) -> Vec<DeviceEvent> {
    let mut rx = XBeeFrameDecoder::new(mode);
    let mut out = Vec::new();
    let mut unusable = 0u64;
    for rec in &cap.records {
        let RecordKind::Rx(bytes) = &rec.kind else {
            continue;
        };
        rx.push(bytes);
        while let Some(frame) = rx.next_frame() {
            let dbm = match frame.map(|f| XBeeFrame::parse(&f)) {
                Ok(Ok(XBeeFrame::AtResponse(r)))
                    if r.command == AtCommandName::DB && r.status() == AtStatus::Ok =>
                {
                    match r.data.as_slice() {
                        [0] | [] => None,
                        [b] => Some(rfloc_xbee::rssi_byte_to_dbm(*b)),
                        _ => {
                            unusable += 1;
                            continue;
                        }
                    }
                }
                Ok(Ok(XBeeFrame::RemoteAtResponse(r)))
                    if r.command == AtCommandName::DB && r.status() == AtStatus::TxFailure =>
                {
                    None
                }
                Ok(Ok(_)) => continue,
                _ => {
                    unusable += 1;
                    continue;
                }
            };
            out.push(DeviceEvent::EmitterRss {
                device: name.to_string(),
                t: rec.t(),
                antenna,
                dbm,
            });
        }
    }
    let dropped = rx.stats().dropped_bytes;
    if unusable > 0 || dropped > 0 {
        tracing::warn!(unusable, dropped, "receiver replay skipped damaged frames");
    }
    out
}

/// Rebuilds a laser task's scans from its capture: every `GD` answer is one
/// [`DeviceEvent::RangeScan`] at the time its last bytes were read.
fn replay_urg(name: &str, cap: &Capture, mount_offset_m: f64) -> Vec<DeviceEvent> {
    let geometry = rfloc_urg::UrgGeometry::default();
    let mut decoder = rfloc_urg::ReplyDecoder::new();
    let mut out = Vec::new();
    let mut unusable = 0u64;
    for rec in &cap.records {
        let RecordKind::Rx(bytes) = &rec.kind else {
            continue;
        };
        decoder.push(bytes);
        while let Some(reply) = decoder.next_reply() {
            let Ok(reply) = reply else {
                unusable += 1;
                continue;
            };
            if !reply.echo.starts_with(b"GD") {
                continue;
            }
            match rfloc_urg::Scan::from_reply(&reply) {
                Ok(scan) => out.push(DeviceEvent::RangeScan {
                    device: name.to_string(),
                    t: rec.t(),
                    beams: crate::devices::urg_scan_beams(&scan, &geometry, mount_offset_m),
                }),
                Err(_) => unusable += 1,
            }
        }
    }
    if unusable > 0 {
        tracing::warn!(
            unusable,
            dropped = decoder.stats().dropped_bytes,
            "laser replay skipped replies it could not read"
        );
    }
    out
}

fn rebuilt_sweep(
    sweep: &SweepInProgress,
    antenna_rad: &[f64],
    scan: &rfloc_bearing::ScanConfig,
) -> Result<Vec<crate::events::SweptBeacon>, String> {
    if antenna_rad.is_empty() {
        return Err("sweep abandoned".into());
    }
    if antenna_rad.len() != sweep.rounds.len() {
        tracing::warn!(
            stops = antenna_rad.len(),
            rounds = sweep.rounds.len(),
            "sweep with as many ND rounds as stops expected; pairing the first ones"
        );
    }
    let samples = antenna_rad
        .iter()
        .zip(&sweep.rounds)
        .map(|(a, (_, readings))| rfloc_bearing::SweepSample {
            antenna_rad: *a,
            heading_rad: sweep.heading_rad,
            readings: readings.clone(),
        })
        .collect();
    let report = rfloc_bearing::estimate_sweep(&rfloc_bearing::Sweep { samples }, &scan.estimator);
    Ok(swept_beacons(&report))
}

/// Parses `YYYY-MM-DDTHH:MM:SS[.fff]Z`.
fn parse_rfc3339(s: &str) -> Option<SystemTime> {
    let s = s.strip_suffix('Z')?;
    let (date, time) = s.split_once('T')?;
    let mut d = date.split('-').map(str::parse::<i64>);
    let (y, m, day) = (d.next()?.ok()?, d.next()?.ok()?, d.next()?.ok()?);
    let mut t = time.split(':');
    let (hh, mm) = (
        t.next()?.parse::<i64>().ok()?,
        t.next()?.parse::<i64>().ok()?,
    );
    let ss: f64 = t.next()?.parse().ok()?;
    let days = days_from_civil(y, m, day);
    let secs = days * 86_400 + hh * 3600 + mm * 60;
    let secs = u64::try_from(secs).ok()?;
    Some(UNIX_EPOCH + Duration::from_secs(secs) + Duration::from_secs_f64(ss.max(0.0)))
}

fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y.rem_euclid(400);
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod tests {
    use super::*;

    fn hex(bytes: &[u8]) -> String {
        bytes
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    }

    #[test]
    fn receiver_polls_replay_from_their_db_answers() {
        // Local DB answer, RSSI byte 0x3C = −60 dBm: 7E 00 06 88 01 44 42 00 3C, checksum
        // 0xFF − (0x88 + 0x01 + 0x44 + 0x42 + 0x00 + 0x3C = 0x14B → 0x4B) = 0xB4.
        let local = [0x7E, 0x00, 0x06, 0x88, 0x01, 0x44, 0x42, 0x00, 0x3C, 0xB4];
        let encoded = XBeeFrame::AtResponse(rfloc_xbee::AtResponse {
            frame_id: 1,
            command: AtCommandName::DB,
            status_byte: 0,
            data: vec![0x3C],
        })
        .encode(ApiMode::Escaped)
        .unwrap();
        assert_eq!(encoded, local, "known answer");
        // The emitter not answering: remote DB with status 4.
        let unanswered = XBeeFrame::RemoteAtResponse(rfloc_xbee::RemoteAtResponse {
            frame_id: 2,
            source: rfloc_xbee::Address64(0x0013_A200_41E0_E001),
            source16: rfloc_xbee::Address16(0xFFFE),
            command: AtCommandName::DB,
            status_byte: 4,
            data: Vec::new(),
        })
        .encode(ApiMode::Escaped)
        .unwrap();
        let text = format!(
            "# rfloc-capture 1\n# device: xbee-api2\n0.200000 rx x:{}\n0.400000 rx x:{}\n0.500000 rx x:7E 00 06 88\n",
            hex(&local),
            hex(&unanswered)
        );
        let cap = Capture::parse(&text, "rx-left.cap").unwrap();
        let events = replay_emitter_receiver("rx-left", &cap, ApiMode::Escaped, AntennaSide::Left);
        let got: Vec<(f64, Option<f64>)> = events
            .iter()
            .map(|e| match e {
                DeviceEvent::EmitterRss {
                    t,
                    antenna: AntennaSide::Left,
                    dbm,
                    ..
                } => (*t, *dbm),
                other => panic!("{other:?}"),
            })
            .collect();
        // The truncated frame at 0.5 s gives nothing.
        assert_eq!(got, vec![(0.2, Some(-60.0)), (0.4, None)]);
    }

    #[test]
    fn rfc3339_round_trips_through_iso8601() {
        let t = parse_rfc3339("2026-11-21T10:00:00Z").unwrap();
        assert_eq!(crate::message::iso8601(t), "2026-11-21T10:00:00.000Z");
        assert!(parse_rfc3339("yesterday").is_none());
    }
}
