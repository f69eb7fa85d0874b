//! [`vectorized!`]: a loop body compiled for the CPU's widest vector instructions, chosen at
//! run time (pulp's dispatch).
//!
//! `pulp::Arch::dispatch(|| body)` alone does not do this reliably: it calls the closure from
//! a function compiled with AVX2 / AVX-512 enabled, but the closure's body is a function of
//! its own, compiled for the baseline x86-64 (SSE2), and it only gains the wider instructions
//! if LLVM inlines it there. For the fused ops' row passes it did not: a profile of the
//! `quick` training step found the group-norm, instance-norm and activation loops running as
//! 4-lane SSE code inside `FnOnce::call_once`. The macro writes the body into an
//! `#[inline(always)] WithSimd::with_simd` instead, which pulp's entry inlines, so the loops
//! are compiled with the entry's instruction set.

/// Runs `body` with the CPU's best vector instruction set (see the module docs).
///
/// ```text
/// let (s1, s2) = vectorized!(arch, <'a> (row: &'a [f32] = row) -> (f64, f64) {
///     sums(row, row)
/// });
/// ```
///
/// The body sees only the named arguments (each `name: type = value`, types may use the
/// lifetime `'a`) and items in scope, not the caller's locals. Written `<'a> |simd| (...)`,
/// it also sees the instruction set as `simd` (a `pulp::Simd`), for kernels written with
/// pulp's vector types.
macro_rules! vectorized {
    ($arch:expr, <$l:lifetime> ($($arg:ident : $ty:ty = $val:expr),* $(,)?) -> $out:ty $body:block) => {
        $crate::fused::vectorized::vectorized!(
            $arch, <$l> |_simd| ($($arg : $ty = $val),*) -> $out $body
        )
    };
    ($arch:expr, <$l:lifetime> |$simd:ident| ($($arg:ident : $ty:ty = $val:expr),* $(,)?) -> $out:ty $body:block) => {{
        struct Kernel<$l> {
            $($arg: $ty,)*
            _borrows: ::std::marker::PhantomData<&$l ()>,
        }
        impl<$l> ::pulp::WithSimd for Kernel<$l> {
            type Output = $out;
            #[inline(always)]
            fn with_simd<S: ::pulp::Simd>(self, $simd: S) -> $out {
                let Kernel { $($arg,)* .. } = self;
                $body
            }
        }
        $arch.dispatch(Kernel {
            $($arg: $val,)*
            _borrows: ::std::marker::PhantomData,
        })
    }};
}

pub(crate) use vectorized;
