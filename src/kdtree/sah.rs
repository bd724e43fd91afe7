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
//! `K_T = opts.traversal_cost`, `K_I = 1` and `λ = opts.empty_bonus` when nothing reaches into
//! one side (it holds only primitives touching the plane), else 1; a leaf costs `K_I N`. A node
//! becomes a leaf when no split is cheaper (but see [`CENTRE_SPLITS`]), at the depth limit, when
//! it holds no primitive, when its voxel has no area, or when its children would exceed its
//! share of the reference budget (`BuildOptions::references_per_prim`).
//!
//! Besides the planes at events, a node of [`GAP_PLANES_MIN_PRIMS`] or more also weighs a plane
//! midway between each two neighbouring event positions (a gap plane).

use rayon::prelude::*;

use super::split::{centre_plane, child_voxels, clip, fork, parallel, Budget, Side, Slot, Subtree};
use super::{BuildInput, BuildOptions};
use crate::fallible::{self, Fallible, TryGrow};
use crate::geometry::{Aabb, Clipped};

/// Cost of one primitive test, the unit of the cost model.
const INTERSECTION_COST: f32 = 1.0;

/// Event kinds in their sort order at equal positions (Wald & Havran §4.2: ends, planar,
/// starts). The sweep counts every event at one position before it scores that plane, so the
/// order within a position does not change its counts; it keeps the events of one position
/// together, grouped by kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    End = 0,
    Planar = 1,
    Start = 2,
}

/// Bits of an event's key left for the primitive's index in its node (the top two hold the
/// kind, the next one [`PADDED`]): a node of the SAH builder holds fewer than 2^29 primitives
/// (`MAX_PRIMS`).
const PRIM_BITS: u32 = 29;
const PRIM_MASK: u32 = (1 << PRIM_BITS) - 1;
/// Marks an event at a padded face (`Clipped::padded`): counted by the sweep, never a split.
const PADDED: u32 = 1 << PRIM_BITS;
const KIND_SHIFT: u32 = PRIM_BITS + 1;

/// Fewest primitives of a node whose sweep also weighs gap planes: planes midway between two
/// neighbouring event positions, which touch no primitive. Every event plane touches the
/// primitives that end, start or lie there, and `split::classify` keeps those on both sides
/// (conservative leaf membership). On geometry aligned to a grid (voxel models, boxes in a
/// row) every event plane is such a plane: the cube faces along it stay in every leaf beside
/// it and no split pays, so a filled 12³ grid of cubes (20k triangles) took 200 primitive
/// tests per ray against the midpoint builder's 12; with gap planes, 19 (random rays through
/// the grid, `tests/kdtree.rs`). In small nodes gap planes bought nothing on meshes but more
/// nodes: weighed in every node, the bunny's tree grew by 37% (dragon 31%) for the same ray
/// speed; from 32 primitives on, the three models' trees grow by 1–2%, their SAH costs move
/// by under 1%, and their build times and ray speeds stay within the machine's noise. Gap
/// planes lie between two event positions only: one past the last position cut off empty
/// space that the event plane there cuts off anyway, and on 20k random slivers it made the
/// tree take 16% more tests per ray.
const GAP_PLANES_MIN_PRIMS: usize = 32;

/// Most splits per path from the root that may go ahead although the SAH finds no plane
/// cheaper than a leaf: at the voxel's centre across its longest axis (the midpoint builder's
/// plane), in nodes of at least [`CENTRE_SPLIT_MIN_PRIMS`] primitives. The SAH is greedy:
/// where every primitive's bounds span much of the node (20k slivers each running from one
/// face of a cube to the opposite one), no single split pays, yet a few levels down the
/// clipped primitives are told apart. The root stayed one leaf of all 20k slivers (20000
/// tests per ray), and of most of 20k triangles fanned around one vertex (19411); with centre
/// splits, 1215 and 665, the midpoint builder 808 and 578 (`tests/kdtree.rs`). Splitting at
/// the least bad plane the SAH found instead did not help with gap planes on: it cut off thin
/// slabs of empty space. Limited per path, as PBRT's bad refines are, and never a split that
/// leaves every primitive on both sides (coincident or nested ones), which only copies the
/// node; on the bunny, dragon and Snowden bust no node takes one.
const CENTRE_SPLITS: u32 = 3;

/// Fewest primitives of a node that may take a centre split ([`CENTRE_SPLITS`]).
const CENTRE_SPLIT_MIN_PRIMS: usize = 64;

/// The gap plane between the event positions `a < b`: midway, if that lies more than `gap`
/// from both, as an event plane at padded faces must lie from its neighbours. A plane a
/// rounding error from geometry would bound a slab a ray may skip, or put a ray's hit on that
/// geometry in the wrong child. (A centre split, half its voxel on each side, makes no thin
/// slab; a plane on geometry keeps the geometry on both sides.)
fn gap_plane(a: f32, b: f32, gap: f32) -> Option<f32> {
    let mid = 0.5 * a + 0.5 * b;
    (b - a > 2.0 * gap && mid > a && mid < b).then_some(mid)
}

/// Most primitives the SAH builder takes; `build` hands larger inputs to the midpoint builder.
pub(super) const MAX_PRIMS: usize = PRIM_MASK as usize;

/// One event packed in a `u64` whose integer order is the sweep order: position (the `f32`
/// bits mapped to an order-preserving `u32`), then kind, then the padded flag and the
/// primitive. Eight bytes instead of a 12-byte struct, and sorts and merges compare one
/// integer: the event lists are most of the builder's memory traffic.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Event(u64);

impl Event {
    fn new(pos: f32, prim: u32, kind: Kind, padded: bool) -> Self {
        // `+ 0.0` turns -0 into +0, so that both zeros are one position of the sweep.
        let bits = (pos + 0.0).to_bits();
        let ordered = if bits >> 31 == 1 {
            !bits
        } else {
            bits | 1 << 31
        };
        let low = ((kind as u32) << KIND_SHIFT) | (u32::from(padded) * PADDED) | prim;
        Event(u64::from(ordered) << 32 | u64::from(low))
    }

    /// The position's key: equal for equal positions, ordered like them.
    fn pos_key(self) -> u32 {
        (self.0 >> 32) as u32
    }

    fn pos(self) -> f32 {
        let ordered = self.pos_key();
        f32::from_bits(if ordered >> 31 == 1 {
            ordered & !(1 << 31)
        } else {
            !ordered
        })
    }

    /// The kind as its numeric value.
    fn kind_bits(self) -> u32 {
        (self.0 as u32) >> KIND_SHIFT
    }

    /// Whether the event lies at a padded face, where the SAH must not split.
    fn padded(self) -> bool {
        self.0 as u32 & PADDED != 0
    }

    fn kind(self) -> Kind {
        match self.kind_bits() {
            0 => Kind::End,
            1 => Kind::Planar,
            _ => Kind::Start,
        }
    }

    fn prim(self) -> usize {
        (self.0 as u32 & PRIM_MASK) as usize
    }

    /// The same event for the primitive's index `prim` in a child's list.
    fn renumbered(self, prim: u32) -> Self {
        Event(self.0 & !u64::from(PRIM_MASK) | u64::from(prim))
    }
}

/// Sorted event lists of one node, one per axis.
type Events = [Vec<Event>; 3];

fn push_events(c: &Clipped, prim: u32, events: &mut Events) -> Fallible<()> {
    for (axis, list) in events.iter_mut().enumerate() {
        let (lo, hi) = (c.bounds.min[axis], c.bounds.max[axis]);
        let padded = |face: usize| c.padded >> (2 * axis + face) & 1 != 0;
        if lo == hi {
            list.try_push(Event::new(lo, prim, Kind::Planar, padded(0) && padded(1)))?;
        } else {
            list.try_push(Event::new(lo, prim, Kind::Start, padded(0)))?;
            list.try_push(Event::new(hi, prim, Kind::End, padded(1)))?;
        }
    }
    Ok(())
}

/// Merges a sorted list of new events into a sorted list while the latter is written out:
/// [`Merge::push`] each event of the list in order, then [`Merge::finish`].
struct Merge<'a> {
    extra: &'a [Event],
    next: usize,
}

impl<'a> Merge<'a> {
    fn new(extra: &'a [Event]) -> Self {
        Merge { extra, next: 0 }
    }

    /// Appends the new events that sort before `e`, then `e`.
    #[inline]
    fn push(&mut self, out: &mut Vec<Event>, e: Event) -> Fallible<()> {
        while let Some(&x) = self.extra.get(self.next).filter(|&&x| x < e) {
            out.try_push(x)?;
            self.next += 1;
        }
        out.try_push(e)
    }

    /// Appends the new events left after the last of the list.
    fn finish(self, out: &mut Vec<Event>) -> Fallible<()> {
        out.try_extend_from_slice(&self.extra[self.next..])
    }
}

/// `prims` are (index, bounds) pairs inside `voxel`.
pub(super) fn build(
    input: &dyn BuildInput,
    prims: Vec<(u32, Aabb)>,
    voxel: Aabb,
    max_depth: u32,
    opts: &BuildOptions,
) -> Fallible<Subtree> {
    let mut events: Events = Default::default();
    for (local, (_, b)) in prims.iter().enumerate() {
        push_events(&Clipped::exact(*b), local as u32, &mut events)?;
    }
    for list in &mut events {
        list.par_sort_unstable();
    }
    let sah = Sah {
        input,
        max_depth,
        traversal_cost: opts.traversal_cost,
        empty_bonus: opts.empty_bonus,
    };
    let budget = Budget::root(prims.len(), opts.references_per_prim);
    let prims = fallible::collect(prims.into_iter().map(|(p, _)| p))?;
    Subtree::built(|slot| sah.node(prims, events, voxel, (0, CENTRE_SPLITS), budget, slot))
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
    /// Writes the subtree of `voxel` at `depth` into `slot`, which may take `centre` more
    /// centre splits ([`CENTRE_SPLITS`]). `prims` are global indices; `events` refer to them
    /// by position in `prims`.
    fn node(
        &self,
        prims: Vec<u32>,
        events: Events,
        voxel: Aabb,
        (depth, centre): (u32, u32),
        budget: Budget,
        slot: Slot,
    ) -> Fallible<()> {
        let n = prims.len();
        let leaf_cost = INTERSECTION_COST * n as f32;
        let plane = if depth < self.max_depth && n > 0 {
            self.best_plane(&events, n, &voxel, depth)
        } else {
            None
        };
        // The SAH's plane, or else a centre split (`forced`), which the cost does not vouch for.
        let (plane, forced) = match plane {
            Some(p) if p.cost < leaf_cost => (p, false),
            // `best_plane` found candidates (depth and area allow a split) but none pays.
            Some(_) if centre > 0 && n >= CENTRE_SPLIT_MIN_PRIMS => match centre_plane(&voxel) {
                Some((axis, pos)) => (
                    Plane {
                        axis,
                        pos,
                        cost: leaf_cost,
                    },
                    true,
                ),
                None => return slot.leaf(prims),
            },
            _ => return slot.leaf(prims),
        };
        let centre = centre - u32::from(forced);
        let voxels = child_voxels(&voxel, plane.axis, plane.pos);
        let [(pb, eb), (pa, ea)] = self.distribute(&prims, events, &voxels, &plane)?;
        // A centre split that leaves every primitive on both sides only copies the node
        // (primitives that all contain its centre: coincident or nested spheres, where 256
        // copies of one sphere took 8 times the references and 56% more tests per ray): a
        // leaf, as the midpoint builder makes it.
        if forced && pb.len() == n && pa.len() == n {
            return slot.leaf(prims);
        }
        let Some([bb, ba]) = budget.split(pb.len(), pa.len()) else {
            return slot.leaf(prims);
        };
        drop(prims);
        let [vb, va] = voxels;
        fork(
            depth,
            pb.len() + pa.len(),
            slot.inner(plane.axis, plane.pos)?,
            |slot| self.node(pb, eb, vb, (depth + 1, centre), bb, slot),
            |slot| self.node(pa, ea, va, (depth + 1, centre), ba, slot),
        )
    }

    /// The cheapest plane over the three axes; near the root the axes are swept in parallel.
    /// Ties go to the lowest axis, then the lowest position, so the choice does not depend on
    /// the thread count.
    fn best_plane(&self, events: &Events, n: usize, voxel: &Aabb, depth: u32) -> Option<Plane> {
        // Lengths and areas at the voxel's unit scale: a voxel past 1e19 has no f32 area.
        let unit = voxel.unit_scale();
        let area = voxel.scaled_surface_area(unit);
        if area <= 0.0 {
            return None;
        }
        let sweep = |axis: usize| self.best_on_axis(&events[axis], axis, n, voxel, unit, area);
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
        unit: f32,
        area: f32,
    ) -> Option<Plane> {
        // A child's area is linear in the plane's position: `2 (face + side · length)`, with
        // `face` the area of the voxel's face across the axis and `side` the half perimeter
        // (all at the voxel's `unit` scale, as `area`).
        let e = voxel.scaled_extent(unit);
        let (u, v) = (e[(axis + 1) % 3], e[(axis + 2) % 3]);
        let (face, side) = (u * v, u + v);
        let scale = 2.0 / area;
        let (lo, hi) = (voxel.min[axis], voxel.max[axis]);
        // The best plane so far, updated by selects rather than a branch: which candidate
        // improves on the best is data the branch predictor cannot learn.
        let (mut best_cost, mut best_pos) = (f32::INFINITY, 0.0);
        // Weighs the plane at `pos` whose children hold `held` primitives, `inside` of them
        // reaching into the child's interior.
        let mut weigh = |pos: f32, held: [usize; 2], inside: [usize; 2]| {
            let probability = [
                scale * (face + side * (pos * unit - lo * unit)),
                scale * (face + side * (hi * unit - pos * unit)),
            ];
            let cost = self.split_cost(probability, held, inside);
            let better = cost < best_cost;
            best_cost = if better { cost } else { best_cost };
            best_pos = if better { pos } else { best_pos };
        };
        // Primitives that start before the current plane, and that do not end before it.
        let (mut below, mut above) = (0usize, n);
        // A plane at padded faces only (`Triangle::clipped_bounds`) is a candidate unless it
        // lies within a few pads of the planes next to it or of the voxel's faces: there it
        // would cut off a slab that thin, holding only the geometry at its other face, which a
        // ray from afar cannot enter. (Keeping every padded plane out made the bunny's tree
        // hold 38% more references: clipped triangles propose most of the useful planes.)
        let gap = 8.0 * f32::EPSILON * voxel.min.abs().max(voxel.max.abs()).max_element();
        let mut previous = lo;
        let gap_planes = n >= GAP_PLANES_MIN_PRIMS;
        let mut i = 0;
        while i < list.len() {
            let key = list[i].pos_key();
            let (mut ends, mut planar, mut starts) = (0usize, 0usize, 0usize);
            let mut geometry = false;
            loop {
                // The kind's raw bits: integer compares, no branch per event.
                let kind = list[i].kind_bits();
                ends += usize::from(kind == Kind::End as u32);
                planar += usize::from(kind == Kind::Planar as u32);
                starts += usize::from(kind == Kind::Start as u32);
                geometry |= !list[i].padded();
                i += 1;
                if i == list.len() || list[i].pos_key() != key {
                    break;
                }
            }
            let pos = list[i - 1].pos();
            let next = list.get(i).map_or(hi, |e| e.pos()).min(hi);
            let apart = pos - previous.max(lo) > gap && next - pos > gap;
            previous = pos;
            if pos > lo && pos < hi && (geometry || apart) {
                // `split::classify` sends every primitive touching the plane (ending, lying or
                // starting on it) to both children: the cost counts them on both sides, or the
                // builder would split forever at planes that only duplicate primitives.
                let held = [below + planar + starts, above];
                weigh(pos, held, [below, above - ends - planar]);
            }
            above -= ends + planar;
            below += starts + planar;
            // The gap plane up to the next position touches nothing: `below` and `above` as
            // they now stand, no primitive on both sides. Only between two positions: past the
            // last (or before the first) it would cut off empty space, which the event plane
            // there already does, touching what lies on it.
            let between = gap_planes && i < list.len();
            if let Some(p) = gap_plane(pos.max(lo), next, gap).filter(|_| between) {
                weigh(p, [below, above], [below, above]);
            }
        }
        (best_cost < f32::INFINITY).then_some(Plane {
            axis,
            pos: best_pos,
            cost: best_cost,
        })
    }

    /// Cost of a split whose children are hit with probabilities `p` and hold `n` primitives
    /// (those touching the plane in both: conservative leaf membership, where Wald & Havran
    /// (§4.2) put the planar ones on the cheaper side), `inside` of them reaching into the
    /// child's interior. A child with nothing inside is the empty space λ favours cutting off:
    /// it holds only primitives touching the plane, so `n` is never 0 at a plane on geometry.
    fn split_cost(&self, p: [f32; 2], n: [usize; 2], inside: [usize; 2]) -> f32 {
        let lambda = if inside[0] == 0 || inside[1] == 0 {
            self.empty_bonus
        } else {
            1.0
        };
        // Counts fit `u32` (`MAX_PRIMS`), whose conversion to `f32` needs no branch.
        let [below, above] = n.map(|k| k as u32 as f32);
        lambda * (self.traversal_cost + INTERSECTION_COST * (p[0] * below + p[1] * above))
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
    ) -> Fallible<[(Vec<u32>, Events); 2]> {
        let n = prims.len();
        // The side of each primitive, from its events along the split axis: the rule of
        // `split::classify` (an end before the plane puts it below, a start after it above).
        let mut side = fallible::filled(Side::Both, n)?;
        for &e in &events[plane.axis] {
            let pos = e.pos();
            match e.kind() {
                Kind::End | Kind::Planar if pos < plane.pos => side[e.prim()] = Side::Below,
                Kind::Start | Kind::Planar if pos > plane.pos => side[e.prim()] = Side::Above,
                _ => {}
            }
        }
        let mut children: [(Vec<u32>, Events); 2] = Default::default();
        let mut straddling: [Events; 2] = Default::default();
        // Position of each one-sided primitive in its child's list.
        let mut moved = fallible::filled(u32::MAX, n)?;
        for (p, &prim) in prims.iter().enumerate() {
            let child = match side[p] {
                Side::Below => 0,
                Side::Above => 1,
                Side::Both => {
                    // Clipped to each child voxel: new events there, or culled.
                    for (child, voxel) in voxels.iter().enumerate() {
                        if let Some(b) = clip(self.input, prim, voxel) {
                            let list = &mut children[child].0;
                            push_events(&b, list.len() as u32, &mut straddling[child])?;
                            list.try_push(prim)?;
                        }
                    }
                    continue;
                }
            };
            let list = &mut children[child].0;
            moved[p] = list.len() as u32;
            list.try_push(prim)?;
        }
        for (axis, list) in events.iter().enumerate() {
            let extra: [&mut [Event]; 2] = straddling.each_mut().map(|s| &mut s[axis][..]);
            for (child, (prims, events)) in children.iter_mut().enumerate() {
                extra[child].sort_unstable();
                // About its share of the parent's events, and its straddlers' new ones.
                events[axis]
                    .try_reserve(list.len() * prims.len() / n.max(1) + extra[child].len())?;
            }
            // One pass: the parent's one-sided events go to their child in order, each child's
            // sorted straddler events merged in as they fall due.
            let mut merges = extra.map(|x| Merge::new(x));
            for &e in list {
                let child = match side[e.prim()] {
                    Side::Below => 0,
                    Side::Above => 1,
                    Side::Both => continue,
                };
                let e = e.renumbered(moved[e.prim()]);
                merges[child].push(&mut children[child].1[axis], e)?;
            }
            for ((_, events), merge) in children.iter_mut().zip(merges) {
                merge.finish(&mut events[axis])?;
            }
        }
        drop(events);
        Ok(children)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const POSITIONS: [f32; 10] = [
        f32::NEG_INFINITY,
        -1e30,
        -1.5,
        -1e-40, // subnormal
        -0.0,
        0.0,
        1e-40,
        1.0,
        3e7,
        f32::INFINITY,
    ];

    #[test]
    fn packed_events_round_trip_and_sort_like_the_sweep_order() {
        let kinds = [Kind::End, Kind::Planar, Kind::Start];
        let mut all = Vec::new();
        for &pos in &POSITIONS {
            for kind in kinds {
                for padded in [false, true] {
                    for prim in [0, 7, PRIM_MASK] {
                        let e = Event::new(pos, prim, kind, padded);
                        assert_eq!(e.pos(), pos + 0.0, "position of {pos:e}");
                        assert_eq!((e.kind(), e.prim()), (kind, prim as usize));
                        assert_eq!(e.padded(), padded);
                        let r = e.renumbered(3);
                        assert_eq!(r.prim(), 3);
                        assert_eq!((r.pos(), r.kind(), r.padded()), (e.pos(), kind, padded));
                        all.push((pos + 0.0, kind as u32, (padded, prim), e));
                    }
                }
            }
        }
        for a in &all {
            for b in &all {
                let expected = a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2));
                assert_eq!(a.3.cmp(&b.3), expected, "{a:?} against {b:?}");
                assert_eq!(a.3.pos_key() == b.3.pos_key(), a.0 == b.0);
            }
        }
    }

    #[test]
    fn merge_gives_the_sorted_union() {
        let events = |positions: &[f32]| -> Vec<Event> {
            let mut v: Vec<Event> = positions
                .iter()
                .enumerate()
                .map(|(i, &p)| Event::new(p, i as u32, Kind::Start, false))
                .collect();
            v.sort_unstable();
            v
        };
        for (a, b) in [
            (&POSITIONS[..], &[0.5, -2.0, 1e31][..]),
            (&[], &POSITIONS[..]),
            (&POSITIONS[..], &[]),
            (&[1.0, 1.0], &[1.0]),
        ] {
            let (list, extra) = (events(a), events(b));
            let mut expected = [list.clone(), extra.clone()].concat();
            expected.sort_unstable();
            let (mut out, mut merge) = (Vec::new(), Merge::new(&extra));
            for &e in &list {
                merge.push(&mut out, e).unwrap();
            }
            merge.finish(&mut out).unwrap();
            assert_eq!(out, expected);
        }
    }
}
