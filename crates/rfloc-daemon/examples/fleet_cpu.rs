//! CPU cost of the fleet link at 10 Hz against a real broker: the fleet task (`rumqttc`, the
//! VDA 5050 agent) is fed a pose every 100 ms, as the estimator thread would, with the robot
//! starting or stopping on every sample so that each one publishes a `state` as well as a
//! `visualization`. After the run it prints the process's CPU time from `/proc/self/stat`.
//!
//! ```sh
//! mosquitto -p 18830 &
//! cargo run --release -p rfloc-daemon --example fleet_cpu -- 127.0.0.1:18830 60
//! ```

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use nalgebra::Matrix3;
use rfloc_daemon::config::RobotConfig;
use rfloc_daemon::events::DeviceEvent;
use rfloc_daemon::pipeline::{OdometryPipeline, Pipeline};
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use tokio_util::sync::CancellationToken;

/// utime + stime of this process, seconds.
fn cpu_seconds() -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat")?;
    // Fields after the command name in parentheses; utime and stime are fields 14 and 15.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .context("unexpected /proc/self/stat")?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| -> anyhow::Result<f64> {
        Ok(fields
            .get(i)
            .context("short /proc/self/stat")?
            .parse::<f64>()?)
    };
    // Clock ticks per second on Linux.
    Ok((ticks(11)? + ticks(12)?) / 100.0)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let broker = args
        .get(1)
        .cloned()
        .unwrap_or_else(|| "127.0.0.1:1883".into());
    let secs: f64 = args.get(2).map_or(Ok(60.0), |s| s.parse())?;
    let text = format!(
        "[robot]\nname = \"cpu\"\n\n[estimator]\npipeline = \"odometry\"\n\n[[device]]\nname = \"base\"\n[device.driver]\nkind = \"aria\"\n\n[fleet]\nbroker = \"{broker}\"\nmanufacturer = \"rfloc\"\nserial_number = \"cpu-1\"\nvisualization_hz = 10.0\n\n[simulation]\n"
    );
    let cfg =
        RobotConfig::parse(&text, "fleet-cpu.toml", None).map_err(|e| anyhow::anyhow!("{e}"))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let stop = CancellationToken::new();
    let fleet = runtime.block_on(async {
        rfloc_daemon::fleet::start(
            &cfg,
            true,
            None,
            Arc::new(rfloc_daemon::devices::Resources::default()),
            stop.clone(),
        )
    })?;
    let mut fleet = fleet.context("no [fleet]")?;
    let mut pipeline = OdometryPipeline::default();
    // Let the link connect.
    std::thread::sleep(Duration::from_secs(1));
    let cpu0 = cpu_seconds()?;
    let start = Instant::now();
    let mut k = 0u32;
    while start.elapsed().as_secs_f64() < secs {
        k += 1;
        let t = f64::from(k) * 0.1;
        let v = if k.is_multiple_of(2) { 0.3 } else { 0.0 };
        let pose = Pose2::new(0.01 * f64::from(k % 100), 0.0, 0.0);
        let odometry = DeviceEvent::Odometry {
            device: "base".into(),
            t,
            pose,
            v,
            w: 0.0,
        };
        fleet.link.before_event(&mut pipeline, &odometry);
        let _ = pipeline.handle(&odometry);
        fleet.link.estimate(&PoseEstimate {
            time: t,
            pose,
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(0.01, 0.01, 0.01)),
            mode: EstimateMode::Fix,
            source: "cpu".into(),
        });
        let next = start + Duration::from_millis(100 * u64::from(k));
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = cpu_seconds()? - cpu0;
    stop.cancel();
    runtime.block_on(async {
        let _ = tokio::time::timeout(Duration::from_secs(5), &mut fleet.task).await;
    });
    println!(
        "{k} samples in {wall:.1} s (10 Hz state + visualization): CPU {cpu:.2} s = {:.3} % of one core",
        100.0 * cpu / wall
    );
    Ok(())
}
