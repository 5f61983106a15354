//! Hot loops compiled three times, for the baseline instruction set, for AVX2 (x86-64-v3) and
//! for AVX-512 (x86-64-v4), and run in the widest the CPU has (chosen at run time; `pulp` holds
//! the one `unsafe` call this needs).
//!
//! Only plain floating-point code runs this way: Rust never fuses a multiply and an add on its
//! own, and the operations and their order are the same in every variant, so every variant
//! gives the same bits (`add_reads_equals_a_plain_loop_bit_for_bit` and
//! `widest_instructions_give_the_same_bits_as_the_baseline` compare them).

/// Runs `f` with the widest vector instructions this CPU has. `f` should be a loop over many
/// items that the compiler vectorises, marked `#[inline(always)]` (a closure that is not
/// inlined into the variant is compiled for the baseline only), and what it calls `#[inline]`.
/// Plain `for` loops over slices: `collect`, `extend` and `array::from_fn` call functions the
/// compiler may leave out of line, which then run in the baseline instructions.
#[inline]
pub(crate) fn widest<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(test)]
    if BASELINE.with(std::cell::Cell::get) {
        return f();
    }
    pulp::Arch::new().dispatch(Run(f))
}

/// True when [`widest`] runs in AVX-512, for which the compiler turns table look-ups at
/// computed indices inside a vectorised loop into vector gathers. With AVX2 it does not (it
/// would run such a loop one element at a time), so loops with look-ups keep them in a scalar
/// pass of their own there.
#[inline]
pub(crate) fn gathers_vectorise() -> bool {
    #[cfg(test)]
    if BASELINE.with(std::cell::Cell::get) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        matches!(pulp::Arch::new(), pulp::Arch::V4(_))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
thread_local! {
    /// Set by [`on_baseline`]: `widest` runs its loops as compiled for the baseline.
    static BASELINE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with every [`widest`] loop (on this thread) in the baseline instructions (tests
/// compare the two).
#[cfg(test)]
pub(crate) fn on_baseline<R>(f: impl FnOnce() -> R) -> R {
    BASELINE.with(|b| b.set(true));
    let out = f();
    BASELINE.with(|b| b.set(false));
    out
}

struct Run<F>(F);

impl<R, F: FnOnce() -> R> pulp::WithSimd for Run<F> {
    type Output = R;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> R {
        (self.0)()
    }
}

/// Interleaved partial sums of [`lane_sums`].
const SUM_LANES: usize = 8;

/// The partial sums of one quantity added pairwise, in the one fixed order every variant uses.
#[inline]
fn add_partials(p: &[f64; SUM_LANES]) -> f64 {
    ((p[0] + p[1]) + (p[2] + p[3])) + ((p[4] + p[5]) + (p[6] + p[7]))
}

/// The `K` sums over the items of `a` and `b` (zipped) of `f(a_i, b_i)`, each kept as 8
/// interleaved partial sums (item `i` goes to partial `i mod 8`) that are added pairwise at the
/// end: independent additions that vectorise, instead of one chain of dependent ones whose
/// latency bounds the loop. The order is fixed, so every instruction set gives the same bits
/// (not those of a plain left-to-right sum).
#[inline]
pub(crate) fn lane_sums<A, B, const K: usize>(
    a: &[A],
    b: &[B],
    f: impl Fn(&A, &B) -> [f64; K],
) -> [f64; K] {
    let acc = widest(
        #[inline(always)]
        || {
            let mut acc = [[0.0_f64; SUM_LANES]; K];
            let n = a.len().min(b.len());
            let (a, b) = (
                a[..n].chunks_exact(SUM_LANES),
                b[..n].chunks_exact(SUM_LANES),
            );
            let (ra, rb) = (a.remainder(), b.remainder());
            for (xa, xb) in a.zip(b) {
                for lane in 0..SUM_LANES {
                    for (sum, v) in acc.iter_mut().zip(f(&xa[lane], &xb[lane])) {
                        sum[lane] += v;
                    }
                }
            }
            for (lane, (xa, xb)) in ra.iter().zip(rb).enumerate() {
                for (sum, v) in acc.iter_mut().zip(f(xa, xb)) {
                    sum[lane] += v;
                }
            }
            acc
        },
    );
    acc.map(|p| add_partials(&p))
}

/// [`lane_sums`] over `C` columns of equal length (structure of arrays: the loads are plain
/// vector loads, where the fields of an array of structures need shuffles the compiler may not
/// vectorise): the `K` sums over the rows `i` of `f([col₀[i], col₁[i], …])`, item `i` in
/// partial `i mod 8` and the partials added in the same order, so the same bits as
/// [`lane_sums`] over the rows. The shortest column decides the length.
#[inline]
pub(crate) fn lane_sums_columns<const C: usize, const K: usize>(
    columns: [&[f64]; C],
    f: impl Fn([f64; C]) -> [f64; K],
) -> [f64; K] {
    let acc = widest(
        #[inline(always)]
        || {
            let mut acc = [[0.0_f64; SUM_LANES]; K];
            let n = columns.iter().map(|c| c.len()).min().unwrap_or(0);
            let cols = columns.map(|c| &c[..n]);
            let whole = n - n % SUM_LANES;
            let mut start = 0;
            while start < whole {
                let chunk = cols.map(|c| &c[start..start + SUM_LANES]);
                for lane in 0..SUM_LANES {
                    let row = chunk.map(|c| c[lane]);
                    for (sum, v) in acc.iter_mut().zip(f(row)) {
                        sum[lane] += v;
                    }
                }
                start += SUM_LANES;
            }
            for (lane, i) in (whole..n).enumerate() {
                let row = cols.map(|c| c[i]);
                for (sum, v) in acc.iter_mut().zip(f(row)) {
                    sum[lane] += v;
                }
            }
            acc
        },
    );
    acc.map(|p| add_partials(&p))
}

/// The largest `f(x)` over `items` (`f64::max`: NaN values are ignored; −∞ when there are
/// none), in 8 interleaved partial maxima: the same value as a plain fold, as the maximum does
/// not depend on the order.
#[inline]
pub(crate) fn lane_max<T>(items: &[T], f: impl Fn(&T) -> f64) -> f64 {
    let acc = widest(
        #[inline(always)]
        || {
            let mut acc = [f64::NEG_INFINITY; SUM_LANES];
            let chunks = items.chunks_exact(SUM_LANES);
            let rest = chunks.remainder();
            for chunk in chunks {
                for (m, x) in acc.iter_mut().zip(chunk) {
                    *m = m.max(f(x));
                }
            }
            for (m, x) in acc.iter_mut().zip(rest) {
                *m = m.max(f(x));
            }
            acc
        },
    );
    acc.into_iter().fold(f64::NEG_INFINITY, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums: exact on whole numbers, close to a plain sum otherwise, the same bits with the
    /// baseline instructions, for every length modulo the lanes.
    #[test]
    fn lane_sums_add_every_item_once() {
        for n in 0..40_usize {
            #[allow(clippy::cast_precision_loss)]
            let a: Vec<f64> = (0..n).map(|i| i as f64).collect();
            let b: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64).sin()).collect();
            let [whole, mixed] = lane_sums(&a, &b, |&x, &y| [x, x * y]);
            #[allow(clippy::cast_precision_loss)]
            let expected = (n * n.saturating_sub(1) / 2) as f64;
            assert_eq!(whole, expected, "{n}");
            let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert!((mixed - plain).abs() <= 1e-12 * plain.abs().max(1.0), "{n}");
            let base = on_baseline(|| lane_sums(&a, &b, |&x, &y| [x, x * y]));
            assert_eq!(base.map(f64::to_bits), [whole, mixed].map(f64::to_bits));
        }
        // The shorter slice decides.
        assert_eq!(lane_sums(&[1.0, 2.0, 3.0], &[(); 2], |&x, ()| [x]), [3.0]);
    }

    /// The maximum equals a plain fold: NaN ignored, −∞ when empty.
    #[test]
    fn lane_max_is_the_maximum() {
        assert_eq!(lane_max(&[] as &[f64], |&x| x), f64::NEG_INFINITY);
        for n in 1..30_usize {
            #[allow(clippy::cast_precision_loss)]
            let v: Vec<f64> = (0..n)
                .map(|i| {
                    if i % 5 == 3 {
                        f64::NAN
                    } else {
                        ((i * 37) % 11) as f64 - 20.0
                    }
                })
                .collect();
            let plain = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(lane_max(&v, |&x| x).to_bits(), plain.to_bits(), "{n}");
        }
    }
}
