//! The scene model: objects, materials and lights as the user described them, and the
//! committed form (primitive set + kd-tree) that the backends trace.

pub mod loaders;
