//! Determinism of simulated trials: `rfloc sim` run twice with one seed writes identical
//! captures (byte for byte: the lock-step emulators and coalesced capture records leave nothing
//! to timing) and identical truth, estimate, `run.mcap` and plot files; another seed writes different ones, so
//! the comparison can fail. Shortened runs of seed 003 case I, seed 002's 3×3 test and seed 001
//! scenario A (full scenario: both systems reach the emitter within 20 s of simulated time)
//! and seed 000 (150 exploration and 20 navigation steps).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A shipped scenario with text replaced, written into `dir` under the same file name (the
/// scenario's name must match its file stem).
fn variant(dir: &Path, file: &str, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(workspace().join("scenarios").join(file)).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{file} has no `{from}`");
        text = text.replace(from, to);
    }
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join(file);
    std::fs::write(&path, text).unwrap();
    path
}

/// Runs one trial of `scenario` into `out` and returns the trial folder.
fn sim(scenario: &Path, out: &Path) -> PathBuf {
    let o = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .current_dir(workspace())
        .arg("sim")
        .arg(scenario)
        .args(["--trials", "1", "--allow-failures", "-o"])
        .arg(out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "rfloc sim failed: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    out.join("trial-00")
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Asserts the files are identical; returns their total size.
fn assert_same(a: &Path, b: &Path, files: &[&str]) -> usize {
    let mut total = 0;
    for f in files {
        let (x, y) = (read(&a.join(f)), read(&b.join(f)));
        if x != y {
            // Name the first record that differs.
            let first = x
                .split(|c| *c == b'\n')
                .zip(y.split(|c| *c == b'\n'))
                .enumerate()
                .find(|(_, (p, q))| p != q)
                .map(|(i, (p, q))| {
                    format!(
                        "line {}:\n  {}\n  {}",
                        i + 1,
                        String::from_utf8_lossy(p),
                        String::from_utf8_lossy(q)
                    )
                });
            panic!("{f} differs between runs with one seed ({first:?})");
        }
        // The capture holds traffic both ways on the simulated clock.
        if f.ends_with(".cap") {
            let cap = rfloc_capture::Capture::from_path(&a.join(f)).unwrap();
            assert!(
                !cap.rx_bytes().is_empty() && !cap.tx_bytes().is_empty(),
                "{f}"
            );
        }
        total += x.len();
    }
    total
}

/// Asserts both trials' `run.mcap` hold every capture record and the same messages (topic, log
/// time, bytes) in the same order. (The files are not byte for byte the same: the MCAP writer
/// lists the schemas of its summary in no fixed order.)
fn assert_same_mcap(a: &Path, b: &Path) {
    let messages = |dir: &Path| -> Vec<(String, u64, Vec<u8>)> {
        let bytes = read(&dir.join("run.mcap"));
        mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.channel.topic.clone(), m.log_time, m.data.to_vec())
            })
            .collect()
    };
    let (x, y) = (messages(a), messages(b));
    assert!(x.len() > 10, "run.mcap has {} messages", x.len());
    assert_mcap_has_every_capture_record(a, &x);
    assert_mcap_has_every_capture_record(b, &y);
    if let Some(i) = (0..x.len().max(y.len())).find(|i| x.get(*i) != y.get(*i)) {
        panic!(
            "run.mcap differs between runs with one seed at message {i}: {:?} vs {:?}",
            x.get(i).map(|m| (&m.0, m.1)),
            y.get(i).map(|m| (&m.0, m.1))
        );
    }
}

/// `run.mcap` is written from the captures when the trial ends: it holds one link message per
/// byte record of the files as they are now (a capture still being written then would be cut
/// short).
fn assert_mcap_has_every_capture_record(dir: &Path, messages: &[(String, u64, Vec<u8>)]) {
    let links = messages.iter().filter(|m| m.0 == "/rfloc/link").count();
    let records: usize = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "cap"))
        .map(|p| {
            let cap = rfloc_capture::Capture::from_path(&p).unwrap();
            cap.records
                .iter()
                .filter(|r| !matches!(r.kind, rfloc_capture::RecordKind::Event(_)))
                .count()
        })
        .sum();
    assert_eq!(
        links,
        records,
        "{}: link messages in run.mcap against capture records",
        dir.display()
    );
}

fn assert_captures_differ(a: &Path, b: &Path, files: &[&str]) {
    assert!(
        files.iter().any(|f| read(&a.join(f)) != read(&b.join(f))),
        "another seed gave identical captures: the comparison cannot fail"
    );
}

#[test]
fn seed003_case1_runs_are_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let short = [("duration_s = 300.0", "duration_s = 20.0")];
    let scenario = variant(&tmp.path().join("s"), "seed003-case1.toml", &short);
    let a = sim(&scenario, &tmp.path().join("a"));
    let b = sim(&scenario, &tmp.path().join("b"));
    let caps = ["pioneer.cap", "xbee.cap"];
    let bytes = assert_same(&a, &b, &caps);
    assert_same(&a, &b, &["truth.csv", "estimate.csv", "plot.svg"]);
    assert_same_mcap(&a, &b);
    eprintln!(
        "seed003 case I: {} captures identical, {bytes} bytes",
        caps.len()
    );
    let other = variant(
        &tmp.path().join("o"),
        "seed003-case1.toml",
        &[short[0], ("seed = 3001", "seed = 3101")],
    );
    let c = sim(&other, &tmp.path().join("c"));
    assert_captures_differ(&a, &c, &caps);
}

#[test]
fn seed002_3x3_runs_are_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = workspace().join("scenarios/seed002-3x3.toml");
    let a = sim(&scenario, &tmp.path().join("a"));
    let b = sim(&scenario, &tmp.path().join("b"));
    let caps = ["pioneer.cap", "kts.cap"];
    let bytes = assert_same(&a, &b, &caps);
    assert_same(&a, &b, &["truth.csv", "estimate.csv", "plot.svg"]);
    assert_same_mcap(&a, &b);
    eprintln!(
        "seed002 3x3: {} captures identical, {bytes} bytes",
        caps.len()
    );
    let other = variant(
        &tmp.path().join("o"),
        "seed002-3x3.toml",
        &[("seed = 2002", "seed = 2102")],
    );
    let c = sim(&other, &tmp.path().join("c"));
    assert_captures_differ(&a, &c, &caps);
}

#[test]
fn seed001_a_runs_are_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = workspace().join("scenarios/seed001-a.toml");
    let a = sim(&scenario, &tmp.path().join("a"));
    let b = sim(&scenario, &tmp.path().join("b"));
    // The scenario's system (full) and the other one (preliminary), each on its own link.
    let caps = ["pioneer.cap", "pioneer-preliminary.cap"];
    let bytes = assert_same(&a, &b, &caps);
    assert_same(&a, &b, &["truth.csv", "estimate.csv", "plot.svg"]);
    assert_same_mcap(&a, &b);
    eprintln!(
        "seed001 A: {} captures identical, {bytes} bytes",
        caps.len()
    );
    // The world file is relative to the scenario: point the copy at the shipped one.
    let world = format!(
        "world_file = \"{}\"",
        workspace()
            .join("scenarios/worlds/seed001-a.toml")
            .display()
    );
    let other = variant(
        &tmp.path().join("o"),
        "seed001-a.toml",
        &[
            ("world_file = \"worlds/seed001-a.toml\"", world.as_str()),
            ("seed = 1001", "seed = 1101"),
        ],
    );
    let c = sim(&other, &tmp.path().join("c"));
    assert_captures_differ(&a, &c, &caps);
}

#[test]
fn seed000_reduced_runs_are_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let world = format!(
        "world_file = \"{}\"",
        workspace()
            .join("scenarios/worlds/seed000-5x5.toml")
            .display()
    );
    let short = [
        ("world_file = \"worlds/seed000-5x5.toml\"", world.as_str()),
        ("exploration_steps = 1000", "exploration_steps = 150"),
        ("navigation_steps = 500", "navigation_steps = 20"),
    ];
    let scenario = variant(&tmp.path().join("s"), "seed000-sim.toml", &short);
    let a = sim(&scenario, &tmp.path().join("a"));
    let b = sim(&scenario, &tmp.path().join("b"));
    let caps = ["pioneer.cap", "alien.cap"];
    let bytes = assert_same(&a, &b, &caps);
    assert_same(
        &a,
        &b,
        &[
            "truth.csv",
            "estimate.csv",
            "navigation.csv",
            "snapshot-db.v1.json",
            "survey.v1.json",
            "tag-map.v1.json",
            "state-manifest.json",
        ],
    );
    assert_same_mcap(&a, &b);
    eprintln!(
        "seed000 reduced: {} captures identical, {bytes} bytes",
        caps.len()
    );
    let mut other: Vec<(&str, &str)> = short.to_vec();
    other.push(("seed = 1000", "seed = 1100"));
    let c = sim(
        &variant(&tmp.path().join("o"), "seed000-sim.toml", &other),
        &tmp.path().join("c"),
    );
    assert_captures_differ(&a, &c, &caps);
}
