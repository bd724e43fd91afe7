// Batch ray queries (rt2_intersect / rt2_occluded): one thread per ray.
@group(1) @binding(1) var<storage, read> rays: array<RayIn>;           // the batch (.rays records)
@group(1) @binding(2) var<storage, read_write> hits: array<HitOut>;    // one answer per ray
@group(1) @binding(3) var<storage, read_write> stats: array<StatsOut>; // work per ray, and whether the driver cut it short
// The primitive each ray ignores, read when params.excluding is set (else another buffer of
// the job is bound here, and not read).
@group(1) @binding(4) var<storage, read> excludes: array<u32>;

fn load_ray(i: u32) -> Ray {
    let q = rays[i];
    var skip = INVALID;
    if (params.excluding != 0u) { skip = excludes[i]; }
    return Ray(v3(q.org), v3(q.dir), q.tmin, q.tmax, skip, INVALID);
}

@compute @workgroup_size(64)
fn intersect_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count) { return; }
    var st = Stats(0u, 0u, 0u);
    let h = closest_hit(load_ray(i), &st);
    hits[i] = HitOut(h.t, h.u, h.v, h.prim);
    stats[i] = StatsOut(st.nodes, st.leaves, st.prims, select(1u, 0u, loops_ran_to_the_end()));
}

@compute @workgroup_size(64)
fn occluded_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count) { return; }
    var st = Stats(0u, 0u, 0u);
    let blocked = occluded(load_ray(i), &st);
    hits[i] = HitOut(0.0, 0.0, 0.0, select(INVALID, 0u, blocked));
    stats[i] = StatsOut(st.nodes, st.leaves, st.prims, select(1u, 0u, loops_ran_to_the_end()));
}
