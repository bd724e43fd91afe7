// Ropes++ (the thesis' algorithm 8): exits from the three planes the direction selects, and a
// ray given the leaf of its origin (`Ray::start`: the render's secondary rays, `start_leaf`)
// starts its walk there. The scene box is clipped as the other traversals clip it, not tested
// for its entry only (see `ropes_plus_plus` in ropes.rs).
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    let scene = clip_scene(r);
    if (!scene.ok) { return; }
    rope_walk(r, h, any_hit, st, walk_start(r), scene.t0, scene.t1, true);
}

// The ray's start leaf when the origin lies strictly inside its box, else the root, as
// `ropes_plus_plus` in ropes.rs: on the boundary the neighbour holds the origin too (its
// primitives may touch it), and the descent from the root searches both.
fn walk_start(r: TRay) -> u32 {
    let s = r.ray.start;
    if (s == INVALID) { return 0u; }
    let b = leaf_boxes[leaf_number(s)];
    let o = ray_at(r.ray, r.ray.tmin);
    if (all(v3(b.min) < o) && all(o < v3(b.max))) { return s; }
    return 0u;
}
