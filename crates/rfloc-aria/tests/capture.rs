//! Recording a client ↔ emulator session over a pty, and replaying the recording into the
//! client.
//!
//! `record_square_capture` (ignored; run it to regenerate) writes
//! `tests/captures/aria-square/pioneer.cap` and `truth.csv` at the workspace root.
//! `replay_square_capture` feeds the committed capture to the client and checks the odometry it
//! decodes against the recorded ground truth.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use rfloc_aria::{
    AriaClient, ClientConfig, EmulatorConfig, FrameDecoder, LinkState, Odometry, RobotEmulator,
    ServerPacket,
};
use rfloc_capture::{Capture, Header};
use rfloc_pose::{angle_diff, Pose2};
use rfloc_transport::replay::{Pace, ReplayMode, Replayer};
use rfloc_transport::{CaptureSink, MonotonicClock, Recorder, SharedClock};
use tokio::sync::watch;
use tokio_serial::SerialStream;

const SCALE: f64 = 20.0;

fn capture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures/aria-square")
}

async fn wait(rx: &mut watch::Receiver<Odometry>, f: impl FnMut(&Odometry) -> bool) -> Odometry {
    tokio::time::timeout(Duration::from_secs(10), rx.wait_for(f))
        .await
        .expect("timed out")
        .map(|o| *o)
        .expect("closed")
}

async fn wait_still(rx: &mut watch::Receiver<Odometry>) -> Odometry {
    let mut still = 0;
    loop {
        let seq = rx.borrow().seq;
        let o = wait(rx, |o| o.seq > seq).await;
        if o.v == 0.0 && o.w == 0.0 {
            still += 1;
            if still >= 3 {
                return o;
            }
        } else {
            still = 0;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "writes tests/captures/aria-square; run to regenerate the capture"]
async fn record_square_capture() {
    let dir = capture_dir();
    std::fs::create_dir_all(&dir).unwrap();
    let clock: SharedClock = Arc::new(MonotonicClock::new());
    let mut header = Header::new("pioneer-aria", "serial 9600 8N1");
    header.notes.push(format!(
        "rfloc-aria client <-> RobotEmulator (p3dx-sh, time_scale {SCALE}) over a pty pair; \
         simulated time = {SCALE} x capture time"
    ));
    header.notes.push(
        "client drives a 1 m square (0.3 m/s sides, 30 deg/s left turns), then STOP and CLOSE"
            .into(),
    );
    let sink = CaptureSink::create(&dir.join("pioneer.cap"), &header, Arc::clone(&clock)).unwrap();

    let (host, robot) = SerialStream::pair().unwrap();
    let mut emu = RobotEmulator::new(EmulatorConfig {
        time_scale: SCALE,
        ..EmulatorConfig::default()
    });
    let handle = emu.handle();
    let emu_task = tokio::spawn(async move {
        emu.serve(robot).await.unwrap();
    });
    // Ground truth on the capture's clock.
    let mut truth_csv = String::from("t,x,y,theta\n");
    let mut states = handle.subscribe();
    let truth_clock = Arc::clone(&clock);
    let truth_task = tokio::spawn(async move {
        while states.changed().await.is_ok() {
            let s = *states.borrow();
            truth_csv.push_str(&format!(
                "{:.6},{:.6},{:.6},{:.6}\n",
                truth_clock.now(),
                s.truth.x,
                s.truth.y,
                s.truth.theta
            ));
        }
        truth_csv
    });

    let recorder = Recorder::new(host, sink.clone());
    let client = AriaClient::from_stream(recorder, ClientConfig::default().scaled(SCALE))
        .await
        .unwrap();
    let mut rx = client.odometry();
    wait(&mut rx, |o| o.seq > 0).await;
    for side in 0..4 {
        sink.event(&format!("mark side {side}"));
        let start = rx.borrow().pose;
        client.set_velocity(0.3, 0.0).await.unwrap();
        wait(&mut rx, |o| o.pose.distance(&start) >= 0.85).await;
        client.stop().await.unwrap();
        let stopped = wait_still(&mut rx).await;
        sink.event(&format!("mark turn {side}"));
        let target = stopped.pose.theta + std::f64::consts::FRAC_PI_2;
        client.set_velocity(0.0, 30f64.to_radians()).await.unwrap();
        wait(&mut rx, |o| {
            angle_diff(target, o.pose.theta) <= 4.5f64.to_radians()
        })
        .await;
        client.stop().await.unwrap();
        wait_still(&mut rx).await;
    }
    let last = *rx.borrow();
    sink.event(&format!(
        "mark end odometry x={:.4} y={:.4} theta={:.5}",
        last.pose.x, last.pose.y, last.pose.theta
    ));
    client.shutdown().await.unwrap();
    emu_task.await.unwrap();
    let truth_csv = truth_task.await.unwrap();
    sink.flush().unwrap();
    let mut f = std::fs::File::create(dir.join("truth.csv")).unwrap();
    f.write_all(truth_csv.as_bytes()).unwrap();
}

/// The last truth row of `truth.csv`.
fn final_truth() -> Pose2 {
    let text = std::fs::read_to_string(capture_dir().join("truth.csv")).unwrap();
    let last = text.lines().rfind(|l| !l.is_empty()).unwrap();
    let v: Vec<f64> = last.split(',').map(|x| x.parse().unwrap()).collect();
    Pose2::new(v[1], v[2], v[3])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replay_square_capture() {
    let capture = Capture::from_path(&capture_dir().join("pioneer.cap")).unwrap();
    assert_eq!(capture.header.device.as_deref(), Some("pioneer-aria"));
    // Count the motor SIPs in the recording with the codec alone.
    let mut decoder = FrameDecoder::new();
    decoder.push(&capture.rx_bytes());
    let mut sips = 0;
    while let Some(r) = decoder.next_frame() {
        if let Ok(ServerPacket::Motor(_)) = ServerPacket::from_frame(r.unwrap()) {
            sips += 1;
        }
    }
    assert!(sips > 100, "only {sips} SIPs recorded");
    let last_rx_t = capture
        .records
        .iter()
        .rfind(|r| matches!(r.kind, rfloc_capture::RecordKind::Rx(_)))
        .map(rfloc_capture::Record::t)
        .unwrap();

    let (io, replay) = Replayer::new(capture)
        .mode(ReplayMode::Stream)
        .pace(Pace::Fast)
        .start();
    let config = ClientConfig {
        clock: Some(replay.clock()),
        // Fast replay: the recorded SIPs arrive at once, never time out on them.
        link_timeout: Duration::from_secs(30),
        reconnect_delay: Duration::from_secs(30),
        ..ClientConfig::default()
    };
    let client = AriaClient::from_stream(io, config).await.unwrap();
    assert_eq!(client.identity().name, "rfloc-emulator");
    // End of the recording = end of stream: the client reports the link lost.
    let mut state = client.link_state();
    tokio::time::timeout(
        Duration::from_secs(10),
        state.wait_for(|s| *s == LinkState::Connecting),
    )
    .await
    .expect("replay did not end")
    .unwrap();
    let odo = *client.odometry().borrow();
    let stats = client.stats();
    let truth = final_truth();
    eprintln!(
        "replay: {sips} SIPs, odometry {:?} at t={:.3}, truth {:?}, stats {stats:?}",
        odo.pose, odo.time, truth
    );
    assert_eq!(stats.sips, sips);
    assert_eq!(odo.seq, sips);
    assert_eq!(stats.dropped_bytes, 0);
    assert_eq!(stats.bad_checksums, 0);
    assert!(odo.pose.distance(&truth) < 0.01, "odometry vs truth");
    assert!(angle_diff(odo.pose.theta, truth.theta).abs() < 0.005);
    // Timestamps come from the replay clock, i.e. the recorded times.
    assert!(
        odo.time > 0.5 && odo.time <= last_rx_t + 1e-9,
        "time {}",
        odo.time
    );
}
