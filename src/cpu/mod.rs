//! The CPU backend (layer 3a): single-ray traversals, 4/8/16-ray packets, n-ray streams, SIMD
//! intersection, batch queries and the Whitted renderer (depth-first or breadth-first).

mod batch;
pub mod packet;
pub mod query;
pub mod ray_order;
pub mod simd;
pub mod stream;
pub mod traverse;
pub mod whitted;

pub use batch::{Excluded, RayTests};
