//! `rfloc validate` on good and bad robot files: exit codes and messages.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn rfloc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rfloc"))
}

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn validate(path: &Path, extra: &[&str]) -> (i32, String) {
    let out = rfloc()
        .arg("validate")
        .args(extra)
        .arg("-c")
        .arg(path)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn every_shipped_config_validates() {
    let mut n = 0;
    for e in std::fs::read_dir(workspace().join("config")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let (code, text) = validate(&p, &["--no-device-check"]);
            assert_eq!(code, 0, "{}: {text}", p.display());
            n += 1;
        }
    }
    assert!(n >= 4, "expected the example configs, found {n}");
}

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const BASE: &str = r#"[robot]
name = "t"

[[device]]
name = "hf"
link = { kind = "tcp", address = "127.0.0.1:9" }
[device.driver]
kind = "kts"

[estimator]
pipeline = "hfgrid"
tag_field = "seed002-test"
"#;

#[test]
fn good_file_exits_zero() {
    let dir = tempfile::tempdir().unwrap();
    let (code, text) = validate(&write(&dir, "ok.toml", BASE), &[]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("ok (robot \"t\""), "{text}");
}

#[test]
fn unknown_key_exits_78_naming_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        &dir,
        "unknown.toml",
        &BASE.replace("kind = \"kts\"", "kind = \"kts\"\nbaudrate = 9600"),
    );
    let (code, text) = validate(&p, &[]);
    assert_eq!(code, 78, "{text}");
    assert!(text.contains("unknown.toml:9:"), "{text}");
    assert!(text.contains("baudrate"), "{text}");
    assert_eq!(text.lines().count(), 1, "one clear message: {text}");
}

#[test]
fn wrong_type_exits_78() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "type.toml", &BASE.replace("name = \"t\"", "name = 3"));
    let (code, text) = validate(&p, &[]);
    assert_eq!(code, 78, "{text}");
    assert!(
        text.contains("type.toml:2:") && text.contains("robot.name"),
        "{text}"
    );
}

#[test]
fn missing_device_path_exits_78() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        &dir,
        "path.toml",
        &BASE.replace(
            "link = { kind = \"tcp\", address = \"127.0.0.1:9\" }",
            "link = { kind = \"serial\", path = \"/dev/ttyRFLOC-missing\", baud = 115200 }",
        ),
    );
    let (code, text) = validate(&p, &[]);
    assert_eq!(code, 78, "{text}");
    assert!(
        text.contains("path.toml:6:") && text.contains("/dev/ttyRFLOC-missing"),
        "{text}"
    );
    // The same file is fine when validated for another machine.
    let (code, _) = validate(&p, &["--no-device-check"]);
    assert_eq!(code, 0);
}

#[test]
fn unreadable_file_exits_78() {
    let (code, text) = validate(Path::new("/nonexistent/robot.toml"), &[]);
    assert_eq!(code, 78);
    assert!(text.contains("/nonexistent/robot.toml"), "{text}");
}

#[test]
fn every_error_of_a_file_is_reported_with_its_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let text = BASE
        .replace("name = \"t\"", "name = \"t\"\ncolour = \"red\"")
        .replace("kind = \"kts\"", "kind = \"kts\"\nresync_after_s = 1e300")
        + "\n[pose]\nprecision = 100000\nclient_queue = 0\n";
    let (code, text) = validate(&write(&dir, "many.toml", &text), &[]);
    assert_eq!(code, 78, "{text}");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert!(
        lines[0].starts_with("many.toml:3:1: key `robot.colour`")
            || lines[0].contains("many.toml:3:1: key `robot.colour`"),
        "{text}"
    );
    assert!(
        lines[1].contains(":10:1: key `device[0].driver.resync_after_s`"),
        "{text}"
    );
    assert!(lines[2].contains(":17:1: key `pose.precision`"), "{text}");
    assert!(
        lines[3].contains(":18:1: key `pose.client_queue`"),
        "{text}"
    );
}

#[test]
fn an_hf_robot_without_its_floor_tags_is_refused() {
    let shipped = std::fs::read_to_string(workspace().join("config/hf-agv.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let no_map: String = shipped
        .lines()
        .filter(|l| !l.starts_with("tag_map"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_ne!(no_map, shipped);
    let (code, text) = validate(&write(&dir, "hf.toml", &no_map), &["--no-device-check"]);
    assert_eq!(code, 78, "{text}");
    assert!(
        text.contains("key `estimator.pipeline`") && text.contains("tags"),
        "{text}"
    );
    // A UID that is not hex is refused at validate, not warned about at run time.
    let bad = BASE.replace(
        "tag_field = \"seed002-test\"",
        "[[estimator.tag]]\nuid = \"E0040150-3A5BD691\"\nx = 0.1\ny = 0.2",
    );
    let (code, text) = validate(&write(&dir, "uid.toml", &bad), &[]);
    assert_eq!(code, 78, "{text}");
    assert!(text.contains("key `estimator.tag[0].uid`"), "{text}");
}

#[test]
fn a_pose_stream_for_other_hosts_needs_access_control() {
    let dir = tempfile::tempdir().unwrap();
    let open = format!("{BASE}\n[pose]\ntcp = \"0.0.0.0:2948\"\n");
    let (code, text) = validate(&write(&dir, "open.toml", &open), &[]);
    assert_eq!(code, 78, "{text}");
    assert!(
        text.contains("key `pose.tcp`") && text.contains("access control"),
        "{text}"
    );
    let token = dir.path().join("pose-token");
    std::fs::write(&token, "0123456789abcdef0123\n").unwrap();
    let guarded = format!("{open}token_file = {:?}\n", token.display().to_string());
    let (code, text) = validate(&write(&dir, "guarded.toml", &guarded), &[]);
    assert_eq!(code, 0, "{text}");
    let listed = format!("{open}allow = [\"192.168.10.0/24\", \"not an address\"]\n");
    let (code, text) = validate(&write(&dir, "listed.toml", &listed), &[]);
    assert_eq!(code, 78, "{text}");
    assert!(text.contains("key `pose.allow[1]`"), "{text}");
    // A Unix socket in a folder that does not exist fails at validate, not at run time.
    let unix = format!("{BASE}\n[pose]\nunix = \"/nonexistent-rfloc/pose.sock\"\n");
    let (code, text) = validate(&write(&dir, "unix.toml", &unix), &[]);
    assert_eq!(code, 78, "{text}");
    assert!(text.contains("key `pose.unix`"), "{text}");
}

#[test]
fn learned_state_that_is_missing_or_damaged_fails_validation() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    std::fs::create_dir(&state).unwrap();
    let robot = format!(
        "[robot]\nname = \"uhf\"\n\n[[device]]\nname = \"base\"\nlink = {{ kind = \"tcp\", address = \"127.0.0.1:9\" }}\n[device.driver]\nkind = \"aria\"\n\n[[device]]\nname = \"uhf\"\nlink = {{ kind = \"tcp\", address = \"127.0.0.1:9\" }}\n[device.driver]\nkind = \"alien\"\n\n[estimator]\npipeline = \"snapshot\"\n\n[state]\ndir = {:?}\n",
        state.display().to_string()
    );
    let path = write(&dir, "uhf.toml", &robot);
    // Missing.
    let (code, text) = validate(&path, &[]);
    assert_eq!(code, 78, "{text}");
    assert!(text.contains("key `estimator.database`"), "{text}");
    // Truncated.
    std::fs::write(
        state.join("snapshot-db.json"),
        "{\"format_version\": 1, \"sta",
    )
    .unwrap();
    let (code, text) = validate(&path, &[]);
    assert_eq!(code, 78, "{text}");
    assert!(text.contains("malformed"), "{text}");
    // Another machine's file is not looked at.
    let (code, _) = validate(&path, &["--no-device-check"]);
    assert_eq!(code, 0);
}

/// Values that once validated and then crashed the daemon (exit 101, a panic converting float
/// seconds or formatting), and others of their kind: each is a configuration error now.
#[test]
fn numbers_out_of_range_are_configuration_errors() {
    let dir = tempfile::tempdir().unwrap();
    let sim = std::fs::read_to_string(workspace().join("config/sim.toml")).unwrap();
    let cases: &[(&str, &str, &str)] = &[
        (
            "stale_after_s = 2.0",
            "stale_after_s = 1e300",
            "device[1].stale_after_s",
        ),
        (
            "duration_s = 40.0",
            "duration_s = -1",
            "simulation.duration_s",
        ),
        (
            "duration_s = 40.0",
            "duration_s = 1e300",
            "simulation.duration_s",
        ),
        (
            "stdout = true",
            "stdout = true\nprecision = 100000",
            "pose.precision",
        ),
        (
            "pulse_period_s = 0.5",
            "pulse_period_s = 1e300",
            "device[0].driver.pulse_period_s",
        ),
        (
            "pulse_period_s = 0.5",
            "pulse_period_s = inf",
            "device[0].driver.pulse_period_s",
        ),
        (
            "kind = \"kts\"",
            "kind = \"kts\"\nresync_after_s = 1e300",
            "device[1].driver.resync_after_s",
        ),
        (
            "stdout = true",
            "stdout = true\nclient_queue = 0",
            "pose.client_queue",
        ),
        (
            "time_scale = 5.0",
            "time_scale = nan",
            "simulation.time_scale",
        ),
        (
            "name = \"sim-agv\"",
            "name = \"sim-agv\"\n\n[log]\nlevel = \"loud\"",
            "log.level",
        ),
    ];
    for (i, (old, new, key)) in cases.iter().enumerate() {
        let text = sim.replacen(old, new, 1);
        assert_ne!(text, sim, "config/sim.toml has no {old:?}");
        let (code, out) = validate(&write(&dir, &format!("case{i}.toml"), &text), &[]);
        assert_eq!(code, 78, "{new}: {out}");
        assert!(out.contains(&format!("key `{key}`")), "{new}: {out}");
    }
}

/// The EKF-SLAM pipeline's count of sweeps at the start pose: at least one, at most 1000.
#[test]
fn start_sweeps_out_of_range_are_configuration_errors() {
    let dir = tempfile::tempdir().unwrap();
    let xbee = std::fs::read_to_string(workspace().join("config/sim-xbee.toml")).unwrap();
    for (i, bad) in ["0", "1001", "-1"].iter().enumerate() {
        let text = xbee.replacen(
            "beacon_init_with_range = true",
            &format!("beacon_init_with_range = true\nstart_sweeps = {bad}"),
            1,
        );
        assert_ne!(
            text, xbee,
            "config/sim-xbee.toml has no beacon_init_with_range"
        );
        let (code, out) = validate(&write(&dir, &format!("start{i}.toml"), &text), &[]);
        assert_eq!(code, 78, "start_sweeps = {bad}: {out}");
        assert!(out.contains("start_sweeps"), "start_sweeps = {bad}: {out}");
    }
    let good = xbee.replacen(
        "beacon_init_with_range = true",
        "beacon_init_with_range = true\nstart_sweeps = 8",
        1,
    );
    let (code, out) = validate(
        &write(&dir, "start-good.toml", &good),
        &["--no-device-check"],
    );
    assert_eq!(code, 0, "{out}");
}
