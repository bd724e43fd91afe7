//! Layer 1: the C API. One module per C object; every exported function validates its
//! arguments, returns an `rt2_status`, leaves objects unchanged on failure and runs inside
//! `ffi::guard`, the panic barrier. `include/rt2.h` is generated from this folder by `build.rs`.
//!
//! Handles are boxed Rust objects carrying a magic number, so a NULL, foreign or destroyed
//! handle is an error rather than undefined behaviour in the common cases.

#![allow(non_camel_case_types)]

mod camera;
mod context;
mod ffi;
mod frame;
mod options;
mod query;
mod render;
mod scene;
mod status;
mod surface;

pub use camera::*;
pub use context::*;
pub use frame::*;
pub use options::*;
pub use query::*;
pub use render::*;
pub use scene::*;
pub use status::*;
pub use surface::*;
