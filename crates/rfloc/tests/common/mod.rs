//! The `rfloc` binary as a child process, for end-to-end tests.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, dead_code)]

pub mod fleet;

use std::process::{Child, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::Duration;

use tokio::io::{BufReader, Lines};
use tokio::net::TcpStream;

/// The numeric rows of a trial's pose file (`truth.csv`, `estimate.csv`: `t,x,y,theta`), the
/// header skipped.
pub fn pose_rows(path: &std::path::Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

/// Messages on `topic` in an MCAP file's summary statistics (0 when it has none).
pub fn mcap_topic_count(summary: &mcap::Summary, topic: &str) -> u64 {
    let Some(stats) = summary.stats.as_ref() else {
        return 0;
    };
    summary
        .channels
        .iter()
        .filter(|(_, c)| c.topic == topic)
        .map(|(id, _)| stats.channel_message_counts.get(id).copied().unwrap_or(0))
        .sum()
}

/// A free loopback TCP port.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A simulation robot file from `config/<name>` written to `dir/robot.toml` for a test: the pose
/// port `port_from` (as `127.0.0.1:NNNN` in the file) moved to `port`, stdout off, the scenario
/// path made absolute, captures into `dir/cap`, then each `(old, new)` edit. Every edit must
/// change the text, so a test cannot silently run the file unedited after it changed.
pub fn sim_robot_file(
    dir: &std::path::Path,
    name: &str,
    port_from: &str,
    port: u16,
    edits: &[(&str, &str)],
) -> std::path::PathBuf {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut text = std::fs::read_to_string(root.join("config").join(name)).unwrap();
    let scenarios = root.join("scenarios").display().to_string();
    let capture = format!(
        "[state]\ncapture_dir = {:?}\n\n[pose]",
        dir.join("cap").display().to_string()
    );
    let fixed = [
        (port_from.to_string(), format!("127.0.0.1:{port}")),
        ("stdout = true".into(), "stdout = false".into()),
        ("\"../scenarios/".into(), format!("\"{scenarios}/")),
        ("[pose]".into(), capture),
    ];
    let all = fixed
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .chain(edits.iter().copied());
    for (old, new) in all {
        let edited = text.replace(old, new);
        assert_ne!(edited, text, "config/{name} has no {old:?} to edit");
        text = edited;
    }
    let path = dir.join("robot.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `rfloc run -c <config>` with its log (stderr) collected.
pub struct Daemon {
    child: Child,
    log: Option<JoinHandle<String>>,
}

impl Daemon {
    /// Starts the daemon with `RFLOC_LOG=<log_level>` and without a systemd credentials folder.
    pub fn start(config: &std::path::Path, log_level: &str) -> Self {
        Self::spawn(
            &["run".as_ref(), "-c".as_ref(), config.as_os_str()],
            log_level,
        )
    }

    /// As [`Daemon::start`], recording every device link into `out` (`rfloc record`).
    pub fn record(config: &std::path::Path, out: &std::path::Path, log_level: &str) -> Self {
        Self::spawn(
            &[
                "record".as_ref(),
                "-c".as_ref(),
                config.as_os_str(),
                "-o".as_ref(),
                out.as_os_str(),
            ],
            log_level,
        )
    }

    fn spawn(args: &[&std::ffi::OsStr], log_level: &str) -> Self {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_rfloc"))
            .args(args)
            .env("RFLOC_LOG", log_level)
            .env_remove("CREDENTIALS_DIRECTORY")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stderr = child.stderr.take().unwrap();
        let log = std::thread::spawn(move || {
            let mut text = String::new();
            let _ = std::io::Read::read_to_string(&mut stderr, &mut text);
            text
        });
        Self {
            child,
            log: Some(log),
        }
    }

    /// The pose stream's JSON lines, retrying the connection while the daemon starts (it
    /// loads its learned state first; up to 30 s on a loaded machine).
    pub async fn pose_lines(&self, port: u16) -> Lines<BufReader<TcpStream>> {
        use tokio::io::AsyncBufReadExt;
        for _ in 0..600 {
            if let Ok(s) = TcpStream::connect(("127.0.0.1", port)).await {
                return BufReader::new(s).lines();
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        panic!("pose port {port} never opened");
    }

    /// Sends SIGTERM and waits up to 15 s; returns the exit status and the whole log.
    pub async fn terminate(mut self) -> (ExitStatus, String) {
        let killed = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        for _ in 0..300 {
            if let Some(status) = self.child.try_wait().unwrap() {
                let log = self.log.take().unwrap().join().unwrap();
                return (status, log);
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let _ = self.child.kill();
        panic!("daemon did not exit within 15 s of SIGTERM");
    }

    /// Waits up to `limit` for the daemon to exit on its own (a simulation's duration);
    /// returns the exit status and the whole log.
    pub async fn wait(mut self, limit: Duration) -> (ExitStatus, String) {
        let deadline = tokio::time::Instant::now() + limit;
        while tokio::time::Instant::now() < deadline {
            if let Some(status) = self.child.try_wait().unwrap() {
                let log = self.log.take().unwrap().join().unwrap();
                return (status, log);
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let _ = self.child.kill();
        let log = self.log.take().unwrap().join().unwrap();
        panic!("daemon still running after {limit:?}; log:\n{log}");
    }

    /// Stops the daemon if it still runs (SIGKILL) and returns its exit status and log; for
    /// reporting a failure whatever state the daemon is in.
    pub async fn terminate_or_collect(mut self) -> (ExitStatus, String) {
        let _ = self.child.kill();
        let status = self.child.wait().unwrap();
        let log = self.log.take().unwrap().join().unwrap();
        (status, log)
    }

    /// Stops the daemon and fails the test with `what` and the last 40 lines of its log.
    pub async fn fail_with_log_tail(self, what: &str) -> ! {
        let (_, log) = self.terminate_or_collect().await;
        let tail: Vec<&str> = log.lines().rev().take(40).collect();
        panic!(
            "{what}; log tail:\n{}",
            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
        );
    }
}

/// The next line of a pose stream before `deadline`; `None` when the stream ended, failed or
/// the time ran out. Every line is checked against `docs/pose-stream.schema.json`.
pub async fn next_line_before(
    lines: &mut Lines<BufReader<TcpStream>>,
    deadline: tokio::time::Instant,
) -> Option<String> {
    match tokio::time::timeout_at(deadline, lines.next_line()).await {
        Ok(Ok(Some(line))) => {
            assert_stream_line(&line);
            Some(line)
        }
        _ => None,
    }
}

/// The pose stream's JSON Schema, compiled once.
fn stream_schema() -> &'static jsonschema::Validator {
    static SCHEMA: std::sync::OnceLock<jsonschema::Validator> = std::sync::OnceLock::new();
    SCHEMA.get_or_init(|| {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../docs/pose-stream.schema.json");
        let schema: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        assert!(
            jsonschema::meta::is_valid(&schema),
            "the schema is not a valid JSON Schema"
        );
        jsonschema::validator_for(&schema).unwrap()
    })
}

/// Panics with the schema's complaints unless `line` is a valid pose stream line.
pub fn assert_stream_line(line: &str) {
    let value: serde_json::Value =
        serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
    let errors: Vec<String> = stream_schema()
        .iter_errors(&value)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect();
    assert!(
        errors.is_empty(),
        "{line}\nfails docs/pose-stream.schema.json: {errors:?}"
    );
}

/// `key=value` of the last log line containing `needle`.
pub fn logged(log: &str, needle: &str, key: &str) -> f64 {
    let line = log
        .lines()
        .rev()
        .find(|l| l.contains(needle))
        .unwrap_or_else(|| panic!("no log line with {needle:?}"));
    let start = line
        .find(&format!(" {key}="))
        .unwrap_or_else(|| panic!("no {key} in {line}"))
        + key.len()
        + 2;
    line[start..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}
