//! Learned state written as one set: the database, the survey and the tag map of one learning
//! run go to disk together or not at all.
//!
//! Each file of a set is written under a versioned name (`survey.json` of version 3 is
//! `survey.v3.json`), each atomically, and only then the manifest `state-manifest.json`, which
//! names the set's version and, per logical name, the versioned file with its length and
//! FNV-1a hash, is renamed into place. A reader resolves logical names through the manifest and
//! checks each file against it. A crash at any point leaves the previous manifest and its files
//! untouched; the leftovers of an unfinished write (temporary files, versioned files no manifest
//! names) are removed by [`clean_stale`]. A folder without a manifest is read directly (files
//! written one by one by older versions).

use std::collections::BTreeMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::SnapshotError;
use crate::store::write_atomic;

/// The manifest's file name.
pub const MANIFEST: &str = "state-manifest.json";

/// One file of a set.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetEntry {
    /// The versioned file, in the set's folder.
    pub file: String,
    /// Its length in bytes.
    pub len: u64,
    /// FNV-1a 64 of its bytes, hex.
    pub fnv1a: String,
}

/// The manifest: the version of the set and its files by logical name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    pub version: u64,
    pub files: BTreeMap<String, SetEntry>,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SnapshotError + '_ {
    move |source| SnapshotError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// FNV-1a 64 of `bytes`, hex.
#[must_use]
pub fn fnv1a(bytes: &[u8]) -> String {
    let h = bytes.iter().fold(0xCBF2_9CE4_8422_2325_u64, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01B3)
    });
    format!("{h:016x}")
}

/// `survey.json`, version 3 → `survey.v3.json`.
fn versioned(name: &str, version: u64) -> String {
    match name.rsplit_once('.') {
        Some((stem, ext)) => format!("{stem}.v{version}.{ext}"),
        None => format!("{name}.v{version}"),
    }
}

/// The manifest of `dir`, if it has one.
///
/// # Errors
/// An unreadable or malformed manifest.
pub fn read_manifest(dir: &Path) -> Result<Option<Manifest>, SnapshotError> {
    let path = dir.join(MANIFEST);
    match fs::read(&path) {
        Ok(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|source| SnapshotError::Format { path, source }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(SnapshotError::Io { path, source: e }),
    }
}

/// Writes `files` (logical name, bytes) as the next version of the set in `dir`, then removes
/// the files of earlier versions. Returns the new version.
///
/// # Errors
/// The first I/O error; the previous set is then still the current one.
pub fn write_set(dir: &Path, files: &[(&str, Vec<u8>)]) -> Result<u64, SnapshotError> {
    fs::create_dir_all(dir).map_err(io_err(dir))?;
    let version = read_manifest(dir)?.map_or(1, |m| m.version + 1);
    let mut manifest = Manifest {
        version,
        files: BTreeMap::new(),
    };
    for (name, bytes) in files {
        let file = versioned(name, version);
        let path = dir.join(&file);
        write_atomic(&path, |f| f.write_all(bytes).map_err(io_err(&path)))?;
        manifest.files.insert(
            (*name).to_string(),
            SetEntry {
                file,
                len: bytes.len() as u64,
                fnv1a: fnv1a(bytes),
            },
        );
    }
    let path = dir.join(MANIFEST);
    let text = serde_json::to_vec_pretty(&manifest).map_err(|source| SnapshotError::Format {
        path: path.clone(),
        source,
    })?;
    write_atomic(&path, |f| f.write_all(&text).map_err(io_err(&path)))?;
    clean_stale(dir)?;
    Ok(version)
}

/// Removes what an unfinished write left in `dir`: temporary files, and versioned files the
/// manifest does not name. Returns the files removed.
///
/// # Errors
/// A folder that cannot be listed.
pub fn clean_stale(dir: &Path) -> Result<Vec<PathBuf>, SnapshotError> {
    let manifest = read_manifest(dir).ok().flatten();
    let keep: Vec<&str> = manifest
        .as_ref()
        .map(|m| m.files.values().map(|e| e.file.as_str()).collect())
        .unwrap_or_default();
    let mut removed = Vec::new();
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(removed),
        Err(e) => {
            return Err(SnapshotError::Io {
                path: dir.to_path_buf(),
                source: e,
            })
        }
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let temporary = name.starts_with('.') && name.contains(".tmp.");
        let old_version =
            manifest.is_some() && is_versioned(&name) && !keep.contains(&name.as_str());
        if temporary || old_version {
            let path = entry.path();
            if fs::remove_file(&path).is_ok() {
                removed.push(path);
            }
        }
    }
    Ok(removed)
}

/// `name.vN.ext` or `name.vN`.
fn is_versioned(name: &str) -> bool {
    name.split('.').any(|part| {
        part.strip_prefix('v')
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    })
}

/// The file that holds `name` in `dir`: through the manifest (checked against its length and
/// hash) when there is one, `dir/name` otherwise.
///
/// # Errors
/// A name the manifest does not list, a missing file, or a file that does not match the
/// manifest (truncated, or from another set).
pub fn resolve(dir: &Path, name: &Path) -> Result<PathBuf, SnapshotError> {
    let Some(manifest) = read_manifest(dir)? else {
        return Ok(dir.join(name));
    };
    let key = name.to_string_lossy();
    let entry = manifest.files.get(key.as_ref()).ok_or_else(|| {
        SnapshotError::InvalidModel(format!(
            "{key} is not in the learned state set of {} (version {})",
            dir.display(),
            manifest.version
        ))
    })?;
    let path = dir.join(&entry.file);
    let bytes = fs::read(&path).map_err(io_err(&path))?;
    if bytes.len() as u64 != entry.len || fnv1a(&bytes) != entry.fnv1a {
        return Err(SnapshotError::InvalidModel(format!(
            "{} does not match {MANIFEST} (length {} of {}): damaged or from another set",
            path.display(),
            bytes.len(),
            entry.len
        )));
    }
    Ok(path)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn text(dir: &Path, name: &str) -> String {
        fs::read_to_string(resolve(dir, Path::new(name)).unwrap()).unwrap()
    }

    #[test]
    fn a_set_replaces_the_previous_one_whole() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        assert_eq!(
            write_set(
                d,
                &[("db.json", b"db1".to_vec()), ("map.json", b"map1".to_vec())]
            )
            .unwrap(),
            1
        );
        assert_eq!(
            write_set(
                d,
                &[("db.json", b"db2".to_vec()), ("map.json", b"map2".to_vec())]
            )
            .unwrap(),
            2
        );
        assert_eq!(
            (text(d, "db.json"), text(d, "map.json")),
            ("db2".into(), "map2".into())
        );
        // The first set's files are gone.
        assert!(!d.join("db.v1.json").exists());
        assert_eq!(FNV_EMPTY, fnv1a(b""));
    }

    const FNV_EMPTY: &str = "cbf29ce484222325";

    #[test]
    fn a_write_killed_before_its_manifest_leaves_the_old_set_current() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_set(
            d,
            &[("db.json", b"db1".to_vec()), ("map.json", b"map1".to_vec())],
        )
        .unwrap();
        // What a kill after the first file of version 2 leaves: one new file, a temporary file.
        fs::write(d.join("db.v2.json"), "db2").unwrap();
        fs::write(d.join(".map.v2.json.tmp.4242"), "ma").unwrap();
        assert_eq!(
            (text(d, "db.json"), text(d, "map.json")),
            ("db1".into(), "map1".into())
        );
        let removed = clean_stale(d).unwrap();
        assert_eq!(removed.len(), 2, "{removed:?}");
        assert!(d.join("db.v1.json").exists() && d.join("map.v1.json").exists());
    }

    #[test]
    fn a_damaged_or_missing_file_of_the_set_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_set(d, &[("db.json", b"{\"a\":1}".to_vec())]).unwrap();
        fs::write(d.join("db.v1.json"), "{\"a\"").unwrap();
        assert!(resolve(d, Path::new("db.json"))
            .unwrap_err()
            .to_string()
            .contains("does not match"));
        fs::remove_file(d.join("db.v1.json")).unwrap();
        assert!(resolve(d, Path::new("db.json")).is_err());
        assert!(resolve(d, Path::new("other.json"))
            .unwrap_err()
            .to_string()
            .contains("not in the learned state set"));
        // Without a manifest, names are read as they are.
        let plain = tempfile::tempdir().unwrap();
        assert_eq!(
            resolve(plain.path(), Path::new("db.json")).unwrap(),
            plain.path().join("db.json")
        );
    }
}
