// Standard traversal (thesis algorithm 2; Jansen, Havran's TA-B), as
// src/cpu/traverse/standard.rs: descend to the nearest leaf pushing the far child of every
// node both children of which the segment crosses; after a leaf, pop. The stack is a private
// array as deep as the deepest tree the builders make.
fn traverse(r: TRay, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) {
    let scene = clip_scene(r);
    if (!scene.ok) { return; }
    var stack: array<Entry, STACK_SIZE>;
    stack[0] = Entry(0u, scene.t0, scene.t1);
    var sp = 1u;
    while (sp > 0u) {
        sp -= 1u;
        let e = stack[sp];
        var node = e.node;
        var t1 = e.t1;
        loop {
            let n = nodes[node];
            (*st).nodes += 1u;
            if (is_leaf(n)) { break; }
            let c = kd_step(n, r, e.t0, t1);
            if (c.both) {
                if (sp < STACK_SIZE) { stack[sp] = Entry(c.far, c.t_split, t1); sp += 1u; }
                t1 = c.t_split;
            }
            node = c.child;
        }
        if (visit_leaf(nodes[node], t1, r.ray, h, any_hit, st)) { return; }
    }
}
