//! Precomputed tables of the reader model, so that scoring a pose or a tag position costs table
//! look-ups instead of an `exp` and a `ln` per tag.
//!
//! - [`ReadTable`]: over the antenna frame `(x, |y|)` on a 1 cm grid, the model's mean RSS `m`
//!   and the miss term `max(ln(1 − P_read(m)), −floor)` of a tag there (0 when the tag is out of
//!   view: behind the antenna or beyond the reach; a tag in view stores at most `−1e−7`, so the
//!   sign says whether it is in view). The outermost rows and columns are zero: anything
//!   outside the table reads as "far away".
//!   For scoring many poses the same table is also kept packed in 32 bits per cell
//!   ([`Packed`], used by [`crate::readpass`]).
//! - [`MissField`]: the sum of the miss terms of **every** mapped tag in view, and their number,
//!   as a function of the antenna pose `(x, y, θ)`, on a 5 cm × 5 cm × 64-heading lattice,
//!   interpolated trilinearly. It is computed lazily in tiles of 0.8 m × 0.8 m (all headings)
//!   the first time a pose in the tile is scored, and shared by clones of the map.
//!
//! With both, the snapshot log-likelihood of a pose is
//! `M(pose) + Σ_{read mapped tags} (g_i − v_i)`, with `g_i` the read tag's floored Gaussian
//! term and `v_i` its miss term (which `M` counted although the tag was read): the work per
//! pose grows with the tags in the snapshot, not with the tags in view.

use std::f64::consts::TAU;
use std::sync::OnceLock;

use crate::readpass::{pair_bits, pair_of_bits, zeroed, Packed};
use crate::tagmap::ReadModel;

/// Grid step of the antenna-frame table, metres.
const TABLE_STEP: f64 = 0.01;
/// Cells per side of the table (a power of two: indices need no bounds check). The table
/// covers `x ∈ [TABLE_X0, TABLE_X0 + 2.55]`, `|y| ≤ 2.55`; beyond, a read tag counts as far
/// away (mean RSS 0).
pub(crate) const TABLE_N: usize = 256;
pub(crate) const TABLE_X0: f64 = -0.06;
/// Stored miss term of an in-view tag is at most this (so that it is negative).
const IN_VIEW_MARK: f64 = -1e-7;
/// Step of the mean-RSS axis of the 1-D miss table, reader units.
const MISS_STEP: f64 = 1.0;

/// Node spacing of the miss field, metres.
pub(crate) const FIELD_STEP: f64 = 0.05;
/// Headings of the miss field over 2π.
pub(crate) const FIELD_HEADINGS: usize = 64;
/// Cells per tile side.
const TILE: usize = 16;
/// Nodes per tile side (a tile holds the nodes on its far edges too).
const TILE_NODES: usize = TILE + 1;
/// Entries of a tile from a node to the node one up and one right, all headings included.
const CORNER_SPAN: usize = (TILE_NODES + 2) * FIELD_HEADINGS;

/// 1.5·2⁵²: adding it to `x` (`|x| < 2⁵¹`) rounds `x` to the nearest integer (ties to even),
/// which the sum holds in its low mantissa bits; subtracting it again gives that integer.
pub(crate) const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

/// Nearest integer of `x` (ties to even) for `|x| < 2⁵¹`, by adding and subtracting
/// [`ROUND_MAGIC`] (the baseline x86-64 target has no rounding instruction, and the library
/// call is slow).
#[inline]
#[must_use]
pub(crate) fn round_f64(x: f64) -> f64 {
    if x.abs() < 2_251_799_813_685_248.0 {
        (x + ROUND_MAGIC) - ROUND_MAGIC
    } else {
        x
    }
}

/// `⌊x⌋` for `|x| < 2⁵¹` (see [`round_f64`]).
#[inline]
#[must_use]
pub(crate) fn floor_f64(x: f64) -> f64 {
    let r = round_f64(x);
    if r > x {
        r - 1.0
    } else {
        r
    }
}

/// The lattice node below `f` (taken modulo 2⁵¹ for negative `f`) and the weight of the next
/// one, `f − node` in `[0, 1]`, without float-to-integer conversions: `f − ½ + 1.5·2⁵²` holds
/// `round(f − ½)` in its low mantissa bits. When `f` is an integer the node may be `f − 1` with
/// weight 1, which interpolates to the same value. The node is 64 bits wide (not `usize`) so
/// that loops over many values vectorise.
#[inline]
fn lower_node_bits(f: f64) -> (u64, f32) {
    let r = (f - 0.5) + ROUND_MAGIC;
    let node = r - ROUND_MAGIC;
    #[allow(clippy::cast_possible_truncation)]
    let w = ((f - node) as f32).clamp(0.0, 1.0);
    (r.to_bits() & ((1 << 51) - 1), w)
}

/// [`lower_node_bits`] with the node as an index (the one-pose reference sampler, tests).
#[cfg(test)]
#[inline]
fn lower_node(f: f64) -> (usize, f32) {
    let (node, w) = lower_node_bits(f);
    #[allow(clippy::cast_possible_truncation)]
    (node as usize, w)
}

/// Lanes of the chunked loops over poses (the compiler keeps a chunk in vector registers).
pub(crate) const LANES: usize = 8;

/// `sin θ`, `cos θ` in single precision (polynomials after reduction to `[−π/4, π/4]`; error
/// below 1e−6).
#[must_use]
pub(crate) fn sincos_f32(theta: f64) -> (f32, f32) {
    let q = round_f64(theta * std::f64::consts::FRAC_2_PI);
    #[allow(clippy::cast_possible_truncation)]
    let r = (theta - q * std::f64::consts::FRAC_PI_2) as f32;
    let r2 = r * r;
    let s = r * (1.0 + r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0))));
    let c = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40320.0))));
    to_quadrant(q, s, c)
}

/// Floats whose sign bit can be flipped and that can be chosen between without branches.
pub(crate) trait Bits: Copy {
    /// `self`, negated when `flip`.
    fn negated_if(self, flip: bool) -> Self;
}

impl Bits for f32 {
    #[inline]
    fn negated_if(self, flip: bool) -> Self {
        f32::from_bits(self.to_bits() ^ (u32::from(flip) << 31))
    }
}

impl Bits for f64 {
    #[inline]
    fn negated_if(self, flip: bool) -> Self {
        f64::from_bits(self.to_bits() ^ (u64::from(flip) << 63))
    }
}

/// `(sin θ, cos θ)` from `(sin r, cos r)` with `θ = r + q·π/2` (`q` an integer below 2⁵¹ in
/// magnitude): `(s, c)`, `(c, −s)`, `(−s, −c)`, `(−c, s)` for `q mod 4 = 0, 1, 2, 3`. Without
/// branches or float-to-integer conversions, so that loops over poses vectorise: `q + 1.5·2⁵²`
/// holds `2⁵¹ + q` in its low mantissa bits, and 2⁵¹ is a multiple of 4.
#[inline]
pub(crate) fn to_quadrant<T: Bits>(q: f64, s: T, c: T) -> (T, T) {
    let k = (q + ROUND_MAGIC).to_bits();
    let swap = k & 1 != 0;
    let (a, b) = if swap { (c, s) } else { (s, c) };
    (a.negated_if(k & 2 != 0), b.negated_if((k + 1) & 2 != 0))
}

/// Antenna poses of many robot poses in single precision, pre-rotated and pre-scaled to table
/// cells: a tag at `(tx, ty)` (relative to an origin) lies in antenna-frame cell
/// `(c·tx + s·ty + u, c·ty − s·tx + v)` (before rounding; the `x` axis from the table's first
/// column), with `c`, `s` the heading's cosine and sine divided by the cell size. Padded to a
/// multiple of [`LANES`] (padding lies far away and scores nothing useful).
#[derive(Debug, Clone, Default)]
pub(crate) struct PoseLanes {
    pub(crate) c: Vec<f32>,
    pub(crate) s: Vec<f32>,
    pub(crate) u: Vec<f32>,
    pub(crate) v: Vec<f32>,
}

impl PoseLanes {
    /// Clears and pads to hold `n` poses (`n` rounded up to lanes).
    pub(crate) fn reset(&mut self, n: usize) {
        let padded = n.div_ceil(LANES) * LANES;
        for (v, fill) in [
            (&mut self.c, 0.0),
            (&mut self.s, 0.0),
            (&mut self.u, -1.0e7),
            (&mut self.v, 1.0e7),
        ] {
            v.clear();
            v.resize(padded, fill);
        }
    }

    /// The lanes of the antenna at `(x, y)` (relative to the origin) with heading cosine `cos`
    /// and sine `sin`.
    #[inline]
    pub(crate) fn lane(x: f64, y: f64, cos: f32, sin: f32) -> [f32; 4] {
        let inv = 1.0 / TABLE_STEP;
        let (c, s) = (f64::from(cos) * inv, f64::from(sin) * inv);
        #[allow(clippy::cast_possible_truncation)]
        [
            c as f32,
            s as f32,
            (-(c * x + s * y) - TABLE_X0 * inv) as f32,
            (s * x - c * y) as f32,
        ]
    }
}

/// The reader model tabulated for one floor (see the module documentation).
#[derive(Clone)]
pub(crate) struct ReadTable {
    /// The model and floor the table was built for.
    pub(crate) model: ReadModel,
    pub(crate) floor: f64,
    /// Reach of the model (in view: `d ≤ reach` and in front), metres.
    pub(crate) reach: f64,
    /// Row-major `[iy][ix]`: (mean RSS, miss term) in one word ([`pair_bits`]). Shared: maps
    /// learned in rounds reuse it.
    cells: std::sync::Arc<[u64; TABLE_N * TABLE_N]>,
    /// The same, packed in 32 bits per cell for scoring many poses.
    packed: Packed,
    /// Miss term by mean RSS, `MISS_STEP` apart, for the field.
    miss: std::sync::Arc<[f64]>,
}

impl std::fmt::Debug for ReadTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReadTable")
            .field("floor", &self.floor)
            .field("reach", &self.reach)
            .finish_non_exhaustive()
    }
}

/// The miss term of a tag of mean RSS `m` in view.
pub(crate) fn miss_term(model: &ReadModel, floor: f64, m: f64) -> f64 {
    (1.0 - model.read_probability(m))
        .max(1e-300)
        .ln()
        .max(-floor)
}

impl ReadTable {
    /// Tabulates `model` with terms floored at `−floor`.
    #[must_use]
    pub(crate) fn new(model: &ReadModel, floor: f64) -> Self {
        let reach = model.reach();
        let (nx, ny) = (TABLE_N, TABLE_N);
        // Built on the heap (the array is 512 KiB); the conversion cannot fail.
        let mut cells: Box<[[f32; 2]; TABLE_N * TABLE_N]> = vec![[0.0_f32; 2]; TABLE_N * TABLE_N]
            .into_boxed_slice()
            .try_into()
            .unwrap_or_else(|_| Box::new([[0.0_f32; 2]; TABLE_N * TABLE_N]));
        let mut top = 0.0_f64;
        for (iy, row) in cells.chunks_exact_mut(TABLE_N).enumerate() {
            if iy + 1 == ny {
                break;
            }
            #[allow(clippy::cast_precision_loss)]
            let y = iy as f64 * TABLE_STEP;
            for (ix, cell) in row.iter_mut().enumerate() {
                if ix == 0 || ix + 1 == nx {
                    continue;
                }
                #[allow(clippy::cast_precision_loss)]
                let x = TABLE_X0 + ix as f64 * TABLE_STEP;
                let m = model.mean_rss(x, y);
                top = top.max(m);
                let in_view = x >= 0.0 && x.hypot(y) <= reach;
                let v = if in_view {
                    miss_term(model, floor, m).min(IN_VIEW_MARK)
                } else {
                    0.0
                };
                #[allow(clippy::cast_possible_truncation)]
                {
                    *cell = [m as f32, v as f32];
                }
            }
        }
        // On-axis mean RSS is largest at the antenna; tabulate the miss term up to it.
        top = top.max(model.mean_rss(0.0, 0.0));
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (top / MISS_STEP).ceil().clamp(1.0, 1e6) as usize + 2;
        #[allow(clippy::cast_precision_loss)]
        let miss = (0..n)
            .map(|i| miss_term(model, floor, i as f64 * MISS_STEP))
            .collect();
        Self {
            model: model.clone(),
            floor,
            reach,
            packed: Packed::new(&cells[..], floor),
            cells: {
                let mut bits = zeroed::<u64>();
                for (b, &[m, v]) in bits.iter_mut().zip(cells.iter()) {
                    *b = pair_bits(m, v);
                }
                bits.into()
            },
            miss,
        }
    }

    /// Index of the cell nearest to antenna-frame `(x, y)`, clamped to the zero border.
    #[inline]
    #[must_use]
    fn index(x: f32, y: f32) -> u32 {
        #[allow(clippy::cast_possible_truncation)]
        let inv = (1.0 / TABLE_STEP) as f32;
        #[allow(clippy::cast_possible_truncation)]
        let x0 = TABLE_X0 as f32;
        Self::cell((x - x0) * inv, y * inv) & 0xFFFF
    }

    /// Index of the cell nearest to `(fx, fy)` in cell units (`fx` from the first column),
    /// clamped to the zero border, in the low 16 bits (the high bits are not zero). Branch-free
    /// and without float-to-integer conversions (which are branchy on the baseline target): a
    /// value `0 ≤ v < 2²³` added to 2²³ holds `round(v)` in the low mantissa bits, so loops
    /// over many poses vectorise.
    #[inline]
    #[must_use]
    pub(crate) fn cell(fx: f32, fy: f32) -> u32 {
        const TWO_23: f32 = 8_388_608.0;
        #[allow(clippy::cast_precision_loss)]
        let top = (TABLE_N - 1) as f32;
        let fx = if fx > 0.0 { fx } else { 0.0 };
        let fx = if fx < top { fx } else { top };
        let fy = fy.abs();
        let fy = if fy < top { fy } else { top };
        // `iy`'s float bits shifted by 8 keep only `iy << 8` (the exponent leaves the word).
        let ix = (fx + TWO_23).to_bits();
        let iy = (fy + TWO_23).to_bits();
        (iy << 8) | ix
    }

    /// The cells as (mean RSS, miss term) words ([`pair_bits`]).
    pub(crate) fn pairs(&self) -> &[u64; TABLE_N * TABLE_N] {
        &self.cells
    }

    /// The cells packed in 32 bits.
    pub(crate) fn packed(&self) -> &Packed {
        &self.packed
    }

    /// (mean RSS, miss term) at antenna-frame `(x, y)`.
    #[inline]
    #[must_use]
    pub(crate) fn at(&self, x: f64, y: f64) -> (f64, f64) {
        #[allow(clippy::cast_possible_truncation)]
        let i = Self::index(x as f32, y as f32) as usize;
        let [m, v] = pair_of_bits(self.cells.get(i).copied().unwrap_or(0));
        (f64::from(m), f64::from(v))
    }

    /// The miss term of an in-view tag of mean RSS `m` (linear between tabulated values).
    #[inline]
    #[must_use]
    pub(crate) fn miss_of_mean(&self, m: f64) -> f64 {
        let f = (m / MISS_STEP).max(0.0);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let i = f as usize;
        #[allow(clippy::cast_precision_loss)]
        let a = f - i as f64;
        match (self.miss.get(i), self.miss.get(i + 1)) {
            (Some(v0), Some(v1)) => v0 + a * (v1 - v0),
            _ => self.miss.last().copied().unwrap_or(0.0),
        }
    }

    /// True when the table was built for this model and floor.
    #[must_use]
    pub(crate) fn is_for(&self, model: &ReadModel, floor: f64) -> bool {
        self.floor == floor && &self.model == model
    }
}

/// Tag positions bucketed for the field's tile computations.
#[derive(Debug, Clone)]
struct Buckets {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    /// Tag positions per bucket, row-major.
    tags: Vec<Vec<(f64, f64)>>,
}

/// Antenna poses of many robot poses, one vector per quantity (so that loops over them
/// vectorise): position, heading, and the heading's cosine and sine in single precision (as the
/// tables use them).
#[derive(Debug, Clone, Default)]
pub(crate) struct AntennaLanes {
    pub(crate) x: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub(crate) theta: Vec<f64>,
    pub(crate) cos: Vec<f32>,
    pub(crate) sin: Vec<f32>,
}

impl AntennaLanes {
    /// Clears and holds `n` zero poses.
    pub(crate) fn reset(&mut self, n: usize) {
        for v in [&mut self.x, &mut self.y, &mut self.theta] {
            v.clear();
            v.resize(n, 0.0);
        }
        for v in [&mut self.cos, &mut self.sin] {
            v.clear();
            v.resize(n, 0.0);
        }
    }

    /// Number of poses.
    pub(crate) fn len(&self) -> usize {
        self.x.len()
    }
}

/// Scratch of [`MissField::sample_many`]: per pose, its place in the field (tile, or
/// `u32::MAX` outside the field; offset of its lower node in the tile; its two headings; the
/// weights of the upper nodes along x, y and the heading), then the values at the eight
/// surrounding nodes.
#[derive(Debug, Clone, Default)]
pub(crate) struct FieldScratch {
    tile: Vec<u32>,
    node: Vec<u32>,
    k0: Vec<u32>,
    k1: Vec<u32>,
    wx: Vec<f32>,
    wy: Vec<f32>,
    wt: Vec<f32>,
    /// 8 rows of one (sum, count) per pose: at the lower heading at the nodes `(0, 0)`,
    /// `(1, 0)`, `(0, 1)`, `(1, 1)` (x, y), then the same at the upper heading.
    corners: Vec<[f32; 2]>,
}

/// Sum and count of the miss terms of all mapped tags in view, by antenna pose (see the module
/// documentation).
pub(crate) struct MissField {
    table: ReadTable,
    buckets: Buckets,
    /// Position of node (0, 0), metres.
    x0: f64,
    y0: f64,
    /// Tiles along x and y.
    tx: usize,
    ty: usize,
    tiles: Vec<OnceLock<Box<[[f32; 2]]>>>,
    cos: [f64; FIELD_HEADINGS],
    sin: [f64; FIELD_HEADINGS],
}

impl std::fmt::Debug for MissField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MissField")
            .field("tiles", &(self.tx, self.ty))
            .field("computed", &self.computed_tiles())
            .finish_non_exhaustive()
    }
}

impl MissField {
    /// A field over `tags` (positions) under `table`; nothing is computed yet.
    #[must_use]
    pub(crate) fn new(table: ReadTable, tags: &[(f64, f64)]) -> Self {
        let reach = table.reach.max(FIELD_STEP);
        let (mut lo_x, mut lo_y, mut hi_x, mut hi_y) = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for (x, y) in tags.iter().filter(|(x, y)| x.is_finite() && y.is_finite()) {
            lo_x = lo_x.min(*x);
            lo_y = lo_y.min(*y);
            hi_x = hi_x.max(*x);
            hi_y = hi_y.max(*y);
        }
        if lo_x > hi_x {
            (lo_x, lo_y, hi_x, hi_y) = (0.0, 0.0, 0.0, 0.0);
        }
        // Every pose from which a tag can be in view lies within the reach of the tags' box.
        let margin = reach + FIELD_STEP;
        let (x0, y0) = (lo_x - margin, lo_y - margin);
        let span = TILE as f64 * FIELD_STEP;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let tiles_for = |extent: f64| ((extent / span).ceil().clamp(1.0, 1e5)) as usize;
        let tx = tiles_for(hi_x + margin - x0);
        let ty = tiles_for(hi_y + margin - y0);
        // Buckets of one tile's size.
        let mut buckets = Buckets {
            x0,
            y0,
            cell: span,
            nx: tx,
            ny: ty,
            tags: vec![Vec::new(); tx * ty],
        };
        for &(x, y) in tags {
            if let Some(b) = buckets.bucket_of(x, y) {
                if let Some(v) = buckets.tags.get_mut(b) {
                    v.push((x, y));
                }
            }
        }
        let mut cos = [0.0; FIELD_HEADINGS];
        let mut sin = [0.0; FIELD_HEADINGS];
        for (k, (c, s)) in cos.iter_mut().zip(sin.iter_mut()).enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let th = k as f64 * TAU / FIELD_HEADINGS as f64;
            (*s, *c) = th.sin_cos();
        }
        Self {
            table,
            buckets,
            x0,
            y0,
            tx,
            ty,
            tiles: (0..tx * ty).map(|_| OnceLock::new()).collect(),
            cos,
            sin,
        }
    }

    /// The table the field was built with.
    pub(crate) fn table(&self) -> &ReadTable {
        &self.table
    }

    /// Number of tiles computed so far.
    #[must_use]
    pub(crate) fn computed_tiles(&self) -> usize {
        self.tiles.iter().filter(|t| t.get().is_some()).count()
    }

    /// Number of tiles.
    #[must_use]
    pub(crate) fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// Computes every tile now (instead of on first use).
    pub(crate) fn compute_all(&self) {
        for t in 0..self.tiles.len() {
            let _ = self.tile(t);
        }
    }

    fn tile(&self, t: usize) -> Option<&[[f32; 2]]> {
        let cell = self.tiles.get(t)?;
        Some(cell.get_or_init(|| self.compute_tile(t)))
    }

    /// All nodes of tile `t`: `[(ly · TILE_NODES + lx) · FIELD_HEADINGS + k]` = (sum, count).
    fn compute_tile(&self, t: usize) -> Box<[[f32; 2]]> {
        let (tx, ty) = (t % self.tx.max(1), t / self.tx.max(1));
        let span = TILE as f64 * FIELD_STEP;
        #[allow(clippy::cast_precision_loss)]
        let (bx, by) = (self.x0 + tx as f64 * span, self.y0 + ty as f64 * span);
        let reach = self.table.reach;
        // Tags within reach of the tile.
        let mut near: Vec<(f64, f64)> = Vec::new();
        self.buckets.for_each_within(
            (bx - reach, by - reach),
            (bx + span + reach, by + span + reach),
            |p| near.push(p),
        );
        let mut out = vec![[0.0_f32; 2]; TILE_NODES * TILE_NODES * FIELD_HEADINGS];
        let mut acc = [(0.0_f64, 0.0_f64); FIELD_HEADINGS];
        for ly in 0..TILE_NODES {
            for lx in 0..TILE_NODES {
                #[allow(clippy::cast_precision_loss)]
                let (nx, ny) = (bx + lx as f64 * FIELD_STEP, by + ly as f64 * FIELD_STEP);
                acc.iter_mut().for_each(|a| *a = (0.0, 0.0));
                for &(x, y) in &near {
                    let (dx, dy) = (x - nx, y - ny);
                    let d2 = dx * dx + dy * dy;
                    if d2 > reach * reach {
                        continue;
                    }
                    let d = d2.sqrt();
                    let on_axis = self.table.model.mean_rss(d, 0.0);
                    let (cf, sf) = if d > 0.0 {
                        (dx / d, dy / d)
                    } else {
                        (1.0, 0.0)
                    };
                    for ((a, c), s) in acc.iter_mut().zip(&self.cos).zip(&self.sin) {
                        // Cosine of the tag's bearing from the boresight.
                        let cb = cf * c + sf * s;
                        if cb >= 0.0 {
                            a.0 += self.table.miss_of_mean(on_axis * cb);
                            a.1 += 1.0;
                        }
                    }
                }
                let base = (ly * TILE_NODES + lx) * FIELD_HEADINGS;
                if let Some(slots) = out.get_mut(base..base + FIELD_HEADINGS) {
                    for (slot, a) in slots.iter_mut().zip(&acc) {
                        #[allow(clippy::cast_possible_truncation)]
                        {
                            *slot = [a.0 as f32, a.1 as f32];
                        }
                    }
                }
            }
        }
        out.into_boxed_slice()
    }

    /// (sum of miss terms, number of tags in view) at antenna pose `(x, y, θ)`, interpolated:
    /// the reference [`MissField::sample_many`] is tested against.
    #[cfg(test)]
    #[must_use]
    pub(crate) fn sample(&self, x: f64, y: f64, theta: f64) -> (f32, f32) {
        let fx = (x - self.x0) * (1.0 / FIELD_STEP);
        let fy = (y - self.y0) * (1.0 / FIELD_STEP);
        #[allow(clippy::cast_precision_loss)]
        let (lim_x, lim_y) = ((self.tx * TILE) as f64, (self.ty * TILE) as f64);
        if !(fx >= 0.0 && fy >= 0.0 && fx < lim_x && fy < lim_y && theta.abs() < 1e9) {
            return (0.0, 0.0);
        }
        // Lower lattice node and weight along each axis (headings wrap).
        let (gx, ax) = lower_node(fx);
        let (gy, ay) = lower_node(fy);
        #[allow(clippy::cast_precision_loss)]
        let (k0, at) = lower_node(theta * (FIELD_HEADINGS as f64 / TAU));
        let (k0, k1) = (k0 % FIELD_HEADINGS, (k0 + 1) % FIELD_HEADINGS);
        let (tx, lx, ty, ly) = (gx / TILE, gx % TILE, gy / TILE, gy % TILE);
        let Some(tile) = self.tile(ty * self.tx + tx) else {
            return (0.0, 0.0);
        };
        let n00 = (ly * TILE_NODES + lx) * FIELD_HEADINGS;
        let (n10, n01) = (n00 + FIELD_HEADINGS, n00 + TILE_NODES * FIELD_HEADINGS);
        let n11 = n01 + FIELD_HEADINGS;
        let Some(last) = tile.get(n11 + FIELD_HEADINGS - 1) else {
            return (0.0, 0.0);
        };
        let _ = last;
        let get = |i: usize| tile.get(i).copied().unwrap_or([0.0, 0.0]);
        let lerp =
            |a: [f32; 2], b: [f32; 2], t: f32| [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
        let corner = |n: usize| lerp(get(n + k0), get(n + k1), at);
        let v = lerp(
            lerp(corner(n00), corner(n10), ax),
            lerp(corner(n01), corner(n11), ax),
            ay,
        );
        (v[0], v[1])
    }

    /// [`MissField::sample`] at many antenna poses, written to `sums` and `counts` (as long as
    /// the poses), with the same bits: the lattice nodes and weights of every pose first (a
    /// loop that vectorises), then the nodes' values (scalar look-ups), then the
    /// interpolations (a loop that vectorises).
    pub(crate) fn sample_many(
        &self,
        poses: &AntennaLanes,
        scratch: &mut FieldScratch,
        sums: &mut [f32],
        counts: &mut [f32],
    ) {
        let n = poses.len();
        let FieldScratch {
            tile,
            node,
            k0,
            k1,
            wx,
            wy,
            wt,
            corners,
        } = scratch;
        // Every value is written below: only new length is filled.
        for v in [&mut *tile, &mut *node, &mut *k0, &mut *k1] {
            v.resize(n, 0);
        }
        for v in [&mut *wx, &mut *wy, &mut *wt] {
            v.resize(n, 0.0);
        }
        // Every value is written below.
        corners.resize(8 * n, [0.0; 2]);
        #[allow(clippy::cast_precision_loss)]
        let (lim_x, lim_y) = ((self.tx * TILE) as f64, (self.ty * TILE) as f64);
        let (x0, y0) = (self.x0, self.y0);
        // Tiles per row fit in 32 bits (at most 10⁵, see `new`).
        #[allow(clippy::cast_possible_truncation)]
        let tiles_x = self.tx as u32;
        crate::simd::widest(
            #[inline(always)]
            || {
                let (px, py, pt) = (&poses.x[..n], &poses.y[..n], &poses.theta[..n]);
                let (tile, node, k0, k1) =
                    (&mut tile[..n], &mut node[..n], &mut k0[..n], &mut k1[..n]);
                let (wx, wy, wt) = (&mut wx[..n], &mut wy[..n], &mut wt[..n]);
                for i in 0..n {
                    let (x, y, theta) = (px[i], py[i], pt[i]);
                    let fx = (x - x0) * (1.0 / FIELD_STEP);
                    let fy = (y - y0) * (1.0 / FIELD_STEP);
                    let inside = fx >= 0.0 && fy >= 0.0 && fx < lim_x && fy < lim_y;
                    let inside = inside && theta.abs() < 1e9;
                    let (gx, ax) = lower_node_bits(fx);
                    let (gy, ay) = lower_node_bits(fy);
                    #[allow(clippy::cast_precision_loss)]
                    let (gk, at) = lower_node_bits(theta * (FIELD_HEADINGS as f64 / TAU));
                    // In 32 bits (vector multiplies of 64-bit integers are slow): inside the
                    // field the nodes are far below 2³², and 2³² is a multiple of the
                    // headings; outside, the tile is replaced.
                    #[allow(clippy::cast_possible_truncation)]
                    let (gx, gy, gk) = (gx as u32, gy as u32, gk as u32);
                    let t = (gy / TILE as u32)
                        .wrapping_mul(tiles_x)
                        .wrapping_add(gx / TILE as u32);
                    let (lx, ly) = (gx % TILE as u32, gy % TILE as u32);
                    tile[i] = if inside { t } else { u32::MAX };
                    node[i] = (ly * TILE_NODES as u32 + lx) * FIELD_HEADINGS as u32;
                    k0[i] = gk % FIELD_HEADINGS as u32;
                    k1[i] = gk.wrapping_add(1) % FIELD_HEADINGS as u32;
                    (wx[i], wy[i], wt[i]) = (ax, ay, at);
                }
            },
        );
        // Poses of a cloud fall in few tiles: keep the last one at hand.
        let mut last: Option<(u32, &[[f32; 2]])> = None;
        let mut rows = corners.chunks_exact_mut(n.max(1));
        let mut rows: [&mut [[f32; 2]]; 8] =
            std::array::from_fn(|_| rows.next().unwrap_or(&mut []));
        for row in &mut rows {
            *row = &mut std::mem::take(row)[..n];
        }
        for i in 0..n {
            let (t, n00) = (tile[i], node[i] as usize);
            let here = match last {
                Some((lt, slice)) if lt == t => Some(slice),
                _ if t == u32::MAX => None,
                _ => self
                    .tile(t as usize)
                    .inspect(|slice| last = Some((t, slice))),
            };
            // The nodes from (0, 0) to (1, 1), all headings (fixed size: no bounds checks).
            let span = here
                .and_then(|slice| slice.get(n00..n00 + CORNER_SPAN))
                .and_then(|nodes| <&[[f32; 2]; CORNER_SPAN]>::try_from(nodes).ok());
            let (ka, kb) = (
                k0[i] as usize % FIELD_HEADINGS,
                k1[i] as usize % FIELD_HEADINGS,
            );
            match span {
                Some(nodes) => {
                    let near = [0, 1, TILE_NODES, TILE_NODES + 1].map(|c| c * FIELD_HEADINGS);
                    for (j, c) in near.into_iter().enumerate() {
                        rows[j][i] = nodes[c + ka];
                        rows[4 + j][i] = nodes[c + kb];
                    }
                }
                // Outside the field: zeros.
                None => {
                    for row in &mut rows {
                        row[i] = [0.0; 2];
                    }
                    (wx[i], wy[i], wt[i]) = (0.0, 0.0, 0.0);
                }
            }
        }
        crate::simd::widest(
            #[inline(always)]
            || {
                let mut rows = corners.chunks_exact(n.max(1));
                let mut c: [&[[f32; 2]]; 8] = [&[]; 8];
                for row in &mut c {
                    *row = rows.next().map_or(&[], |r| &r[..n]);
                }
                let (wx, wy, wt) = (&wx[..n], &wy[..n], &wt[..n]);
                let (sums, counts) = (&mut sums[..n], &mut counts[..n]);
                let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
                for i in 0..n {
                    let (ax, ay, at) = (wx[i], wy[i], wt[i]);
                    // Along the heading at the four corners, then along x, then along y.
                    // (No `array::from_fn` here: it is not always inlined.)
                    let h = |j: usize, q: usize| lerp(c[j][i][q], c[j + 4][i][q], at);
                    let (s0, c0) = (lerp(h(0, 0), h(1, 0), ax), lerp(h(0, 1), h(1, 1), ax));
                    let (s1, c1) = (lerp(h(2, 0), h(3, 0), ax), lerp(h(2, 1), h(3, 1), ax));
                    (sums[i], counts[i]) = (lerp(s0, s1, ay), lerp(c0, c1, ay));
                }
            },
        );
    }

    /// Exact (uninterpolated) sum and count at an antenna pose, by direct summation (tests).
    #[cfg(test)]
    #[must_use]
    pub(crate) fn exact(&self, antenna: &rfloc_pose::Pose2) -> (f64, f64) {
        let reach = self.table.reach;
        let (mut sum, mut count) = (0.0, 0.0);
        self.buckets.for_each_within(
            (antenna.x - reach, antenna.y - reach),
            (antenna.x + reach, antenna.y + reach),
            |(x, y)| {
                let (s, c) = antenna.theta.sin_cos();
                let (dx, dy) = (x - antenna.x, y - antenna.y);
                let ax = c * dx + s * dy;
                if ax >= 0.0 && dx.hypot(dy) <= reach {
                    sum += miss_term(
                        &self.table.model,
                        self.table.floor,
                        self.table.model.mean_rss(ax, -s * dx + c * dy),
                    );
                    count += 1.0;
                }
            },
        );
        (sum, count)
    }
}

impl Buckets {
    fn bucket_of(&self, x: f64, y: f64) -> Option<usize> {
        let fx = ((x - self.x0) / self.cell).floor();
        let fy = ((y - self.y0) / self.cell).floor();
        #[allow(clippy::cast_precision_loss)]
        let ok = fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        ok.then(|| fy as usize * self.nx + fx as usize)
    }

    /// Calls `f` with every tag whose bucket overlaps the box `lo`–`hi`.
    fn for_each_within(&self, lo: (f64, f64), hi: (f64, f64), mut f: impl FnMut((f64, f64))) {
        #[allow(clippy::cast_precision_loss)]
        let clamp_x = |v: f64| {
            ((v - self.x0) / self.cell)
                .floor()
                .clamp(0.0, self.nx as f64 - 1.0)
        };
        #[allow(clippy::cast_precision_loss)]
        let clamp_y = |v: f64| {
            ((v - self.y0) / self.cell)
                .floor()
                .clamp(0.0, self.ny as f64 - 1.0)
        };
        if self.nx == 0 || self.ny == 0 {
            return;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (x_lo, x_hi, y_lo, y_hi) = (
            clamp_x(lo.0) as usize,
            clamp_x(hi.0) as usize,
            clamp_y(lo.1) as usize,
            clamp_y(hi.1) as usize,
        );
        for by in y_lo..=y_hi {
            for bx in x_lo..=x_hi {
                if let Some(v) = self.tags.get(by * self.nx + bx) {
                    v.iter().copied().for_each(&mut f);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sincos_matches_the_library() {
        let mut worst = 0.0_f64;
        for i in -2000..=2000 {
            let th = f64::from(i) * 0.0137;
            let (s, c) = sincos_f32(th);
            worst = worst
                .max((f64::from(s) - th.sin()).abs())
                .max((f64::from(c) - th.cos()).abs());
        }
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn table_agrees_with_the_model() {
        let model = ReadModel::seed000(1000.0, 2);
        let t = ReadTable::new(&model, 6.0);
        let reach = model.reach();
        for &(x, y) in &[
            (0.3, 0.1),
            (1.0, -0.5),
            (0.05, 0.0),
            (1.5, 0.4),
            (0.7, -0.9),
        ] {
            let (m, v) = t.at(x, y);
            let exact = model.mean_rss(x, y);
            // Nearest 1 cm cell: the mean RSS is within the model's change over half a cell.
            let grad = (model.mean_rss(x + 0.005, y) - exact)
                .abs()
                .max((model.mean_rss(x, y + 0.005) - exact).abs());
            assert!(
                (m - exact).abs() <= 2.0 * grad + 1.0,
                "{x} {y}: {m} vs {exact}"
            );
            if x.hypot(y) < reach - 0.02 {
                assert!(v < 0.0);
            }
        }
        // Behind the antenna, beyond the reach and off the table: out of view.
        assert_eq!(t.at(-0.5, 0.0).1, 0.0);
        assert_eq!(t.at(0.0, 2.0).1, 0.0);
        assert_eq!(t.at(9.0, 0.0), (0.0, 0.0));
        assert_eq!(t.at(0.3, -9.0), (0.0, 0.0));
        assert!((t.miss_of_mean(3000.0) - miss_term(&model, 6.0, 3000.0)).abs() < 1e-6);
    }

    /// The interpolated field against direct summation at random antenna poses: it is a
    /// smoothed version (each tag's miss term drops from 0 to the floor within a few
    /// centimetres at the edge of the view), close on average and never far off.
    #[test]
    fn field_interpolates_the_exact_sum() {
        use rand::{Rng, SeedableRng};
        let model = ReadModel::seed000(1000.0, 2);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let tags: Vec<(f64, f64)> = (0..800)
            .map(|_| (5.0 * rng.random::<f64>(), 5.0 * rng.random::<f64>()))
            .collect();
        let field = MissField::new(ReadTable::new(&model, 6.0), &tags);
        let (mut err, mut scale, mut worst) = (0.0, 0.0, 0.0_f64);
        let n = 400;
        for _ in 0..n {
            let a = rfloc_pose::Pose2::new(
                5.0 * rng.random::<f64>(),
                5.0 * rng.random::<f64>(),
                20.0 * rng.random::<f64>() - 10.0,
            );
            let (sum, count) = field.sample(a.x, a.y, a.theta);
            let (exact_sum, exact_count) = field.exact(&a);
            err += (f64::from(sum) - exact_sum).abs();
            scale += exact_sum.abs();
            worst = worst.max((f64::from(count) - exact_count).abs());
        }
        assert!(err / scale < 0.03, "relative error {}", err / scale);
        assert!(worst < 8.0, "count off by {worst}");
        // Outside the tags' box (beyond the reach) nothing is in view.
        assert_eq!(field.sample(-5.0, -5.0, 0.0), (0.0, 0.0));
        assert!(field.computed_tiles() < field.tile_count());
        field.compute_all();
        assert_eq!(field.computed_tiles(), field.tile_count());
    }

    /// `sample_many` (three passes, in whatever instructions this CPU has) against `sample`
    /// one pose at a time in the baseline instructions: the same bits, for poses inside and
    /// outside the field, at every heading (also far outside one turn) and on lattice nodes.
    #[test]
    fn sample_many_equals_sample_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let model = ReadModel::seed000(1000.0, 2);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let tags: Vec<(f64, f64)> = (0..300)
            .map(|_| (4.0 * rng.random::<f64>(), 3.0 * rng.random::<f64>()))
            .collect();
        let field = MissField::new(ReadTable::new(&model, 6.0), &tags);
        let mut poses = AntennaLanes::default();
        let n = 1003;
        poses.reset(n);
        for i in 0..n {
            let (x, y, theta) = match i % 7 {
                // Outside, and not finite.
                0 => (-9.0 + 30.0 * rng.random::<f64>(), 9.0, 0.3),
                1 => (f64::NAN, 1.0, 0.0),
                2 => (1.0, 1.0, f64::INFINITY),
                // On lattice nodes.
                3 => (
                    FIELD_STEP * f64::from(rng.random_range(0..60_u8)) + field.x0,
                    FIELD_STEP * f64::from(rng.random_range(0..40_u8)) + field.y0,
                    TAU / 64.0 * f64::from(rng.random_range(0..64_u8)),
                ),
                _ => (
                    -3.0 + 10.0 * rng.random::<f64>(),
                    -3.0 + 9.0 * rng.random::<f64>(),
                    100.0 * rng.random::<f64>() - 50.0,
                ),
            };
            (poses.x[i], poses.y[i], poses.theta[i]) = (x, y, theta);
        }
        let (mut sums, mut counts) = (vec![f32::NAN; n], vec![f32::NAN; n]);
        let mut scratch = FieldScratch::default();
        // Twice: the scratch is reused.
        for _ in 0..2 {
            field.sample_many(&poses, &mut scratch, &mut sums, &mut counts);
            for i in 0..n {
                let expected = crate::simd::on_baseline(|| {
                    field.sample(poses.x[i], poses.y[i], poses.theta[i])
                });
                assert_eq!(
                    (sums[i].to_bits(), counts[i].to_bits()),
                    (expected.0.to_bits(), expected.1.to_bits()),
                    "pose {i}"
                );
            }
        }
        let scored = sums.iter().filter(|s| **s < 0.0).count();
        assert!(scored > n / 10, "{scored} poses see tags");
    }

    #[test]
    fn quadrants_without_branches() {
        let (s, c) = (0.25_f64, -0.75_f64);
        for q in -9_i64..=9 {
            let want = match q.rem_euclid(4) {
                0 => (s, c),
                1 => (c, -s),
                2 => (-s, -c),
                _ => (-c, s),
            };
            #[allow(clippy::cast_precision_loss)]
            let got = to_quadrant(q as f64, s, c);
            assert_eq!(got, want, "{q}");
            #[allow(clippy::cast_precision_loss, clippy::cast_possible_truncation)]
            let got32 = to_quadrant(q as f64, s as f32, c as f32);
            #[allow(clippy::cast_possible_truncation)]
            let want32 = (want.0 as f32, want.1 as f32);
            assert_eq!(got32, want32, "{q}");
        }
    }

    #[test]
    fn lower_node_and_rounding() {
        assert_eq!(lower_node(3.25), (3, 0.25));
        assert_eq!(lower_node(0.0).1, 0.0_f32.max(lower_node(0.0).1));
        let (k, w) = lower_node(-0.25);
        assert_eq!(k % 64, 63);
        assert!((w - 0.75).abs() < 1e-6);
        for x in [-3.7, -0.5, 0.0, 0.49, 2.5, 1e6 + 0.3] {
            assert_eq!(round_f64(x), x.round_ties_even(), "{x}");
            assert_eq!(floor_f64(x), x.floor(), "{x}");
        }
    }
}
