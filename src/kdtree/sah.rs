//! SAH builder with perfect splits in O(N log N): Wald & Havran 2006, "On building fast
//! kd-trees for ray tracing, and on doing that in O(N log N)", §5.
//!
//! Each primitive's clipped bounds give, per axis, a start and an end event (or one planar
//! event when the bounds are flat on that axis). The events are sorted once at the root; each
//! node sweeps its three sorted lists to find the plane of least cost, then splits them into
//! the children's lists keeping their order. Only primitives that straddle the plane are
//! clipped again (to each child voxel); their few new events are sorted and merged in, so no
//! node sorts more than its straddling primitives.
//!
//! Cost model (MacDonald & Booth; Wald & Havran §3): a split costs
//! `λ (K_T + K_I (P_below N_below + P_above N_above))`, `P = A(child) / A(voxel)`, with
//! `K_T = opts.traversal_cost`, `K_I = 1` and `λ = opts.empty_bonus` when a side is empty
//! (else 1); a leaf costs `K_I N`. A node becomes a leaf when no split is cheaper, at the depth
//! limit, when it holds no primitive, or when its voxel has no area.

use std::cmp::Ordering;

use rayon::prelude::*;

use super::split::{child_voxels, classify, clip, fork, parallel, BuildNode, Side};
use super::{BuildInput, BuildOptions};
use crate::geometry::Aabb;

/// Cost of one primitive test, the unit of the cost model.
const INTERSECTION_COST: f32 = 1.0;

/// Event kinds in their sort order at equal positions: the sweep must see the ends of the
/// primitives left of a plane before the planar ones and the starts (Wald & Havran §4.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    End = 0,
    Planar = 1,
    Start = 2,
}

#[derive(Clone, Copy, Debug)]
struct Event {
    pos: f32,
    /// Index into the node's primitive list.
    prim: u32,
    kind: Kind,
}

/// Total order: position, kind, then primitive, so that sorting is deterministic.
fn order(a: &Event, b: &Event) -> Ordering {
    a.pos
        .total_cmp(&b.pos)
        .then(a.kind.cmp(&b.kind))
        .then(a.prim.cmp(&b.prim))
}

/// Sorted event lists of one node, one per axis.
type Events = [Vec<Event>; 3];

fn push_events(b: &Aabb, prim: u32, events: &mut Events) {
    for (axis, list) in events.iter_mut().enumerate() {
        let (lo, hi) = (b.min[axis], b.max[axis]);
        if lo == hi {
            list.push(Event {
                pos: lo,
                prim,
                kind: Kind::Planar,
            });
        } else {
            list.push(Event {
                pos: lo,
                prim,
                kind: Kind::Start,
            });
            list.push(Event {
                pos: hi,
                prim,
                kind: Kind::End,
            });
        }
    }
}

/// Merges two sorted lists.
fn merge(a: Vec<Event>, b: Vec<Event>) -> Vec<Event> {
    if b.is_empty() {
        return a;
    }
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut a, mut b) = (a.into_iter().peekable(), b.into_iter().peekable());
    while let (Some(x), Some(y)) = (a.peek(), b.peek()) {
        let next = if order(x, y) == Ordering::Greater {
            b.next()
        } else {
            a.next()
        };
        out.extend(next);
    }
    out.extend(a);
    out.extend(b);
    out
}

/// `prims` are (index, bounds) pairs inside `voxel`.
pub(super) fn build(
    input: &dyn BuildInput,
    prims: Vec<(u32, Aabb)>,
    voxel: Aabb,
    max_depth: u32,
    opts: &BuildOptions,
) -> BuildNode {
    let mut events: Events = Default::default();
    for (local, (_, b)) in prims.iter().enumerate() {
        push_events(b, local as u32, &mut events);
    }
    for list in &mut events {
        list.par_sort_unstable_by(order);
    }
    let sah = Sah {
        input,
        max_depth,
        traversal_cost: opts.traversal_cost,
        empty_bonus: opts.empty_bonus,
    };
    sah.node(
        prims.into_iter().map(|(p, _)| p).collect(),
        events,
        voxel,
        0,
    )
}

/// A candidate split plane.
struct Plane {
    axis: usize,
    pos: f32,
    cost: f32,
}

struct Sah<'a> {
    input: &'a dyn BuildInput,
    max_depth: u32,
    traversal_cost: f32,
    empty_bonus: f32,
}

impl Sah<'_> {
    /// `prims` are global indices; `events` refer to them by position in `prims`.
    fn node(&self, prims: Vec<u32>, events: Events, voxel: Aabb, depth: u32) -> BuildNode {
        let leaf_cost = INTERSECTION_COST * prims.len() as f32;
        let plane = if depth < self.max_depth && !prims.is_empty() {
            self.best_plane(&events, prims.len(), &voxel, depth)
        } else {
            None
        };
        let Some(plane) = plane.filter(|p| p.cost < leaf_cost) else {
            return BuildNode::leaf(prims);
        };
        let voxels = child_voxels(&voxel, plane.axis, plane.pos);
        let [(pb, eb), (pa, ea)] = self.distribute(&prims, events, &voxels, &plane);
        drop(prims);
        let [vb, va] = voxels;
        let children = fork(
            depth,
            pb.len() + pa.len(),
            || self.node(pb, eb, vb, depth + 1),
            || self.node(pa, ea, va, depth + 1),
        );
        BuildNode::Inner {
            axis: plane.axis,
            split: plane.pos,
            children: Box::new(children),
        }
    }

    /// The cheapest plane over the three axes; near the root the axes are swept in parallel.
    /// Ties go to the lowest axis, then the lowest position, so the choice does not depend on
    /// the thread count.
    fn best_plane(&self, events: &Events, n: usize, voxel: &Aabb, depth: u32) -> Option<Plane> {
        let area = voxel.surface_area();
        if area <= 0.0 {
            return None;
        }
        let sweep = |axis: usize| self.best_on_axis(&events[axis], axis, n, voxel, area);
        let per_axis: Vec<Option<Plane>> = if parallel(depth, n) {
            (0..3).into_par_iter().map(sweep).collect()
        } else {
            (0..3).map(sweep).collect()
        };
        per_axis
            .into_iter()
            .flatten()
            .reduce(|best, p| if p.cost < best.cost { p } else { best })
    }

    /// Sweeps the sorted events of one axis (Wald & Havran, Algorithm 4). Only planes strictly
    /// inside the voxel are candidates: a plane on its boundary would leave a child equal to
    /// the parent and never terminate.
    fn best_on_axis(
        &self,
        list: &[Event],
        axis: usize,
        n: usize,
        voxel: &Aabb,
        area: f32,
    ) -> Option<Plane> {
        let mut best: Option<Plane> = None;
        // Primitives that start before the current plane, and that do not end before it.
        let (mut below, mut above) = (0usize, n);
        let mut i = 0;
        while i < list.len() {
            let pos = list[i].pos;
            let mut count = [0usize; 3];
            while i < list.len() && list[i].pos == pos {
                count[list[i].kind as usize] += 1;
                i += 1;
            }
            let [ends, planar, starts] = count;
            if pos > voxel.min[axis] && pos < voxel.max[axis] {
                // `split::classify` sends every primitive touching the plane (ending, lying or
                // starting on it) to both children: the cost counts them on both sides, or the
                // builder would split forever at planes that only duplicate primitives.
                let counts = [below + planar + starts, above];
                let candidate = self.split_cost(voxel, area, axis, pos, counts);
                if best.as_ref().is_none_or(|b| candidate.cost < b.cost) {
                    best = Some(candidate);
                }
            }
            above -= ends + planar;
            below += starts + planar;
        }
        best
    }

    /// Cost of the plane `axis = pos` with `below` and `above` primitives in the two children
    /// (those touching the plane in both: conservative leaf membership, where Wald & Havran
    /// (§4.2) put the planar ones on the cheaper side).
    fn split_cost(&self, voxel: &Aabb, area: f32, axis: usize, pos: f32, n: [usize; 2]) -> Plane {
        let [below, above] = n;
        let [vb, va] = child_voxels(voxel, axis, pos);
        let (pb, pa) = (vb.surface_area() / area, va.surface_area() / area);
        let cost = |nb: usize, na: usize| {
            let lambda = if nb == 0 || na == 0 {
                self.empty_bonus
            } else {
                1.0
            };
            lambda * (self.traversal_cost + INTERSECTION_COST * (pb * nb as f32 + pa * na as f32))
        };
        Plane {
            axis,
            pos,
            cost: cost(below, above),
        }
    }

    /// Splits the primitives and their events between the two children (Wald & Havran §5.2):
    /// one-sided primitives keep their events, in order; straddling ones are clipped to each
    /// child voxel and their new events sorted and merged in.
    fn distribute(
        &self,
        prims: &[u32],
        events: Events,
        voxels: &[Aabb; 2],
        plane: &Plane,
    ) -> [(Vec<u32>, Events); 2] {
        let n = prims.len();
        // Extent of each primitive along the split axis, read back from its events.
        let (mut lo, mut hi) = (vec![0f32; n], vec![0f32; n]);
        for e in &events[plane.axis] {
            let p = e.prim as usize;
            match e.kind {
                Kind::Start => lo[p] = e.pos,
                Kind::End => hi[p] = e.pos,
                Kind::Planar => (lo[p], hi[p]) = (e.pos, e.pos),
            }
        }
        let side: Vec<Side> = (0..n).map(|p| classify(lo[p], hi[p], plane.pos)).collect();
        drop((lo, hi));

        let mut children: [(Vec<u32>, Events); 2] = Default::default();
        let mut straddling: [Events; 2] = Default::default();
        // Position of each parent primitive in each child's list.
        let mut moved = vec![[u32::MAX; 2]; n];
        for (p, &prim) in prims.iter().enumerate() {
            for child in 0..2 {
                // One-sided primitives keep their events (`None`); straddling ones get new
                // events from their part inside the child voxel, or are culled there.
                let clipped = match (side[p], child) {
                    (Side::Both, _) => match clip(self.input, prim, &voxels[child]) {
                        Some(b) => Some(b),
                        None => continue,
                    },
                    (Side::Below, 0) | (Side::Above, 1) => None,
                    _ => continue,
                };
                let (list, _) = &mut children[child];
                moved[p][child] = list.len() as u32;
                if let Some(b) = clipped {
                    push_events(&b, list.len() as u32, &mut straddling[child]);
                }
                list.push(prim);
            }
        }
        for (axis, list) in events.into_iter().enumerate() {
            for e in list {
                let child = match side[e.prim as usize] {
                    Side::Below => 0,
                    Side::Above => 1,
                    Side::Both => continue,
                };
                let prim = moved[e.prim as usize][child];
                children[child].1[axis].push(Event { prim, ..e });
            }
        }
        for ((_, events), mut extra) in children.iter_mut().zip(straddling) {
            for (list, extra) in events.iter_mut().zip(&mut extra) {
                extra.sort_unstable_by(order);
                *list = merge(std::mem::take(list), std::mem::take(extra));
            }
        }
        children
    }
}
