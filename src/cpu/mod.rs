//! The CPU backend (layer 3a): single-ray traversals and the Whitted renderer.

pub mod traverse;
pub mod whitted;
