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
    /// `Σ |rss|` (equal to `total` for real reads, which are positive).
    abs_total: f64,
}

impl IndexedSnapshot {
    fn from_pairs(mut pairs: Vec<(u32, f64)>) -> Self {
        pairs.sort_by_key(|p| p.0);
        Self {
            ids: pairs.iter().map(|p| p.0).collect(),
            rss: pairs.iter().map(|p| p.1).collect(),
            total: pairs.iter().map(|p| p.1).sum(),
            abs_total: pairs.iter().map(|p| p.1.abs()).sum(),
        }
    }

    /// `(interned tag, RSS)` pairs in tag order.
    pub(crate) fn pairs(&self) -> impl Iterator<Item = (u32, f64)> + '_ {
        self.ids.iter().copied().zip(self.rss.iter().copied())
    }
}

/// What two snapshots share, accumulated tag by tag over an inverted index: the number of
/// common tags, `Σ |a − b|` and `Σ (|a| + |b|)` over them.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Shared {
    pub(crate) common: u32,
    pub(crate) diff: f64,
    pub(crate) abs: f64,
}

impl Shared {
    /// Adds one common tag.
    #[inline]
    pub(crate) fn add(&mut self, a: f64, b: f64) {
        self.common += 1;
        self.diff += (a - b).abs();
        self.abs += a.abs() + b.abs();
    }
}

impl SnapshotDistance {
    /// Dissimilarity of `a` and `b` from what they share (same value as a merge over both).
    #[inline]
    pub(crate) fn with_shared(self, a: &IndexedSnapshot, b: &IndexedSnapshot, s: Shared) -> f64 {
        let o = Overlap {
            len_a: a.ids.len(),
            len_b: b.ids.len(),
            common: s.common as usize,
            total_a: a.total,
            total_b: b.total,
            diff_common: s.diff,
            diff_union: (a.abs_total + b.abs_total - s.abs).max(0.0) + s.diff,
        };
        self.score_overlap(&o)
    }
}

/// Interns tag IDs so that many snapshots can be compared quickly.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct TagIndex {
    ids: HashMap<TagId, u32>,
}

impl TagIndex {
    /// Number of interned IDs.
    pub(crate) fn len(&self) -> usize {
        self.ids.len()
    }

    /// Converts a query snapshot without changing the index: unknown IDs get fresh numbers above
    /// every interned one, so they match nothing.
    pub(crate) fn index_query(&self, s: &Snapshot) -> IndexedSnapshot {
        let mut fresh = self.ids.len() as u32;
        IndexedSnapshot::from_pairs(
            s.iter()
                .map(|(id, rss)| match self.ids.get(id) {
                    Some(&i) => (i, rss),
                    None => {
                        fresh = fresh.saturating_add(1);
                        (fresh, rss)
                    }
                })
                .collect(),
        )
    }

    /// Converts a snapshot, interning unseen IDs. Tags keep a sorted order by interned index.
    pub(crate) fn index(&mut self, s: &Snapshot) -> IndexedSnapshot {
        IndexedSnapshot::from_pairs(
            s.iter()
                .map(|(id, rss)| {
                    let next = self.ids.len() as u32;
                    (*self.ids.entry(id.clone()).or_insert(next), rss)
                })
                .collect(),
        )
    }
}

/// For each interned tag, the snapshots that contain it (in snapshot order) with its RSS.
pub(crate) fn postings(snapshots: &[IndexedSnapshot], tags: usize) -> Vec<Vec<(u32, f64)>> {
    let mut out: Vec<Vec<(u32, f64)>> = vec![Vec::new(); tags];
    for (i, s) in snapshots.iter().enumerate() {
        for (t, r) in s.pairs() {
            if let Some(p) = out.get_mut(t as usize) {
                p.push((i as u32, r));
            }
        }
    }
    out
}

/// A symmetric dissimilarity matrix with zero diagonal, stored whole (row-major, `n × n`) so
/// that every row is contiguous, in single precision (clustering streams the whole matrix per
/// pass: half the memory traffic of doubles).
#[derive(Debug, Clone)]
pub struct DissimilarityMatrix {
    n: usize,
    data: Vec<f32>,
}

impl DissimilarityMatrix {
    /// Builds the matrix from a pairwise function `d(i, j)` called once for each `i > j`.
    pub fn from_fn(n: usize, mut d: impl FnMut(usize, usize) -> f64) -> Self {
        let mut m = Self {
            n,
            data: vec![0.0; n * n],
        };
        for i in 1..n {
            if let Some(row) = m.data.get_mut(i * n..i * n + i) {
                for (j, x) in row.iter_mut().enumerate() {
                    #[allow(clippy::cast_possible_truncation)]
                    {
                        *x = d(i, j) as f32;
                    }
                }
            }
        }
        m.mirror_lower();
        m
    }

    /// Copies the strict lower triangle onto the upper one, in square blocks so that both the
    /// rows read and the columns written stay in cache.
    fn mirror_lower(&mut self) {
        const B: usize = 32;
        let n = self.n;
        for bi in (0..n).step_by(B) {
            // Rows `bi..` are read, rows `..bi` (and the diagonal block) written.
            let (upper, lower) = self.data.split_at_mut(bi * n);
            for bj in (0..bi).step_by(B) {
                let rows = lower.chunks_exact(n).take(B).enumerate();
                for (di, row) in rows {
                    let src = row.get(bj..(bj + B).min(bi)).unwrap_or(&[]);
                    for (dj, &v) in src.iter().enumerate() {
                        if let Some(x) = upper.get_mut((bj + dj) * n + bi + di) {
                            *x = v;
                        }
                    }
                }
            }
            // The diagonal block.
            let end = (bi + B).min(n);
            for i in bi..end {
                for j in bi..i {
                    let v = lower.get((i - bi) * n + j).copied().unwrap_or(0.0_f32);
                    if let Some(x) = lower.get_mut((j - bi) * n + i) {
                        *x = v;
                    }
                }
            }
        }
    }

    /// Pairwise snapshot dissimilarities. Pairs are accumulated over an inverted index (tag →
    /// snapshots that read it), so the work grows with the pairs that share a tag; pairs with
    /// none are 1 (0 when both are empty).
    #[must_use]
    pub fn from_snapshots(snapshots: &[Snapshot], distance: SnapshotDistance) -> Self {
        let mut index = TagIndex::default();
        let indexed: Vec<IndexedSnapshot> = snapshots.iter().map(|s| index.index(s)).collect();
        let post = postings(&indexed, index.len());
        let n = indexed.len();
        let mut m = Self {
            n,
            data: vec![0.0; n * n],
        };
        let positive = indexed.iter().all(|s| s.rss.iter().all(|r| *r > 0.0));
        if distance == SnapshotDistance::RssL1 && positive {
            // With positive RSS, Σ_{A∪B} |a − b| = ΣA + ΣB − 2 Σ_{A∩B} min(a, b): one sum per
            // pair.
            let totals: Vec<f64> = indexed.iter().map(|s| s.total).collect();
            // Postings split into snapshot numbers and RSS, for a tight inner loop; snapshots
            // are taken in order, so the postings of tag `t` before snapshot `i` are the first
            // `seen[t]` of them.
            let post: Vec<(Vec<u32>, Vec<f64>)> = post
                .iter()
                .map(|p| {
                    (
                        p.iter().map(|e| e.0).collect(),
                        p.iter().map(|e| e.1).collect(),
                    )
                })
                .collect();
            let mut seen = vec![0_usize; post.len()];
            let mut common = vec![0.0_f64; n];
            for (i, a) in indexed.iter().enumerate() {
                let Some(acc) = common.get_mut(..i) else {
                    continue;
                };
                for (t, ra) in a.pairs() {
                    let (Some((js, rs)), Some(before)) =
                        (post.get(t as usize), seen.get_mut(t as usize))
                    else {
                        continue;
                    };
                    for (&j, &rb) in js.iter().zip(rs).take(*before) {
                        if let Some(c) = acc.get_mut(j as usize) {
                            *c += if ra < rb { ra } else { rb };
                        }
                    }
                    *before += 1;
                }
                let ta = a.total;
                if let (Some(row), Some(tb)) = (m.data.get_mut(i * n..i * n + i), totals.get(..i)) {
                    for ((x, c), &tb) in row.iter_mut().zip(acc.iter_mut()).zip(tb) {
                        let denom = ta + tb;
                        let d = if denom > 0.0 {
                            1.0 - 2.0 * *c / denom
                        } else {
                            0.0
                        };
                        #[allow(clippy::cast_possible_truncation)]
                        {
                            *x = d.clamp(0.0, 1.0) as f32;
                        }
                        *c = 0.0;
                    }
                }
            }
        } else {
            let mut shared = vec![Shared::default(); n];
            for (i, a) in indexed.iter().enumerate() {
                for (t, ra) in a.pairs() {
                    let Some(p) = post.get(t as usize) else {
                        continue;
                    };
                    for &(j, rb) in p {
                        if j as usize >= i {
                            break;
                        }
                        if let Some(s) = shared.get_mut(j as usize) {
                            s.add(ra, rb);
                        }
                    }
                }
                if let (Some(row), Some(acc)) =
                    (m.data.get_mut(i * n..i * n + i), shared.get_mut(..i))
                {
                    for ((x, s), b) in row.iter_mut().zip(acc.iter_mut()).zip(&indexed) {
                        #[allow(clippy::cast_possible_truncation)]
                        {
                            *x = distance.with_shared(a, b, *s) as f32;
                        }
                        *s = Shared::default();
                    }
                }
            }
        }
        m.mirror_lower();
        m
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
        if i >= self.n || j >= self.n {
            return f64::INFINITY;
        }
        self.data
            .get(i * self.n + j)
            .map_or(f64::INFINITY, |x| f64::from(*x))
    }

    /// Row `i`: `d(i, j)` for every `j` (empty out of range).
    #[inline]
    #[must_use]
    pub fn row(&self, i: usize) -> &[f32] {
        if i >= self.n {
            return &[];
        }
        self.data.get(i * self.n..(i + 1) * self.n).unwrap_or(&[])
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
                    assert!((m.get(i, j) - direct).abs() < 1e-7, "{i} {j}");
                    assert_eq!(m.get(i, j), m.get(j, i));
                }
            }
            assert_eq!(m.get(4, 0), f64::INFINITY);
        }
    }

    /// The inverted-index matrix equals pairwise merges on random snapshots with overlapping
    /// tag sets (and empty ones).
    #[test]
    fn inverted_index_matrix_equals_pairwise_distances() {
        let mut state = 12345_u32;
        let mut next = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            f64::from(state) / 4_294_967_296.0
        };
        let snaps: Vec<Snapshot> = (0..60)
            .map(|i| {
                if i % 17 == 3 {
                    return Snapshot::new();
                }
                let start = (next() * 40.0) as u8;
                let len = (next() * 12.0) as u8;
                let mut s = Snapshot::new();
                for k in 0..len {
                    if next() < 0.8 {
                        s.insert(TagId::new(vec![start + k]), 1000.0 + 5000.0 * next());
                    }
                }
                s
            })
            .collect();
        for kind in [
            SnapshotDistance::RssL1,
            SnapshotDistance::SeedScore { id_weight: 0.6 },
        ] {
            let m = DissimilarityMatrix::from_snapshots(&snaps, kind);
            for i in 0..snaps.len() {
                assert_eq!(m.row(i).len(), snaps.len());
                for j in 0..snaps.len() {
                    let direct = kind.between(&snaps[i], &snaps[j]);
                    assert!((m.get(i, j) - direct).abs() < 1e-7, "{kind:?} {i} {j}");
                }
            }
        }
    }
}
