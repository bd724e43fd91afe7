// push-down (algorithm 4): restart from the deepest node holding the rest of the segment. The loop is restart.wgsl's.
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    restart_traverse(r, h, any_hit, st, 0u, true);
}
