//! Snapshots: what one TagList poll saw.

use crate::error::AlienError;
use crate::taglist::{MalformedTagLine, TagId, TagRead};

/// What the RSSI numbers mean. The ALR-9900 prints an unscaled magnitude in the thousands
/// (seed 000 thresholds 1000/1500; reference §3.6), newer readers print dBm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum RssiMeaning {
    /// A linear magnitude, larger = stronger (ALR-9900).
    #[default]
    Linear,
    /// dBm.
    Dbm,
}

/// One TagList poll.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Snapshot {
    /// Seconds on the client's clock when the reply was complete.
    pub t: f64,
    pub tags: Vec<TagRead>,
    /// Lines that did not parse (also counted in the client's stats).
    pub malformed: Vec<MalformedTagLine>,
    pub rssi_meaning: RssiMeaning,
}

impl Snapshot {
    /// (tag ID, RSSI) pairs of the tags that carried an RSSI, the seed's snapshot.
    #[must_use]
    pub fn id_rss(&self) -> Vec<(TagId, f64)> {
        self.tags
            .iter()
            .filter_map(|t| t.rssi.map(|r| (t.id.clone(), r)))
            .collect()
    }
}

/// What the daemon needs from a UHF reader.
pub trait SnapshotReader {
    /// Reads the tags in view now.
    fn read_snapshot(
        &mut self,
    ) -> impl std::future::Future<Output = Result<Snapshot, AlienError>> + Send;
}
