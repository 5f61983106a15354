//! Atomic save and load of the learned database (JSON).
//!
//! Saving writes the whole file to a temporary file in the same directory, `fsync`s it, renames
//! it over the target (atomic on POSIX file systems) and `fsync`s the directory, so a crash or a
//! failed write leaves either the old file or the new one, never a mix.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::database::{SnapshotDatabase, FORMAT_VERSION};
use crate::error::SnapshotError;

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SnapshotError + '_ {
    move |source| SnapshotError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "database".into());
    path.with_file_name(format!(".{name}.tmp.{}", std::process::id()))
}

/// Writes a file atomically: `produce` writes the content into the temporary file; only if it
/// and the `fsync` succeed is the temporary file renamed over `path`. On any error the temporary
/// file is removed and `path` is untouched.
///
/// # Errors
/// The first I/O error, or what `produce` returns.
pub fn write_atomic(
    path: &Path,
    produce: impl FnOnce(&mut File) -> Result<(), SnapshotError>,
) -> Result<(), SnapshotError> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut file = File::create(&tmp).map_err(io_err(&tmp))?;
        produce(&mut file)?;
        file.flush().map_err(io_err(&tmp))?;
        file.sync_all().map_err(io_err(&tmp))?;
        drop(file);
        fs::rename(&tmp, path).map_err(io_err(path))?;
        Ok(())
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
        return result;
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        // Persist the rename; not every platform can open a directory, so failures are ignored.
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

/// Serialises `value` as JSON and writes it atomically.
fn save_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), SnapshotError> {
    let bytes = serde_json::to_vec(value).map_err(|source| SnapshotError::Format {
        path: path.to_path_buf(),
        source,
    })?;
    write_atomic(path, |f| f.write_all(&bytes).map_err(io_err(path)))
}

/// Reads and parses a JSON file.
fn load_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, SnapshotError> {
    let bytes = fs::read(path).map_err(io_err(path))?;
    parse_json(&bytes, path)
}

/// Parses JSON bytes (`path` names them in errors).
fn parse_json<T: serde::de::DeserializeOwned>(
    bytes: &[u8],
    path: &Path,
) -> Result<T, SnapshotError> {
    serde_json::from_slice(bytes).map_err(|source| SnapshotError::Format {
        path: path.to_path_buf(),
        source,
    })
}

/// The JSON bytes [`save_json`] writes (for a set written with [`crate::state_set::write_set`]).
///
/// # Errors
/// [`SnapshotError::Format`] if `value` cannot be serialised.
pub fn to_json<T: serde::Serialize>(value: &T, name: &str) -> Result<Vec<u8>, SnapshotError> {
    serde_json::to_vec(value).map_err(|source| SnapshotError::Format {
        path: PathBuf::from(name),
        source,
    })
}

impl SnapshotDatabase {
    /// Saves the database as JSON, atomically (see the module documentation).
    ///
    /// # Errors
    /// [`SnapshotError::Io`] or [`SnapshotError::Format`].
    pub fn save(&self, path: &Path) -> Result<(), SnapshotError> {
        save_json(path, self)
    }

    /// Loads a database saved by [`SnapshotDatabase::save`].
    ///
    /// # Errors
    /// [`SnapshotError::Io`], [`SnapshotError::Format`] for malformed or truncated JSON,
    /// [`SnapshotError::Version`] for another layout version, [`SnapshotError::InvalidModel`]
    /// when the transition model does not match the states.
    pub fn load(path: &Path) -> Result<Self, SnapshotError> {
        Self::checked(load_json(path)?)
    }

    /// [`SnapshotDatabase::load`] from bytes (`name` names them in errors).
    ///
    /// # Errors
    /// As [`SnapshotDatabase::load`].
    pub fn from_json(bytes: &[u8], name: &str) -> Result<Self, SnapshotError> {
        Self::checked(parse_json(bytes, Path::new(name))?)
    }

    fn checked(mut db: SnapshotDatabase) -> Result<Self, SnapshotError> {
        if db.format_version != FORMAT_VERSION {
            return Err(SnapshotError::Version {
                found: db.format_version,
                expected: FORMAT_VERSION,
            });
        }
        if db.transitions.states() != db.state_count() || db.counts.states() != db.state_count() {
            return Err(SnapshotError::InvalidModel(format!(
                "transition model has {} states, database {}",
                db.transitions.states(),
                db.state_count()
            )));
        }
        db.rebuild_lookup();
        Ok(db)
    }
}

impl crate::tagmap::TagMap {
    /// Saves the tag map as JSON, atomically (see the module documentation).
    ///
    /// # Errors
    /// [`SnapshotError::Io`] or [`SnapshotError::Format`].
    pub fn save(&self, path: &Path) -> Result<(), SnapshotError> {
        save_json(path, self)
    }

    /// Loads a map saved by [`crate::tagmap::TagMap::save`] and rebuilds its index.
    ///
    /// # Errors
    /// [`SnapshotError::Io`], [`SnapshotError::Format`] for malformed or truncated JSON,
    /// [`SnapshotError::InvalidModel`] for a tag with a non-finite position or a model without
    /// coefficients.
    pub fn load(path: &Path) -> Result<Self, SnapshotError> {
        Self::checked(load_json(path)?)
    }

    /// [`crate::tagmap::TagMap::load`] from bytes (`name` names them in errors).
    ///
    /// # Errors
    /// As [`crate::tagmap::TagMap::load`].
    pub fn from_json(bytes: &[u8], name: &str) -> Result<Self, SnapshotError> {
        Self::checked(parse_json(bytes, Path::new(name))?)
    }

    fn checked(mut map: crate::tagmap::TagMap) -> Result<Self, SnapshotError> {
        if map.model.coeffs.is_empty() {
            return Err(SnapshotError::InvalidModel(
                "tag map: read model without coefficients".into(),
            ));
        }
        if let Some(t) = map
            .tags
            .iter()
            .find(|t| !(t.x.is_finite() && t.y.is_finite() && t.sigma.is_finite()))
        {
            return Err(SnapshotError::InvalidModel(format!(
                "tag map: tag {} has a non-finite position",
                t.id
            )));
        }
        map.rebuild_index();
        Ok(map)
    }
}

impl crate::survey::Survey {
    /// Saves the survey as JSON, atomically (see the module documentation).
    ///
    /// # Errors
    /// [`SnapshotError::Io`] or [`SnapshotError::Format`].
    pub fn save(&self, path: &Path) -> Result<(), SnapshotError> {
        save_json(path, self)
    }

    /// Loads a survey saved by [`crate::survey::Survey::save`].
    ///
    /// # Errors
    /// [`SnapshotError::Io`], [`SnapshotError::Format`] for malformed or truncated JSON,
    /// [`SnapshotError::Version`] for another layout version, [`SnapshotError::InvalidModel`]
    /// for a pose that is not finite.
    pub fn load(path: &Path) -> Result<Self, SnapshotError> {
        Self::checked(load_json(path)?)
    }

    /// [`crate::survey::Survey::load`] from bytes (`name` names them in errors).
    ///
    /// # Errors
    /// As [`crate::survey::Survey::load`].
    pub fn from_json(bytes: &[u8], name: &str) -> Result<Self, SnapshotError> {
        Self::checked(parse_json(bytes, Path::new(name))?)
    }

    fn checked(survey: crate::survey::Survey) -> Result<Self, SnapshotError> {
        if survey.format_version != crate::survey::SURVEY_FORMAT_VERSION {
            return Err(SnapshotError::Version {
                found: survey.format_version,
                expected: crate::survey::SURVEY_FORMAT_VERSION,
            });
        }
        if let Some(i) = survey.samples.iter().position(|s| {
            !(s.pose.x.is_finite() && s.pose.y.is_finite() && s.pose.theta.is_finite())
        }) {
            return Err(SnapshotError::InvalidModel(format!(
                "survey sample {i} has a non-finite pose"
            )));
        }
        Ok(survey)
    }
}
