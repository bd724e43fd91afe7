//! RT2: a real-time kd-tree ray tracer with a C API.
//!
//! Layers (DESIGN.md §2): [`api`] is the C boundary (layer 1); [`dispatch`] decides where each
//! operation runs (layer 2); [`cpu`] is the CPU backend (layer 3a), [`gpu`] the GPU backend
//! (layer 3b). Shared by all: the
//! [`geometry`] vocabulary, the [`scene`] model, the [`kdtree`], [`camera`], [`frame`] and
//! [`shading`], and the [`precision`] modes. [`context::Context`] ties a thread pool to a
//! dispatch decision.

pub mod api;
pub mod camera;
pub mod context;
pub mod cpu;
pub mod dispatch;
mod env;
pub mod error;
pub mod fallible;
pub mod frame;
pub mod geometry;
pub mod gpu;
mod huge_pages;
mod job_record;
pub mod kdtree;
pub mod precision;
mod process;
pub mod rayset;
mod read_mostly;
pub mod render;
pub mod rng;
pub mod scene;
pub mod shading;
mod workers;
