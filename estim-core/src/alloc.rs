//! One bound that stands for all the nalgebra allocator bounds estim needs.
//!
//! nalgebra code that is generic over dimensions must say, for every matrix shape it creates,
//! that `DefaultAllocator` can allocate it. Instead of six bounds on every signature, estim asks
//! for one: `DefaultAllocator: Alloc<N, M>`. Supertraits are implied at use sites, so inside a
//! function bounded this way every shape below is available.
//!
//! For static sizes (`Const<N>`) and for `Dyn` the bound always holds; users never implement it.

use nalgebra::{DefaultAllocator, Dim, U1, allocator::Allocator};

/// `DefaultAllocator` can allocate every vector and matrix shape a map from an `N`-dimensional
/// space to an `M`-dimensional space needs: N, M, N×N, M×M, N×M, M×N, 1×N and 1×M.
pub trait Alloc<N: Dim, M: Dim = N>:
    Allocator<N>
    + Allocator<M>
    + Allocator<N, N>
    + Allocator<M, M>
    + Allocator<N, M>
    + Allocator<M, N>
    + Allocator<U1, N>
    + Allocator<U1, M>
{
}

impl<N: Dim, M: Dim> Alloc<N, M> for DefaultAllocator where
    DefaultAllocator: Allocator<N>
        + Allocator<M>
        + Allocator<N, N>
        + Allocator<M, M>
        + Allocator<N, M>
        + Allocator<M, N>
        + Allocator<U1, N>
        + Allocator<U1, M>
{
}
