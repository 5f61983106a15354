//! A robot driving a circle among four beacons, served live and optionally recorded.
//!
//! ```sh
//! cargo run -p rfloc-viz --example demo -- [ADDR] [SECONDS] [FILE.mcap]
//! ```
//! Defaults: `127.0.0.1:8765`, 60 s, no recording. Open `ws://ADDR` in Foxglove.

use std::time::{Duration, SystemTime};

use nalgebra::{Matrix2, Matrix3};
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use rfloc_viz::{
    Direction, Landmark, LandmarkKind, LogLevel, Particle, RangeScan, Stamp, TargetEstimate, Viz,
};

#[tokio::main]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let addr = args
        .next()
        .unwrap_or_else(|| "127.0.0.1:8765".into())
        .parse()?;
    let seconds: u32 = args.next().map_or(Ok(60), |s| s.parse())?;
    let viz = Viz::new();
    let server = viz.serve(addr, None).await?;
    let recording = args.next().map(|p| viz.record(p)).transpose()?;
    println!(
        "open {} in Foxglove (Open connection → Foxglove WebSocket)",
        server.url()
    );

    let beacons: Vec<Landmark> = [(-6.0, -6.0), (6.0, -6.0), (6.0, 6.0), (-6.0, 6.0)]
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| Landmark {
            id: format!("beacon-{i}"),
            x,
            y,
            covariance: Some(Matrix2::identity() * 0.05),
        })
        .collect();
    let mut path = Vec::new();
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    for i in 0..seconds * 10 {
        tick.tick().await;
        let stamp = Stamp::from(SystemTime::now());
        let t = f64::from(i) * 0.1;
        let (a, r) = (0.2 * t, 4.0);
        let map_pose = Pose2::new(r * a.cos(), r * a.sin(), a + std::f64::consts::FRAC_PI_2);
        // Odometry drifts: it thinks the circle is a little larger.
        let odom_pose = Pose2::new(1.05 * r * a.cos(), 1.05 * r * a.sin(), map_pose.theta);
        let sd = 0.1 + 0.05 * (0.5 * t).sin().abs();
        let estimate = PoseEstimate {
            time: stamp.unix_secs(),
            pose: map_pose,
            covariance: Matrix3::new(sd * sd, 0.0, 0.0, 0.0, 0.25 * sd * sd, 0.0, 0.0, 0.0, 0.01),
            mode: if (i / 50) % 4 == 3 {
                EstimateMode::Degraded
            } else {
                EstimateMode::Fix
            },
            source: "demo".into(),
        };
        path.push(map_pose);
        viz.pose(stamp, &estimate);
        viz.transforms(stamp, &map_pose, &odom_pose);
        viz.path(stamp, &path);
        viz.scan(
            stamp,
            &RangeScan {
                mount: Pose2::new(0.2, 0.0, 0.0),
                start_angle: -2.0,
                end_angle: 2.0,
                ranges: (0..181)
                    .map(|k| 3.0 + 0.5 * (f64::from(k) * 0.1 + t).sin())
                    .collect(),
                intensities: Vec::new(),
            },
        );
        viz.particles(
            stamp,
            &(0..200)
                .map(|k| {
                    let (dx, dy) = (
                        f64::from(k % 20) * 0.02 - 0.2,
                        f64::from(k / 20) * 0.04 - 0.2,
                    );
                    Particle {
                        pose: map_pose.compose(&Pose2::new(dx, dy, 0.0)),
                        weight: 1.0 / 200.0,
                    }
                })
                .collect::<Vec<_>>(),
        );
        viz.target(
            stamp,
            &TargetEstimate {
                id: "emitter".into(),
                x: 2.0,
                y: 1.0,
                covariance: Matrix2::new(0.5, 0.2, 0.2, 0.3) / (1.0 + t),
            },
        );
        if i % 10 == 0 {
            viz.landmarks(stamp, LandmarkKind::Beacon, &beacons);
            viz.status(
                stamp,
                "demo",
                LogLevel::Info,
                &format!("{t:.0} s, {} clients", server.client_count()),
            );
            viz.link_bytes(stamp, "urg", Direction::Tx, b"GD0044072501\n");
        }
    }
    if let Some(r) = recording {
        println!("recorded {}", r.finish()?.display());
    }
    server.stop().await;
    Ok(())
}
