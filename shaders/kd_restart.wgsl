// kd-restart (algorithm 3): no stack; after each leaf, restart from the root. The loop is restart.wgsl's.
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    restart_traverse(r, h, any_hit, st, 0u, false);
}
