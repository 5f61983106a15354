//! The known tag grid: tag UID → floor position, with a bucket index for "tags near a point".

use std::collections::HashMap;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// An ISO 15693 tag UID (64 bits, e.g. `0xE00401503A5BD691`).
pub type TagUid = u64;

/// Errors building a [`TagGrid`].
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GridError {
    /// The UID is already in the grid.
    #[error("tag {uid:016X} inserted twice")]
    Duplicate {
        /// The repeated UID.
        uid: TagUid,
    },
    /// A coordinate or the pitch was NaN, infinite or (for the pitch) not positive.
    #[error("invalid geometry: {0}")]
    Geometry(String),
}

/// Regular layout parameters: tag `(col, row)` sits at `origin + pitch·(col, row)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GridLayout {
    /// Distance between neighbouring tags, m (seed 002: 0.10).
    pub pitch_m: f64,
    /// Position of tag (0, 0) in the map frame, m.
    pub origin_m: (f64, f64),
}

/// Known tags and their positions (m, map frame).
#[derive(Debug, Clone, PartialEq)]
pub struct TagGrid {
    tags: HashMap<TagUid, (f64, f64)>,
    buckets: HashMap<(i64, i64), Vec<TagUid>>,
    bucket_m: f64,
}

/// The seed's nine-tag test field (seed 002 Table 9): last three hex digits of the UID →
/// position in mm. The full UIDs in the reference captures are `0xE00401503A5BD000 | suffix`.
pub const SEED002_TABLE9: [(u16, f64, f64); 9] = [
    (0xAE4, 0.0, 0.0),
    (0x689, 100.0, 0.0),
    (0x47A, 200.0, 0.0),
    (0x586, 0.0, 100.0),
    (0x785, 100.0, 100.0),
    (0xADC, 200.0, 100.0),
    (0xBF4, 0.0, 200.0),
    (0x691, 100.0, 200.0),
    (0x78D, 200.0, 200.0),
];

/// UID prefix of the seed's test tags (the captures' UIDs differ only in the last 3 hex digits).
pub const SEED002_UID_PREFIX: TagUid = 0xE004_0150_3A5B_D000;

impl TagGrid {
    /// An empty grid whose spatial index uses buckets of `bucket_m` metres (use the pitch).
    pub fn new(bucket_m: f64) -> Result<Self, GridError> {
        if !(bucket_m.is_finite() && bucket_m > 0.0) {
            return Err(GridError::Geometry(format!("bucket size {bucket_m}")));
        }
        Ok(Self {
            tags: HashMap::new(),
            buckets: HashMap::new(),
            bucket_m,
        })
    }

    /// A regular `cols × rows` grid; `uid_of(col, row)` names each tag.
    pub fn regular(
        layout: GridLayout,
        cols: u32,
        rows: u32,
        uid_of: impl Fn(u32, u32) -> TagUid,
    ) -> Result<Self, GridError> {
        let mut g = Self::new(layout.pitch_m)?;
        for r in 0..rows {
            for c in 0..cols {
                g.insert_cell(uid_of(c, r), layout, c, r)?;
            }
        }
        Ok(g)
    }

    /// The nine-tag field of seed 002 Table 9 with the full UIDs used in the reference captures.
    #[must_use]
    pub fn seed002_test_field() -> Self {
        let mut g = Self {
            tags: HashMap::new(),
            buckets: HashMap::new(),
            bucket_m: 0.1,
        };
        for (suffix, x_mm, y_mm) in SEED002_TABLE9 {
            // Cannot fail: distinct suffixes and finite coordinates.
            let _ = g.insert(
                SEED002_UID_PREFIX | TagUid::from(suffix),
                x_mm / 1000.0,
                y_mm / 1000.0,
            );
        }
        g
    }

    fn key(&self, x: f64, y: f64) -> (i64, i64) {
        #[allow(clippy::cast_possible_truncation)]
        (
            (x / self.bucket_m).floor() as i64,
            (y / self.bucket_m).floor() as i64,
        )
    }

    /// Adds a tag at `(x, y)` metres.
    pub fn insert(&mut self, uid: TagUid, x: f64, y: f64) -> Result<(), GridError> {
        if !(x.is_finite() && y.is_finite()) {
            return Err(GridError::Geometry(format!("tag {uid:016X} at ({x}, {y})")));
        }
        if self.tags.contains_key(&uid) {
            return Err(GridError::Duplicate { uid });
        }
        self.tags.insert(uid, (x, y));
        let k = self.key(x, y);
        self.buckets.entry(k).or_default().push(uid);
        Ok(())
    }

    /// Adds a tag at grid cell `(col, row)` of `layout`.
    pub fn insert_cell(
        &mut self,
        uid: TagUid,
        layout: GridLayout,
        col: u32,
        row: u32,
    ) -> Result<(), GridError> {
        if !(layout.pitch_m.is_finite() && layout.pitch_m > 0.0) {
            return Err(GridError::Geometry(format!("pitch {}", layout.pitch_m)));
        }
        let x = layout.origin_m.0 + layout.pitch_m * f64::from(col);
        let y = layout.origin_m.1 + layout.pitch_m * f64::from(row);
        self.insert(uid, x, y)
    }

    /// Position of a tag, m.
    #[must_use]
    pub fn position(&self, uid: TagUid) -> Option<(f64, f64)> {
        self.tags.get(&uid).copied()
    }

    /// Number of tags.
    #[must_use]
    pub fn len(&self) -> usize {
        self.tags.len()
    }

    /// True when the grid has no tags.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.tags.is_empty()
    }

    /// All tags `(uid, x, y)`, sorted by UID.
    #[must_use]
    pub fn tags(&self) -> Vec<(TagUid, f64, f64)> {
        let mut v: Vec<_> = self.tags.iter().map(|(u, (x, y))| (*u, *x, *y)).collect();
        v.sort_unstable_by_key(|t| t.0);
        v
    }

    /// Tags within `radius` metres of `(x, y)`, as `(uid, x, y)`, sorted by UID.
    #[must_use]
    pub fn tags_within(&self, x: f64, y: f64, radius: f64) -> Vec<(TagUid, f64, f64)> {
        let mut out = Vec::new();
        if !(x.is_finite() && y.is_finite() && radius.is_finite() && radius >= 0.0) {
            return out;
        }
        let (k0x, k0y) = self.key(x - radius, y - radius);
        let (k1x, k1y) = self.key(x + radius, y + radius);
        for kx in k0x..=k1x {
            for ky in k0y..=k1y {
                for uid in self.buckets.get(&(kx, ky)).into_iter().flatten() {
                    if let Some(&(tx, ty)) = self.tags.get(uid) {
                        if (tx - x).hypot(ty - y) <= radius {
                            out.push((*uid, tx, ty));
                        }
                    }
                }
            }
        }
        out.sort_unstable_by_key(|t| t.0);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_field_matches_table9() {
        let g = TagGrid::seed002_test_field();
        assert_eq!(g.len(), 9);
        assert_eq!(g.position(0xE004_0150_3A5B_D691), Some((0.1, 0.2)));
        assert_eq!(g.position(0xE004_0150_3A5B_DAE4), Some((0.0, 0.0)));
        assert_eq!(g.position(0xE004_0150_3A5B_D78D), Some((0.2, 0.2)));
        // Table 9's decimal column is the last three hex digits: 0x691 = 1681.
        assert_eq!(0x691, 1681);
        assert_eq!(0xAE4, 2788);
    }

    #[test]
    fn neighbourhood_query_and_duplicates() {
        let layout = GridLayout {
            pitch_m: 0.1,
            origin_m: (0.0, 0.0),
        };
        let mut g = TagGrid::regular(layout, 5, 5, |c, r| u64::from(r * 5 + c)).unwrap();
        let near = g.tags_within(0.2, 0.2, 0.1001);
        assert_eq!(
            near.iter().map(|t| t.0).collect::<Vec<_>>(),
            vec![7, 11, 12, 13, 17]
        );
        assert_eq!(
            g.insert(12, 1.0, 1.0),
            Err(GridError::Duplicate { uid: 12 })
        );
        assert!(g.insert(99, f64::NAN, 0.0).is_err());
        assert!(TagGrid::new(0.0).is_err());
        assert!(g.tags_within(f64::NAN, 0.0, 1.0).is_empty());
    }
}
