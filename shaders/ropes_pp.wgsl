// Ropes++ (the thesis' algorithm 8): exits from the three planes the direction selects. The
// scene box is clipped as the other traversals clip it, not tested for its entry only (see
// `ropes_plus_plus` in ropes.rs). Every ray starts at the root, as on the CPU's query paths:
// the thesis' start of secondary rays in the leaf of their origin is the CPU's depth-first
// render's alone (`Tracer::start_leaf` in whitted.rs).
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    let scene = clip_scene(r);
    if (!scene.ok) { return; }
    rope_walk(r, h, any_hit, st, 0u, scene.t0, scene.t1, true);
}
