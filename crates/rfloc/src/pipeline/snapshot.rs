//! UHF snapshot pipeline (seed 000) on a live robot: a histogram filter over the states of a
//! learned database, updated with each averaged snapshot from the reader.
//!
//! The database (states, their positions, transition matrices) is learned by an exploration
//! run (`rfloc sim` writes one per trial) and loaded from `[state] dir`. Without it the
//! pipeline publishes nothing and says why once.

use std::path::{Path, PathBuf};

use rfloc_pose::PoseEstimate;
use rfloc_snapshot::{FilterConfig, Snapshot, SnapshotDatabase, StateFilter, TagId};

use crate::config::SnapshotSettings;
use crate::events::DeviceEvent;
use crate::pipeline::Pipeline;

/// Histogram filter over learned states.
pub struct SnapshotPipeline {
    learned: Option<(SnapshotDatabase, StateFilter)>,
    path: PathBuf,
    warned: bool,
}

impl std::fmt::Debug for SnapshotPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SnapshotPipeline")
            .field("path", &self.path)
            .field("loaded", &self.learned.is_some())
            .finish()
    }
}

impl SnapshotPipeline {
    /// Loads the database named in the settings (relative paths from `state_dir`).
    #[must_use]
    pub fn new(settings: &SnapshotSettings, state_dir: Option<&Path>) -> Self {
        let path = match state_dir {
            Some(dir) if settings.database.is_relative() => dir.join(&settings.database),
            _ => settings.database.clone(),
        };
        let learned = match SnapshotDatabase::load(&path) {
            Ok(db) => {
                tracing::info!(path = %path.display(), states = db.state_count(), "learned snapshot database loaded");
                let filter = StateFilter::new(&db, FilterConfig::default());
                Some((db, filter))
            }
            Err(e) => {
                tracing::error!(path = %path.display(), error = %e, "no learned snapshot database");
                None
            }
        };
        Self {
            learned,
            path,
            warned: false,
        }
    }
}

impl Pipeline for SnapshotPipeline {
    fn name(&self) -> &'static str {
        "snapshot"
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        let DeviceEvent::UhfSnapshot { t, tags, .. } = event else {
            return None;
        };
        let Some((db, filter)) = &mut self.learned else {
            if !self.warned {
                self.warned = true;
                tracing::error!(path = %self.path.display(), "snapshots arrive but there is no learned database: no poses");
            }
            return None;
        };
        let snapshot = Snapshot::from_reads(
            tags.iter()
                .filter_map(|(id, rss)| Some((TagId::from_hex(id)?, *rss))),
        );
        filter.update(db, &snapshot);
        let mut est = filter.estimate(db, *t);
        est.source = "snapshot".into();
        Some(est)
    }
}
