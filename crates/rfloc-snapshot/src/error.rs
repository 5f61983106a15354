//! Errors of the snapshot estimator.

use std::path::PathBuf;

/// Everything that can go wrong in this crate.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// A state index outside `0..states`.
    #[error("state {state} out of range ({states} states)")]
    StateOutOfRange { state: usize, states: usize },
    /// A transition or reward model that is not a valid MDP.
    #[error("invalid model: {0}")]
    InvalidModel(String),
    /// A configuration value outside its domain.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// Learning needs snapshots with positions of equal count.
    #[error("learning data mismatch: {0}")]
    LearningData(String),
    /// Reading or writing the database file failed.
    #[error("database file {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The database file is not valid JSON for this format.
    #[error("database file {path} is malformed: {source}")]
    Format {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// The database was written with a different format version.
    #[error("database format version {found}, expected {expected}")]
    Version { found: u32, expected: u32 },
}
