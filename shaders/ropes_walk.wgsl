// Rope traversals (src/cpu/traverse/ropes.rs): each leaf knows its box and, per face, the
// node across it; after a leaf the ray follows the rope of its exit face and descends from
// there to the leaf it enters: no stack, no restart. ropes.wgsl and ropes_pp.wgsl pick the
// exit test and the scene test.

struct Exit { t: f32, face: u32 }

// Rope `face` of leaf `leaf` (`RopeLinks::get`): rope k = 6 leaf + face takes
// `params.rope_bits` bits from bit k rope_bits of the word stream, the all-ones value for
// INVALID. 32 ropes fill exactly rope_bits words, so the word is found per group of 32: the
// bit offset itself would overflow u32 past 512 MiB of ropes.
fn rope(leaf: u32, face: u32) -> u32 {
    let bits = params.rope_bits;
    let k = 6u * leaf + face;
    let r = (k & 31u) * bits;
    let w = (k >> 5u) * bits + (r >> 5u);
    let shift = r & 31u;
    var value = ropes[w] >> shift;
    if (shift + bits > 32u) { value |= ropes[w + 1u] << (32u - shift); }
    let mask = select((1u << bits) - 1u, 0xffffffffu, bits >= 32u);
    value &= mask;
    return select(value, INVALID, value == mask);
}

// Popov's exit: both planes of every slab, the farther one is where the ray leaves it.
fn exit_six_faces(b: Aabb, r: TRay) -> Exit {
    var best = Exit(inf(), 0u);
    for (var a = 0u; a < 3u; a++) {
        let ta = dist(r, a, b.min[a]);
        let tb = dist(r, a, b.max[a]);
        var e: Exit;
        // A flat slab (ta == tb) is left through the face the direction points to: the other
        // rope leads back to the leaf the ray came from (as exit_six_faces in ropes.rs).
        if (ta > tb || (ta == tb && !positive(r, a))) { e = Exit(ta, 2u * a); } else if (tb >= ta) { e = Exit(tb, 2u * a + 1u); } else { continue; }
        if (e.t < best.t) { best = e; }
    }
    return best;
}

// ropes++: the exit face of each slab follows from the direction sign: three planes.
fn exit_three_faces(b: Aabb, r: TRay) -> Exit {
    var best = Exit(inf(), 0u);
    for (var a = 0u; a < 3u; a++) {
        let pos = positive(r, a);
        let t = dist(r, a, select(b.min[a], b.max[a], pos));
        if (t < best.t) { best = Exit(t, 2u * a + select(0u, 1u, pos)); }
    }
    return best;
}

// `tied_exit` of ropes.rs: leaving the scene through an edge or a corner of the leaf, the faces
// meeting there tie up to rounding; go on through another of them whose rope leads somewhere.
fn tied_exit(leaf: u32, r: TRay, ex: Exit) -> u32 {
    let b = leaf_boxes[leaf];
    let tol = 8.0 * 1.1920929e-7 * max(abs(ex.t), 1.1754944e-38);
    for (var a = 0u; a < 3u; a++) {
        let pos = positive(r, a);
        let other = 2u * a + select(0u, 1u, pos);
        let t = dist(r, a, select(b.min[a], b.max[a], pos));
        let link = rope(leaf, other);
        if (other != ex.face && abs(t - ex.t) <= tol && link != INVALID) { return link; }
    }
    return INVALID;
}

// The loop of algorithms 7 and 8: locate the leaf, test its primitives, follow the rope, up to
// `t_end`, the end of the scene box's clip.
fn rope_walk(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>,
             start: u32, t_start: f32, t_end: f32, three_faces: bool) {
    var node = start;
    var t_entry = t_start;
    for (var visit = 0u; visit < params.n_leaves; visit++) {
        var t1 = inf();
        loop {
            let n = nodes[node];
            (*st).nodes += 1u;
            if (is_leaf(n)) { break; }
            let c = kd_step(n, r, t_entry, t1);
            if (c.both) { t1 = c.t_split; }
            node = c.child;
        }
        let leaf = leaf_number(node);
        var ex: Exit;
        if (three_faces) { ex = exit_three_faces(leaf_boxes[leaf], r); } else { ex = exit_six_faces(leaf_boxes[leaf], r); }
        if (visit_leaf(nodes[node], ex.t, r.ray, h, any_hit, st) || ex.t >= t_end) { return; }
        node = rope(leaf, ex.face);
        if (node == INVALID) {
            node = tied_exit(leaf, r, ex);
            if (node == INVALID) { return; }
        }
        t_entry = max(t_entry, ex.t);
    }
}
