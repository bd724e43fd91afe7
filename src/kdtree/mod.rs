//! The kd-tree shared by every traversal and both backends: one flat format (DESIGN.md §2,
//! "one tree format, two backends"), two builders (SAH with perfect splits, midpoint), two
//! node layouts (depth-first, van Emde Boas) and optional ropes.
//!
//! Format: `nodes[0]` is the root. An inner node's two children sit side by side at
//! `child` (below the split) and `child + 1` (above). A voxel is split into
//! `[min, split]` (below) and `[split, max]` (above) along `axis`. A leaf holds its range of
//! primitive indices in `prim_indices` itself (see [`KdNode`]).
//!
//! Building: `build.rs` (entry point, options), `midpoint.rs` and `sah.rs` (the builders),
//! `split.rs` (what they share: the depth-first node arrays they write, the side of a
//! primitive, the parallel recursion), `layout.rs` (van Emde Boas order), `ropes.rs`,
//! `stats.rs`, `walk.rs` (leaf voxels, point location).

mod build;
mod layout;
mod midpoint;
mod ropes;
mod sah;
mod split;
mod stats;
mod walk;

pub use build::{build, BuildInput, BuildOptions, Builder, Layout, MAX_DEPTH_LIMIT};

use crate::fallible::{self, Fallible};
use crate::geometry::{Aabb, Clipped, PrimitiveSet, INVALID};

/// 8-byte node. `bits & 3` is the split axis (0–2) of an inner node or 3 for a leaf.
///
/// Inner node: `split` is the split position, `bits >> 2` the index of the first child.
/// Leaf: `bits >> 2` is the number of primitives and `split` holds, as its bit pattern, the index
/// of the first of them in `prim_indices`. The leaf's range lives in the node rather than in a
/// table of ranges: 8 bytes less per leaf, and a leaf visit goes from the node straight to its
/// list instead of through one more dependent load. The GPU reads the word as bits (a subnormal
/// float could be flushed there); on the CPU `to_bits`/`from_bits` are exact for every pattern.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct KdNode {
    pub split: f32,
    pub bits: u32,
}

impl KdNode {
    pub const LEAF: u32 = 3;

    /// An inner node splitting `axis` at `split`, children at `first_child` and the next.
    ///
    /// # Panics
    /// When `first_child` does not fit the node's 30 bits (a tree of 2^30 nodes, 8 GiB): a
    /// wrapped index would send rays into another subtree, so release builds check it too.
    pub fn inner(axis: usize, split: f32, first_child: u32) -> Self {
        assert!(
            axis < 3 && first_child < (1 << 30),
            "kd-tree node index {first_child} past 2^30"
        );
        KdNode {
            split,
            bits: (first_child << 2) | axis as u32,
        }
    }

    /// A leaf listing `prim_indices[first..first + count]`.
    ///
    /// # Panics
    /// When `count` does not fit the node's 30 bits (scenes hold fewer than 2^30 primitives,
    /// so a leaf never lists more).
    pub fn leaf(first: u32, count: u32) -> Self {
        assert!(count < (1 << 30), "kd-tree leaf of {count} primitives");
        KdNode {
            split: f32::from_bits(first),
            bits: (count << 2) | Self::LEAF,
        }
    }

    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.bits & 3 == Self::LEAF
    }

    /// Split axis of an inner node.
    #[inline]
    pub fn axis(&self) -> usize {
        (self.bits & 3) as usize
    }

    /// First child of an inner node.
    #[inline]
    pub fn index(&self) -> u32 {
        self.bits >> 2
    }

    /// A leaf's range in `prim_indices`.
    #[inline]
    pub fn prim_range(&self) -> std::ops::Range<usize> {
        let first = self.split.to_bits() as usize;
        first..first + (self.bits >> 2) as usize
    }
}

/// A leaf shows its range, an inner node its split (the derived form would print a leaf's first
/// index as a tiny float).
impl std::fmt::Debug for KdNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.is_leaf() {
            write!(f, "Leaf {:?}", self.prim_range())
        } else {
            let child = self.index();
            write!(
                f,
                "Inner {{ axis: {}, split: {}, child: {child} }}",
                self.axis(),
                self.split
            )
        }
    }
}

/// One word of [`Ropes::rank`]: which of 32 consecutive nodes are leaves, and how many leaves
/// come before them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RankWord {
    pub leaf_bits: u32,
    pub before: u32,
}

impl RankWord {
    /// The leaves before node `node` in the nodes that `rank` describes.
    #[inline]
    pub fn leaf_number(rank: &[RankWord], node: u32) -> usize {
        let w = rank[node as usize / 32];
        let below = w.leaf_bits & ((1u32 << (node % 32)) - 1);
        (w.before + below.count_ones()) as usize
    }
}

/// Rope faces in the order `-x, +x, -y, +y, -z, +z`: face `2*axis + (positive as usize)`.
pub const ROPE_FACES: usize = 6;

/// Ropes (Popov et al. 2007): per leaf, the node across each face of its box (`INVALID` where
/// the face lies on the scene boundary) and the leaf's box. Built only when a rope traversal
/// asks for them ("model no more than a scene needs").
///
/// Leaves are numbered by node index order, and a leaf node finds its number through `rank`
/// (2 bits per node: a rank directory, as in succinct data structures) rather than carrying it:
/// the plain tree's leaf nodes hold their primitive range, and only rope trees pay for numbers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Ropes {
    pub links: RopeLinks,
    pub leaf_bounds: Vec<Aabb>,
    pub rank: Vec<RankWord>,
}

impl Ropes {
    /// The number of leaf node `node`: its index into `links` and `leaf_bounds`.
    #[inline]
    pub fn leaf_number(&self, node: u32) -> usize {
        RankWord::leaf_number(&self.rank, node)
    }
}

/// The six ropes of every leaf, each packed in `bits` bits: the fewest that hold every node
/// index, with the all-ones value for `INVALID`. A rope is read once per leaf a ray leaves, so
/// unpacking costs little, and 16–21 bits instead of 32 take the ropes from 24 to 12–16 bytes
/// per leaf. Rope `k = 6 * leaf + face` occupies bits `[k * bits, (k + 1) * bits)` of the
/// little-endian stream of `words` (the GPU reads the same words).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RopeLinks {
    pub bits: u32,
    /// Ends with a spare word, so a rope straddling the last two words reads no further.
    pub words: Vec<u32>,
}

impl RopeLinks {
    /// Packs `links` (faces `-x, +x, -y, +y, -z, +z` per leaf) for a tree of `nodes` nodes.
    pub fn pack(links: &[[u32; ROPE_FACES]], nodes: usize) -> Fallible<Self> {
        // `nodes` itself must stay below the all-ones value that means INVALID.
        let bits = (usize::BITS - nodes.leading_zeros()).max(1);
        let total = links.len() * ROPE_FACES * bits as usize;
        let mut words = fallible::filled(0u32, total.div_ceil(32) + 1)?;
        let invalid = Self::mask(bits);
        for (k, &link) in links.iter().flatten().enumerate() {
            let value = u64::from(if link == INVALID { invalid } else { link });
            let at = k * bits as usize;
            let (w, shift) = (at / 32, at % 32);
            let both = (value << shift).to_le_bytes();
            words[w] |= u32::from_le_bytes([both[0], both[1], both[2], both[3]]);
            words[w + 1] |= u32::from_le_bytes([both[4], both[5], both[6], both[7]]);
        }
        Ok(RopeLinks { bits, words })
    }

    fn mask(bits: u32) -> u32 {
        (((1u64 << bits) - 1) & u64::from(u32::MAX)) as u32
    }

    /// Rope `face` of leaf `leaf`.
    #[inline]
    pub fn get(&self, leaf: usize, face: usize) -> u32 {
        let at = (leaf * ROPE_FACES + face) * self.bits as usize;
        let (w, shift) = (at / 32, at % 32);
        let pair = u64::from(self.words[w]) | u64::from(self.words[w + 1]) << 32;
        let mask = Self::mask(self.bits);
        let value = (pair >> shift) as u32 & mask;
        if value == mask {
            INVALID
        } else {
            value
        }
    }

    /// All six ropes of leaf `leaf`.
    pub fn leaf(&self, leaf: usize) -> [u32; ROPE_FACES] {
        std::array::from_fn(|face| self.get(leaf, face))
    }

    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.words.as_slice())
    }
}

/// Build statistics and memory, reported through `rt2_scene_stats`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TreeStats {
    pub node_count: u32,
    pub leaf_count: u32,
    pub empty_leaf_count: u32,
    pub max_depth: u32,
    /// Mean depth of the leaves.
    pub avg_leaf_depth: f32,
    /// Mean number of primitive references per non-empty leaf.
    pub avg_prims_per_leaf: f32,
    /// SAH cost of the tree with the builder's cost constants (relative units).
    pub sah_cost: f32,
    pub build_ms: f32,
}

#[derive(Clone, Debug)]
pub struct KdTree {
    pub nodes: Vec<KdNode>,
    pub prim_indices: Vec<u32>,
    /// The root voxel: the union of the primitive bounds, `Aabb::EMPTY` (never NaN) when the
    /// tree holds no primitive.
    pub bounds: Aabb,
    pub ropes: Option<Ropes>,
    pub stats: TreeStats,
}

impl KdTree {
    /// Primitive indices of the leaf node `leaf`.
    #[inline]
    pub fn leaf_prims(&self, leaf: KdNode) -> &[u32] {
        &self.prim_indices[leaf.prim_range()]
    }

    /// Number of leaves: every inner node has two children, so `(nodes + 1) / 2`.
    pub fn leaf_count(&self) -> usize {
        self.nodes.len().div_ceil(2)
    }

    /// Adds ropes (with leaf boxes and the rank words that number the leaves) if they are not
    /// there yet.
    pub fn ensure_ropes(&mut self) -> Fallible<()> {
        if self.ropes.is_none() {
            self.ropes = Some(ropes::build_ropes(self)?);
        }
        Ok(())
    }

    pub fn node_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
    }

    pub fn leaf_list_bytes(&self) -> usize {
        std::mem::size_of_val(self.prim_indices.as_slice())
    }

    /// Ropes and the rank words that number the leaves for them.
    pub fn rope_bytes(&self) -> usize {
        self.ropes.as_ref().map_or(0, |r| {
            r.links.bytes() + std::mem::size_of_val(r.rank.as_slice())
        })
    }

    pub fn leaf_box_bytes(&self) -> usize {
        self.ropes
            .as_ref()
            .map_or(0, |r| std::mem::size_of_val(r.leaf_bounds.as_slice()))
    }
}

impl BuildInput for PrimitiveSet {
    fn prim_count(&self) -> usize {
        self.len()
    }

    fn bounds(&self, prim: usize) -> Aabb {
        PrimitiveSet::bounds(self, prim)
    }

    fn clipped_bounds(&self, prim: usize, voxel: &Aabb) -> Clipped {
        PrimitiveSet::clipped_bounds(self, prim, voxel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every width from 1 to 32 bits: values up to the node count and `INVALID` come back, in
    /// any order of leaves and faces, also where a rope straddles two words.
    #[test]
    fn packed_ropes_read_back_what_was_packed() {
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            state
        };
        for bits in 1..=32u32 {
            let nodes = ((1u64 << bits) - 1).min(u64::from(u32::MAX) - 1) as usize;
            let links: Vec<[u32; ROPE_FACES]> = (0..37)
                .map(|_| {
                    std::array::from_fn(|_| match next() % 4 {
                        0 => INVALID,
                        1 => nodes as u32 - 1,
                        _ => next() % nodes as u32,
                    })
                })
                .collect();
            let packed = RopeLinks::pack(&links, nodes).unwrap();
            assert_eq!(packed.bits, bits, "{nodes} nodes");
            // One node more and the all-ones value would be a node index: one bit more.
            let wider = RopeLinks::pack(&links, nodes + 1).unwrap();
            assert_eq!(wider.bits, (bits + 1).min(32), "{} nodes", nodes + 1);
            for (leaf, l) in links.iter().enumerate() {
                assert_eq!(packed.leaf(leaf), *l, "{bits} bits, leaf {leaf}");
            }
        }
    }
}
