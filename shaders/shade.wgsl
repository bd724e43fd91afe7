// Whitted shading, the WGSL twin of src/shading.rs and Tracer::radiance in
// src/cpu/whitted.rs: Phong with point lights and hard shadows, mirror reflection,
// transparency straight or refracted (Snell + Schlick). Both render paths call `shade` for one
// ray and get its local colour and up to two child rays.

// glam's normalize_or_zero: times the reciprocal length, zero when that is not finite.
fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let r = 1.0 / sqrt(dot(v, v));
    if ((bitcast<u32>(r) & 0x7fffffffu) < 0x7f800000u && r > 0.0) { return v * r; }
    return vec3<f32>(0.0);
}

// Rust's powf for the Phong exponent: pow(0, 0) = 1 and pow(0, y) = 0 without log2(0).
fn powf(x: f32, y: f32) -> f32 {
    if (y == 0.0) { return 1.0; }
    if (x <= 0.0) { return 0.0; }
    return pow(x, y);
}

fn reflect_dir(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> { return d - 2.0 * dot(d, n) * n; }

// `refract`: the direction and the Fresnel reflectance; w < 0 signals total internal
// reflection.
fn refract_dir(d: vec3<f32>, n: vec3<f32>, eta: f32) -> vec4<f32> {
    let cos_i = -dot(d, n);
    let sin2_t = eta * eta * max(1.0 - cos_i * cos_i, 0.0);
    if (sin2_t > 1.0) { return vec4<f32>(0.0, 0.0, 0.0, -1.0); }
    let cos_t = sqrt(1.0 - sin2_t);
    let t = normalize_or_zero(eta * d + (eta * cos_i - cos_t) * n);
    return vec4<f32>(t, schlick(cos_i, cos_t, eta));
}

// `shading::schlick`: the cosine on the less dense side.
fn schlick(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    let a = (1.0 - eta) / (1.0 + eta);
    let r0 = a * a;
    let x = 1.0 - clamp(select(cos_i, cos_t, eta > 1.0), 0.0, 1.0);
    let x2 = x * x;
    return r0 + (1.0 - r0) * (x2 * x2 * x);
}

fn phong(m: Material, base: vec3<f32>, p: vec3<f32>, n: vec3<f32>, view: vec3<f32>, light: Light) -> vec3<f32> {
    let l = unit_or_zero(v3(light.position) - p);
    let ndotl = dot(n, l);
    // `shading::phong`: a light of intensity 0 adds nothing, even where the colours overflow.
    if (ndotl <= 0.0 || light.intensity == 0.0) { return vec3<f32>(0.0); }
    let r = reflect_dir(-l, n);
    let spec = powf(max(dot(r, view), 0.0), m.shininess);
    return (m.diffuse * ndotl * base + vec3<f32>(m.specular * spec)) * v3(light.color) * light.intensity;
}

// `box_face`: the box face nearest to p by distance, as (axis, whether it is the max face).
fn box_face(b: Aabb, p: vec3<f32>) -> vec2<u32> {
    let below = p - v3(b.min);
    let above = v3(b.max) - p;
    let gap = min(below, above);
    var axis = 2u;
    if (gap.x <= gap.y && gap.x <= gap.z) { axis = 0u; } else if (gap.y <= gap.z) { axis = 1u; }
    return vec2<u32>(axis, select(0u, 1u, above[axis] <= below[axis]));
}

// Outward normal of the box face nearest to p (`box_normal`).
fn box_normal(b: Aabb, p: vec3<f32>) -> vec3<f32> {
    let f = box_face(b, p);
    var n = vec3<f32>(0.0);
    n[f.x] = select(-1.0, 1.0, f.y == 1u);
    return n;
}

// `box_on_surface`: p moved onto the box face nearest to it.
fn box_on_surface(b: Aabb, p: vec3<f32>) -> vec3<f32> {
    let f = box_face(b, p);
    var q = clamp(p, v3(b.min), v3(b.max));
    q[f.x] = select(v3(b.min), v3(b.max), f.y == 1u)[f.x];
    return q;
}

// `Triangle::unit_normal`: e1 × e2 normalised. Where its square leaves the normal range (edges
// below about 1e-10 or above about 1e10) each edge is first scaled by a power of two, which
// keeps the direction, and the product divided by its largest component (`geometry::unit`).
// The CPU takes those, and slivers (sin² of the angle between the edges below 2^-12), in f64;
// WGSL has no f64, so a sliver's normal here keeps the f32 cancellation (about 2^-23 / sin θ
// rad: 0.02 rad at sin θ = 2e-6) and may differ from the CPU's by that much.
fn triangle_normal(t: Triangle) -> vec3<f32> {
    let n = cross(v3(t.e1), v3(t.e2));
    if (square_is_normal(n)) { return normalize_or_zero(n); }
    return unit_or_zero(cross(scaled_edge(v3(t.e1)), scaled_edge(v3(t.e2))));
}

// Whether |v|² is a normal float: `normalize_or_zero` is then exact to rounding.
fn square_is_normal(v: vec3<f32>) -> bool {
    let l2 = bitcast<u32>(dot(v, v)) & 0x7fffffffu;
    return l2 >= 0x00800000u && l2 < 0x7f800000u;
}

// `v` normalised, or zero for a zero or non-finite vector: plainly where its square is a
// normal float (`normalize_or_zero`'s bits), else divided by its largest component first
// (`geometry::unit`), as the square under- or overflows.
fn unit_or_zero(v: vec3<f32>) -> vec3<f32> {
    if (square_is_normal(v)) { return normalize_or_zero(v); }
    let k = max3(abs(v));
    if (!(k > 0.0) || (bitcast<u32>(k) & 0x7fffffffu) >= 0x7f800000u) { return vec3<f32>(0.0); }
    return normalize_or_zero(v / k);
}

// `shading::distance`: |v|, also where its square leaves the normal range (a light 2e19
// away squared to infinity).
fn distance_of(v: vec3<f32>) -> f32 {
    if (square_is_normal(v)) { return length(v); }
    let k = max3(abs(v));
    if (!(k > 0.0) || (bitcast<u32>(k) & 0x7fffffffu) >= 0x7f800000u) { return k; }
    return k * length(v / k);
}

// An edge scaled by the power of two that brings its largest component near 1 (kept as it is
// where there is none: a zero edge).
fn scaled_edge(e: vec3<f32>) -> vec3<f32> {
    let s = pow2_scale(max3(abs(e)));
    return e * select(1.0, s, s > 0.0);
}

// `PrimitiveSet::normal`: geometric normal at p, not oriented towards the ray.
fn prim_normal(i: u32, p: vec3<f32>) -> vec3<f32> {
    let nb = n_bounded();
    if (i >= nb) { return normalize_or_zero(v3(planes[i - nb].normal)); }
    var k = i;
    if (k < params.n_tri) { return triangle_normal(triangles[k]); }
    k -= params.n_tri;
    if (k < params.n_sph) { return normalize_or_zero(p - v3(spheres[k].center)); }
    k -= params.n_sph;
    if (k < params.n_ell) {
        let m = m3(ellipsoids[k].inv);
        return quadric_normal(m, m * (p - v3(ellipsoids[k].center)));
    }
    return box_normal(boxes[k - params.n_ell], p);
}

// `quadric_normal`: the gradient M⁻ᵀ u of the quadric |M⁻¹ x| = 1 at unit-space point u,
// normalised (its square overflows for semi-axes below about 5e-20: `unit_or_zero`).
fn quadric_normal(m: mat3x3<f32>, u: vec3<f32>) -> vec3<f32> {
    return unit_or_zero(transpose(m) * u);
}

// A shading point and geometric normal; ok is false where a re-solve failed.
struct Surface { ok: bool, p: vec3<f32>, n: vec3<f32> }

// `resolve_quadric` of src/geometry/analytic.rs, operation for operation (its doc says why):
// the hit at t of the ray oc + s d (oc relative to the centre) on |M⁻¹ x| = 1, re-solved from
// q = oc + t d in unit space, not from the rounded world point; the point relative to the
// centre and the normal from the unit-space point. `sphere_roots` scales the direction by the
// power of two k and scales the roots back, as the CPU does.
fn resolve_quadric(m: mat3x3<f32>, oc: vec3<f32>, d: vec3<f32>, t: f32, tmin: f32) -> Surface {
    let no = Surface(false, vec3<f32>(0.0), vec3<f32>(0.0));
    let q = oc + t * d;
    let u = m * q;
    let du = m * d;
    let k = pow2_scale(max3(abs(du)));
    if (k == 0.0) { return no; }
    let dk = du * k;
    let roots = sphere_roots(u, du, -1.0, 1.0);
    var s = -(dot(u, dk) / dot(dk, dk)) * k;
    if (roots.hit) {
        // f32::EPSILON = 2^-23.
        if (roots.t1 - roots.t0 <= 4.0 * abs(t) * 1.1920929e-7) {
            let start = m * (oc + tmin * d);
            let l = dot(start, start);
            let entering = (bitcast<u32>(tmin) & 0x7fffffffu) >= 0x7f800000u || l > 1.0 || is_nan(l);
            s = select(roots.t1, roots.t0, entering);
        } else {
            s = select(roots.t0, roots.t1, abs(roots.t1) < abs(roots.t0));
        }
    }
    let point = q + s * d;
    let n = quadric_normal(m, u + s * du);
    if (!finite3(point) || all(n == vec3<f32>(0.0))) { return no; }
    return Surface(true, point, n);
}

// `PrimitiveSet::quadric_surface_f32`: `resolve_quadric` for a sphere (M⁻¹ = I / r) or an
// ellipsoid, in world space; not ok for other kinds.
fn quadric_surface(h: Hit, r: Ray) -> Surface {
    let no = Surface(false, vec3<f32>(0.0), vec3<f32>(0.0));
    if (h.prim < params.n_tri || h.prim >= n_bounded()) { return no; }
    var k = h.prim - params.n_tri;
    var m: mat3x3<f32>;
    var c: vec3<f32>;
    if (k < params.n_sph) {
        let i = 1.0 / spheres[k].radius;
        m = mat3x3<f32>(i, 0.0, 0.0, 0.0, i, 0.0, 0.0, 0.0, i);
        c = v3(spheres[k].center);
    } else {
        k -= params.n_sph;
        if (k >= params.n_ell) { return no; }
        m = m3(ellipsoids[k].inv);
        c = v3(ellipsoids[k].center);
    }
    let s = resolve_quadric(m, r.org - c, r.dir, h.t, r.tmin);
    let p = c + s.p;
    if (!s.ok || !finite3(p)) { return no; }
    return Surface(true, p, s.n);
}

// `Material::color_at`: the checkerboard by the parity of floor(p / scale) summed.
fn color_at(m: Material, p: vec3<f32>) -> vec3<f32> {
    if (m.checker == 0u) { return v3(m.color); }
    let q = floor(p / m.scale);
    var s = (q.x + q.y + q.z) % 2.0;
    if (s < 0.0) { s += 2.0; }
    return select(v3(m.color2), v3(m.color), s < 1.0);
}

// ---- Secondary-ray origins (src/precision.rs, `Tracer::surface` and `Tracer::leave`) ----

// `OffsetMode` values in Params.offset_mode.
const OFFSET_EPSILON: u32 = 0u;
const OFFSET_ROBUST: u32 = 1u;

// `offset_ray_origin` (Wächter & Binder): 256 ULPs along n per coordinate, or 2^-16 · scale
// for coordinates below scale / 32.
fn offset_ray_origin(p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let scale = params.scale;
    var out = p;
    for (var a = 0u; a < 3u; a++) {
        if (abs(p[a]) < scale / 32.0) {
            out[a] = p[a] + (scale / 65536.0) * n[a];
        } else {
            // Adding to the bit pattern moves away from zero for either sign of p.
            var of_i = i32(256.0 * n[a]);
            if (p[a] < 0.0) { of_i = -of_i; }
            out[a] = bitcast<f32>(bitcast<i32>(p[a]) + of_i);
        }
    }
    return out;
}

// Rust's Vec3::is_finite: no component infinite or NaN.
fn finite3(v: vec3<f32>) -> bool {
    return all((bitcast<vec3<u32>>(v) & vec3<u32>(0x7fffffffu)) < vec3<u32>(0x7f800000u));
}

// `PrimitiveSet::shading_surface`: the point (`org + t·dir`, or recomputed on the surface
// where on_surface) and geometric normal the render shades; a sphere's or ellipsoid's
// re-solved relative to its centre.
fn shading_surface(h: Hit, r: Ray, on_surface: bool) -> Surface {
    let p = ray_at(r, h.t);
    let quad = quadric_surface(h, r);
    if (quad.ok) { return Surface(true, select(p, quad.p, on_surface), quad.n); }
    var q = p;
    if (on_surface) { q = flat_point(h, p); }
    return Surface(true, q, prim_normal(h.prim, q));
}

// `PrimitiveSet::flat_point`: p (`org + t·dir`) recomputed on the surface, from the
// barycentrics for triangles; projected onto a plane, snapped onto a box face; kept for a
// sphere or ellipsoid.
fn flat_point(h: Hit, p: vec3<f32>) -> vec3<f32> {
    let nb = n_bounded();
    if (h.prim >= nb) {
        let pl = planes[h.prim - nb];
        let n = v3(pl.normal);
        return p - (dot(n, p) - pl.offset) * n;
    }
    if (h.prim < params.n_tri) {
        let t = triangles[h.prim];
        return v3(t.v0) + h.u * v3(t.e1) + h.v * v3(t.e2);
    }
    let k = h.prim - params.n_tri;
    if (k < params.n_sph + params.n_ell) { return p; }
    return box_on_surface(boxes[k - params.n_sph - params.n_ell], p);
}

// `PrimitiveSet::is_flat`: triangles and planes.
fn is_flat(i: u32) -> bool { return i < params.n_tri || i >= n_bounded(); }

// Where a secondary ray leaving point p of primitive `prim` (outward normal n_geo) into the
// side of the unit normal `side` starts, and the primitive it ignores.
struct Origin { org: vec3<f32>, skip: u32 }

fn leave(p: vec3<f32>, prim: u32, n_geo: vec3<f32>, side: vec3<f32>) -> Origin {
    if (params.offset_mode == OFFSET_EPSILON) { return Origin(p + params.background.w * side, INVALID); }
    // Exclude-prim: leaving a flat primitive, or a convex one to its outside, never meets it
    // again; entering a curved one takes the robust offset.
    if (params.offset_mode != OFFSET_ROBUST && (is_flat(prim) || dot(side, n_geo) > 0.0)) {
        return Origin(p, prim);
    }
    return Origin(offset_ray_origin(p, side), INVALID);
}

// `start`: the leaf of `org` where it was located (`start_leaf`), else INVALID.
struct Child { ok: bool, org: vec3<f32>, dir: vec3<f32>, w: vec3<f32>, skip: u32, start: u32 }
// One ray's work: its contribution and its children (transmitted, mirror), in the order the
// CPU pushes them onto its stack of pending rays.
struct Shaded { color: vec3<f32>, transmitted: Child, mirror: Child }

fn child(o: Origin, dir: vec3<f32>, w: vec3<f32>, start: u32) -> Child {
    return Child(max(w.x, max(w.y, w.z)) >= params.min_weight, o.org, dir, w, o.skip, start);
}

fn shade(r: Ray, weight: vec3<f32>, depth: u32) -> Shaded {
    let none = Child(false, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), INVALID, INVALID);
    var out = Shaded(vec3<f32>(0.0), none, none);
    var st = Stats(0u, 0u, 0u);
    // Secondary rays (below the primary's depth) start in the leaf of their origin (ropes++),
    // located here unless the parent located it already (`Child::start`).
    var traced = r;
    if (depth > 1u && r.start == INVALID) { traced.start = start_leaf(r.org); }
    let hit = closest_hit(traced, &st);
    if (hit.prim == INVALID) {
        out.color = weight * params.background.xyz;
        return out;
    }
    let m = materials[prim_material[hit.prim]];
    let eps = params.background.w;
    // The fixed epsilon keeps `org + t·dir`; the other modes start on the surface.
    let surface = shading_surface(hit, r, params.offset_mode != OFFSET_EPSILON);
    let p = surface.p;
    let n_geo = surface.n;
    let entering = dot(n_geo, r.dir) < 0.0;
    let n = select(-n_geo, n_geo, entering);
    // Sampled just inside the surface (behind the primitive's own normal), as on the CPU: no
    // flicker on a checker boundary, and one colour from either side.
    let base = color_at(m, p - eps * n_geo);
    let local_weight = 1.0 - m.reflectivity - m.transparency;
    // The leaf of the shadow rays' origin, which the mirror ray leaves from too.
    var above_leaf = INVALID;
    if (local_weight > 0.0) {
        var local = m.ambient * base;
        let above = leave(p, hit.prim, n_geo, n);
        // Every shadow ray leaves from the same point: its leaf is located once.
        above_leaf = start_leaf(above.org);
        for (var k = 0u; k < params.n_lights; k++) {
            let light = lights[k];
            let to_light = v3(light.position) - above.org;
            // `Tracer::shadow_rays`: a light beyond ~1.8e19 squares to infinity.
            let d = distance_of(to_light);
            let dir = select(unit_or_zero(to_light), to_light / d, square_is_normal(to_light));
            let shadow = Ray(above.org, dir, 0.0, d, above.skip, above_leaf);
            if (d > 0.0 && !occluded(shadow, &st)) {
                local += phong(m, base, p, n, -r.dir, light);
            }
        }
        out.color = weight * local_weight * local;
    }
    if (depth >= params.max_depth) { return out; }
    var mirror = m.reflectivity;
    if (m.transparency > 0.0) {
        if (params.refract == 0u) {
            out.transmitted = child(leave(p, hit.prim, n_geo, -n), r.dir, weight * m.transparency, INVALID);
        } else {
            let eta = select(m.ior, 1.0 / m.ior, entering);
            let t = refract_dir(r.dir, n, eta);
            if (t.w >= 0.0) {
                let f = t.w;
                mirror += m.transparency * f;
                let w = weight * (m.transparency * (1.0 - f));
                out.transmitted = child(leave(p, hit.prim, n_geo, -n), t.xyz, w, INVALID);
            } else {
                mirror += m.transparency;
            }
        }
    }
    if (mirror > 0.0) {
        // Leaves from where the shadow rays did (`above`): their leaf is its leaf.
        let o = leave(p, hit.prim, n_geo, n);
        out.mirror = child(o, reflect_dir(r.dir, n), weight * mirror, above_leaf);
    }
    return out;
}

// The sample positions of whitted.rs: `mix`, `stratified`, `pixel_offset`, `lens_offset`
// (a stratified grid jittered by a hash; the lens deals the cells to the samples in an order
// shuffled per pixel by Kensler's `permute`).
fn mix(x: u32, y: u32, s: u32, k: u32) -> u32 {
    var v = (x * 0x9E3779B1u) ^ (y * 0x85EBCA77u) ^ (s * 0xC2B2AE3Du) ^ k;
    v ^= v >> 16u;
    v *= 0x7FEB352Du;
    v ^= v >> 15u;
    v *= 0x846CA68Bu;
    return v ^ (v >> 16u);
}

fn stratified(x: u32, y: u32, s: u32, cell: u32, side: u32, salt: u32) -> vec2<f32> {
    let h1 = f32(mix(x, y, s, 1u ^ salt) >> 8u) / f32(1u << 24u);
    let h2 = f32(mix(x, y, s, 2u ^ salt) >> 8u) / f32(1u << 24u);
    return vec2<f32>((f32(cell % side) + h1) / f32(side), (f32(cell / side) + h2) / f32(side));
}

// `side` of whitted.rs: the smallest k with k² >= n, the float root corrected in integers.
fn side_of(n: u32) -> u32 {
    var k = u32(ceil(sqrt(f32(n))));
    if (k > 1u && (k - 1u) * (k - 1u) >= n) { k -= 1u; }
    if (k * k < n) { k += 1u; }
    return k;
}

fn pixel_offset(x: u32, y: u32, s: u32, n: u32) -> vec2<f32> {
    if (n == 1u) { return vec2<f32>(0.5, 0.5); }
    let k = side_of(n);
    if (k * k == n) { return stratified(x, y, s, s, k, 0u); }
    // n-rooks for counts that are not squares (whitted.rs `pixel_offset`).
    let col = permute(s, n, mix(x, y, 0u, 0x68e31da4u));
    return stratified(x, y, s, s * n + col, n, 0x68e31da4u);
}

fn permute(index: u32, l: u32, p: u32) -> u32 {
    var w = l - 1u;
    w |= w >> 1u; w |= w >> 2u; w |= w >> 4u; w |= w >> 8u; w |= w >> 16u;
    var i = index;
    loop {
        i ^= p;
        i *= 0xe170893du;
        i ^= p >> 16u;
        i ^= (i & w) >> 4u;
        i ^= p >> 8u;
        i *= 0x0929eb3fu;
        i ^= p >> 23u;
        i ^= (i & w) >> 1u;
        i *= 1u | (p >> 27u);
        i *= 0x6935fa69u;
        i ^= (i & w) >> 11u;
        i *= 0x74dcb303u;
        i ^= (i & w) >> 2u;
        i *= 0x9e501cc3u;
        i ^= (i & w) >> 2u;
        i *= 0xc860a3dfu;
        i &= w;
        i ^= i >> 5u;
        if (i < l) { break; }
    }
    return (i + p % l) % l;
}

fn lens_offset(x: u32, y: u32, s: u32, n: u32) -> vec2<f32> {
    let side = side_of(n);
    let cell = permute(s, side * side, mix(x, y, 0u, 0x5bd1e995u));
    return stratified(x, y, s, cell, side, 0x5bd1e995u);
}

// `CameraRays::ray`: pinhole or thin lens.
fn camera_ray(pixel: vec2<f32>, lens: vec2<f32>) -> Ray {
    let size = vec2<f32>(f32(params.width), f32(params.height));
    let ndc = vec2<f32>(2.0 * pixel.x / size.x - 1.0, 1.0 - 2.0 * pixel.y / size.y);
    let fwd = params.forward.xyz;
    let right = params.right.xyz;
    let up = params.up.xyz;
    let dir = normalize_or_zero(fwd + (ndc.x * params.right.w) * right + (ndc.y * params.up.w) * up);
    let eye = params.eye.xyz;
    let aperture = params.eye.w;
    if (aperture == 0.0) { return Ray(eye, dir, 0.0, inf(), INVALID, INVALID); }
    let focus_point = eye + dir * (params.forward.w / dot(dir, fwd));
    let rad = 0.5 * aperture * sqrt(lens.x);
    let phi = 6.28318530717958647692 * lens.y;
    let org = eye + rad * (cos(phi) * right + sin(phi) * up);
    let lens_dir = normalize_or_zero(focus_point - org);
    if (all(lens_dir == vec3<f32>(0.0))) { return Ray(eye, dir, 0.0, inf(), INVALID, INVALID); }
    return Ray(org, lens_dir, 0.0, inf(), INVALID, INVALID);
}

// Primary ray of sample s of the chunk's pixel i.
fn primary(i: u32, s: u32) -> Ray {
    let g = params.row0 * params.width + i;
    let x = g % params.width;
    let y = g / params.width;
    let pixel = vec2<f32>(f32(x), f32(y)) + pixel_offset(x, y, s, params.samples);
    let lens = lens_offset(x, y, s, params.samples);
    return camera_ray(pixel, lens);
}

// RGBA8 in memory order r, g, b, 255 (little-endian u32).
fn pack(sum: vec3<f32>) -> u32 {
    let c = clamp(sum / f32(params.samples), vec3<f32>(0.0), vec3<f32>(1.0)) * 255.0 + 0.5;
    let b = vec3<u32>(c);
    return b.x | (b.y << 8u) | (b.z << 16u) | (255u << 24u);
}
