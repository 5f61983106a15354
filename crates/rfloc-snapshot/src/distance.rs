//! Snapshot dissimilarity for snapshots with different tag sets.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use crate::snapshot::Snapshot;
use crate::tag::TagId;

/// Which dissimilarity compares two snapshots. Both return a value in `[0, 1]`, 0 for identical
/// snapshots and 1 for snapshots with no tag in common; both are symmetric.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum SnapshotDistance {
    /// The seed's localisation score (section 3.3.3 and appendix A `localise`), turned into a
    /// dissimilarity: `1 − (w·S_id + (1−w)·S_rss)` with
    /// `S_id = |A∩B| / max(|A|,|B|)` (ID overlap) and
    /// `S_rss = clamp(1 − Σ_{A∩B}|a−b| / min(ΣA, ΣB), 0, 1)` (RSS match on common tags).
    /// The seed weights the ID score by 60 % (`id_weight = 0.6`).
    SeedScore { id_weight: f64 },
    /// Normalised L1 over the union of tags, a missing tag counting as RSS 0:
    /// `Σ_{A∪B}|a−b| / (ΣA + ΣB)` (Bray–Curtis). This is the L1 analogue of the seed's simulation
    /// code, which compared full tag vectors with zeros for non-detections (`norm(c − ss)`).
    #[default]
    RssL1,
}

/// Counts gathered by one merge pass over two sorted snapshots.
#[derive(Debug, Clone, Copy, Default)]
struct Overlap {
    len_a: usize,
    len_b: usize,
    common: usize,
    total_a: f64,
    total_b: f64,
    diff_common: f64,
    diff_union: f64,
}

fn overlap<K: Ord>(
    a: impl Iterator<Item = (K, f64)>,
    b: impl Iterator<Item = (K, f64)>,
) -> Overlap {
    let mut o = Overlap::default();
    let mut a = a.peekable();
    let mut b = b.peekable();
    loop {
        let ord = match (a.peek(), b.peek()) {
            (None, None) => break,
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (Some((ka, _)), Some((kb, _))) => ka.cmp(kb),
        };
        match ord {
            std::cmp::Ordering::Less => {
                if let Some((_, va)) = a.next() {
                    o.len_a += 1;
                    o.total_a += va;
                    o.diff_union += va.abs();
                }
            }
            std::cmp::Ordering::Greater => {
                if let Some((_, vb)) = b.next() {
                    o.len_b += 1;
                    o.total_b += vb;
                    o.diff_union += vb.abs();
                }
            }
            std::cmp::Ordering::Equal => {
                if let (Some((_, va)), Some((_, vb))) = (a.next(), b.next()) {
                    o.len_a += 1;
                    o.len_b += 1;
                    o.common += 1;
                    o.total_a += va;
                    o.total_b += vb;
                    let d = (va - vb).abs();
                    o.diff_common += d;
                    o.diff_union += d;
                }
            }
        }
    }
    o
}

impl SnapshotDistance {
    fn score_overlap(self, o: &Overlap) -> f64 {
        if o.len_a == 0 && o.len_b == 0 {
            return 0.0;
        }
        if o.len_a == 0 || o.len_b == 0 {
            return 1.0;
        }
        match self {
            SnapshotDistance::SeedScore { id_weight } => {
                let w = id_weight.clamp(0.0, 1.0);
                let s_id = o.common as f64 / o.len_a.max(o.len_b) as f64;
                let denom = o.total_a.min(o.total_b);
                let s_rss = if o.common == 0 || denom <= 0.0 {
                    0.0
                } else {
                    (1.0 - o.diff_common / denom).clamp(0.0, 1.0)
                };
                (1.0 - (w * s_id + (1.0 - w) * s_rss)).clamp(0.0, 1.0)
            }
            SnapshotDistance::RssL1 => {
                let denom = o.total_a.abs() + o.total_b.abs();
                if denom <= 0.0 {
                    0.0
                } else {
                    (o.diff_union / denom).clamp(0.0, 1.0)
                }
            }
        }
    }

    /// Dissimilarity of two snapshots.
    #[must_use]
    pub fn between(self, a: &Snapshot, b: &Snapshot) -> f64 {
        self.score_overlap(&overlap(a.iter(), b.iter()))
    }

    pub(crate) fn between_indexed(self, a: &IndexedSnapshot, b: &IndexedSnapshot) -> f64 {
        // Index-based merge (same result as `overlap`, faster on interned IDs).
        let mut o = Overlap {
            len_a: a.ids.len(),
            len_b: b.ids.len(),
            total_a: a.total,
            total_b: b.total,
            ..Overlap::default()
        };
        let (mut i, mut j) = (0, 0);
        let mut only = 0.0;
        while let (Some(&ka), Some(&kb)) = (a.ids.get(i), b.ids.get(j)) {
            if ka == kb {
                let d = (a.rss.get(i).copied().unwrap_or(0.0)
                    - b.rss.get(j).copied().unwrap_or(0.0))
                .abs();
                o.common += 1;
                o.diff_common += d;
                i += 1;
                j += 1;
            } else if ka < kb {
                only += a.rss.get(i).copied().unwrap_or(0.0).abs();
                i += 1;
            } else {
                only += b.rss.get(j).copied().unwrap_or(0.0).abs();
                j += 1;
            }
        }
        only += a
            .rss
            .get(i..)
            .map_or(0.0, |r| r.iter().map(|x| x.abs()).sum());
        only += b
            .rss
            .get(j..)
            .map_or(0.0, |r| r.iter().map(|x| x.abs()).sum());
        o.diff_union = o.diff_common + only;
        self.score_overlap(&o)
    }
}

/// A snapshot whose tag IDs were interned to small integers (faster comparisons).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct IndexedSnapshot {
    ids: Vec<u32>,
    rss: Vec<f64>,
    total: f64,
}

/// Interns tag IDs so that many snapshots can be compared quickly.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct TagIndex {
    ids: HashMap<TagId, u32>,
}

impl TagIndex {
    /// Converts a query snapshot without changing the index: unknown IDs get fresh numbers above
    /// every interned one, so they match nothing.
    pub(crate) fn index_query(&self, s: &Snapshot) -> IndexedSnapshot {
        let mut fresh = self.ids.len() as u32;
        let mut pairs: Vec<(u32, f64)> = s
            .iter()
            .map(|(id, rss)| match self.ids.get(id) {
                Some(&i) => (i, rss),
                None => {
                    fresh = fresh.saturating_add(1);
                    (fresh, rss)
                }
            })
            .collect();
        pairs.sort_by_key(|p| p.0);
        IndexedSnapshot {
            ids: pairs.iter().map(|p| p.0).collect(),
            rss: pairs.iter().map(|p| p.1).collect(),
            total: pairs.iter().map(|p| p.1).sum(),
        }
    }

    /// Converts a snapshot, interning unseen IDs. Tags keep a sorted order by interned index.
    pub(crate) fn index(&mut self, s: &Snapshot) -> IndexedSnapshot {
        let mut pairs: Vec<(u32, f64)> = s
            .iter()
            .map(|(id, rss)| {
                let next = self.ids.len() as u32;
                (*self.ids.entry(id.clone()).or_insert(next), rss)
            })
            .collect();
        pairs.sort_by_key(|p| p.0);
        IndexedSnapshot {
            ids: pairs.iter().map(|p| p.0).collect(),
            rss: pairs.iter().map(|p| p.1).collect(),
            total: pairs.iter().map(|p| p.1).sum(),
        }
    }
}

/// A symmetric dissimilarity matrix with zero diagonal, stored as its strict lower triangle.
#[derive(Debug, Clone)]
pub struct DissimilarityMatrix {
    n: usize,
    lower: Vec<f64>,
}

impl DissimilarityMatrix {
    /// Builds the matrix from a pairwise function `d(i, j)` called for `i > j`.
    pub fn from_fn(n: usize, mut d: impl FnMut(usize, usize) -> f64) -> Self {
        let mut lower = Vec::with_capacity(n.saturating_sub(1) * n / 2);
        for i in 1..n {
            for j in 0..i {
                lower.push(d(i, j));
            }
        }
        Self { n, lower }
    }

    /// Pairwise snapshot dissimilarities.
    #[must_use]
    pub fn from_snapshots(snapshots: &[Snapshot], distance: SnapshotDistance) -> Self {
        let mut index = TagIndex::default();
        let indexed: Vec<IndexedSnapshot> = snapshots.iter().map(|s| index.index(s)).collect();
        Self::from_fn(indexed.len(), |i, j| {
            match (indexed.get(i), indexed.get(j)) {
                (Some(a), Some(b)) => distance.between_indexed(a, b),
                _ => 1.0,
            }
        })
    }

    /// Number of objects.
    #[must_use]
    pub fn len(&self) -> usize {
        self.n
    }

    /// True when there are no objects.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// `d(i, j)`; 0 on the diagonal and `f64::INFINITY` out of range.
    #[inline]
    #[must_use]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        use std::cmp::Ordering;
        let (hi, lo) = match i.cmp(&j) {
            Ordering::Equal => return if i < self.n { 0.0 } else { f64::INFINITY },
            Ordering::Greater => (i, j),
            Ordering::Less => (j, i),
        };
        if hi >= self.n {
            return f64::INFINITY;
        }
        self.lower
            .get(hi * (hi - 1) / 2 + lo)
            .copied()
            .unwrap_or(f64::INFINITY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn snap(pairs: &[(u8, f64)]) -> Snapshot {
        pairs
            .iter()
            .map(|(b, r)| (TagId::new(vec![*b]), *r))
            .collect()
    }

    #[test]
    fn seed_score_matches_hand_computation() {
        // A = {1:2000, 2:3000, 3:1000}, B = {2:2500, 3:1000, 4:4000}
        let a = snap(&[(1, 2000.0), (2, 3000.0), (3, 1000.0)]);
        let b = snap(&[(2, 2500.0), (3, 1000.0), (4, 4000.0)]);
        let d = SnapshotDistance::SeedScore { id_weight: 0.6 };
        // S_id = 2/3; S_rss = 1 − 500/min(6000, 7500) = 11/12
        let expected = 1.0 - (0.6 * 2.0 / 3.0 + 0.4 * 11.0 / 12.0);
        assert!((d.between(&a, &b) - expected).abs() < 1e-12);
        assert!((d.between(&b, &a) - expected).abs() < 1e-12);
        assert_eq!(d.between(&a, &a), 0.0);
    }

    #[test]
    fn rss_l1_matches_hand_computation_and_limits() {
        let a = snap(&[(1, 2000.0), (2, 3000.0), (3, 1000.0)]);
        let b = snap(&[(2, 2500.0), (3, 1000.0), (4, 4000.0)]);
        let d = SnapshotDistance::RssL1;
        // union diffs: 2000 + 500 + 0 + 4000 = 6500; totals 6000 + 7500
        assert!((d.between(&a, &b) - 6500.0 / 13500.0).abs() < 1e-12);
        let disjoint = snap(&[(9, 1000.0)]);
        assert_eq!(d.between(&a, &disjoint), 1.0);
        assert_eq!(d.between(&a, &Snapshot::new()), 1.0);
        assert_eq!(d.between(&Snapshot::new(), &Snapshot::new()), 0.0);
        assert_eq!(
            SnapshotDistance::SeedScore { id_weight: 0.6 }.between(&a, &disjoint),
            1.0
        );
    }

    #[test]
    fn matrix_agrees_with_direct_distance_and_is_symmetric() {
        let snaps = vec![
            snap(&[(1, 2000.0), (2, 3000.0)]),
            snap(&[(2, 2500.0), (3, 1000.0)]),
            snap(&[(5, 1000.0)]),
            Snapshot::new(),
        ];
        for kind in [
            SnapshotDistance::RssL1,
            SnapshotDistance::SeedScore { id_weight: 0.6 },
        ] {
            let m = DissimilarityMatrix::from_snapshots(&snaps, kind);
            for i in 0..4 {
                for j in 0..4 {
                    let direct = kind.between(&snaps[i], &snaps[j]);
                    assert!((m.get(i, j) - direct).abs() < 1e-12, "{i} {j}");
                    assert_eq!(m.get(i, j), m.get(j, i));
                }
            }
            assert_eq!(m.get(4, 0), f64::INFINITY);
        }
    }
}
