//! `rfloc`: the rfloc localisation daemon and its tools.
#![forbid(unsafe_code)]

mod config;
mod daemon;
mod devices;
mod events;
mod message;
mod notify;
mod pipeline;
mod replay;
mod scenario;
mod server;
mod sim;
mod watch;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The default robot file: the simulated HF-grid AGV.
const EMBEDDED_SIM: &str = include_str!("../../../config/sim.toml");

/// Exit status for configuration errors (sysexits EX_CONFIG).
const EX_CONFIG: u8 = 78;

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
        #[arg(short, long)]
        config: Option<PathBuf>,
        /// Print each pose as a JSON line on stdout as well.
        #[arg(long)]
        stdout: bool,
    },
    /// Check a robot configuration and exit (78 on error).
    Validate {
        #[arg(short, long)]
        config: PathBuf,
        /// Do not check that device nodes and credential files exist (validate for another machine).
        #[arg(long)]
        no_device_check: bool,
    },
    /// Run the pipeline on captured device logs and print poses as JSON lines.
    Replay {
        /// A capture folder (one .cap per device, optional truth.csv).
        dir: PathBuf,
        /// Pipeline to run (default: chosen from the devices in the folder).
        #[arg(long)]
        pipeline: Option<String>,
        /// Robot configuration supplying pipeline parameters (default: the folder's
        /// `robot.toml`, which `rfloc record` writes, when there is one).
        #[arg(short, long)]
        config: Option<PathBuf>,
    },
    /// Run the daemon and record a capture of every device link into a folder.
    Record {
        #[arg(short, long)]
        config: PathBuf,
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Run a seed scenario against emulated devices and report its metrics next to the seed's.
    Sim {
        /// Scenario file (see scenarios/).
        scenario: PathBuf,
        /// Output folder (default out/<scenario name>).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Run only this many trials.
        #[arg(long)]
        trials: Option<usize>,
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
    let filter = EnvFilter::try_from_env("RFLOC_LOG").unwrap_or_else(|_| EnvFilter::new(level));
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

fn load_config(path: &std::path::Path) -> Result<config::RobotConfig, ExitCode> {
    load_config_with(path, true)
}

fn load_config_with(
    path: &std::path::Path,
    check_devices: bool,
) -> Result<config::RobotConfig, ExitCode> {
    config::RobotConfig::load_with(path, check_devices).map_err(|e| {
        eprintln!("rfloc: configuration error: {e}");
        ExitCode::from(EX_CONFIG)
    })
}

fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Validate {
            config,
            no_device_check,
        } => match load_config_with(&config, !no_device_check) {
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
            let config_dir = config
                .as_ref()
                .and_then(|p| p.parent().map(std::path::Path::to_path_buf));
            let (cfg, stdout) = match config {
                Some(path) => match load_config(&path) {
                    Ok(c) => (c, stdout),
                    Err(code) => return code,
                },
                // The embedded default always prints its poses.
                None => {
                    match config::RobotConfig::parse(EMBEDDED_SIM, "config/sim.toml (embedded)") {
                        Ok(c) => (c, true),
                        Err(e) => {
                            eprintln!("rfloc: embedded configuration error: {e}");
                            return ExitCode::from(EX_CONFIG);
                        }
                    }
                }
            };
            init_logging(&cfg.log.level, &cfg.log.format);
            run_async(daemon::run(
                cfg,
                daemon::RunOptions {
                    stdout,
                    capture_dir: None,
                    config_dir,
                },
            ))
        }
        Command::Record { config, out } => {
            let config_dir = config.parent().map(std::path::Path::to_path_buf);
            let cfg = match load_config(&config) {
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
            run_async(daemon::run(
                cfg,
                daemon::RunOptions {
                    stdout: false,
                    capture_dir: Some(out),
                    config_dir,
                },
            ))
        }
        Command::Replay {
            dir,
            pipeline,
            config,
        } => {
            init_logging("warn", "text");
            // Without -c, the robot file recorded with the session (if any) configures the
            // pipeline; its devices need not exist here.
            let session_robot = dir.join("robot.toml");
            let cfg = match config {
                Some(c) => load_config(&c).map(Some),
                None if pipeline.is_none() && session_robot.is_file() => {
                    load_config_with(&session_robot, false).map(Some)
                }
                None => Ok(None),
            };
            let cfg = match cfg {
                Ok(c) => c,
                Err(code) => return code,
            };
            run_async(replay::replay_dir(dir, pipeline, cfg))
        }
        Command::Sim {
            scenario: path,
            out,
            trials,
        } => {
            init_logging("warn", "text");
            run_async(scenario::run(&path, scenario::SimOptions { out, trials }))
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
