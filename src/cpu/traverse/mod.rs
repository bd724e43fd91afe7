//! The seven single-ray kd-tree traversals of the RT² thesis.
