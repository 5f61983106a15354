//! `rfloc`: the rfloc localisation daemon and its tools.
#![forbid(unsafe_code)]

mod watch;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use rfloc_daemon::config::{ConfigErrors, LoadOptions, RobotConfig, SectionCheck};

/// The default robot file: the simulated HF-grid AGV.
#[cfg(feature = "lab")]
const EMBEDDED_SIM: &str = include_str!("../../../config/sim.toml");

/// Exit status for configuration errors (sysexits EX_CONFIG).
const EX_CONFIG: u8 = 78;
/// Exit status of `rfloc sim` when the run finished but some trials failed.
#[cfg(feature = "lab")]
const EX_TRIALS_FAILED: u8 = 2;

/// Sections this build implements beyond the daemon's own.
#[cfg(feature = "lab")]
const EXTENSIONS: &[&dyn SectionCheck] = &[&rfloc_lab::sim::SimulationSection];
#[cfg(not(feature = "lab"))]
const EXTENSIONS: &[&dyn SectionCheck] = &[];

#[derive(Debug, Parser)]
#[command(
    name = "rfloc",
    version,
    about = "Radio-based robot localisation daemon"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the daemon with a robot configuration (default: the embedded simulation, config/sim.toml).
    Run {
        /// Robot file (TOML). Without it: the embedded simulated HF-grid robot.
        #[arg(short, long)]
        config: Option<PathBuf>,
        /// Print each pose as a JSON line on stdout as well.
        #[arg(long)]
        stdout: bool,
    },
    /// Check a robot configuration and exit (78 with every error as file:line:col: key …).
    Validate {
        /// Robot file (TOML).
        #[arg(short, long)]
        config: PathBuf,
        /// Do not check that device nodes, credential and map files exist (validate for another machine).
        #[arg(long)]
        no_device_check: bool,
    },
    /// Run the recorded devices' own code on captured logs; print poses (or observations) as JSON lines.
    Replay {
        /// A capture folder (one .cap per device; robot.toml and pipeline.order from `rfloc record`).
        dir: PathBuf,
        /// Pipeline to run when the folder has no robot file (its default parameters).
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(rfloc_daemon::config::PIPELINES))]
        pipeline: Option<String>,
        /// Robot configuration supplying pipeline parameters (default: the folder's `robot.toml`).
        #[arg(short, long)]
        config: Option<PathBuf>,
        /// Print the decoded observations instead of running a pipeline.
        #[arg(long)]
        observations: bool,
        /// Also write an MCAP file for Foxglove: raw link bytes, observations, poses, scene.
        #[arg(long, value_name = "OUT.mcap")]
        mcap: Option<PathBuf>,
    },
    /// Run the daemon and record a capture of every device link into a folder.
    Record {
        /// Robot file (TOML).
        #[arg(short, long)]
        config: PathBuf,
        /// Folder for the captures, the robot file and the pipeline's input order.
        #[arg(short, long)]
        out: PathBuf,
        /// When the run ends, also write `run.mcap` into the folder (a replay of the recording:
        /// raw link bytes, observations, poses, scene).
        #[arg(long)]
        mcap: bool,
    },
    /// Run a seed scenario against emulated devices and report its metrics next to the seed's.
    #[cfg(feature = "lab")]
    Sim {
        /// Scenario file (see scenarios/).
        scenario: PathBuf,
        /// Output folder (default out/<scenario name>).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Run only this many trials.
        #[arg(long)]
        trials: Option<usize>,
        /// Exit 0 even when trials failed (they are still reported and warned about).
        #[arg(long)]
        allow_failures: bool,
    },
    /// Serve one emulated device to any client (ARIA programs, digi-xbee, SCIP tools …).
    #[cfg(feature = "lab")]
    Emulate {
        /// The device: aria (Pioneer), kts (HF reader), alien (UHF reader), xbee, urg (laser).
        #[arg(value_parser = ["aria", "kts", "alien", "xbee", "urg"])]
        device: String,
        /// Serve on a pseudo-terminal and make PATH a symlink to it.
        #[arg(long, value_name = "PATH", conflicts_with = "tcp")]
        pty: Option<PathBuf>,
        /// Serve on a TCP listener, one client at a time (the Pioneer's simulator port: 8101).
        #[arg(long, value_name = "ADDR:PORT")]
        tcp: Option<std::net::SocketAddr>,
        /// A scenario whose world (walls, tags, beacons) and sensor models the device senses.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Where the device (or the robot, at the start) is: x (m), y (m), heading (degrees).
        #[arg(long, value_name = "X,Y,DEG", value_delimiter = ',', num_args = 3, default_values_t = [0.0, 0.0, 0.0])]
        pose: Vec<f64>,
        /// XBee API mode: 1 (unescaped) or 2 (escaped).
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
        api_mode: u8,
        /// XBee firmware: zigbee or 802.15.4.
        #[arg(long, default_value = "zigbee", value_parser = ["zigbee", "802.15.4"])]
        flavor: String,
        /// Seed of every random draw.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Print the pose stream of a running daemon.
    Watch {
        /// TCP address of the pose stream.
        #[arg(long, default_value = "127.0.0.1:2948")]
        tcp: String,
        /// Unix socket of the pose stream (instead of TCP).
        #[arg(long)]
        unix: Option<PathBuf>,
        /// Print raw JSON lines.
        #[arg(long)]
        raw: bool,
        /// Exit after this many poses.
        #[arg(long)]
        count: Option<usize>,
    },
}

fn init_logging(level: &str, format: &str) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_env("RFLOC_LOG")
        .or_else(|_| EnvFilter::try_new(level))
        .unwrap_or_else(|_| EnvFilter::new("info"));
    // Under systemd the journal adds its own timestamps and does not want colours.
    let journald = std::env::var_os("JOURNAL_STREAM").is_some() && format != "full";
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(false);
    if journald {
        builder.without_time().init();
    } else {
        builder.init();
    }
}

fn report(errors: &ConfigErrors) -> ExitCode {
    for e in &errors.0 {
        eprintln!("{e}");
    }
    ExitCode::from(EX_CONFIG)
}

fn load_config(path: &Path, check_files: bool) -> Result<RobotConfig, ExitCode> {
    RobotConfig::load(
        path,
        &LoadOptions {
            check_files,
            extensions: EXTENSIONS,
            for_replay: false,
        },
    )
    .map_err(|e| report(&e))
}

fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
}

/// The embedded default robot file.
#[cfg(feature = "lab")]
fn embedded() -> Result<RobotConfig, ExitCode> {
    RobotConfig::load_text(
        EMBEDDED_SIM,
        "config/sim.toml (embedded)",
        None,
        &LoadOptions {
            check_files: true,
            extensions: EXTENSIONS,
            for_replay: false,
        },
    )
    .map_err(|e| report(&e))
}

#[cfg(not(feature = "lab"))]
fn embedded() -> Result<RobotConfig, ExitCode> {
    eprintln!(
        "rfloc: this build has no simulator (cargo feature `lab`); give a robot file with -c"
    );
    Err(ExitCode::from(EX_CONFIG))
}

/// Runs the daemon, with the lab's emulators when the robot file asks for a simulation.
#[cfg(feature = "lab")]
async fn run_daemon(
    mut cfg: RobotConfig,
    opts: rfloc_daemon::daemon::RunOptions,
) -> anyhow::Result<()> {
    let sim: Option<Box<dyn rfloc_daemon::simulation::Simulation>> = if cfg.simulation {
        Some(Box::new(rfloc_lab::sim::start(&mut cfg).await?))
    } else {
        None
    };
    rfloc_daemon::daemon::run(cfg, opts, sim).await
}

/// Runs the daemon (this build has no simulator; `validate` refuses `[simulation]`).
#[cfg(not(feature = "lab"))]
async fn run_daemon(
    cfg: RobotConfig,
    opts: rfloc_daemon::daemon::RunOptions,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        !cfg.simulation,
        "this build has no simulator (cargo feature `lab`)"
    );
    rfloc_daemon::daemon::run(cfg, opts, None).await
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Validate {
            config,
            no_device_check,
        } => match load_config(&config, !no_device_check) {
            Ok(cfg) => {
                println!(
                    "{}: ok (robot {:?}, {} device(s), pipeline {})",
                    config.display(),
                    cfg.robot.name,
                    cfg.devices.len(),
                    cfg.estimator.name()
                );
                ExitCode::SUCCESS
            }
            Err(code) => code,
        },
        Command::Run { config, stdout } => {
            let (cfg, stdout) = match config {
                Some(path) => match load_config(&path, true) {
                    Ok(c) => (c, stdout),
                    Err(code) => return code,
                },
                // The embedded default always prints its poses.
                None => match embedded() {
                    Ok(c) => (c, true),
                    Err(code) => return code,
                },
            };
            init_logging(&cfg.log.level, &cfg.log.format);
            run_async(run_daemon(
                cfg,
                rfloc_daemon::daemon::RunOptions {
                    stdout,
                    capture_dir: None,
                },
            ))
        }
        Command::Record { config, out, mcap } => {
            let cfg = match load_config(&config, true) {
                Ok(c) => c,
                Err(code) => return code,
            };
            init_logging(&cfg.log.level, &cfg.log.format);
            // The robot file goes with the captures: `rfloc replay` runs the pipeline with it.
            let copied = std::fs::create_dir_all(&out)
                .and_then(|()| std::fs::copy(&config, out.join("robot.toml")));
            if let Err(e) = copied {
                eprintln!(
                    "rfloc: cannot copy {} into {}: {e}",
                    config.display(),
                    out.display()
                );
                return ExitCode::from(73);
            }
            let code = run_async(run_daemon(
                cfg,
                rfloc_daemon::daemon::RunOptions {
                    stdout: false,
                    capture_dir: Some(out.clone()),
                },
            ));
            if !mcap || code != ExitCode::SUCCESS {
                return code;
            }
            let path = out.join("run.mcap");
            let opts = rfloc_daemon::replay::ReplayOptions {
                mcap: Some(path.clone()),
                ..rfloc_daemon::replay::ReplayOptions::default()
            };
            match rfloc_daemon::replay::replay_blocking(&out, &opts) {
                Ok(_) => {
                    eprintln!("rfloc: wrote {}", path.display());
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("rfloc: {}: {e:#}", path.display());
                    ExitCode::FAILURE
                }
            }
        }
        Command::Replay {
            dir,
            pipeline,
            config,
            observations,
            mcap,
        } => {
            init_logging("warn", "text");
            let cfg = match config {
                Some(c) => match load_config(&c, false) {
                    Ok(c) => Some(c),
                    Err(code) => return code,
                },
                None => None,
            };
            let opts = rfloc_daemon::replay::ReplayOptions {
                pipeline,
                config: cfg,
                observations,
                mcap,
            };
            match rfloc_daemon::replay::replay_dir(dir, &opts) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("rfloc: {e:#}");
                    ExitCode::FAILURE
                }
            }
        }
        #[cfg(feature = "lab")]
        Command::Sim {
            scenario: path,
            out,
            trials,
            allow_failures,
        } => {
            init_logging("warn", "text");
            let outcome = std::sync::Mutex::new(None);
            let code = run_async(async {
                let o = rfloc_lab::scenario::run(
                    &path,
                    rfloc_lab::scenario::SimOptions { out, trials },
                )
                .await?;
                if let Ok(mut slot) = outcome.lock() {
                    *slot = Some(o);
                }
                Ok(())
            });
            let outcome = outcome.into_inner().ok().flatten();
            match outcome {
                Some(o) if o.failures > 0 => {
                    eprintln!(
                        "warning: {} of {} trials failed (see the report)",
                        o.failures, o.trials
                    );
                    if allow_failures {
                        code
                    } else {
                        ExitCode::from(EX_TRIALS_FAILED)
                    }
                }
                _ => code,
            }
        }
        #[cfg(feature = "lab")]
        Command::Emulate {
            device,
            pty,
            tcp,
            scenario,
            pose,
            api_mode,
            flavor,
            seed,
        } => {
            init_logging("info", "text");
            let Some(device) = rfloc_lab::emulate::EmulatedDevice::named(&device) else {
                return ExitCode::from(2);
            };
            let tcp = match (&pty, tcp, device) {
                (None, None, rfloc_lab::emulate::EmulatedDevice::Aria) => {
                    Some(std::net::SocketAddr::from(([127, 0, 0, 1], 8101)))
                }
                _ => tcp,
            };
            let opts = rfloc_lab::emulate::EmulateOptions {
                device,
                pty,
                tcp,
                scenario,
                pose: [
                    pose.first().copied().unwrap_or(0.0),
                    pose.get(1).copied().unwrap_or(0.0),
                    pose.get(2).copied().unwrap_or(0.0),
                ],
                api_mode,
                flavor,
                seed,
            };
            run_async(rfloc_lab::emulate::run(opts))
        }
        Command::Watch {
            tcp,
            unix,
            raw,
            count,
        } => {
            init_logging("warn", "text");
            let endpoint = unix.map_or(watch::Endpoint::Tcp(tcp), watch::Endpoint::Unix);
            run_async(watch::watch(endpoint, raw, count))
        }
    }
}

fn run_async(fut: impl std::future::Future<Output = anyhow::Result<()>>) -> ExitCode {
    let rt = match runtime() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("rfloc: cannot start runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match rt.block_on(fut) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("rfloc: {e:#}");
            ExitCode::FAILURE
        }
    }
}
