// The restart family of Foley & Sugerman (2005) and Horn et al. (2007): thesis algorithms 3
// (kd-restart), 4 (push-down), 5 (short-stack) and 6 (push-down + short-stack), one loop
// with two parameters as in src/cpu/traverse/restart.rs. A short stack of size 0 never pops;
// without push-down the restart root stays the tree root. Each traversal's own file is one
// call to this function.
fn restart_traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>, short_size: u32, push_down_on: bool) {
    let scene = clip_scene(r);
    if (!scene.ok) { return; }
    // Circular short stack: a push onto a full stack overwrites the oldest entry.
    var stack: array<Entry, SHORT_STACK_MAX>;
    let cap = min(short_size, SHORT_STACK_MAX);
    var top = 0u;
    var len = 0u;
    var root = 0u;
    var t_max = scene.t0;
    for (var visit = 0u; visit < params.n_leaves; visit++) {
        var node = root;
        var t0 = t_max;
        var t1 = scene.t1;
        var push_down = push_down_on;
        if (len > 0u) {
            len -= 1u;
            let e = stack[top];
            top = (top + cap - 1u) % cap;
            node = e.node;
            t0 = e.t0;
            t1 = e.t1;
            push_down = false;
        }
        loop {
            let n = nodes[node];
            (*st).nodes += 1u;
            if (is_leaf(n)) { break; }
            let c = kd_step(n, r, t0, t1);
            if (c.both) {
                push_down = false;
                if (cap > 0u) {
                    top = (top + 1u) % cap;
                    stack[top] = Entry(c.far, c.t_split, t1);
                    len = min(len + 1u, cap);
                }
                t1 = c.t_split;
            } else if (push_down) {
                root = c.child;
            }
            node = c.child;
        }
        if (visit_leaf(nodes[node], t1, r.ray, h, any_hit, st) || t1 >= scene.t1) { return; }
        t_max = t1;
    }
}
