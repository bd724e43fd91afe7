// push-down + short-stack (algorithm 6): both combined. The loop is restart.wgsl's.
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    restart_traverse(r, h, any_hit, st, params.short_stack, true);
}
