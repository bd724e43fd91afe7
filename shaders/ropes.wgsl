// Ropes (Popov et al. 2007; thesis algorithm 7): the scene box clipped first, every leaf exit
// from all six planes of the leaf box.
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    let scene = clip_scene(r);
    if (!scene.ok) { return; }
    rope_walk(r, h, any_hit, st, 0u, scene.t0, scene.t1, false);
}
