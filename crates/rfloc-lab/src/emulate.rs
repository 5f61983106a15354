//! `rfloc emulate`: one emulated device served to any client — on a pseudo-terminal (with a
//! symlink at a path of the user's choosing) or on a TCP listener — so that people can develop
//! and test their own ARIA programs, digi-xbee scripts or SCIP tools with no hardware.
//!
//! What the device senses comes from a scenario file when one is given (its world's walls,
//! tags and beacons, its sensor models, seen from `--pose`), and from a small built-in bench
//! otherwise (the HF reader over seed 002's 3×3 test floor, three XBee beacons at −40, −55 and
//! −70 dBm, a laser facing a wall 2 m ahead, a UHF reader seeing nothing).

use std::f64::consts::PI;
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use rfloc_pose::Pose2;
use tokio::net::TcpListener;
use tokio_serial::{SerialPort, SerialStream};

/// Which device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmulatedDevice {
    Aria,
    Kts,
    Alien,
    Xbee,
    Urg,
}

impl EmulatedDevice {
    /// By name (`aria`, `kts`, `alien`, `xbee`, `urg`).
    #[must_use]
    pub fn named(name: &str) -> Option<Self> {
        Some(match name {
            "aria" => Self::Aria,
            "kts" => Self::Kts,
            "alien" => Self::Alien,
            "xbee" => Self::Xbee,
            "urg" => Self::Urg,
            _ => return None,
        })
    }
}

/// Where and what to serve.
#[derive(Debug, Clone)]
pub struct EmulateOptions {
    pub device: EmulatedDevice,
    /// Serve on a pseudo-terminal and make this path a symlink to it.
    pub pty: Option<PathBuf>,
    /// Serve on this TCP address (one client at a time).
    pub tcp: Option<SocketAddr>,
    /// A scenario whose world and sensor models the device senses.
    pub scenario: Option<PathBuf>,
    /// Where the device is in the world (x m, y m, heading degrees); the robot's start pose.
    pub pose: [f64; 3],
    /// XBee API mode (1 or 2).
    pub api_mode: u8,
    /// XBee firmware: `zigbee` or `802.15.4`.
    pub flavor: String,
    /// Seed of every random draw.
    pub seed: u64,
}

/// A stream a served device talks over.
trait Link: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send {}
impl<T: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send> Link for T {}

/// Runs until interrupted (SIGINT/SIGTERM) or the device ends.
pub async fn run(opts: EmulateOptions) -> anyhow::Result<()> {
    let scenario = match &opts.scenario {
        Some(p) => {
            Some(rfloc_sim::Scenario::load(p).with_context(|| format!("loading {}", p.display()))?)
        }
        None => None,
    };
    let pose = Pose2::new(opts.pose[0], opts.pose[1], opts.pose[2].to_radians());
    let server = Server::new(&opts, scenario.as_ref(), pose)?;
    let stop = async {
        let term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate());
        match term {
            Ok(mut term) => {
                tokio::select! {
                    _ = term.recv() => {}
                    _ = tokio::signal::ctrl_c() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    };
    let served = async {
        match (&opts.pty, opts.tcp) {
            (Some(path), None) => serve_pty(server, path).await,
            (None, Some(addr)) => serve_tcp(server, addr).await,
            _ => anyhow::bail!("give one of --pty PATH or --tcp ADDR:PORT"),
        }
    };
    tokio::select! {
        () = stop => Ok(()),
        r = served => r,
    }
}

/// The emulated device, ready to serve one link after another.
enum Server {
    Aria(Box<rfloc_aria::RobotEmulator>),
    Kts(Box<rfloc_kts::KtsEmulator>),
    Alien(rfloc_alien::ReaderEmulator),
    Xbee(rfloc_xbee::CoordinatorEmulator),
    Urg(rfloc_urg::UrgEmulator),
}

impl Server {
    fn new(
        opts: &EmulateOptions,
        scenario: Option<&rfloc_sim::Scenario>,
        pose: Pose2,
    ) -> anyhow::Result<Self> {
        Ok(match opts.device {
            EmulatedDevice::Aria => {
                let config = rfloc_aria::EmulatorConfig {
                    initial_pose: pose,
                    noise_seed: opts.seed,
                    ..rfloc_aria::EmulatorConfig::default()
                };
                let mut robot = rfloc_aria::RobotEmulator::new(config);
                if let Some(sc) = scenario {
                    let world = Arc::new(sc.world.clone());
                    robot = robot
                        .with_motion_hook(crate::sim::walls::wall_hook(
                            Arc::clone(&world),
                            sc.spec.robot.drive.body_radius,
                        ))
                        .with_sonar_hook(crate::sim::walls::sonar_hook(world));
                }
                Self::Aria(Box::new(robot))
            }
            EmulatedDevice::Kts => {
                let grid = match scenario.filter(|s| !s.world.hf_tags.is_empty()) {
                    Some(sc) => crate::scenario::hfinit::reader_grid(sc)?,
                    None => rfloc_kts::TagGrid::seed002_test_field(),
                };
                let antenna = Arc::new(move || (pose.x, pose.y));
                let mut config = rfloc_kts::EmulatorConfig::new(grid, antenna);
                config.seed = opts.seed;
                Self::Kts(Box::new(rfloc_kts::KtsEmulator::new(config)))
            }
            EmulatedDevice::Alien => {
                let field: rfloc_alien::TagField = match scenario {
                    Some(sc) => {
                        let world = Arc::new(sc.world.clone());
                        let sensors = Mutex::new(rfloc_sim::SensorSuite::for_trial(sc, 0));
                        Arc::new(move || {
                            let reads = sensors
                                .lock()
                                .map(|mut s| s.uhf_inventory(&world, &pose))
                                .unwrap_or_default();
                            reads
                                .into_iter()
                                .filter_map(|(epc, rss)| {
                                    rfloc_snapshot::TagId::from_hex(&epc).map(|id| (id.0, rss))
                                })
                                .collect()
                        })
                    }
                    None => Arc::new(Vec::new),
                };
                Self::Alien(rfloc_alien::ReaderEmulator::new(
                    field,
                    rfloc_alien::EmulatorOptions::default(),
                ))
            }
            EmulatedDevice::Xbee => {
                let mode = if opts.api_mode == 1 {
                    rfloc_xbee::ApiMode::Unescaped
                } else {
                    rfloc_xbee::ApiMode::Escaped
                };
                let flavor = match opts.flavor.as_str() {
                    "zigbee" => rfloc_xbee::Flavor::Zigbee,
                    "802.15.4" => rfloc_xbee::Flavor::Ieee802154,
                    other => anyhow::bail!("--flavor {other:?}: zigbee or 802.15.4"),
                };
                let (beacons, rssi): (Vec<rfloc_xbee::Beacon>, rfloc_xbee::RssiFn) =
                    match scenario.filter(|s| !s.world.beacons.is_empty()) {
                        Some(sc) => {
                            let world = sc.world.clone();
                            let sensors = Mutex::new(rfloc_sim::SensorSuite::for_trial(sc, 0));
                            (
                                crate::sim::xbee_beacons(&world),
                                Arc::new(move |i| {
                                    sensors
                                        .lock()
                                        .ok()
                                        .and_then(|mut s| s.xbee_rssi(&world, &pose, 0.0, i))
                                }),
                            )
                        }
                        None => {
                            let levels = [-40.0, -55.0, -70.0];
                            (
                                (1..=3).map(rfloc_xbee::Beacon::numbered).collect(),
                                Arc::new(move |i| levels.get(i).copied()),
                            )
                        }
                    };
                Self::Xbee(rfloc_xbee::CoordinatorEmulator::new(
                    beacons,
                    rssi,
                    rfloc_xbee::EmulatorConfig {
                        mode,
                        flavor,
                        nd_layout: match flavor {
                            rfloc_xbee::Flavor::Zigbee => rfloc_xbee::NdLayout::ZigbeeOrDigiMesh,
                            rfloc_xbee::Flavor::Ieee802154 => rfloc_xbee::NdLayout::Ieee802154,
                        },
                        ..rfloc_xbee::EmulatorConfig::default()
                    },
                ))
            }
            EmulatedDevice::Urg => {
                let reach = f64::from(rfloc_urg::UrgGeometry::default().max_mm) / 1000.0;
                let ranges: rfloc_urg::RangeFn = match scenario {
                    Some(sc) => {
                        let world = Arc::new(sc.world.clone());
                        Arc::new(move |angle| {
                            world
                                .ray_cast(
                                    &rfloc_sim::Point::new(pose.x, pose.y),
                                    pose.theta + angle,
                                )
                                .filter(|d| *d <= reach)
                        })
                    }
                    // A wall 2 m ahead, across the front ±60°.
                    None => {
                        Arc::new(|angle: f64| (angle.abs() < PI / 3.0).then(|| 2.0 / angle.cos()))
                    }
                };
                Self::Urg(rfloc_urg::UrgEmulator::new(
                    ranges,
                    rfloc_urg::EmulatorConfig::default(),
                ))
            }
        })
    }

    /// Serves one link until it closes. False when the device cannot serve another.
    async fn serve<S: Link>(&mut self, link: S) -> anyhow::Result<bool> {
        match self {
            Self::Aria(robot) => robot.serve(link).await.map(|_| true).map_err(Into::into),
            Self::Kts(reader) => reader.serve(link).await.map(|()| true).map_err(Into::into),
            Self::Alien(reader) => reader
                .serve_stream(link)
                .await
                .map(|()| true)
                .map_err(Into::into),
            Self::Xbee(radio) => radio.serve(link).await.map(|_| true).map_err(Into::into),
            Self::Urg(laser) => laser.serve(link).await.map(|_| true).map_err(Into::into),
        }
    }
}

fn announce(what: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{what}")?;
    out.flush()?;
    Ok(())
}

async fn serve_pty(mut server: Server, link: &std::path::Path) -> anyhow::Result<()> {
    let (master, slave) = SerialStream::pair().context("creating a pseudo-terminal pair")?;
    let path = slave.name().context("the pseudo-terminal has no name")?;
    if std::fs::symlink_metadata(link).is_ok_and(|m| m.file_type().is_symlink()) {
        std::fs::remove_file(link).with_context(|| format!("replacing {}", link.display()))?;
    }
    std::os::unix::fs::symlink(&path, link)
        .with_context(|| format!("linking {} to {path}", link.display()))?;
    announce(&format!("PTY {path} {}", link.display()))?;
    // The slave end stays open here, so the device never reads end-of-file between clients.
    let _slave = slave;
    let served = server.serve(master).await;
    let _ = std::fs::remove_file(link);
    served.map(drop)
}

async fn serve_tcp(mut server: Server, addr: SocketAddr) -> anyhow::Result<()> {
    let listener = TcpListener::bind(addr)
        .await
        .with_context(|| format!("listening on {addr}"))?;
    announce(&format!("TCP {}", listener.local_addr()?))?;
    loop {
        let (stream, peer) = listener.accept().await?;
        tracing::info!(%peer, "client connected");
        let again = server.serve(stream).await;
        tracing::info!(%peer, "client left");
        match again {
            Ok(true) => {}
            Ok(false) => return Ok(()),
            Err(e) => tracing::warn!(error = %e, "link ended with an error"),
        }
    }
}
