// Ropes++ (the thesis' algorithm 8): exits from the three planes the direction selects and an
// entry-only scene test, completed at the first leaf (a ray leaving it before entering it
// missed the scene; `rope_walk` clips the box in the rare cases where rounding could make
// ropes++ disagree with the others). Every ray starts at the root, as on the CPU's render
// and query paths.
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    let t_entry = entry_three_faces(r);
    if (t_entry > r.ray.tmax) { return; }
    rope_walk(r, h, any_hit, st, 0u, t_entry, r.ray.tmax, true, true);
}
