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
