//! Products into a destination, dst (+)= α a op(b), on the whole of dst or its lower
//! triangle: nalgebra's fixed-size operators on small static sizes, one runtime-size
//! [`product`] (loops for small ones; faer, or [`Matvec`](crate::dense::Matvec) for one column,
//! for larger ones) otherwise.

use nalgebra::{DefaultAllocator, Dim, OMatrix, allocator::Allocator};

#[cfg(feature = "dense")]
use super::dense_route;
use super::{fixed_route, is_static, loops};
use crate::dense::{Accum, Operand, Part};
#[cfg(feature = "dense")]
use crate::dense::{view, view_mut};
use crate::scalar::Real;

/// The form of a runtime-size product dst (+)= α a op(b): whether b enters transposed, and
/// which part of dst is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Form {
    /// b or bᵀ.
    b: Operand,
    /// All of dst, or its lower triangle.
    part: Part,
}

impl Form {
    /// dst (+)= α a b.
    const PLAIN: Self = Self {
        b: Operand::AsIs,
        part: Part::Whole,
    };
    /// dst (+)= α a bᵀ.
    const B_TRANSPOSED: Self = Self {
        b: Operand::Transposed,
        part: Part::Whole,
    };
    /// The lower triangle of dst (+)= α a b.
    const LOWER: Self = Self {
        b: Operand::AsIs,
        part: Part::Lower,
    };
    /// The lower triangle of dst (+)= α a bᵀ.
    const LOWER_B_TRANSPOSED: Self = Self {
        b: Operand::Transposed,
        part: Part::Lower,
    };
}

/// dst (+)= α a op(b) on runtime sizes, b transposed and only the lower triangle of dst
/// written as `form` says: the loops ([`loops::product`], the whole of dst) up to
/// [`SMALL_RUNTIME_WORK`](super::SMALL_RUNTIME_WORK) multiply–adds or without the `dense`
/// feature, faer above (one-column products of the [`Form::PLAIN`] form:
/// [`Matvec`](crate::dense::Matvec)). The one product behind [`mul`], [`mul_tr`], [`mul_lower`]
/// and [`mul_tr_lower`] on the runtime route.
#[cfg_attr(not(debug_assertions), inline(always))]
#[track_caller]
fn product<T: Real, R: Dim, C: Dim, RA: Dim, CA: Dim, RB: Dim, CB: Dim>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    b: &OMatrix<T, RB, CB>,
    form: Form,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RB, CB>,
{
    let (rows, cols) = dst.shape();
    let inner = a.ncols();
    let b_shape = match form.b {
        Operand::AsIs => (inner, cols),
        Operand::Transposed => (cols, inner),
    };
    // The message's arguments are formatted only on failure (built before the assertion,
    // they cost ~90 instructions a `Dyn` KF step at n = 4).
    assert!(
        a.nrows() == rows && b.shape() == b_shape,
        "{}: {:?} ← {:?} × {:?}{}",
        if cols == 1 {
            "matrix × vector"
        } else {
            "matrix product"
        },
        dst.shape(),
        a.shape(),
        b.shape(),
        if form.b == Operand::Transposed {
            "ᵀ"
        } else {
            ""
        }
    );
    #[cfg(feature = "dense")]
    if dense_route(rows.saturating_mul(inner).saturating_mul(cols)) {
        if cols == 1 && form == Form::PLAIN {
            return T::matvec(dst.as_mut_slice(), accum, alpha, a.as_slice(), b.as_slice());
        }
        let b = match form.b {
            Operand::AsIs => view(b),
            Operand::Transposed => view(b).transpose(),
        };
        return T::matmul(view_mut(dst), accum, alpha, view(a), b, form.part);
    }
    let (dst, a, b) = (dst.as_mut_slice(), a.as_slice(), b.as_slice());
    loops::product(dst, (rows, cols), accum, alpha, a, inner, b, form.b);
}

/// Writes or adds α · `value` into `dst` (static sizes), skipping the scaling when α = 1.
#[cfg_attr(not(debug_assertions), inline(always))]
fn store<T: Real, R: Dim, C: Dim>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    value: OMatrix<T, R, C>,
) where
    DefaultAllocator: Allocator<R, C>,
{
    let value = if alpha == T::one() {
        value
    } else {
        value * alpha
    };
    match accum {
        Accum::Replace => *dst = value,
        Accum::Add => *dst += value,
    }
}

/// dst (+)= α a b.
#[cfg_attr(not(debug_assertions), inline(always))]
#[track_caller]
pub fn mul<T: Real, R: Dim, K: Dim, C: Dim>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, R, K>,
    b: &OMatrix<T, K, C>,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<R, K> + Allocator<K, C>,
{
    let fixed = is_static::<R>() && is_static::<K>() && is_static::<C>();
    if fixed_route(fixed, a.nrows().max(a.ncols()).max(b.ncols())) {
        store(dst, accum, alpha, a * b);
    } else {
        product(dst, accum, alpha, a, b, Form::PLAIN);
    }
}

/// dst (+)= α a bᵀ.
#[cfg_attr(not(debug_assertions), inline(always))]
#[track_caller]
pub fn mul_tr<T: Real, R: Dim, K: Dim, C: Dim>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, R, K>,
    b: &OMatrix<T, C, K>,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<R, K> + Allocator<C, K> + Allocator<K, C>,
{
    let fixed = is_static::<R>() && is_static::<K>() && is_static::<C>();
    if fixed_route(fixed, a.nrows().max(a.ncols()).max(b.nrows())) {
        // The operator form: for small static sizes it unrolls, where nalgebra's generic
        // `gemm` loops column by column (measured: the filters bench).
        store(dst, accum, alpha, a * b.transpose());
    } else {
        product(dst, accum, alpha, a, b, Form::B_TRANSPOSED);
    }
}

/// The lower triangle (diagonal included) of dst (+)= α a b, for a product known to be
/// symmetric (such as J (C Jᵀ)): on runtime sizes only that triangle is computed, about half
/// the work. The strict upper triangle of `dst` is unspecified afterwards (static sizes compute
/// the whole product, which is cheaper than selecting a triangle there); mirror the lower
/// triangle ([`crate::linalg::mirror_lower_checked`]) before using it.
#[cfg_attr(not(debug_assertions), inline(always))]
#[track_caller]
pub fn mul_lower<T: Real, D: Dim, K: Dim>(
    dst: &mut OMatrix<T, D, D>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, D, K>,
    b: &OMatrix<T, K, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<D, K> + Allocator<K, D>,
{
    let fixed = is_static::<D>() && is_static::<K>();
    if fixed_route(fixed, a.nrows().max(a.ncols())) {
        store(dst, accum, alpha, a * b);
    } else {
        product(dst, accum, alpha, a, b, Form::LOWER);
    }
}

/// The lower triangle of dst (+)= α a bᵀ (see [`mul_lower`]; e.g. w D Dᵀ or (K S) Kᵀ).
#[cfg_attr(not(debug_assertions), inline(always))]
#[track_caller]
pub fn mul_tr_lower<T: Real, D: Dim, K: Dim>(
    dst: &mut OMatrix<T, D, D>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, D, K>,
    b: &OMatrix<T, D, K>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<D, K> + Allocator<K, D>,
{
    let fixed = is_static::<D>() && is_static::<K>();
    if fixed_route(fixed, a.nrows().max(a.ncols())) {
        store(dst, accum, alpha, a * b.transpose());
    } else {
        product(dst, accum, alpha, a, b, Form::LOWER_B_TRANSPOSED);
    }
}
