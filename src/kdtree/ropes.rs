//! Ropes and leaf boxes (Popov et al. 2007).

use super::{KdTree, Ropes};

pub(super) fn build_ropes(_tree: &KdTree) -> Ropes {
    unimplemented!("ropes land in the kd-tree issue")
}
