//! One bound that stands for all the nalgebra allocator bounds estim needs.
//!
//! nalgebra code that is generic over dimensions must say, for every matrix shape it creates,
//! that `DefaultAllocator` can allocate it. Instead of eight bounds on every signature, estim
//! asks for one: `DefaultAllocator: Alloc<N, M>`. Supertraits are implied at use sites, so
//! inside a function bounded this way every shape below is available.
//!
//! It holds for every pair of static (`Const<R>`) and runtime (`Dyn`) dimensions; users never
//! implement it. Without the `std` feature only static dimensions exist.

#[cfg(feature = "std")]
use nalgebra::Dyn;
use nalgebra::{Const, DefaultAllocator, Dim, U1, allocator::Allocator};

/// `DefaultAllocator` can allocate every vector and matrix shape a map from an `N`-dimensional
/// space to an `M`-dimensional space needs: N, M, N×N, M×M, N×M, M×N, 1×N and 1×M.
pub trait Alloc<N: Dim, M: Dim = N>:
    Allocator<N, M> + Allocator<M, N> + DimAlloc<N> + DimAlloc<M>
{
}

impl<N: Dim, M: Dim> Alloc<N, M> for DefaultAllocator where
    DefaultAllocator: Allocator<N, M> + Allocator<M, N> + DimAlloc<N> + DimAlloc<M>
{
}

/// The shapes of one dimension D (D, D×D, 1×D, and D against `Dyn`), and whether D is a
/// runtime size. Implemented for every `Const<R>` and for `Dyn`; part of [`Alloc`].
#[doc(hidden)]
pub trait DimAlloc<D: Dim>:
    Allocator<D> + Allocator<D, D> + Allocator<U1, D> + RuntimeShapes<D>
{
    /// `x`, made with `Dyn` for the family's dimension, as the same value with D, when D is
    /// `Dyn`; `None` when D is static. How code generic over dimensions reaches buffers kept
    /// for runtime sizes without a type-erased downcast.
    #[cfg(feature = "std")]
    fn runtime_sized<P: Dim, F: SizeFamily<P>>(x: &mut F::Of<Dyn>) -> Option<&mut F::Of<D>>
    where
        DefaultAllocator: Alloc<Dyn, P> + Alloc<D, P>;
}

/// A type constructor over one dimension Z, with a partner dimension P fixed (say, a filter's
/// update buffers for Z states and P measurement components), for [`DimAlloc::runtime_sized`].
#[doc(hidden)]
pub trait SizeFamily<P: Dim> {
    /// The type at dimension Z.
    type Of<Z: Dim>
    where
        DefaultAllocator: Alloc<Z, P>;
}

/// The shapes of D against `Dyn` (D × Dyn and Dyn × D), part of [`DimAlloc`]; without std
/// (no runtime sizes: nalgebra's `alloc` is off) no shape at all.
#[doc(hidden)]
#[cfg(feature = "std")]
pub trait RuntimeShapes<D: Dim>: Allocator<D, Dyn> + Allocator<Dyn, D> {}
#[cfg(feature = "std")]
impl<D: Dim> RuntimeShapes<D> for DefaultAllocator where
    DefaultAllocator: Allocator<D, Dyn> + Allocator<Dyn, D>
{
}
/// The shapes of D against `Dyn`, part of [`DimAlloc`]: none without std.
#[doc(hidden)]
#[cfg(not(feature = "std"))]
pub trait RuntimeShapes<D: Dim> {}
#[cfg(not(feature = "std"))]
impl<D: Dim> RuntimeShapes<D> for DefaultAllocator {}

#[cfg(feature = "std")]
impl DimAlloc<Dyn> for DefaultAllocator {
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn runtime_sized<P: Dim, F: SizeFamily<P>>(x: &mut F::Of<Dyn>) -> Option<&mut F::Of<Dyn>>
    where
        DefaultAllocator: Alloc<Dyn, P>,
    {
        Some(x)
    }
}

impl<const R: usize> DimAlloc<Const<R>> for DefaultAllocator {
    #[cfg(feature = "std")]
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn runtime_sized<P: Dim, F: SizeFamily<P>>(_: &mut F::Of<Dyn>) -> Option<&mut F::Of<Const<R>>>
    where
        DefaultAllocator: Alloc<Dyn, P> + Alloc<Const<R>, P>,
    {
        None
    }
}
