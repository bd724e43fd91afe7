//! RT2: a real-time kd-tree ray tracer with a C API.
//!
//! Layers (DESIGN.md §2): [`api`] is the C boundary (layer 1), [`dispatch`] decides where each
//! operation runs (layer 2), [`cpu`] is the CPU backend (layer 3a). Shared by all: the
//! [`geometry`] vocabulary, the [`scene`] model and the [`kdtree`].

pub mod geometry;
pub mod kdtree;
pub mod cpu;
pub mod error;
pub mod scene;
