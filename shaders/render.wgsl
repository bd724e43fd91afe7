// The two render paths of thesis §3.3 over shade.wgsl. Group 1 of the megakernel: bindings
// 0-2; of the wavefront kernels: bindings 0 and 2-7 (src/gpu/render.rs makes both layouts).
@group(1) @binding(1) var<storage, read_write> frame: array<u32>;        // RGBA8 per chunk pixel
@group(1) @binding(2) var<storage, read> mask: array<u32>;               // HUD mask, 0 = skip
@group(1) @binding(3) var<storage, read_write> queue: array<Item>;       // rays of this wave
@group(1) @binding(4) var<storage, read_write> slots: array<Item>;       // 2 child slots per ray
@group(1) @binding(5) var<storage, read_write> scan: array<u32>;         // slot flags -> prefix sums
@group(1) @binding(6) var<storage, read_write> contrib: array<vec4<f32>>; // colour per ray
@group(1) @binding(7) var<storage, read_write> accum: array<vec4<f32>>;  // colour sum per pixel

fn masked(i: u32) -> bool { return params.has_mask != 0u && mask[i] == 0u; }

// A pixel as the frame holds it: alpha 0 marks one whose work the driver cut short
// (`loops_ran_to_the_end`), which src/gpu/render.rs refuses to show.
fn pixel(sum: vec3<f32>, cut: bool) -> u32 {
    return select(pack(sum), pack(sum) & 0x00ffffffu, cut);
}

struct Pending { org: vec3<f32>, dir: vec3<f32>, w: vec3<f32>, depth: u32, skip: u32, start: u32 }
// Longest pending list: each pop pushes at most two, so it grows by one per level at most.
const PENDING_MAX: u32 = 72u;

// Megakernel: one thread per pixel runs the whole iterative Whitted loop of
// Tracer::radiance (a stack of pending rays, popped last in first out).
@compute @workgroup_size(64)
fn megakernel(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count || masked(i)) { return; }
    var sum = vec3<f32>(0.0);
    var pending: array<Pending, PENDING_MAX>;
    for (var s = 0u; s < params.samples; s++) {
        let r0 = primary(i, s);
        var color = vec3<f32>(0.0);
        pending[0] = Pending(r0.org, r0.dir, vec3<f32>(1.0), 1u, INVALID, INVALID);
        var sp = 1u;
        while (sp > 0u) {
            sp -= 1u;
            let q = pending[sp];
            let sh = shade(Ray(q.org, q.dir, 0.0, inf(), q.skip, q.start), q.w, q.depth);
            color += sh.color;
            if (sh.transmitted.ok && sp < PENDING_MAX) {
                let t = sh.transmitted;
                pending[sp] = Pending(t.org, t.dir, t.w, q.depth + 1u, t.skip, t.start);
                sp += 1u;
            }
            if (sh.mirror.ok && sp < PENDING_MAX) {
                let m = sh.mirror;
                pending[sp] = Pending(m.org, m.dir, m.w, q.depth + 1u, m.skip, m.start);
                sp += 1u;
            }
        }
        sum += color;
    }
    frame[i] = pixel(sum, !loops_ran_to_the_end());
}

// ---- Wavefront: one kernel per bounce, live rays compacted by a prefix sum ----

fn item(org: vec3<f32>, pixel: u32, dir: vec3<f32>, depth: u32, w: vec3<f32>, skip: u32, start: u32) -> Item {
    return Item(a3(org), pixel, a3(dir), depth, a3(w), skip, start);
}

// Primary rays of sample `params.sample` into the child slots (slot 2i, flag set unless
// masked), so that the first wave is compacted like every other. Clears the sums first.
@compute @workgroup_size(64)
fn wave_generate(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count) { return; }
    if (params.sample == 0u) { accum[i] = vec4<f32>(0.0); }
    let r = primary(i, params.sample);
    slots[2u * i] = item(r.org, i, r.dir, 1u, vec3<f32>(1.0), INVALID, INVALID);
    scan[2u * i] = select(1u, 0u, masked(i));
    scan[2u * i + 1u] = 0u;
}

// One bounce: shade every ray of the wave; children go to its two slots.
@compute @workgroup_size(64)
fn wave_trace(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count) { return; }
    let q = queue[i];
    let sh = shade(Ray(v3(q.org), v3(q.dir), 0.0, inf(), q.skip, q.start), v3(q.weight), q.depth);
    // w: 1 when the driver cut this ray short, summed per pixel by wave_accumulate.
    contrib[i] = vec4<f32>(sh.color, select(1.0, 0.0, loops_ran_to_the_end()));
    let t = sh.transmitted;
    let m = sh.mirror;
    slots[2u * i] = item(t.org, q.pixel, t.dir, q.depth + 1u, t.w, t.skip, t.start);
    slots[2u * i + 1u] = item(m.org, q.pixel, m.dir, q.depth + 1u, m.w, m.skip, m.start);
    scan[2u * i] = select(0u, 1u, t.ok);
    scan[2u * i + 1u] = select(0u, 1u, m.ok);
}

// Adds the wave's colours to the pixel sums. Compaction keeps the order of the rays, so the
// rays of one pixel are neighbours; the first of each run sums the run, so every pixel has
// one writer and no atomics on floats are needed.
@compute @workgroup_size(64)
fn wave_accumulate(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count) { return; }
    let pixel = queue[i].pixel;
    if (i > 0u && queue[i - 1u].pixel == pixel) { return; }
    var sum = vec4<f32>(0.0);
    for (var j = i; j < params.count && queue[j].pixel == pixel; j++) {
        sum += contrib[j];
    }
    accum[pixel] += sum;
}

// Moves every flagged slot to its place in the next wave: the inclusive prefix sum of the
// flags is one past its index. `params.count` is the number of slots here.
@compute @workgroup_size(64)
fn wave_compact(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let j = flat_id(wid, lid, nwg);
    if (j >= params.count) { return; }
    let incl = scan[j];
    var prev = 0u;
    if (j > 0u) { prev = scan[j - 1u]; }
    if (incl > prev && incl - 1u < arrayLength(&queue)) { queue[incl - 1u] = slots[j]; }
}

// Sums over samples into RGBA8 (alpha 0 where a ray of the pixel was cut short).
@compute @workgroup_size(64)
fn wave_finalize(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i >= params.count || masked(i)) { return; }
    frame[i] = pixel(accum[i].xyz, accum[i].w != 0.0);
}
