//! Atomic save/load of the learned database.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

mod common;

use std::io::Write;

use common::{explore, World};
use rfloc_snapshot::store::write_atomic;
use rfloc_snapshot::*;

/// Structural equality with floats equal to 1e-12 relative. serde_json (without its
/// `float_roundtrip` feature, which the workspace does not enable) may parse a printed f64 one
/// ULP away from the original, so a bit-exact comparison would fail spuriously.
fn assert_same(a: &SnapshotDatabase, b: &SnapshotDatabase) {
    fn walk(x: &serde_json::Value, y: &serde_json::Value, at: &str) {
        use serde_json::Value::*;
        match (x, y) {
            (Number(p), Number(q)) => {
                let (p, q) = (p.as_f64().unwrap(), q.as_f64().unwrap());
                assert!(
                    (p - q).abs() <= 1e-12 * p.abs().max(q.abs()).max(1e-300),
                    "{at}: {p} vs {q}"
                );
            }
            (Array(p), Array(q)) => {
                assert_eq!(p.len(), q.len(), "{at}");
                for (i, (u, v)) in p.iter().zip(q).enumerate() {
                    walk(u, v, &format!("{at}[{i}]"));
                }
            }
            (Object(p), Object(q)) => {
                assert_eq!(
                    p.keys().collect::<Vec<_>>(),
                    q.keys().collect::<Vec<_>>(),
                    "{at}"
                );
                for (k, u) in p {
                    walk(u, &q[k], &format!("{at}.{k}"));
                }
            }
            _ => assert_eq!(x, y, "{at}"),
        }
    }
    walk(
        &serde_json::to_value(a).unwrap(),
        &serde_json::to_value(b).unwrap(),
        "db",
    );
}

fn small_db() -> SnapshotDatabase {
    let world = World::seed_world(5, 0.05);
    let obs = explore(&world, 120, 0.25, 8);
    SnapshotDatabase::learn(&obs, &LearnConfig::default()).unwrap()
}

#[test]
fn save_load_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("snapshot-db.json");
    let db = small_db();
    db.save(&path).unwrap();
    let back = SnapshotDatabase::load(&path).unwrap();
    assert_same(&back, &db);
    assert_eq!(back.counts, db.counts);
    assert_eq!(back.states.len(), db.states.len());
    assert_eq!(back.config_hash, LearnConfig::default().hash());
    // the reloaded database localises like the original
    for s in &db.states {
        let (a, b) = (back.localise(&s.prototype), db.localise(&s.prototype));
        assert_eq!(a.state, b.state);
        assert!((a.distance - b.distance).abs() < 1e-12);
    }
    // no temporary file is left behind
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
}

#[test]
fn failed_write_keeps_the_good_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("snapshot-db.json");
    let db = small_db();
    db.save(&path).unwrap();
    let good = std::fs::read(&path).unwrap();
    // a writer that dies half way through the new content
    let err = write_atomic(&path, |f| {
        f.write_all(&good[..good.len() / 2]).unwrap();
        Err(SnapshotError::InvalidConfig(
            "simulated crash during write".into(),
        ))
    });
    assert!(err.is_err());
    assert_eq!(std::fs::read(&path).unwrap(), good);
    assert_same(&SnapshotDatabase::load(&path).unwrap(), &db);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "temporary file left: {names:?}");
}

#[test]
fn truncated_or_foreign_files_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db.json");
    let db = small_db();
    db.save(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 3]).unwrap();
    assert!(matches!(
        SnapshotDatabase::load(&path),
        Err(SnapshotError::Format { .. })
    ));
    let mut v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    v["format_version"] = serde_json::json!(99);
    std::fs::write(&path, serde_json::to_vec(&v).unwrap()).unwrap();
    assert!(matches!(
        SnapshotDatabase::load(&path),
        Err(SnapshotError::Version { found: 99, .. })
    ));
    assert!(matches!(
        SnapshotDatabase::load(&dir.path().join("missing.json")),
        Err(SnapshotError::Io { .. })
    ));
}

#[test]
fn config_hash_changes_with_config() {
    let a = LearnConfig::default();
    let b = LearnConfig {
        distance: SnapshotDistance::SeedScore { id_weight: 0.6 },
        ..a
    };
    assert_ne!(a.hash(), b.hash());
    assert_eq!(a.hash(), LearnConfig::default().hash());
    assert_eq!(a.hash().len(), 16);
}

#[test]
fn tag_map_saves_atomically_and_rejects_bad_files() {
    let world = World::seed_world(5, 0.05);
    let obs = explore(&world, 300, 0.25, 8);
    let map = TagMap::learn(
        obs.iter().map(|o| (&o.snapshot, o.pose)),
        ReadModel::seed000(1000.0, 1),
        TagMapConfig::default(),
    );
    assert!(!map.is_empty());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tag-map.json");
    map.save(&path).unwrap();
    let back = TagMap::load(&path).unwrap();
    assert_eq!(back.len(), map.len());
    for t in &map.tags {
        let b = back.get(&t.id).unwrap();
        assert!((b.x - t.x).abs() < 1e-9 && (b.y - t.y).abs() < 1e-9);
    }
    // The reloaded map scores a snapshot like the original (its index was rebuilt).
    let o = &obs[150];
    let (a, b) = (
        map.log_likelihood(&o.pose, &map.observe(&o.snapshot)),
        back.log_likelihood(&o.pose, &back.observe(&o.snapshot)),
    );
    assert_eq!(a.1, b.1);
    assert!((a.0 - b.0).abs() < 1e-6 * a.0.abs().max(1.0));
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
    // Truncated JSON, a position that is not a number, a model without coefficients.
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    assert!(matches!(
        TagMap::load(&path),
        Err(SnapshotError::Format { .. })
    ));
    let mut v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    v["tags"][0]["x"] = serde_json::Value::Null;
    std::fs::write(&path, serde_json::to_vec(&v).unwrap()).unwrap();
    assert!(matches!(
        TagMap::load(&path),
        Err(SnapshotError::Format { .. })
    ));
    let mut v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    v["model"]["coeffs"] = serde_json::json!([]);
    std::fs::write(&path, serde_json::to_vec(&v).unwrap()).unwrap();
    assert!(matches!(
        TagMap::load(&path),
        Err(SnapshotError::InvalidModel(_))
    ));
}
