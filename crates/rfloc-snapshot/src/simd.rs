//! Hot loops compiled twice, for the baseline instruction set and for AVX2, and run in the
//! widest the CPU has (chosen at run time; `pulp` holds the one `unsafe` call this needs).
//!
//! Only plain floating-point code runs this way: Rust never fuses a multiply and an add on its
//! own, and the operations and their order are the same in every variant, so every variant
//! gives the same bits (`readtable`'s tests compare the two).

/// Runs `f` with the widest vector instructions this CPU has. `f` should be a loop over many
/// items that the compiler vectorises, marked `#[inline(always)]` (a closure that is not
/// inlined into the variant is compiled for the baseline only), and what it calls `#[inline]`.
#[inline]
pub(crate) fn widest<R>(f: impl FnOnce() -> R) -> R {
    pulp::Arch::new().dispatch(Run(f))
}

struct Run<F>(F);

impl<R, F: FnOnce() -> R> pulp::WithSimd for Run<F> {
    type Output = R;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> R {
        (self.0)()
    }
}
