//! Client against emulator through a real pseudo-terminal pair (`SerialStream::pair`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use std::sync::Arc;
use std::time::Duration;

use rfloc_aria::{
    AriaClient, ClientConfig, ClientError, ConnectFuture, EmulatorConfig, EmulatorHandle,
    LinkState, MobileBase, Odometry, RobotEmulator,
};
use rfloc_pose::{angle_diff, Pose2};
use tokio::sync::{watch, Mutex};
use tokio::task::JoinHandle;
use tokio_serial::SerialStream;

/// Simulated seconds per wall second in these tests.
const SCALE: f64 = 10.0;

fn emulator_config() -> EmulatorConfig {
    EmulatorConfig {
        time_scale: SCALE,
        ..EmulatorConfig::default()
    }
}

/// The client's periods scaled to the emulator; the pulse comes every 250 ms of simulated time
/// (an eighth of the watchdog) so that a briefly descheduled test process does not trip it.
/// `scaled` keeps wall-time floors on the SYNC and link timeouts and the CLOSE linger.
fn client_config() -> ClientConfig {
    ClientConfig {
        pulse_period: Duration::from_millis(250),
        ..ClientConfig::default()
    }
    .scaled(SCALE)
}

/// Starts an emulator on one end of a pty pair and returns the other end.
fn spawn_emulator(
    config: EmulatorConfig,
) -> (SerialStream, EmulatorHandle, JoinHandle<RobotEmulator>) {
    let (host, robot) = SerialStream::pair().expect("pty pair");
    let mut emu = RobotEmulator::new(config);
    let handle = emu.handle();
    let task = tokio::spawn(async move {
        emu.serve(robot).await.expect("emulator serve");
        emu
    });
    (host, handle, task)
}

async fn wait_odometry(
    rx: &mut watch::Receiver<Odometry>,
    what: &str,
    f: impl FnMut(&Odometry) -> bool,
) -> Odometry {
    tokio::time::timeout(Duration::from_secs(10), rx.wait_for(f))
        .await
        .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
        .map(|o| *o)
        .expect("odometry channel closed")
}

/// Waits for a few fresh SIPs with the robot standing still.
async fn wait_still(rx: &mut watch::Receiver<Odometry>) -> Odometry {
    let mut still = 0;
    loop {
        let seq = rx.borrow().seq;
        let o = wait_odometry(rx, "next SIP", |o| o.seq > seq).await;
        if o.v.abs() < 1e-9 && o.w.abs() < 1e-9 {
            still += 1;
            if still >= 3 {
                return o;
            }
        } else {
            still = 0;
        }
    }
}

/// Drives one side with velocity commands and odometry feedback, then turns left to
/// `heading_deg` with HEAD (the robot's own heading servo, so the turn does not depend on how
/// fast this process reacts).
async fn drive_side(
    client: &AriaClient,
    rx: &mut watch::Receiver<Odometry>,
    side: f64,
    heading_deg: f64,
) {
    let start = rx.borrow().pose;
    let speed = 0.3;
    // Stop early by the braking distance v²/(2·0.3 m/s²) = 0.15 m.
    let brake = speed * speed / (2.0 * 0.3);
    client.set_velocity(speed, 0.0).await.unwrap();
    wait_odometry(rx, "side", |o| o.pose.distance(&start) >= side - brake).await;
    client.stop().await.unwrap();
    wait_still(rx).await;
    let target = heading_deg.to_radians();
    client.set_heading(target).await.unwrap();
    wait_odometry(rx, "turn", |o| {
        angle_diff(target, o.pose.theta).abs() < 0.01
    })
    .await;
    wait_still(rx).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn square_closes_on_emulator_truth() {
    // This test is about odometry, not the watchdog (tested below): a long robot watchdog keeps
    // a test process starved of CPU on a loaded machine from stopping the robot mid-side.
    let (host, emu, task) = spawn_emulator(EmulatorConfig {
        watchdog: Duration::from_secs(20),
        ..emulator_config()
    });
    let client = AriaClient::from_stream(host, client_config())
        .await
        .unwrap();
    assert_eq!(client.identity().subclass, "p3dx-sh");
    let mut rx = client.odometry();
    wait_odometry(&mut rx, "first SIP", |o| o.seq > 0 && o.motors_enabled).await;
    for heading in [90.0, 180.0, 270.0, 0.0] {
        drive_side(&client, &mut rx, 1.0, heading).await;
        eprintln!("side: {:?} truth {:?}", rx.borrow().pose, emu.truth());
    }
    let odo = wait_still(&mut rx).await;
    let truth = emu.truth();
    let err = odo.pose.distance(&truth);
    let err_th = angle_diff(odo.pose.theta, truth.theta).abs();
    let closure = truth.distance(&Pose2::default());
    eprintln!(
        "square: odometry {:?} truth {:?} | odo-truth {:.4} m {:.5} rad | truth closure {:.4} m",
        odo.pose, truth, err, err_th, closure
    );
    assert!(err < 0.01, "odometry vs truth {err} m");
    assert!(err_th < 0.005, "heading vs truth {err_th} rad");
    // It was a square: back near the start (side lengths depend on how fast this process
    // reacted, hence the loose bound), facing the start heading.
    assert!(closure < 0.25, "square did not close: {closure} m");
    assert!(angle_diff(truth.theta, 0.0).abs() < 0.01);
    let state = emu.state();
    eprintln!("square: emulator {state:?}");
    let stats = client.stats();
    assert_eq!(stats.dropped_bytes, 0);
    assert_eq!(stats.bad_checksums, 0);
    client.shutdown().await.unwrap();
    let emu_after = task.await.unwrap();
    let final_state = emu_after.handle().state();
    assert!(!final_state.open, "CLOSE received");
    assert_eq!(final_state.v, 0.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emulator_stops_robot_when_client_stops_pulsing() {
    let (host, emu, _task) = spawn_emulator(emulator_config());
    let config = ClientConfig {
        // Far longer than the 2 s (simulated) watchdog.
        pulse_period: Duration::from_secs(60),
        ..client_config()
    };
    let client = AriaClient::from_stream(host, config).await.unwrap();
    let mut rx = client.odometry();
    client.set_velocity(0.2, 0.0).await.unwrap();
    wait_odometry(&mut rx, "moving", |o| o.v > 0.19).await;
    let mut st = emu.subscribe();
    let tripped = tokio::time::timeout(Duration::from_secs(5), st.wait_for(|s| s.watchdog_tripped))
        .await
        .expect("watchdog did not trip")
        .unwrap()
        .sim_time;
    // The robot decelerates to a stop and the client sees it.
    let o = wait_odometry(&mut rx, "stopped", |o| o.v == 0.0).await;
    let stopped_at = emu.state();
    assert!(stopped_at.watchdog_tripped);
    assert_eq!(stopped_at.watchdog_trips, 1);
    assert!(
        tripped >= 2.0,
        "watchdog tripped after {tripped} s simulated"
    );
    // Still standing a while later (no command), SIPs keep flowing.
    let later = wait_odometry(&mut rx, "later SIPs", |x| x.seq > o.seq + 10).await;
    assert!(later.pose.distance(&o.pose) < 1e-9);
    // A command revives the robot to its last setpoint, as ARCOS does.
    client.send(rfloc_aria::Command::Pulse).await.unwrap();
    wait_odometry(&mut rx, "revived", |o| o.v > 0.19).await;
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pulses_keep_an_idle_robot_alive() {
    // Default 1 s pulse against the 2 s watchdog, at a time scale low enough (5) that the
    // 200 ms wall-clock margin is not eaten by scheduling delays.
    let scale = 5.0;
    let config = EmulatorConfig {
        time_scale: scale,
        ..EmulatorConfig::default()
    };
    let (host, emu, _task) = spawn_emulator(config);
    let client = AriaClient::from_stream(host, ClientConfig::default().scaled(scale))
        .await
        .unwrap();
    let mut rx = client.odometry();
    client.set_velocity(0.1, 0.0).await.unwrap();
    // 6 s simulated without any command from the caller.
    let s0 = rx.borrow().seq;
    wait_odometry(&mut rx, "6 s of SIPs", |o| o.seq > s0 + 60).await;
    let state = emu.state();
    assert_eq!(state.watchdog_trips, 0);
    assert!((state.v - 0.1).abs() < 1e-9);
    assert!(
        client.stats().pulses >= 4,
        "pulses: {}",
        client.stats().pulses
    );
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn resyncs_on_line_noise_and_skips_unknown_packets() {
    let config = EmulatorConfig {
        garbage_probability: 0.3,
        noise_seed: 42,
        ..emulator_config()
    };
    let (host, emu, _task) = spawn_emulator(config);
    let client = AriaClient::from_stream(host, client_config())
        .await
        .unwrap();
    let mut rx = client.odometry();
    // ENCODER 2: continuous encoder packets (type 0x90), which the client does not interpret.
    client
        .send(rfloc_aria::Command::Other {
            number: 19,
            arg: rfloc_aria::Arg::Int(2),
        })
        .await
        .unwrap();
    client.set_velocity(0.25, 0.2).await.unwrap();
    let s0 = rx.borrow().seq;
    wait_odometry(&mut rx, "40 SIPs", |o| o.seq > s0 + 40).await;
    client.stop().await.unwrap();
    let odo = wait_still(&mut rx).await;
    let truth = emu.truth();
    let stats = client.stats();
    eprintln!(
        "noise: {stats:?}, odo-truth {:.5} m",
        odo.pose.distance(&truth)
    );
    assert!(stats.dropped_bytes > 0, "garbage was injected");
    assert!(stats.unknown_packets > 10);
    assert!(odo.pose.distance(&truth) < 0.005);
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn config_request_and_wheel_velocities() {
    let (host, emu, _task) = spawn_emulator(emulator_config());
    let client = AriaClient::from_stream(host, client_config())
        .await
        .unwrap();
    let cfg = client.request_config(Duration::from_secs(2)).await.unwrap();
    assert_eq!(cfg.subclass, "p3dx-sh");
    assert_eq!(cfg.watchdog_ms, 2000);
    assert_eq!(cfg.sip_cycle_ms, 100);
    let mut rx = client.odometry();
    // VEL2: left 0.2 m/s, right 0.4 m/s (10 and 20 units of 20 mm/s).
    client.set_wheel_velocities(0.2, 0.4).await.unwrap();
    let o = wait_odometry(&mut rx, "wheels", |o| (o.v - 0.3).abs() < 1e-9).await;
    let track = EmulatorConfig::default().wheel_track_mm / 1000.0;
    assert!((o.w - 0.2 / track).abs() < 0.01, "w = {}", o.w);
    assert!((emu.state().v - 0.3).abs() < 1e-9);
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reconnects_after_the_link_drops() {
    let emu = Arc::new(Mutex::new(RobotEmulator::new(emulator_config())));
    let handle = emu.lock().await.handle();
    let serving: Arc<std::sync::Mutex<Option<JoinHandle<()>>>> = Arc::default();
    let connector = {
        let emu = Arc::clone(&emu);
        let serving = Arc::clone(&serving);
        move || -> ConnectFuture<SerialStream> {
            let emu = Arc::clone(&emu);
            let serving = Arc::clone(&serving);
            Box::pin(async move {
                let (host, robot) = SerialStream::pair()?;
                let task = tokio::spawn(async move {
                    let mut e = emu.lock().await;
                    let _ = e.serve(robot).await;
                });
                *serving.lock().unwrap() = Some(task);
                Ok(host)
            })
        }
    };
    let client = AriaClient::connect(connector, client_config())
        .await
        .unwrap();
    let mut rx = client.odometry();
    client.set_velocity(0.3, 0.0).await.unwrap();
    wait_odometry(&mut rx, "moving", |o| o.pose.x > 0.2).await;
    // Stop before pulling the cable: motion between the last SIP the client read and the pull
    // would be a race of this test, not a property of the client.
    client.set_velocity(0.0, 0.0).await.unwrap();
    let before = wait_still(&mut rx).await;
    // Pull the cable: the robot end of the pty goes away.
    let task = serving.lock().unwrap().take().unwrap();
    task.abort();
    let _ = task.await;
    let mut state = client.link_state();
    tokio::time::timeout(
        Duration::from_secs(5),
        state.wait_for(|s| *s == LinkState::Connecting),
    )
    .await
    .expect("drop not noticed")
    .unwrap();
    assert!(matches!(
        client.set_velocity(0.1, 0.0).await,
        Err(ClientError::NotConnected) | Ok(())
    ));
    tokio::time::timeout(
        Duration::from_secs(5),
        state.wait_for(|s| matches!(s, LinkState::Connected(_))),
    )
    .await
    .expect("no reconnect")
    .unwrap();
    let seq = rx.borrow().seq;
    wait_odometry(&mut rx, "SIPs after reconnect", |o| o.seq > seq + 3).await;
    // The 0.1 m/s command above may have reached the robot; compare standing still, or the
    // truth read a moment after the odometry is ahead of it.
    client.set_velocity(0.0, 0.0).await.unwrap();
    let after = wait_still(&mut rx).await;
    assert_eq!(client.stats().reconnects, 1);
    let st = handle.state();
    assert_eq!(st.opens, 2);
    assert!(st.closes >= 1, "the client closed the still-open robot");
    // The robot stayed open across the drop, so the client had to CLOSE it first; its odometry
    // carried on, and the published pose is continuous and still matches the truth.
    let truth = handle.truth();
    assert!(
        after.pose.distance(&truth) < 0.01,
        "{:?} vs {:?}",
        after.pose,
        truth
    );
    assert!(after.pose.x >= before.pose.x);
    // And it can drive again.
    client.set_velocity(0.2, 0.0).await.unwrap();
    let x0 = after.pose.x;
    wait_odometry(&mut rx, "driving after reconnect", |o| o.pose.x > x0 + 0.05).await;
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn handshake_fails_when_nothing_answers() {
    let (host, _silent) = SerialStream::pair().unwrap();
    let config = ClientConfig {
        sync_timeout: Duration::from_millis(50),
        sync_attempts: 3,
        ..ClientConfig::default()
    };
    let err = AriaClient::from_stream(host, config).await.unwrap_err();
    assert!(
        matches!(err, ClientError::Handshake { attempts: 3, .. }),
        "{err}"
    );
}

/// The mock stands in for the client through the trait.
async fn drive_forward<B: MobileBase>(base: &B) -> Result<(), ClientError> {
    base.set_velocity(0.1, 0.0).await?;
    base.stop().await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn client_works_through_the_mobile_base_trait() {
    let (host, emu, _task) = spawn_emulator(emulator_config());
    let client = AriaClient::from_stream(host, client_config())
        .await
        .unwrap();
    drive_forward(&client).await.unwrap();
    let mut rx = MobileBase::odometry(&client);
    wait_odometry(&mut rx, "SIP", |o| o.seq > 2).await;
    assert!(emu.state().commands >= 4);
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wheel_slip_separates_odometry_from_truth() {
    let config = EmulatorConfig {
        slip: Some(rfloc_aria::WheelSlip {
            seed: 3,
            relative_std: 0.05,
        }),
        ..emulator_config()
    };
    let (host, emu, _task) = spawn_emulator(config);
    let client = AriaClient::from_stream(host, client_config())
        .await
        .unwrap();
    let mut rx = client.odometry();
    wait_odometry(&mut rx, "first SIP", |o| o.seq > 0).await;
    drive_side(&client, &mut rx, 1.0, 90.0).await;
    let odo = wait_still(&mut rx).await;
    let state = emu.state();
    let vs_robot = odo.pose.distance(&state.odometry);
    let vs_truth = odo.pose.distance(&state.truth);
    eprintln!("slip: odometry-robot {vs_robot:.5} m, odometry-truth {vs_truth:.5} m");
    // The client reports the robot's encoder odometry, which slip does not touch.
    assert!(vs_robot < 0.002);
    assert!(vs_truth > vs_robot);
    client.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn long_run_crosses_the_15_bit_wrap_on_a_p3dx() {
    // `p3dx`: 0.485 mm per unit, so XPOS wraps every 32768 · 0.485 mm ≈ 15.9 m.
    let scale = 50.0;
    let mut config = EmulatorConfig {
        time_scale: scale,
        ..EmulatorConfig::default()
    };
    config.identity.subclass = "p3dx".into();
    let (host, emu, _task) = spawn_emulator(config);
    // Fully scaled, the link timeout would be 40 ms of wall time; `scaled` keeps its floor.
    let client = AriaClient::from_stream(host, ClientConfig::default().scaled(scale))
        .await
        .unwrap();
    assert!((client.factors().dist_conv - 0.485).abs() < 1e-12);
    let mut rx = client.odometry();
    client.set_velocity(2.0, 0.0).await.unwrap();
    wait_odometry(&mut rx, "20 m", |o| o.pose.x > 20.0).await;
    client.stop().await.unwrap();
    let odo = wait_still(&mut rx).await;
    let truth = emu.truth();
    eprintln!("wrap: odometry x {:.4} truth x {:.4}", odo.pose.x, truth.x);
    assert!(truth.x > 20.0);
    assert!(odo.pose.distance(&truth) < 0.01);
    client.shutdown().await.unwrap();
}

/// Counts the bytes the client has written to its end of the pty (the lock-step barrier).
struct CountingIo<T> {
    inner: T,
    written: Arc<std::sync::atomic::AtomicU64>,
}

impl<T: tokio::io::AsyncRead + Unpin> tokio::io::AsyncRead for CountingIo<T> {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: tokio::io::AsyncWrite + Unpin> tokio::io::AsyncWrite for CountingIo<T> {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        let r = std::pin::Pin::new(&mut self.inner).poll_write(cx, buf);
        if let std::task::Poll::Ready(Ok(n)) = &r {
            self.written
                .fetch_add(*n as u64, std::sync::atomic::Ordering::SeqCst);
        }
        r
    }
    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// One scripted lock-step session: a command right before every tick (alternating speeds), the
/// SIP of each tick read before the next; returns the odometry and truth of every tick.
async fn lock_step_session() -> (Vec<Pose2>, Vec<Pose2>, rfloc_aria::EmulatorState) {
    let (host, robot) = SerialStream::pair().expect("pty pair");
    let mut emu = RobotEmulator::new(EmulatorConfig {
        slip: Some(rfloc_aria::WheelSlip {
            seed: 5,
            relative_std: 0.05,
        }),
        ..EmulatorConfig::default()
    });
    let control = emu.lock_step();
    let handle = emu.handle();
    let task = tokio::spawn(async move {
        emu.serve(robot).await.expect("emulator serve");
    });
    let written = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let io = CountingIo {
        inner: host,
        written: Arc::clone(&written),
    };
    // No keep-alive on wall time: every byte on the link is one the test sent.
    let config = ClientConfig {
        pulse_period: Duration::from_secs(3600),
        link_timeout: Duration::from_secs(3600),
        close_linger: Duration::ZERO,
        ..ClientConfig::default()
    };
    let client = AriaClient::from_stream(io, config).await.unwrap();
    let mut rx = client.odometry();
    let (mut odometry, mut truth) = (Vec::new(), Vec::new());
    for k in 0..40u32 {
        let v = if (k / 5) % 2 == 0 { 0.4 } else { 0.1 };
        client.set_velocity(v, 0.2).await.unwrap();
        let barrier = written.load(std::sync::atomic::Ordering::SeqCst);
        let st = tokio::time::timeout(Duration::from_secs(10), control.advance(1, barrier))
            .await
            .expect("tick")
            .unwrap();
        let o = wait_odometry(&mut rx, "the tick's SIP", |o| o.seq >= st.sips_sent).await;
        odometry.push(o.pose);
        truth.push(st.truth);
    }
    let state = handle.state();
    client.shutdown().await.unwrap();
    task.abort();
    (odometry, truth, state)
}

#[tokio::test]
async fn lock_step_runs_are_identical() {
    let (o1, t1, s1) = lock_step_session().await;
    let (o2, t2, s2) = lock_step_session().await;
    assert_eq!(o1, o2);
    assert_eq!(t1, t2);
    // Every command was handled before the tick it preceded: 40 × (VEL, RVEL), time is
    // exactly 40 ticks, and the robot moved (with slip, the truth left the odometry).
    assert_eq!(s1.commands, s2.commands);
    assert_eq!(s1.ticks, 40);
    assert_eq!(s1.sips_sent, 40);
    assert!((s1.sim_time - 4.0).abs() < 1e-12);
    assert!(o1.last().unwrap().x.hypot(o1.last().unwrap().y) > 0.3);
    assert!(t1.last().unwrap().distance(&s1.odometry) > 0.0);
}

#[tokio::test]
async fn lock_step_emulator_stands_still_without_steps() {
    let (host, robot) = SerialStream::pair().expect("pty pair");
    let mut emu = RobotEmulator::new(EmulatorConfig::default());
    let control = emu.lock_step();
    let handle = emu.handle();
    let task = tokio::spawn(async move {
        emu.serve(robot).await.expect("emulator serve");
    });
    let config = ClientConfig {
        pulse_period: Duration::from_secs(3600),
        link_timeout: Duration::from_secs(3600),
        close_linger: Duration::ZERO,
        ..ClientConfig::default()
    };
    // The handshake is answered without any tick.
    let client = AriaClient::from_stream(host, config).await.unwrap();
    client.set_velocity(0.5, 0.0).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let st = handle.state();
    assert!(st.open);
    assert_eq!((st.ticks, st.sips_sent, st.sim_time), (0, 0, 0.0));
    // A barrier beyond what was written holds the tick back.
    let far = st.rx_bytes + 1;
    let held = tokio::time::timeout(Duration::from_millis(300), control.advance(1, far)).await;
    assert!(held.is_err(), "ticked before the barrier");
    assert_eq!(handle.state().ticks, 0);
    client.shutdown().await.unwrap();
    task.abort();
}
