//! The read tags' terms of a snapshot for many poses at once, looked up in a [`ReadTable`]:
//! per pair of pose and read tag, the tag's cell in the antenna's frame, the table's entry
//! there, the floored Gaussian term of its RSS against the entry's mean, less the miss term the
//! field counted for it.
//!
//! Three ways to score ([`ReadMode`]):
//! - [`ReadMode::Packed`], what the particle filter uses: the table packed in 32 bits per cell
//!   ([`Packed`]), so that one look-up serves a pair, and where the CPU has vector gathers the
//!   compiler uses (AVX-512), one fused loop whose look-ups are 16-lane gathers.
//! - [`ReadMode::Full`]: the table's single floats as they are (the joint learning of map and
//!   trajectory, whose runs are compared with earlier runs bit for bit).
//! - [`ReadMode::ReadsOnly`]: the Gaussian terms alone, no miss terms (no field).
//!
//! Per pose the terms are added in the tags' order in every variant; the loops run in the widest
//! vector instructions the CPU has (`simd::widest`), plain floating-point code without fused
//! multiply-adds, so every instruction set gives the same bits.

use crate::readtable::{PoseLanes, ReadTable, TABLE_N};

/// Cells of the table (a power of two: an index masked to it needs no bounds check).
const CELLS: usize = TABLE_N * TABLE_N;

/// 2²³: added to a float in `[0, 2²³)` it rounds it to a whole number held in the low mantissa
/// bits.
const TWO_23: f32 = 8_388_608.0;

/// Read tags whose packed miss terms (at most 2¹⁵ − 1 each) one `u32` per pose sums.
const MAX_TAGS_PER_SUM: usize = 1 << 15;

/// Largest `q` of a packed mean (13 bits).
const MEAN_Q_MAX: f32 = 8_191.0;
/// Largest `q` of a packed miss term (15 bits).
const MISS_Q_MAX: f32 = 32_767.0;
/// Packed cells: the in-view bit, and the shift of the miss term's `q`.
const IN_VIEW_BIT: u32 = 13;
const MISS_SHIFT: u32 = 17;

/// Read tags handled per pass over the poses (their terms are added in the tags' order).
const TAGS_PER_PASS: usize = 4;

/// Most tags whose marks one [`Scoring::settle`] may take (the packed in-view count has four
/// bits).
const MAX_TAGS_PER_SETTLE: usize = 15;

/// How the read tags are scored (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ReadMode {
    Packed,
    Full,
    ReadsOnly,
}

/// The read tags of a snapshot and how to score them.
pub(crate) struct Reads<'a> {
    /// `(x, y, RSS)` per read tag, `(x, y)` relative to the poses' origin.
    pub(crate) tags: &'a [(f32, f32, f32)],
    /// `1/σ` of the RSS.
    pub(crate) inv_sigma: f32,
    /// Terms are floored at `−floor`.
    pub(crate) floor: f32,
    pub(crate) mode: ReadMode,
}

/// Scratch of [`add_reads`] for `n` poses (padded).
#[derive(Debug, Clone, Default)]
pub(crate) struct ReadScratch {
    cells: Vec<u32>,
    packed: Vec<u32>,
    pairs: Vec<u64>,
    /// Per pose: read tags the field counted as in view (their miss term was replaced).
    in_view: Vec<u32>,
    /// Per pose: the sum of the read tags' packed miss terms' `q`s.
    high: Vec<u32>,
    /// Per pose (packed cells): the sum of the read tags' floored squared differences.
    squares: Vec<f32>,
    /// The tags with their RSS in the units of the mode.
    tags: Vec<(f32, f32, f32)>,
}

/// The read table packed in 32 bits per cell: bits 0–12 the mean RSS as `lo + q·mean_step`
/// (`q` rounded, 0–8191, over the table's range of means), bit 13 set when the tag is in view,
/// bits 14–16 zero, bits 17–31 the miss term as `−q·miss_step` (0–32767 over `[−floor, 0]`).
/// The rounding moves a mean by at most half a step (1/16382 of the range of means: 0.44 RSS
/// units for seed 000's model, whose σ is 169) and a miss term by at most `floor / 65534`.
///
/// Bits 13 and up shifted down by 13 hold the in-view mark in bit 0 and the miss term's `q`
/// from bit 4: the sum of up to 15 of them keeps the in-view count in its low four bits and
/// the miss terms' sum above, so that one integer addition per pair counts both.
#[derive(Clone)]
pub(crate) struct Packed {
    cells: std::sync::Arc<[u32; CELLS]>,
    /// Mean RSS of `q = 0` and per unit of `q`.
    mean_lo: f32,
    mean_step: f32,
    /// Miss term per unit of its `q` (negated).
    miss_step: f32,
}

impl Packed {
    /// Packs the (mean RSS, miss term) cells of a table floored at `−floor`.
    pub(crate) fn new(pairs: &[[f32; 2]], floor: f64) -> Self {
        let (lo, hi) = pairs
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[0]), hi.max(p[0]))
            });
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
        let mean_step = if hi > lo { (hi - lo) / MEAN_Q_MAX } else { 1.0 };
        #[allow(clippy::cast_possible_truncation)]
        let miss_step = ((floor / f64::from(MISS_Q_MAX)) as f32).max(f32::MIN_POSITIVE);
        let mut cells = zeroed::<u32>();
        for (out, &[m, v]) in cells.iter_mut().zip(pairs) {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let q_mean = ((m - lo) / mean_step).round().clamp(0.0, MEAN_Q_MAX) as u32;
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let q_miss = (-v / miss_step).round().clamp(0.0, MISS_Q_MAX) as u32;
            *out = q_mean | (u32::from(v < 0.0) << IN_VIEW_BIT) | (q_miss << MISS_SHIFT);
        }
        Self {
            cells: cells.into(),
            mean_lo: lo,
            mean_step,
            miss_step,
        }
    }

    /// `2²³ + q` for the `q` of the mean of a packed cell, as a float (exact), without an
    /// integer-to-float conversion: the float with `q` in its low mantissa bits.
    #[inline(always)]
    fn biased_mean_q(g: u32) -> f32 {
        f32::from_bits((g & ((1 << IN_VIEW_BIT) - 1)) | 0x4B00_0000)
    }

    /// An RSS in the units of the packed means, biased like [`Packed::biased_mean_q`]:
    /// `2²³ + (r − lo) / step`, which rounds it to a whole step (by at most half a step).
    #[inline]
    fn biased_rss(&self, r: f32) -> f32 {
        (r - self.mean_lo) / self.mean_step + TWO_23
    }

    /// (mean RSS, miss term, in view) of a packed cell.
    #[cfg(test)]
    fn unpack(&self, g: u32) -> (f32, f32, bool) {
        #[allow(clippy::cast_precision_loss)]
        let miss = -((g >> MISS_SHIFT) as f32) * self.miss_step;
        (
            self.mean_lo + (Self::biased_mean_q(g) - TWO_23) * self.mean_step,
            miss,
            (g >> IN_VIEW_BIT) & 1 == 1,
        )
    }
}

/// A table of `CELLS` zeros on the heap (built there: up to 512 KiB).
pub(crate) fn zeroed<T: Copy + Default>() -> Box<[T; CELLS]> {
    vec![T::default(); CELLS]
        .into_boxed_slice()
        .try_into()
        .unwrap_or_else(|_| Box::new([T::default(); CELLS]))
}

/// A table's (mean RSS, miss term) in one word: the mean's bits low, the miss term's high.
#[inline]
pub(crate) fn pair_bits(m: f32, v: f32) -> u64 {
    u64::from(m.to_bits()) | (u64::from(v.to_bits()) << 32)
}

/// The (mean RSS, miss term) of [`pair_bits`].
#[inline(always)]
pub(crate) fn pair_of_bits(g: u64) -> [f32; 2] {
    #[allow(clippy::cast_possible_truncation)]
    [f32::from_bits(g as u32), f32::from_bits((g >> 32) as u32)]
}

/// One way to score a read tag against a table cell.
trait Scoring: Copy {
    type Cell: Copy + Default;
    /// Adds the term of a tag read with RSS `r` whose cell holds `g`: to the pose's sum, and
    /// to `marks`, which [`Scoring::settle`] turns into counts after at most 15 tags.
    fn add(self, r: f32, g: Self::Cell, sum: &mut f32, marks: &mut u32);
    /// Adds what `marks` counted to the pose's in-view count and (packed cells) its sum of
    /// miss terms' `q`s. The loops settle into local copies and then store them: settling
    /// through references into the per-pose slices kept the compiler from vectorising the
    /// fused loop (`log_likelihoods` 150 against 50 µs).
    fn settle(self, marks: u32, seen: &mut u32, high: &mut u32);
}

/// The floored Gaussian term `max(d² · scale, −floor)` (`scale = −½/σ²` in the units of `d`).
#[derive(Clone, Copy)]
struct Gauss {
    scale: f32,
    floor: f32,
}

impl Gauss {
    #[inline(always)]
    fn term(self, d: f32) -> f32 {
        let t = d * d * self.scale;
        if t > -self.floor {
            t
        } else {
            -self.floor
        }
    }
}

/// [`ReadMode::Packed`]: `r` as [`Packed::biased_rss`]. Per pair the squared difference
/// floored at `cap` (`max(d²·scale, −floor) = scale·min(d², cap)` with `cap = −floor/scale`),
/// scaled once per pose; the in-view marks and miss terms in one integer sum.
#[derive(Clone, Copy)]
struct PackedTerms {
    cap: f32,
}

impl Scoring for PackedTerms {
    type Cell = u32;
    #[inline(always)]
    fn add(self, r: f32, g: u32, sum: &mut f32, marks: &mut u32) {
        // Both biased by 2²³ and whole: the difference is exact. A difference that is not a
        // number is floored.
        let d = r - Packed::biased_mean_q(g);
        let d2 = d * d;
        *sum += if d2 < self.cap { d2 } else { self.cap };
        *marks += g >> IN_VIEW_BIT;
    }
    #[inline(always)]
    fn settle(self, marks: u32, seen: &mut u32, high: &mut u32) {
        *seen += marks & 0xF;
        *high += marks >> 4;
    }
}

/// [`ReadMode::Full`]: the cell's single floats; the miss term is subtracted per tag.
#[derive(Clone, Copy)]
struct FullTerms(Gauss);

impl Scoring for FullTerms {
    type Cell = u64;
    #[inline(always)]
    fn add(self, r: f32, g: u64, sum: &mut f32, marks: &mut u32) {
        let [m, v] = pair_of_bits(g);
        *sum += self.0.term(r - m) - v;
        // The sign bit marks a tag in view.
        *marks += v.to_bits() >> 31;
    }
    #[inline(always)]
    fn settle(self, marks: u32, seen: &mut u32, _: &mut u32) {
        *seen += marks;
    }
}

/// [`ReadMode::ReadsOnly`]: the Gaussian term against the cell's mean, nothing else.
#[derive(Clone, Copy)]
struct ReadTerms(Gauss);

impl Scoring for ReadTerms {
    type Cell = u64;
    #[inline(always)]
    fn add(self, r: f32, g: u64, sum: &mut f32, _: &mut u32) {
        *sum += self.0.term(r - pair_of_bits(g)[0]);
    }
    #[inline(always)]
    fn settle(self, _: u32, _: &mut u32, _: &mut u32) {}
}

/// The cell of a tag at `(tx, ty)` seen from pose lane `(c, s, u, v)`.
#[inline(always)]
fn cell_of(c: f32, s: f32, u: f32, v: f32, tx: f32, ty: f32) -> usize {
    ReadTable::cell(c * tx + s * ty + u, c * ty - s * tx + v) as usize & (CELLS - 1)
}

/// Per pose, what the passes add to.
struct Sums<'a> {
    acc: &'a mut [f32],
    in_view: &'a mut [u32],
    high: &'a mut [u32],
}

/// Adds the terms of `K` read tags to every pose in three passes: the tags in each antenna's
/// frame as table cells (vectorised), the table's entries there (scalar), the terms
/// (vectorised). For instruction sets without vector gathers the compiler uses. `cells` and
/// `gathered` are scratch of at least `K` times the poses. (Slices as arguments, not in a
/// struct: the compiler then knows they do not overlap.)
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn run_in_passes<S: Scoring, const K: usize>(
    scoring: S,
    table: &[S::Cell; CELLS],
    poses: &PoseLanes,
    tags: &[(f32, f32, f32); K],
    cells: &mut [u32],
    gathered: &mut [S::Cell],
    acc: &mut [f32],
    in_view: &mut [u32],
    high: &mut [u32],
) {
    const { assert!(K <= MAX_TAGS_PER_SETTLE) };
    let n = acc.len();
    let (pc, ps, pu, pv) = (&poses.c[..n], &poses.s[..n], &poses.u[..n], &poses.v[..n]);
    let (in_view, high) = (&mut in_view[..n], &mut high[..n]);
    for (&(tx, ty, _), out) in tags.iter().zip(cells.chunks_exact_mut(n)) {
        let out = &mut out[..n];
        for i in 0..n {
            #[allow(clippy::cast_possible_truncation)]
            {
                out[i] = cell_of(pc[i], ps[i], pu[i], pv[i], tx, ty) as u32;
            }
        }
    }
    for (g, &i) in gathered.iter_mut().zip(&cells[..K * n]) {
        *g = table[i as usize & (CELLS - 1)];
    }
    let mut rows = gathered.chunks_exact(n);
    let g: [&[S::Cell]; K] = std::array::from_fn(|_| rows.next().unwrap_or(&[]));
    let g = g.map(|rows| &rows[..n]);
    for i in 0..n {
        let (mut sum, mut marks) = (acc[i], 0);
        for (&(_, _, r), rows) in tags.iter().zip(&g) {
            scoring.add(r, rows[i], &mut sum, &mut marks);
        }
        let (mut seen, mut hi) = (in_view[i], high[i]);
        scoring.settle(marks, &mut seen, &mut hi);
        (acc[i], in_view[i], high[i]) = (sum, seen, hi);
    }
}

/// [`run_in_passes`] as one loop over the poses with the look-ups inside, for instruction
/// sets whose vector gathers the compiler uses (one 16-lane gather per 16 pairs of pose and
/// tag with packed cells). The operations and their order per pose are the same, so are the
/// results.
#[inline(always)]
fn run_fused<S: Scoring, const K: usize>(
    scoring: S,
    table: &[S::Cell; CELLS],
    poses: &PoseLanes,
    tags: &[(f32, f32, f32); K],
    acc: &mut [f32],
    in_view: &mut [u32],
    high: &mut [u32],
) {
    const { assert!(K <= MAX_TAGS_PER_SETTLE) };
    let n = acc.len();
    let (pc, ps, pu, pv) = (&poses.c[..n], &poses.s[..n], &poses.u[..n], &poses.v[..n]);
    let (in_view, high) = (&mut in_view[..n], &mut high[..n]);
    for i in 0..n {
        let (c, s, u, v) = (pc[i], ps[i], pu[i], pv[i]);
        let (mut sum, mut marks) = (acc[i], 0);
        for &(tx, ty, r) in tags {
            let g = table[cell_of(c, s, u, v, tx, ty)];
            scoring.add(r, g, &mut sum, &mut marks);
        }
        let (mut seen, mut hi) = (in_view[i], high[i]);
        scoring.settle(marks, &mut seen, &mut hi);
        (acc[i], in_view[i], high[i]) = (sum, seen, hi);
    }
}

/// [`run_fused`] for two quadruples of tags per pass over the poses.
#[inline(always)]
fn run_fused_twice<S: Scoring>(
    scoring: S,
    table: &[S::Cell; CELLS],
    poses: &PoseLanes,
    tags: &[[(f32, f32, f32); 4]; 2],
    acc: &mut [f32],
    in_view: &mut [u32],
    high: &mut [u32],
) {
    let n = acc.len();
    let (pc, ps, pu, pv) = (&poses.c[..n], &poses.s[..n], &poses.u[..n], &poses.v[..n]);
    let (in_view, high) = (&mut in_view[..n], &mut high[..n]);
    const { assert!(8 <= MAX_TAGS_PER_SETTLE) };
    let [first, second] = tags;
    for i in 0..n {
        let (c, s, u, v) = (pc[i], ps[i], pu[i], pv[i]);
        let (mut sum, mut marks) = (acc[i], 0);
        for &(tx, ty, r) in first {
            let g = table[cell_of(c, s, u, v, tx, ty)];
            scoring.add(r, g, &mut sum, &mut marks);
        }
        for &(tx, ty, r) in second {
            let g = table[cell_of(c, s, u, v, tx, ty)];
            scoring.add(r, g, &mut sum, &mut marks);
        }
        let (mut seen, mut hi) = (in_view[i], high[i]);
        scoring.settle(marks, &mut seen, &mut hi);
        (acc[i], in_view[i], high[i]) = (sum, seen, hi);
    }
}

/// Every read tag over every pose, four tags per pass, fused or in passes.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn run_all<S: Scoring>(
    scoring: S,
    table: &[S::Cell; CELLS],
    poses: &PoseLanes,
    tags: &[(f32, f32, f32)],
    fused: bool,
    cells: &mut Vec<u32>,
    gathered: &mut Vec<S::Cell>,
    sums: Sums<'_>,
) {
    let n = sums.acc.len();
    let scratch = if fused { 0 } else { TAGS_PER_PASS * n };
    cells.clear();
    cells.resize(scratch, 0);
    gathered.clear();
    gathered.resize(scratch, S::Cell::default());
    let Sums { acc, in_view, high } = sums;
    let mut tags = tags;
    while fused && tags.len() >= 8 {
        let (acc, in_view, high) = (&mut acc[..], &mut in_view[..], &mut high[..]);
        if let [a, b, c, d, e, f, g, h, ref rest @ ..] = *tags {
            run_fused_twice(
                scoring,
                table,
                poses,
                &[[a, b, c, d], [e, f, g, h]],
                acc,
                in_view,
                high,
            );
            tags = rest;
        }
    }
    for chunk in tags.chunks(TAGS_PER_PASS) {
        let (cells, gathered) = (&mut cells[..], &mut gathered[..]);
        let (acc, in_view, high) = (&mut acc[..], &mut in_view[..], &mut high[..]);
        match (chunk, fused) {
            (&[a, b, c, d], true) => {
                run_fused(scoring, table, poses, &[a, b, c, d], acc, in_view, high);
            }
            (&[a, b, c, d], false) => run_in_passes(
                scoring,
                table,
                poses,
                &[a, b, c, d],
                cells,
                gathered,
                acc,
                in_view,
                high,
            ),
            (_, true) => {
                for &a in chunk {
                    run_fused(scoring, table, poses, &[a], acc, in_view, high);
                }
            }
            (_, false) => {
                for &a in chunk {
                    run_in_passes(
                        scoring,
                        table,
                        poses,
                        &[a],
                        cells,
                        gathered,
                        acc,
                        in_view,
                        high,
                    );
                }
            }
        }
    }
}

/// Adds the read tags' terms to every pose of `poses` (`acc`, `terms` padded like them): for a
/// tag read with RSS `r` whose cell holds mean `m` and miss term `v`,
/// `acc += max(−½((r − m)/σ)², −floor) − v` (its Gaussian term replaces the miss term the field
/// counted) and `terms += 1` unless the field counted it already (in view). With
/// [`ReadMode::ReadsOnly`] nothing is subtracted and every read tag is a term (no field was
/// added). Packed cells: per pose the Gaussian terms in the tags' order, then the miss terms'
/// sum.
pub(crate) fn add_reads(
    table: &ReadTable,
    reads: &Reads<'_>,
    poses: &PoseLanes,
    scratch: &mut ReadScratch,
    acc: &mut [f32],
    terms: &mut [f32],
) {
    let fused = reads.mode == ReadMode::Packed && crate::simd::gathers_vectorise();
    add_reads_in(table, reads, poses, scratch, acc, terms, fused);
}

/// [`add_reads`] fused or in passes (the same bits).
fn add_reads_in(
    table: &ReadTable,
    reads: &Reads<'_>,
    poses: &PoseLanes,
    scratch: &mut ReadScratch,
    acc: &mut [f32],
    terms: &mut [f32],
    fused: bool,
) {
    let packed = table.packed();
    let ReadScratch {
        cells,
        packed: packed_rows,
        pairs: pair_rows,
        in_view,
        high,
        squares,
        tags,
    } = scratch;
    // Packed: the RSS in the packed mean's units, `(r − lo) / step`, and σ with it.
    tags.clear();
    let step = if reads.mode == ReadMode::Packed {
        tags.extend(
            reads
                .tags
                .iter()
                .map(|&(x, y, r)| (x, y, packed.biased_rss(r))),
        );
        packed.mean_step * reads.inv_sigma
    } else {
        tags.extend_from_slice(reads.tags);
        reads.inv_sigma
    };
    let gauss = Gauss {
        // `t = −½ z²` as `d² · k`.
        scale: -0.5 * step * step,
        floor: reads.floor,
    };
    // Packed: `max(d²·scale, −floor)` as `scale·min(d², cap)`; the cap bounded so that the
    // sum of a part's tags stays finite (a term then differs from the floor by at most
    // `10³⁰·|scale|`); no cap (zero terms) when the scale is zero or the floor not a number.
    let cap = -gauss.floor / gauss.scale;
    let cap = if gauss.scale < 0.0 && cap >= 0.0 {
        cap.min(1e30)
    } else {
        0.0
    };
    // The per-pose integer sums stay below 2³¹ for up to `MAX_TAGS_PER_SUM` tags; a snapshot
    // with more is added in parts (each part's miss terms then added on their own).
    for tags in tags.chunks(MAX_TAGS_PER_SUM) {
        crate::simd::widest(
            #[inline(always)]
            || {
                let n = poses.c.len();
                for v in [&mut *in_view, &mut *high] {
                    v.clear();
                    v.resize(n, 0);
                }
                let acc = &mut acc[..n];
                // Packed: the squares are summed from zero and scaled at the end.
                let packed_mode = reads.mode == ReadMode::Packed;
                squares.clear();
                squares.resize(if packed_mode { n } else { 0 }, 0.0);
                let sums = Sums {
                    acc: if packed_mode {
                        &mut squares[..]
                    } else {
                        &mut acc[..]
                    },
                    in_view: &mut in_view[..],
                    high: &mut high[..],
                };
                match reads.mode {
                    ReadMode::Packed => run_all(
                        PackedTerms { cap },
                        &packed.cells,
                        poses,
                        tags,
                        fused,
                        cells,
                        packed_rows,
                        sums,
                    ),
                    ReadMode::Full => run_all(
                        FullTerms(gauss),
                        table.pairs(),
                        poses,
                        tags,
                        fused,
                        cells,
                        pair_rows,
                        sums,
                    ),
                    ReadMode::ReadsOnly => run_all(
                        ReadTerms(gauss),
                        table.pairs(),
                        poses,
                        tags,
                        fused,
                        cells,
                        pair_rows,
                        sums,
                    ),
                }
                #[allow(clippy::cast_precision_loss)]
                let read = tags.len() as f32;
                let m = n.min(terms.len());
                let terms = &mut terms[..m];
                match reads.mode {
                    ReadMode::ReadsOnly => {
                        for k in terms.iter_mut() {
                            *k += read;
                        }
                    }
                    ReadMode::Full => {
                        for (k, &seen) in terms.iter_mut().zip(in_view.iter()) {
                            #[allow(clippy::cast_precision_loss)]
                            {
                                *k += read - seen as f32;
                            }
                        }
                    }
                    ReadMode::Packed => {
                        let (miss_step, scale) = (packed.miss_step, gauss.scale);
                        let squares = &squares[..n];
                        for (i, k) in terms.iter_mut().enumerate() {
                            let (seen, hi) = (in_view[i], high[i]);
                            #[allow(clippy::cast_precision_loss)]
                            {
                                acc[i] += squares[i] * scale;
                                acc[i] += hi as f32 * miss_step;
                                *k += read - seen as f32;
                            }
                        }
                    }
                }
            },
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::readtable::{sincos_f32, TABLE_X0};
    use crate::tagmap::ReadModel;

    /// `add_reads_in` from `(acc0, terms0)` in both loop shapes (fused and in passes), each in
    /// the widest instructions this CPU has and in the baseline ones: `(variant, acc, terms)`.
    fn every_variant(
        table: &ReadTable,
        reads: &Reads<'_>,
        poses: &PoseLanes,
        scratch: &mut ReadScratch,
        acc0: &[f32],
        terms0: &[f32],
    ) -> Vec<(String, Vec<f32>, Vec<f32>)> {
        let mut runs = Vec::new();
        for (fused, baseline) in [(true, false), (false, false), (true, true), (false, true)] {
            let (mut acc, mut terms) = (acc0.to_vec(), terms0.to_vec());
            let mut run = || {
                add_reads_in(table, reads, poses, scratch, &mut acc, &mut terms, fused);
            };
            if baseline {
                crate::simd::on_baseline(run);
            } else {
                run();
            }
            runs.push((format!("fused {fused}, baseline {baseline}"), acc, terms));
        }
        runs
    }

    /// `add_reads` in every mode and both loop shapes (fused and in passes), each in the
    /// widest instructions this CPU has and in the baseline ones, against a plain loop over
    /// poses and tags: the same bits, for every number of tags modulo the pass, poses on and
    /// off the table.
    #[test]
    fn add_reads_equals_a_plain_loop_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let model = ReadModel::seed000(1000.0, 2);
        let table = ReadTable::new(&model, 6.0);
        let packed = table.packed();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (inv_sigma, floor) = (1.0 / 45.0_f32, 6.0_f32);
        let mut scratch = ReadScratch::default();
        let modes = [ReadMode::Packed, ReadMode::Full, ReadMode::ReadsOnly];
        for (count, mode) in (0..11).flat_map(|c| modes.map(|m| (c, m))) {
            let mut poses = PoseLanes::default();
            let n = 37;
            poses.reset(n);
            for i in 0..n {
                let (s, c) = sincos_f32(rng.random_range(-4.0..4.0));
                let (x, y) = (rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
                [poses.c[i], poses.s[i], poses.u[i], poses.v[i]] = PoseLanes::lane(x, y, c, s);
            }
            let tags: Vec<(f32, f32, f32)> = (0..count)
                .map(|_| {
                    (
                        rng.random_range(-2.0..2.0),
                        rng.random_range(-2.0..2.0),
                        rng.random_range(500.0..2500.0),
                    )
                })
                .collect();
            let padded = poses.c.len();
            let acc0: Vec<f32> = (0..padded).map(|_| rng.random_range(-30.0..0.0)).collect();
            let terms0: Vec<f32> = (0..padded).map(|_| rng.random_range(0.0..20.0)).collect();
            let reads = Reads {
                tags: &tags,
                inv_sigma,
                floor,
                mode,
            };
            let runs = every_variant(&table, &reads, &poses, &mut scratch, &acc0, &terms0);
            let term = |d: f32, scale: f32| (d * d * scale).max(-floor);
            for i in 0..padded {
                let (mut a, mut seen, mut high, mut squares) = (acc0[i], 0_u32, 0_u32, 0.0_f32);
                let step = packed.mean_step * inv_sigma;
                let packed_scale = -0.5 * step * step;
                let cap = -floor / packed_scale;
                for &(tx, ty, r) in &tags {
                    let (c, s, u, v) = (poses.c[i], poses.s[i], poses.u[i], poses.v[i]);
                    let cell = ReadTable::cell(c * tx + s * ty + u, c * ty - s * tx + v) & 0xFFFF;
                    let [m, miss] = pair_of_bits(table.pairs()[cell as usize]);
                    let exact = -0.5 * inv_sigma * inv_sigma;
                    match mode {
                        ReadMode::ReadsOnly => a += term(r - m, exact),
                        ReadMode::Full => {
                            a += term(r - m, exact) - miss;
                            seen += u32::from(miss < 0.0);
                        }
                        ReadMode::Packed => {
                            let g = packed.cells[cell as usize];
                            let d = packed.biased_rss(r) - Packed::biased_mean_q(g);
                            squares += (d * d).min(cap);
                            seen += (g >> 13) & 1;
                            high += g >> 17;
                        }
                    }
                }
                if mode == ReadMode::Packed {
                    a += squares * packed_scale;
                    a += high as f32 * packed.miss_step;
                }
                let k = terms0[i] + (count as f32 - seen as f32);
                for (name, acc, terms) in &runs {
                    let what = format!("{mode:?}, {name}: {count} tags, pose {i}");
                    assert_eq!(acc[i].to_bits(), a.to_bits(), "{what}");
                    assert_eq!(terms[i].to_bits(), k.to_bits(), "{what}");
                }
            }
        }
    }

    /// Non-finite poses, tag positions and RSS (a corrupt capture, a diverged pose): no panic,
    /// every term finite (a NaN or infinite difference is floored, a non-finite cell index is
    /// clamped onto the table), and every loop shape and instruction set gives the same bits.
    #[test]
    fn non_finite_inputs_give_finite_terms_in_every_variant() {
        let table = ReadTable::new(&ReadModel::seed000(1000.0, 2), 6.0);
        let odd = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, 0.5];
        let mut poses = PoseLanes::default();
        let n = odd.len() * odd.len();
        poses.reset(n);
        for i in 0..n {
            let (a, b) = (odd[i % odd.len()], odd[i / odd.len()]);
            [poses.c[i], poses.s[i], poses.u[i], poses.v[i]] = [a, b, b, a];
        }
        let tags: Vec<(f32, f32, f32)> = (0..11)
            .map(|k| {
                (
                    odd[k % odd.len()],
                    odd[(k + 2) % odd.len()],
                    odd[(k + 3) % odd.len()],
                )
            })
            .collect();
        let padded = poses.c.len();
        for mode in [ReadMode::Packed, ReadMode::Full, ReadMode::ReadsOnly] {
            let reads = Reads {
                tags: &tags,
                inv_sigma: 1.0 / 45.0,
                floor: 6.0,
                mode,
            };
            let zeros = vec![0.0_f32; padded];
            let mut scratch = ReadScratch::default();
            let runs = every_variant(&table, &reads, &poses, &mut scratch, &zeros, &zeros);
            for (name, acc, terms) in &runs {
                assert!(
                    acc.iter().chain(terms).all(|v| v.is_finite()),
                    "{mode:?}, {name}: {acc:?}"
                );
            }
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let (_, acc0, terms0) = &runs[0];
            for (name, acc, terms) in &runs[1..] {
                assert_eq!(bits(acc), bits(acc0), "{mode:?}, {name}");
                assert_eq!(bits(terms), bits(terms0), "{mode:?}, {name}");
            }
            // Every tag is floored at worst: a sum no lower than the tags' floors (and the
            // miss terms taken back, at most one floor each, can only raise it).
            let lowest = -6.0 * tags.len() as f32;
            assert!(acc0.iter().all(|a| *a >= lowest), "{mode:?}: {acc0:?}");
        }
    }

    /// A snapshot of more read tags than one integer sum per pose holds (a corrupt or hostile
    /// capture): no overflow (a debug build would panic), and the same as adding it in parts.
    #[test]
    fn more_tags_than_one_sum_holds_are_added_in_parts() {
        let table = ReadTable::new(&ReadModel::seed000(1000.0, 2), 6.0);
        let mut poses = PoseLanes::default();
        poses.reset(3);
        for i in 0..3 {
            let (s, c) = sincos_f32(0.01 * i as f64);
            [poses.c[i], poses.s[i], poses.u[i], poses.v[i]] = PoseLanes::lane(0.0, 0.0, c, s);
        }
        // Just in front of the antenna: in view, and a large miss term.
        let tags = vec![(0.3_f32, 0.0_f32, 1500.0_f32); 10 * MAX_TAGS_PER_SUM + 4000];
        let cell = ReadTable::cell((0.3 - TABLE_X0 as f32) * 100.0, 0.0) as usize & (CELLS - 1);
        let q = u64::from(table.packed().cells[cell] >> MISS_SHIFT);
        assert!(q * tags.len() as u64 > u64::from(u32::MAX), "{q}");
        let n = poses.c.len();
        let score = |tags: &[(f32, f32, f32)], acc: &mut Vec<f32>, terms: &mut Vec<f32>| {
            let reads = Reads {
                tags,
                inv_sigma: 1.0 / 45.0,
                floor: 6.0,
                mode: ReadMode::Packed,
            };
            add_reads(
                &table,
                &reads,
                &poses,
                &mut ReadScratch::default(),
                acc,
                terms,
            );
        };
        let (mut acc, mut terms) = (vec![0.0; n], vec![0.0; n]);
        score(&tags, &mut acc, &mut terms);
        let (mut parts, mut part_terms) = (vec![0.0; n], vec![0.0; n]);
        for part in tags.chunks(MAX_TAGS_PER_SUM) {
            score(part, &mut parts, &mut part_terms);
        }
        for i in 0..3 {
            assert!(acc[i].is_finite(), "{}", acc[i]);
            assert_eq!(acc[i].to_bits(), parts[i].to_bits());
            assert_eq!(terms[i].to_bits(), part_terms[i].to_bits());
        }
    }

    /// The packed table against the cells it packs: every mean within half a step, every miss
    /// term within half its step, the in-view mark where the miss term is negative.
    #[test]
    fn packed_cells_hold_the_pairs_within_half_a_step() {
        for floor in [6.0, 0.5] {
            let table = ReadTable::new(&ReadModel::seed000(1000.0, 2), floor);
            let p = table.packed();
            assert!(p.mean_step > 0.0 && p.miss_step > 0.0);
            let mut in_view = 0;
            for (&g, &pair) in p.cells.iter().zip(table.pairs().iter()) {
                let [m, v] = pair_of_bits(pair);
                let (pm, pv, seen) = p.unpack(g);
                assert!(
                    (pm - m).abs() <= 0.5 * p.mean_step + m.abs() * 1e-6,
                    "{pm} {m}"
                );
                #[allow(clippy::cast_possible_truncation)]
                let floor32 = floor as f32;
                assert!(
                    (pv - v).abs() <= 0.5 * p.miss_step + floor32 * 1e-6,
                    "{pv} {v}"
                );
                assert_eq!(seen, v < 0.0);
                in_view += usize::from(seen);
            }
            // The view covers a good part of the table.
            assert!(in_view > CELLS / 20, "{in_view}");
        }
    }
}
