//! Snapshots: the set of tags seen at one place with their received signal strength (RSS).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::tag::TagId;

/// One RFID snapshot: tag ID → RSS in reader units (the Alien reader's `%m` field; the seed's
/// sensor model gives 0 to about 6500 units, section 3.1).
///
/// Tags are kept sorted by ID. An empty snapshot means "no tags visible".
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Snapshot {
    tags: BTreeMap<TagId, f64>,
}

/// Which tags an averaged snapshot keeps when the reads disagree.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum AverageTagSet {
    /// The seed's rule (appendix A, `scanNetTags`): keep exactly the tags of the read that saw
    /// the most tags (the first such read on ties); tags seen only in other reads are dropped.
    LargestRead,
    /// Keep a tag if it appears in at least `min_presence` (0..=1) of the reads.
    Presence { min_presence: f64 },
}

/// How [`Snapshot::average`] combines several reads taken at one place.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AverageConfig {
    /// Which tags survive.
    pub tag_set: AverageTagSet,
    /// Tags whose averaged RSS is below this are dropped (the seed uses 1000 units in simulation,
    /// 1500 on the real reader).
    pub threshold: f64,
}

impl Default for AverageConfig {
    fn default() -> Self {
        Self {
            tag_set: AverageTagSet::LargestRead,
            threshold: 1500.0,
        }
    }
}

impl Snapshot {
    /// An empty snapshot (no tags visible).
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds a snapshot from (tag, RSS) pairs. Non-finite RSS values are skipped; a repeated
    /// tag keeps the larger RSS.
    #[must_use]
    pub fn from_reads(reads: impl IntoIterator<Item = (TagId, f64)>) -> Self {
        let mut tags = BTreeMap::new();
        for (id, rss) in reads {
            if !rss.is_finite() {
                continue;
            }
            tags.entry(id)
                .and_modify(|v: &mut f64| *v = v.max(rss))
                .or_insert(rss);
        }
        Self { tags }
    }

    /// Inserts or replaces one tag reading.
    pub fn insert(&mut self, id: TagId, rss: f64) {
        if rss.is_finite() {
            self.tags.insert(id, rss);
        }
    }

    /// Number of tags.
    #[must_use]
    pub fn len(&self) -> usize {
        self.tags.len()
    }

    /// True when no tag is visible.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.tags.is_empty()
    }

    /// RSS of one tag, if seen.
    #[must_use]
    pub fn rss(&self, id: &TagId) -> Option<f64> {
        self.tags.get(id).copied()
    }

    /// Tags in ID order.
    pub fn iter(&self) -> impl Iterator<Item = (&TagId, f64)> + '_ {
        self.tags.iter().map(|(k, v)| (k, *v))
    }

    /// Sum of the RSS of all tags.
    #[must_use]
    pub fn total_rss(&self) -> f64 {
        self.tags.values().sum()
    }

    /// Drops tags below `threshold` RSS units.
    #[must_use]
    pub fn thresholded(mut self, threshold: f64) -> Self {
        self.tags.retain(|_, v| *v >= threshold);
        self
    }

    /// Averages `n` reads taken at one place into one snapshot.
    ///
    /// The RSS of a kept tag is the mean over the reads **in which it appears** (reads that
    /// missed it do not count as zero), as the seed's `scanNetTags` does. Which tags are kept is
    /// set by [`AverageConfig::tag_set`]; then tags below [`AverageConfig::threshold`] are
    /// dropped. The seed's loop over the other reads (`while sc<=n && sc~=maxScan`) stops at the
    /// reference read instead of skipping it, so reads after the reference are ignored there;
    /// this function averages over all reads.
    #[must_use]
    pub fn average(reads: &[Snapshot], config: &AverageConfig) -> Snapshot {
        let Some(largest) = reads.iter().fold(None::<&Snapshot>, |best, r| match best {
            Some(b) if b.len() >= r.len() => Some(b),
            _ => Some(r),
        }) else {
            return Snapshot::new();
        };
        let mut sums: BTreeMap<&TagId, (f64, usize)> = BTreeMap::new();
        for read in reads {
            for (id, rss) in read.iter() {
                let e = sums.entry(id).or_insert((0.0, 0));
                e.0 += rss;
                e.1 += 1;
            }
        }
        let n = reads.len() as f64;
        let tags = sums
            .into_iter()
            .filter(|(id, (_, count))| match config.tag_set {
                AverageTagSet::LargestRead => largest.tags.contains_key(*id),
                AverageTagSet::Presence { min_presence } => *count as f64 >= min_presence * n,
            })
            .map(|(id, (sum, count))| (id.clone(), sum / count as f64))
            .filter(|(_, rss)| *rss >= config.threshold)
            .collect();
        Snapshot { tags }
    }
}

impl FromIterator<(TagId, f64)> for Snapshot {
    fn from_iter<T: IntoIterator<Item = (TagId, f64)>>(iter: T) -> Self {
        Snapshot::from_reads(iter)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(b: u8) -> TagId {
        TagId::new(vec![b])
    }

    #[test]
    fn average_follows_the_largest_read_and_ignores_misses() {
        let r1 = Snapshot::from_reads([(id(1), 2000.0), (id(2), 3000.0)]);
        let r2 = Snapshot::from_reads([(id(1), 4000.0), (id(2), 1000.0), (id(3), 5000.0)]);
        let r3 = Snapshot::from_reads([(id(3), 3000.0), (id(4), 9000.0)]);
        let cfg = AverageConfig {
            tag_set: AverageTagSet::LargestRead,
            threshold: 1500.0,
        };
        let avg = Snapshot::average(&[r1.clone(), r2.clone(), r3.clone()], &cfg);
        // reference read is r2 (3 tags): tag 4 is dropped even though its RSS is high
        assert_eq!(avg.rss(&id(1)), Some(3000.0));
        assert_eq!(avg.rss(&id(2)), Some(2000.0));
        assert_eq!(avg.rss(&id(3)), Some(4000.0));
        assert_eq!(avg.rss(&id(4)), None);
        assert_eq!(avg.len(), 3);

        let cfg = AverageConfig {
            tag_set: AverageTagSet::Presence { min_presence: 0.6 },
            threshold: 2500.0,
        };
        let avg = Snapshot::average(&[r1, r2, r3], &cfg);
        // tags 1,2,3 are in 2 of 3 reads; tag 4 in 1 of 3; tag 2 averages 2000 < 2500
        assert_eq!(avg.rss(&id(1)), Some(3000.0));
        assert_eq!(avg.rss(&id(2)), None);
        assert_eq!(avg.rss(&id(3)), Some(4000.0));
        assert_eq!(avg.rss(&id(4)), None);
    }

    #[test]
    fn average_of_nothing_is_empty_and_nan_is_skipped() {
        assert!(Snapshot::average(&[], &AverageConfig::default()).is_empty());
        let s = Snapshot::from_reads([(id(1), f64::NAN), (id(2), 10.0), (id(2), 20.0)]);
        assert_eq!(s.len(), 1);
        assert_eq!(s.rss(&id(2)), Some(20.0));
    }
}
