//! The CPU backend (layer 3a): single-ray traversals, batch queries and the Whitted renderer.

pub mod query;
pub mod traverse;
pub mod whitted;
