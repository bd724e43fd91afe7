// RT2 WGSL prelude: the flat kd-tree and primitive arrays (byte-for-byte the CPU's, see
// src/gpu/layout.rs), the ray/hit vocabulary, intersection of every primitive kind and the
// pieces all traversals share (src/cpu/traverse/common.rs mirrored line by line, so that GPU
// and CPU agree on every split decision). Each kernel is this file + one traversal file +
// one entry-point file, concatenated by src/gpu/kernels.rs.
//
// Floating point: NaN and infinities carry meaning here (rays in split planes give NaN
// distances, zero direction components infinite reciprocals), and WGSL lets compilers assume
// neither exists. So NaN tests and sign tests read the bits, never `x != x` or `sign(x)`.

// `split` is read as bits: a leaf keeps its first primitive index there (`KdNode` in
// src/kdtree/mod.rs), which as a float is a subnormal that a shader compiler may flush.
struct KdNode { split: u32, bits: u32 }
struct RankWord { leaf_bits: u32, before: u32 }
struct Triangle { v0: array<f32, 3>, e1: array<f32, 3>, e2: array<f32, 3> }
struct Sphere { center: array<f32, 3>, radius: f32 }
struct Ellipsoid { center: array<f32, 3>, inv: array<f32, 9>, half: array<f32, 3>, sigma: f32, cof: array<f32, 9> }
struct Aabb { min: array<f32, 3>, max: array<f32, 3> }
struct Plane { normal: array<f32, 3>, offset: f32 }
struct Material {
    color: array<f32, 3>, ambient: f32, diffuse: f32, specular: f32, shininess: f32,
    reflectivity: f32, transparency: f32, ior: f32, checker: u32, color2: array<f32, 3>,
    scale: f32, pad: u32,
}
struct Light { position: array<f32, 3>, intensity: f32, color: array<f32, 3>, pad: f32 }
struct RayIn { org: array<f32, 3>, tmin: f32, dir: array<f32, 3>, tmax: f32 }
struct HitOut { t: f32, u: f32, v: f32, prim: u32 }
struct StatsOut { nodes: u32, leaves: u32, prims: u32, cut: u32 }
struct Item { org: array<f32, 3>, pixel: u32, dir: array<f32, 3>, depth: u32, weight: array<f32, 3>, skip: u32, start: u32 }
struct Params {
    bounds_min: vec4<f32>, bounds_max: vec4<f32>,
    eye: vec4<f32>, forward: vec4<f32>, right: vec4<f32>, up: vec4<f32>, background: vec4<f32>,
    n_tri: u32, n_sph: u32, n_ell: u32, n_box: u32,
    n_planes: u32, n_leaves: u32, n_lights: u32, short_stack: u32,
    count: u32, width: u32, height: u32, row0: u32,
    samples: u32, sample: u32, max_depth: u32, refract: u32,
    has_mask: u32, rope_bits: u32, excluding: u32, offset_mode: u32,
    scale: f32, min_weight: f32, probe_trips: u32, pad3: u32,
}

// Group 0: the committed scene, uploaded once per commit (src/gpu/scene.rs). Empty arrays
// are padded to one element (wgpu rejects zero-sized bindings); the counts live in Params.
@group(0) @binding(0) var<storage, read> nodes: array<KdNode>;          // kd-tree nodes
@group(0) @binding(1) var<storage, read> leaf_rank: array<RankWord>;   // leaf numbers (rope traversals)
@group(0) @binding(2) var<storage, read> prim_indices: array<u32>;      // leaf primitive lists
@group(0) @binding(3) var<storage, read> triangles: array<Triangle>;    // v0, e1, e2
@group(0) @binding(4) var<storage, read> spheres: array<Sphere>;        // centre, radius
@group(0) @binding(5) var<storage, read> ellipsoids: array<Ellipsoid>;  // centre, M^-1, half box, σ, cof(σ M^-1)
@group(0) @binding(6) var<storage, read> boxes: array<Aabb>;            // solid boxes
@group(0) @binding(7) var<storage, read> planes: array<Plane>;          // unbounded, outside the tree
@group(0) @binding(8) var<storage, read> ropes: array<u32>;             // packed, 6 per leaf (rope traversals)
@group(0) @binding(9) var<storage, read> leaf_boxes: array<Aabb>;      // per leaf (rope traversals)
@group(0) @binding(10) var<storage, read> prim_material: array<u32>;    // global prim -> material
@group(0) @binding(11) var<storage, read> materials: array<Material>;   // Phong/Whitted terms
@group(0) @binding(12) var<storage, read> lights: array<Light>;         // point lights

const INVALID: u32 = 0xffffffffu;
// Group 1 binding 0, per dispatch: scene sizes, camera, the job's size (layout.rs GpuParams).
@group(1) @binding(0) var<uniform> params: Params;
const WG: u32 = 64u;

fn inf() -> f32 { return bitcast<f32>(0x7f800000u); }
fn is_nan(x: f32) -> bool { return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u; }
// Sign bit set (true for -0.0): the CPU's `!is_sign_positive()`.
fn negative(x: f32) -> bool { return (bitcast<u32>(x) & 0x80000000u) != 0u; }
fn v3(a: array<f32, 3>) -> vec3<f32> { return vec3<f32>(a[0], a[1], a[2]); }
fn a3(v: vec3<f32>) -> array<f32, 3> { return array<f32, 3>(v.x, v.y, v.z); }
// A column-major 3x3 matrix (the ellipsoid's `inv` and `cof`).
fn m3(a: array<f32, 9>) -> mat3x3<f32> { return mat3x3<f32>(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8]); }

// Rust's f32::next_up for finite x: the smallest float above x.
fn next_up(x: f32) -> f32 {
    let b = bitcast<u32>(x);
    let a = b & 0x7fffffffu;
    if (a == 0u) { return bitcast<f32>(1u); }
    if (b == a) { return bitcast<f32>(b + 1u); }
    return bitcast<f32>(b - 1u);
}

// Global thread index of a 1-D job dispatched as a 2-D grid of 64-wide workgroups (the
// per-dimension workgroup limit is 65535; src/gpu/device.rs splits larger jobs).
fn flat_id(wid: vec3<u32>, lid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return (wid.y * nwg.x + wid.x) * WG + lid.x;
}

// Whether every loop this invocation ran ended by its own condition. Mesa's llvmpipe
// (lavapipe) counts the loop iterations of an invocation (a SIMD group of them, in lockstep)
// over all its loops and, past 65535, ends each loop at its next back edge, with no error
// (gallivm's loop limiter). This loop wants `params.probe_trips` (2) iterations, a count the
// compiler cannot see and so cannot unroll; once the limiter has run out it does not take its
// back edge. The answer is whether it did (`trips > 1`), not its exit condition, which a
// compiler may take as true after the loop. Called last, it tells a job cut short from one
// that was not (src/dispatch.rs SOFTWARE_LOOP_BUDGET); on drivers without such a limit it is
// always true.
fn loops_ran_to_the_end() -> bool {
    var trips = 0u;
    loop {
        trips += 1u;
        if (trips >= params.probe_trips) { break; }
    }
    return trips > 1u;
}

// `skip`: the global index of the primitive the ray ignores (`RayTest::exclude`; INVALID: none).
// `start`: a leaf node holding the ray's origin (`start_leaf`), where ropes++ starts its walk
// (`TraverseOptions::start_node`); INVALID, or ignored by the other traversals: the root.
struct Ray { org: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32, skip: u32, start: u32 }
struct TRay { ray: Ray, inv_dir: vec3<f32> }
struct Hit { t: f32, u: f32, v: f32, prim: u32 }
struct Stats { nodes: u32, leaves: u32, prims: u32 }

fn miss() -> Hit { return Hit(inf(), 0.0, 0.0, INVALID); }
fn tray(r: Ray) -> TRay { return TRay(r, vec3<f32>(1.0) / r.dir); }
fn ray_at(r: Ray, t: f32) -> vec3<f32> { return r.org + t * r.dir; }

// `Ray::is_degenerate`: such rays are misses that touch nothing.
fn degenerate(r: Ray) -> bool {
    let big = vec3<u32>(0x7f800000u);
    let o = (bitcast<vec3<u32>>(r.org) & vec3<u32>(0x7fffffffu)) >= big;
    let d = (bitcast<vec3<u32>>(r.dir) & vec3<u32>(0x7fffffffu)) >= big;
    let zero = all(r.dir == vec3<f32>(0.0));
    return any(o) || any(d) || zero || is_nan(r.tmin) || is_nan(r.tmax) || r.tmin > r.tmax;
}

// `TRay::dist`: the one formula for every plane distance.
fn dist(r: TRay, axis: u32, plane: f32) -> f32 { return (plane - r.ray.org[axis]) * r.inv_dir[axis]; }
fn positive(r: TRay, axis: u32) -> bool { return !negative(r.ray.dir[axis]); }

// `Hit::bound`: exclusive upper bound for candidates, just above the current hit so that an
// equal-t candidate still reaches the tie rule of `offer`.
fn bound(h: Hit, r: Ray) -> f32 {
    if (h.t < r.tmax) { return next_up(h.t); }
    return r.tmax;
}

// `Hit::offer`: closest wins, equal t goes to the lower primitive index.
fn offer(h: ptr<function, Hit>, t: f32, u: f32, v: f32, prim: u32) -> bool {
    if (t < (*h).t || (t == (*h).t && prim < (*h).prim)) {
        *h = Hit(t, u, v, prim);
        return true;
    }
    return false;
}

// ---- Primitives (src/geometry) ----

struct Tuv { ok: bool, t: f32, u: f32, v: f32 }

// Möller–Trumbore, as `Triangle::intersect`.
fn hit_triangle(tri: Triangle, r: Ray, tmax: f32) -> Tuv {
    let no = Tuv(false, 0.0, 0.0, 0.0);
    let e1 = v3(tri.e1);
    let e2 = v3(tri.e2);
    let p = cross(r.dir, e2);
    let det = dot(e1, p);
    if (det == 0.0 || (bitcast<u32>(det) & 0x7fffffffu) >= 0x7f800000u) { return no; }
    let inv = 1.0 / det;
    let s = r.org - v3(tri.v0);
    let u = dot(s, p) * inv;
    if (is_nan(u) || u < 0.0 || u > 1.0) { return no; }
    let q = cross(s, e1);
    let v = dot(r.dir, q) * inv;
    // A NaN v (an overflowing dot product) is a miss, as on the CPU.
    if (is_nan(v) || v < 0.0 || u + v > 1.0) { return no; }
    let t = dot(e2, q) * inv;
    if (!is_nan(t) && t >= r.tmin && t < tmax) { return Tuv(true, t, u, v); }
    return no;
}

// The power of two that brings m into [1, 2) (`power_of_two_scale`), but 2^-126 rather than the
// subnormal 2^-127 for m past 2^127 (GPUs may flush subnormals): [2, 4) there instead, as
// exact. 0 for a zero, negative, infinite or NaN m.
fn pow2_scale(m: f32) -> f32 {
    let exponent = (bitcast<u32>(m) >> 23u) & 0xffu;
    if (!(m > 0.0) || exponent == 255u) { return 0.0; }
    return bitcast<f32>((254u - min(exponent, 253u)) << 23u);
}

// `sphere_root` of src/geometry/analytic.rs: the nearest root in [tmin, tmax) of the ray
// o + t d (relative to the centre) with the sphere of squared radius r2. The discriminant comes
// from the centre-to-line distance (Ray Tracing Gems ch. 7), not from b² - ac, which cancels:
// its square is l2 where l2 >= 0 (the ellipsoid's `Line::Distance2`), else taken from o and d
// (`Line::Projected`; pass -1). The direction is solved scaled by a power of two for its
// largest component (d·d and d·d r² would over- or underflow for long or short directions),
// its roots scaled back; exact, so the roots are those of the unscaled direction wherever that
// one is finite (l2 does not depend on the direction's length). (The CPU skips the scaling
// where d·d and d·d r² are normal and o·d finite, which gives the same roots.)
fn sphere_root(o: vec3<f32>, d_in: vec3<f32>, l2: f32, r2: f32, tmin: f32, tmax: f32) -> Tuv {
    let no = Tuv(false, 0.0, 0.0, 0.0);
    let r = sphere_roots(o, d_in, l2, r2);
    if (!r.hit) { return no; }
    if (r.t0 >= tmin && r.t0 < tmax) { return Tuv(true, r.t0, 0.0, 0.0); }
    if (r.t1 >= tmin && r.t1 < tmax) { return Tuv(true, r.t1, 0.0, 0.0); }
    return no;
}

// Both roots of `sphere_root`, ascending (`sphere_roots` and `scaled_sphere_roots`): the
// direction scaled by a power of two for the solve, the roots scaled back.
struct Roots { hit: bool, t0: f32, t1: f32 }

fn sphere_roots(o: vec3<f32>, d_in: vec3<f32>, l2: f32, r2: f32) -> Roots {
    let no = Roots(false, 0.0, 0.0);
    let s = pow2_scale(max(abs(d_in.x), max(abs(d_in.y), abs(d_in.z))));
    if (s == 0.0) { return no; }
    let d = d_in * s;
    let a = dot(d, d);
    if (a == 0.0) { return no; }
    let b = dot(o, d);
    var dist2 = l2;
    if (!(l2 >= 0.0)) {
        let l = o - (b / a) * d;
        dist2 = dot(l, l);
    }
    let disc = a * (r2 - dist2);
    if (disc < 0.0 || is_nan(disc)) { return no; }
    let c = dot(o, o) - r2;
    let sgn = select(1.0, -1.0, negative(b));
    let q = -(b + sgn * sqrt(disc));
    var t0 = q / a;
    var t1 = q / a;
    if (q != 0.0) { t1 = c / q; }
    if (t0 > t1) { let x = t0; t0 = t1; t1 = x; }
    return Roots(true, t0 * s, t1 * s);
}

fn hit_sphere(s: Sphere, r: Ray, tmax: f32) -> Tuv {
    return sphere_root(r.org - v3(s.center), r.dir, -1.0, s.radius * s.radius, r.tmin, tmax);
}

fn max3(v: vec3<f32>) -> f32 { return max(v.x, max(v.y, v.z)); }

// `Ellipsoid::line_distance2`: the squared distance of the centre from the line o + t d (o
// relative to the centre) in unit space, |o_u × d_u|² / |d_u|², with o_u × d_u = cof(A) (o × d)
// for A = σ M⁻¹ and o scaled by 1/σ: the cross product taken in world space, where it is well
// conditioned (o_u of a thin ellipsoid seen from afar is ~distance/thickness long, and
// o_u - (b/a) d_u cancels to an error far past the radius 1). σ and cof(A) come with the
// ellipsoid (made once by `Ellipsoid::new`); both sides scaled by the largest component of
// σ d_u before squaring. inf (no hit) for a degenerate input. The cross product is taken from
// the line's point nearest the centre (a ray down a needle's axis: o nearly parallel to d).
fn ell_line_distance2(e: Ellipsoid, o: vec3<f32>, d: vec3<f32>, du: vec3<f32>) -> f32 {
    let kd = pow2_scale(max3(abs(d)));
    if (kd == 0.0) { return inf(); }
    // The direction scaled too (the ratio is unchanged): a long one overflows the cross product.
    let os = o / e.sigma;
    let ds = d * kd;
    let nearest = os - ds * (dot(os, ds) / dot(ds, ds));
    let finite = all(abs(nearest) < vec3<f32>(inf()));
    let w = m3(e.cof) * cross(select(os, nearest, finite), ds);
    let dus = du * e.sigma * kd;
    let k = pow2_scale(max3(abs(dus)));
    if (k == 0.0) { return inf(); }
    let wk = w * k;
    let dk = dus * k;
    return dot(wk, wk) / dot(dk, dk);
}

fn hit_ellipsoid(e: Ellipsoid, r: Ray, tmax: f32) -> Tuv {
    let m = m3(e.inv);
    let o = r.org - v3(e.center);
    let du = m * r.dir;
    let l2 = ell_line_distance2(e, o, r.dir, du);
    return sphere_root(m * o, du, l2, 1.0, r.tmin, tmax);
}

// `Aabb::clip_ray` over the whole line, then the first end inside [tmin, tmax) (`box_intersect`).
fn hit_box(b: Aabb, r: Ray, tmax: f32) -> Tuv {
    let no = Tuv(false, 0.0, 0.0, 0.0);
    let inv = vec3<f32>(1.0) / r.dir;
    var t0 = -inf();
    var t1 = inf();
    for (var a = 0u; a < 3u; a++) {
        let ta = (b.min[a] - r.org[a]) * inv[a];
        let tb = (b.max[a] - r.org[a]) * inv[a];
        // Near and far planes by the direction sign, as `Aabb::clip_ray`: a ray lying in a face
        // plane (NaN distance) is inside the closed slab for either sign of zero.
        var near = tb;
        var far = ta;
        if (!negative(inv[a])) { near = ta; far = tb; }
        if (near > t0) { t0 = near; }
        if (far < t1) { t1 = far; }
    }
    if (!(t0 <= t1)) { return no; }
    if (t0 >= r.tmin && t0 < tmax) { return Tuv(true, t0, 0.0, 0.0); }
    if (t1 >= r.tmin && t1 < tmax) { return Tuv(true, t1, 0.0, 0.0); }
    return no;
}

fn hit_plane(p: Plane, r: Ray, tmax: f32) -> Tuv {
    let n = v3(p.normal);
    let denom = dot(n, r.dir);
    if (denom == 0.0) { return Tuv(false, 0.0, 0.0, 0.0); }
    let t = (p.offset - dot(n, r.org)) / denom;
    return Tuv(t >= r.tmin && t < tmax, t, 0.0, 0.0);
}

// `PrimitiveSet::intersect`: bounded primitive `i` by its global index (kinds in the order
// triangles, spheres, ellipsoids, boxes).
fn intersect_prim(i: u32, r: Ray, h: ptr<function, Hit>) -> bool {
    if (i == r.skip) { return false; }
    let tmax = bound(*h, r);
    var k = i;
    var f: Tuv;
    if (k < params.n_tri) {
        f = hit_triangle(triangles[k], r, tmax);
    } else {
        k -= params.n_tri;
        if (k < params.n_sph) {
            f = hit_sphere(spheres[k], r, tmax);
        } else {
            k -= params.n_sph;
            if (k < params.n_ell) {
                f = hit_ellipsoid(ellipsoids[k], r, tmax);
            } else {
                f = hit_box(boxes[k - params.n_ell], r, tmax);
            }
        }
    }
    if (!f.ok) { return false; }
    return offer(h, f.t, f.u, f.v, i);
}

fn n_bounded() -> u32 { return params.n_tri + params.n_sph + params.n_ell + params.n_box; }

// `PrimitiveSet::intersect_planes`: plane k has global index n_bounded + k.
fn intersect_planes(r: Ray, h: ptr<function, Hit>) {
    let base = n_bounded();
    for (var k = 0u; k < params.n_planes; k++) {
        if (base + k == r.skip) { continue; }
        let f = hit_plane(planes[k], r, bound(*h, r));
        if (f.ok) { offer(h, f.t, 0.0, 0.0, base + k); }
    }
}

// ---- Traversal pieces (src/cpu/traverse/common.rs) ----

struct Seg { ok: bool, t0: f32, t1: f32 }

// `clip`: the ray's segment inside the closed scene box, near/far planes by direction sign.
fn clip_scene(r: TRay) -> Seg {
    var t0 = r.ray.tmin;
    var t1 = r.ray.tmax;
    for (var a = 0u; a < 3u; a++) {
        var near = params.bounds_max[a];
        var far = params.bounds_min[a];
        if (positive(r, a)) { near = params.bounds_min[a]; far = params.bounds_max[a]; }
        let tn = dist(r, a, near);
        let tf = dist(r, a, far);
        if (tn > t0) { t0 = tn; }
        if (tf < t1) { t1 = tf; }
    }
    return Seg(t0 <= t1 && t0 < inf(), t0, t1);
}

fn is_leaf(n: KdNode) -> bool { return (n.bits & 3u) == 3u; }
fn node_index(n: KdNode) -> u32 { return n.bits >> 2u; }
// A leaf's primitives: prim_indices[split .. split + count].
fn prim_count(n: KdNode) -> u32 { return n.bits >> 2u; }
// A leaf's number (`Ropes::leaf_number`): the leaves before leaf node `node`.
fn leaf_number(node: u32) -> u32 {
    let w = leaf_rank[node / 32u];
    let below = w.leaf_bits & ((1u << (node % 32u)) - 1u);
    return w.before + countOneBits(below);
}

// `kd_step` (`step` on the CPU): what the segment [t0, t1] does at an inner node. both == false: only `child`
// (the far child when the split is at or before t0 or the ray lies in the plane, else the
// near one). both == true: descend into `child` = near for [t0, t_split], `far` remains.
struct Crossing { both: bool, child: u32, far: u32, t_split: f32 }

fn kd_step(n: KdNode, r: TRay, t0: f32, t1: f32) -> Crossing {
    let axis = n.bits & 3u;
    let t_split = dist(r, axis, bitcast<f32>(n.split));
    let below = node_index(n);
    var near = below + 1u;
    var far = below;
    if (positive(r, axis)) { near = below; far = below + 1u; }
    if (t_split <= t0 || is_nan(t_split)) { return Crossing(false, far, far, t_split); }
    if (t_split >= t1) { return Crossing(false, near, far, t_split); }
    return Crossing(true, near, far, t_split);
}

// `Tracer::start_leaf`: for a traversal that starts secondary rays in the leaf of their origin
// (STARTS_IN_ORIGIN_LEAF, the first line of the module: ropes++), the leaf node holding p
// (`KdTree::locate_leaf`: below the plane when p[axis] <= split), located once for all the
// rays leaving p; INVALID for the others, which pay nothing. A descent that does not reach a
// leaf within the deepest tree the builders make gives INVALID too: the ray starts at the root.
fn start_leaf(p: vec3<f32>) -> u32 {
    if (!STARTS_IN_ORIGIN_LEAF) { return INVALID; }
    var node = 0u;
    for (var depth = 0u; depth <= STACK_SIZE; depth++) {
        let n = nodes[node];
        if (is_leaf(n)) { return node; }
        node = node_index(n) + select(0u, 1u, p[n.bits & 3u] > bitcast<f32>(n.split));
    }
    return INVALID;
}

// The leaf visit of both queries (`Closest` / `AnyHit`): true when the traversal can stop.
fn visit_leaf(leaf: KdNode, t_exit: f32, r: Ray, h: ptr<function, Hit>, any_hit: bool, st: ptr<function, Stats>) -> bool {
    (*st).leaves += 1u;
    for (var j = 0u; j < prim_count(leaf); j++) {
        let p = prim_indices[leaf.split + j];
        (*st).prims += 1u;
        if (any_hit) {
            var fresh = miss();
            if (intersect_prim(p, r, &fresh)) { *h = fresh; return true; }
        } else {
            intersect_prim(p, r, h);
        }
    }
    return !any_hit && (*h).t < t_exit;
}

// A subtree still to traverse for [t0, t1].
struct Entry { node: u32, t0: f32, t1: f32 }

// Deepest tree the builders make (MAX_DEPTH_LIMIT): at most one pending entry per level.
const STACK_SIZE: u32 = 64u;
// MAX_SHORT_STACK of the CPU; larger requests are clamped alike.
const SHORT_STACK_MAX: u32 = 32u;

// `traverse::intersect`: planes first (their hit bounds the tree search), then the tree with
// the kernel's traversal (`traverse`, defined by the traversal file).
fn closest_hit(r: Ray, st: ptr<function, Stats>) -> Hit {
    var h = miss();
    if (degenerate(r)) { return h; }
    intersect_planes(r, &h);
    traverse(tray(r), &h, false, st);
    return h;
}

// `traverse::occluded`: any hit in [tmin, tmax).
fn occluded(r: Ray, st: ptr<function, Stats>) -> bool {
    if (degenerate(r)) { return false; }
    var h = miss();
    intersect_planes(r, &h);
    if (h.prim != INVALID) { return true; }
    traverse(tray(r), &h, true, st);
    return h.prim != INVALID;
}
