//! The driver registry, the robot file schema and replay see every device kind: each kind
//! parses from a robot file and validates, and each kind that has a link has a capture under
//! `tests/captures` that replays through its driver.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;

use rfloc_daemon::config::{LoadOptions, RobotConfig};
use rfloc_daemon::devices::{kind_for_capture, REGISTRY};

/// The smallest `[device.driver]` body of each kind (after `kind = "…"`).
fn minimal(kind: &str) -> Option<&'static str> {
    Some(match kind {
        "aria" | "kts" | "alien" | "urg" => "",
        "xbee" => "api_mode = 2",
        "stepper" => {
            "chip = \"/dev/gpiochip0\"\nstep_line = \"17\"\ndir_line = \"18\"\nsteps_per_rev = 200"
        }
        _ => return None,
    })
}

#[test]
fn every_kind_parses_and_validates_from_a_robot_file() {
    for k in REGISTRY {
        let body = minimal(k.kind()).unwrap_or_else(|| {
            panic!("kind {:?} has no minimal robot file in this test", k.kind())
        });
        let text = format!(
            "[robot]\nname = \"r\"\n\n[[device]]\nname = \"d\"\nlink = {{ kind = \"tcp\", address = \"127.0.0.1:9\" }}\n[device.driver]\nkind = \"{}\"\n{body}\n\n[[device]]\nname = \"base\"\nlink = {{ kind = \"tcp\", address = \"127.0.0.1:9\" }}\n[device.driver]\nkind = \"aria\"\n\n[estimator]\npipeline = \"odometry\"\n",
            k.kind()
        );
        let cfg = RobotConfig::load_text(
            &text,
            "r.toml",
            None,
            &LoadOptions {
                check_files: false,
                extensions: &[],
                for_replay: false,
            },
        )
        .unwrap_or_else(|e| panic!("{}: {e}", k.kind()));
        assert_eq!(cfg.devices[0].driver.kind(), k.kind());
        // An unknown key is an error at its own line, whatever the kind.
        let bad = text.replacen(
            &format!("kind = \"{}\"\n", k.kind()),
            &format!("kind = \"{}\"\nno_such_key = 1\n", k.kind()),
            1,
        );
        let e = RobotConfig::parse(&bad, "r.toml", None).unwrap_err();
        assert!(
            e.to_string()
                .contains("r.toml:9:1: key `device[0].driver.no_such_key`"),
            "{}: {e}",
            k.kind()
        );
    }
}

#[test]
fn every_kind_with_a_link_has_a_capture_that_replays() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures");
    let mut captured = std::collections::HashSet::new();
    for dir in std::fs::read_dir(&root).unwrap() {
        for f in std::fs::read_dir(dir.unwrap().path()).unwrap() {
            let p = f.unwrap().path();
            if p.extension().is_some_and(|e| e == "cap") {
                let cap = rfloc_capture::Capture::from_path(&p).unwrap();
                let device = cap.header.device.unwrap_or_default();
                let kind = kind_for_capture(&device)
                    .unwrap_or_else(|| panic!("{}: no kind replays {device:?}", p.display()));
                captured.insert(kind.kind());
            }
        }
    }
    for k in REGISTRY {
        if k.kind() == "stepper" {
            continue; // GPIO, no link: its angles travel in the radio's sweep marks.
        }
        assert!(
            captured.contains(k.kind()),
            "no capture of kind {:?}",
            k.kind()
        );
        for c in k.captures() {
            assert!(
                k.for_capture(c).is_some(),
                "{} cannot replay {c:?} alone",
                k.kind()
            );
        }
    }
}
