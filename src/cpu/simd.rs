//! SIMD lane width, the triangle tests of the vectorised-traversal paper (Noguera & Ureña,
//! seeds/000, "intersección rayo–triángulo": the precomputed 1 ray × 4 triangles variant, and N
//! rays × 1 triangle for the leaves that many rays of a stream or packet reach), for
//! Möller–Trumbore and the watertight test, and the stream compaction.
//!
//! The code is portable: fixed-size `[f32; N]` lanes written as straight-line loops that LLVM
//! turns into vector instructions; only the compaction, the lane masks ([`lanes_less`]) and the
//! gathers of rays' values by index ([`gather_columns`]) have x86 intrinsics, each with a
//! portable loop. [`dispatch`] picks `N` at run time from the CPU's
//! features and runs the whole kernel (traversal included, inlined) inside a `#[target_feature]`
//! function, so the same source becomes SSE (4 lanes), AVX2 (8) or AVX-512 (16) code. A function
//! the kernel calls without inlining is compiled without those features: hot code here avoids
//! `array::map` and `array::from_fn` with large elements, whose closures LLVM left as calls.

use super::batch::{for_lanes, lanes_where};
use crate::geometry::{
    shear_axes, watertight, watertight_f32, Hit, PrimIndex, PrimitiveSet, Ray, RayTest,
    TriangleTest, INVALID,
};
use crate::precision::Intersector;

/// Lane width of packets, stream lists and triangle blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Width {
    /// SSE2, every x86-64 (and the portable fallback elsewhere).
    W4,
    /// AVX2 (with POPCNT, which every AVX2 CPU has).
    W8,
    /// AVX-512F (with POPCNT).
    W16,
}

impl Width {
    pub const ALL: [Width; 3] = [Width::W4, Width::W8, Width::W16];

    pub fn lanes(self) -> usize {
        match self {
            Width::W4 => 4,
            Width::W8 => 8,
            Width::W16 => 16,
        }
    }

    /// Whether this CPU runs the width's instructions.
    pub fn supported(self) -> bool {
        match self {
            Width::W4 => true,
            #[cfg(target_arch = "x86_64")]
            Width::W8 => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("popcnt")
            }
            #[cfg(target_arch = "x86_64")]
            Width::W16 => {
                std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("popcnt")
            }
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// The width used by default: the widest this CPU runs. On the Intel Xeon with AVX-512
    /// used for BENCHMARKS.md, 16 lanes beat 8 on coherent rays (`rt2 bench streams`, bunny
    /// primary set: packets 8.68 against 7.29 Mrays/s, streams 10.55 against 8.22) and match
    /// them on incoherent ones; on an AMD EPYC (Zen 4, which runs 512-bit operations as two
    /// halves) they were within noise of 8, so the wider width costs nothing there.
    pub fn best() -> Width {
        [Width::W16, Width::W8]
            .into_iter()
            .find(|w| w.supported())
            .unwrap_or(Width::W4)
    }
}

/// Proof that this CPU runs `N`-lane instructions: made by [`dispatch`] after its feature check
/// and handed to the [`Kernel`], or by [`Isa::baseline`] for one and four lanes (portable code,
/// and SSE, which every x86-64 has). The lane compares and the compaction take it instead of
/// checking the CPU's features at every call: that check (a load and a branch per compare,
/// with a scalar fallback LLVM had to keep beside each) cost 12% of the instructions of 8-lane
/// packets and streams.
#[derive(Clone, Copy, Debug)]
pub struct Isa<const N: usize>(());

impl<const N: usize> Isa<N> {
    /// The proof for widths every CPU runs (1 and 4 lanes).
    pub fn baseline() -> Self {
        const { assert!(N <= 4, "only 1 and 4 lanes run everywhere") };
        Isa(())
    }

    /// The proof for `M` lanes, which one for at least as many gives (a CPU with AVX-512F has
    /// AVX2, which [`dispatch`]'s 16-lane kernel is compiled for); `None` when `M > N`.
    pub fn narrow<const M: usize>(self) -> Option<Isa<M>> {
        (M <= N).then_some(Isa(()))
    }
}

/// A computation generic over the lane width, run by [`dispatch`] with the proof that the CPU
/// runs that width.
pub trait Kernel {
    type Out;
    fn run<const N: usize>(self, isa: Isa<N>) -> Self::Out;
}

/// Runs `k` with `width` lanes, compiled for the instruction set of that width. Everything the
/// kernel calls in its hot loop is `#[inline(always)]`, so it is compiled with the wrapper's
/// target features. A width the CPU lacks falls back to the portable 4 lanes.
pub fn dispatch<K: Kernel>(width: Width, k: K) -> K::Out {
    #[cfg(target_arch = "x86_64")]
    {
        if width == Width::W16 && width.supported() {
            // SAFETY: the CPU has AVX-512F and POPCNT (checked just above).
            return unsafe { run_avx512(k) };
        }
        if width == Width::W8 && width.supported() {
            // SAFETY: the CPU has AVX2 and POPCNT (checked just above).
            return unsafe { run_avx2(k) };
        }
    }
    let _ = width;
    k.run::<4>(Isa::baseline())
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn run_avx2<K: Kernel>(k: K) -> K::Out {
    // The caller checked AVX2 and POPCNT: the proof for 8 lanes.
    k.run::<8>(Isa(()))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,popcnt")]
unsafe fn run_avx512<K: Kernel>(k: K) -> K::Out {
    // The caller checked AVX-512F and POPCNT: the proof for 16 lanes.
    k.run::<16>(Isa(()))
}

/// N triangles in structure-of-arrays form: per lane, the three rows the block's test reads
/// ([`PrimitiveSet::triangle_rows`]: Möller–Trumbore's `v0, e1, e2`, or the watertight test's
/// corners). Unused lanes hold a zero triangle, whose determinant is 0: never hit.
#[derive(Clone, Copy, Debug)]
pub struct TriBlock<const N: usize> {
    /// `rows[r][axis][lane]`.
    rows: [[[f32; N]; 3]; 3],
    prim: [PrimIndex; N],
}

impl<const N: usize> TriBlock<N> {
    const EMPTY: Self = TriBlock {
        rows: [[[0.0; N]; 3]; 3],
        prim: [INVALID; N],
    };

    /// The triangles `ids` (the first N, every one a triangle index) as `intersector` reads
    /// them; lanes past `ids.len()` hold the zero triangle and `INVALID`.
    #[inline(always)]
    pub fn from_prims(set: &PrimitiveSet, ids: &[u32], intersector: Intersector) -> Self {
        const ZERO: [[f32; 3]; 3] = [[0.0; 3]; 3];
        let stored: [&[[f32; 3]; 3]; N] = std::array::from_fn(|l| {
            ids.get(l)
                .map_or(&ZERO, |&p| set.stored_rows(p as usize, intersector))
        });
        // Each column built whole (in registers) rather than lane by lane in memory: a vector
        // load of lanes just stored one by one waits for the stores to drain (no forwarding),
        // which cost a tenth of a single ray's time.
        let column = |r: usize, a: usize| -> [f32; N] { std::array::from_fn(|l| stored[l][r][a]) };
        let mut rows = [
            [column(0, 0), column(0, 1), column(0, 2)],
            [column(1, 0), column(1, 1), column(1, 2)],
            [column(2, 0), column(2, 1), column(2, 2)],
        ];
        if set.rebuilds_corners(intersector) {
            // `PrimitiveSet::triangle_rows`'s corners, `v0 + e1` and `v0 + e2`, lane by lane.
            let [v0, e1, e2] = &mut rows;
            for edge in [e1, e2] {
                for (e, v) in edge.iter_mut().zip(v0.iter()) {
                    for (e, v) in e.iter_mut().zip(v) {
                        *e += v;
                    }
                }
            }
        }
        TriBlock {
            rows,
            prim: std::array::from_fn(|l| ids.get(l).copied().unwrap_or(INVALID)),
        }
    }

    /// Closest-hit test of one ray against the block, offered to `hit` lane by lane. Every lane
    /// does the scalar test's operations in the same order (no fused multiply-add), so `t`,
    /// `u`, `v` are bit-identical to the single-ray path.
    #[inline(always)]
    pub fn intersect(&self, isa: Isa<N>, ray: &Ray, test: &RayTest, hit: &mut Hit) {
        let tmax = hit.bound(ray);
        let (t, u, v) = self.lanes(ray, test, tmax);
        // The lanes hit, as one mask first: a test per lane inside the loop lets LLVM move the
        // whole computation into per-lane branches.
        let hits = lanes_less(isa, &t, &[f32::INFINITY; N]);
        for_lanes(hits, |l| {
            hit.offer(t[l], u[l], v[l], self.prim[l]);
        });
    }

    /// Any-hit test: the mask of the lanes hit in `[tmin, tmax)` (0: none). The lowest one is
    /// where a search in leaf order stops, for the statistics.
    #[inline(always)]
    pub fn occluders(&self, isa: Isa<N>, ray: &Ray, test: &RayTest) -> u32 {
        let (t, _, _) = self.lanes(ray, test, ray.tmax);
        lanes_less(isa, &t, &[f32::INFINITY; N])
    }

    /// The test `test` asks for on every lane; `t = inf` marks a miss, and the excluded
    /// primitive is missed.
    #[inline(always)]
    fn lanes(&self, ray: &Ray, test: &RayTest, tmax: f32) -> ([f32; N], [f32; N], [f32; N]) {
        let (o, d) = (ray.org.to_array(), ray.dir.to_array());
        let (mut t, mut u, mut v) = ([0.0; N], [0.0; N], [0.0; N]);
        let row = |r: usize, l: usize| [self.rows[r][0][l], self.rows[r][1][l], self.rows[r][2][l]];
        let rows = |l: usize| [row(0, l), row(1, l), row(2, l)];
        match test.triangle {
            TriangleTest::MollerTrumbore => {
                for l in 0..N {
                    (t[l], u[l], v[l]) = moller_trumbore(rows(l), o, d, ray.tmin, tmax);
                }
            }
            TriangleTest::Watertight { k, s } => {
                let mut exact = [false; N];
                for l in 0..N {
                    (t[l], u[l], v[l], exact[l]) = watertight_f32(rows(l), o, k, s, ray.tmin, tmax);
                }
                // The padding's zero triangle has zero edge functions too, and is never hit.
                let redo = lanes_where::<N>(|l| exact[l] && self.prim[l] != INVALID);
                for_lanes(redo, |l| {
                    (t[l], u[l], v[l]) =
                        watertight(rows(l), ray, k, s, tmax).unwrap_or((f32::INFINITY, 0.0, 0.0));
                });
            }
        }
        if test.exclude != INVALID {
            for (t, &p) in t.iter_mut().zip(&self.prim) {
                if p == test.exclude {
                    *t = f32::INFINITY;
                }
            }
        }
        (t, u, v)
    }
}

/// One ray against one triangle (`rows`: `v0, e1, e2`) with the scalar
/// [`Triangle::intersect`]'s operations in the same order (no fused multiply-add), its
/// rejections as masks rather than early returns, so `t`, `u`, `v` are bit-identical to the
/// single-ray path; `t = inf` marks a miss. Both lane orders ([`TriBlock`]: 1 ray × N
/// triangles, [`RayLanes`]: N rays × 1 triangle) run it per lane.
///
/// [`Triangle::intersect`]: crate::geometry::Triangle::intersect
#[inline(always)]
fn moller_trumbore(
    [v0, [e1x, e1y, e1z], [e2x, e2y, e2z]]: [[f32; 3]; 3],
    o: [f32; 3],
    d: [f32; 3],
    tmin: f32,
    tmax: f32,
) -> (f32, f32, f32) {
    // p = dir × e2 (glam's Vec3::cross order), det = e1 · p.
    let px = d[1] * e2z - e2y * d[2];
    let py = d[2] * e2x - e2z * d[0];
    let pz = d[0] * e2y - e2x * d[1];
    let det = (e1x * px) + (e1y * py) + (e1z * pz);
    let inv = 1.0 / det;
    let sx = o[0] - v0[0];
    let sy = o[1] - v0[1];
    let sz = o[2] - v0[2];
    let u = ((sx * px) + (sy * py) + (sz * pz)) * inv;
    // q = s × e1
    let qx = sy * e1z - e1y * sz;
    let qy = sz * e1x - e1z * sx;
    let qz = sx * e1y - e1x * sy;
    let v = ((d[0] * qx) + (d[1] * qy) + (d[2] * qz)) * inv;
    let t = ((e2x * qx) + (e2y * qy) + (e2z * qz)) * inv;
    // `det * 0.0 == 0.0` is `det.is_finite()` (inf and NaN give NaN): written so, LLVM tested
    // every lane's bits with integer instructions, 15% of a single ray's instructions.
    let ok = (det != 0.0)
        & (det * 0.0 == 0.0)
        & (0.0..=1.0).contains(&u)
        & (v >= 0.0)
        & (u + v <= 1.0)
        & (t >= tmin)
        & (t < tmax);
    (if ok { t } else { f32::INFINITY }, u, v)
}

/// N rays in structure-of-arrays form, for the leaves of a stream and those a packet's rays
/// reach at least one per two primitives: the rays are tested N at a time against each
/// triangle in turn (broadcast, not gathered).
/// SAH leaves hold ~2 triangles per visit, so a [`TriBlock`] of N lanes is mostly padding.
pub struct RayLanes<const N: usize> {
    pub org: [[f32; N]; 3],
    pub dir: [[f32; N]; 3],
    pub tmin: [f32; N],
    pub tmax: [f32; N],
}

/// The per-ray part of every lane's triangle test ([`TriangleTest`] in structure-of-arrays
/// form), computed once per leaf visit of the lanes.
pub enum LaneTests<const N: usize> {
    MollerTrumbore,
    Watertight { k: [[u32; N]; 3], s: [[f32; N]; 3] },
}

impl<const N: usize> RayLanes<N> {
    /// The rays `rays[ids[l]]` (an index past the end reads the last ray: lanes past a list's
    /// end hold stale indices).
    #[inline(always)]
    pub fn gather(isa: Isa<N>, rays: &[Ray], ids: &[u32; N]) -> Self {
        // A ray is the row `org, dir, tmin, tmax` of eight floats (`repr(C)`).
        let rows: &[[f32; 8]] = bytemuck::cast_slice(rays);
        let [ox, oy, oz, dx, dy, dz, tmin, tmax] =
            gather_columns(isa, rows, [0, 1, 2, 3, 4, 5, 6, 7], ids);
        RayLanes {
            org: [ox, oy, oz],
            dir: [dx, dy, dz],
            tmin,
            tmax,
        }
    }

    /// Lane `l`'s origin and direction.
    #[inline(always)]
    fn ray(&self, l: usize) -> ([f32; 3], [f32; 3]) {
        let (o, d) = (&self.org, &self.dir);
        ([o[0][l], o[1][l], o[2][l]], [d[0][l], d[1][l], d[2][l]])
    }

    /// Every lane's per-ray setup of `intersector`'s test.
    #[inline(always)]
    pub fn tests(&self, intersector: Intersector) -> LaneTests<N> {
        match intersector {
            Intersector::MollerTrumbore => LaneTests::MollerTrumbore,
            Intersector::Watertight => {
                let (mut k, mut s) = ([[0; N]; 3], [[0.0; N]; 3]);
                for l in 0..N {
                    let (kl, sl) = shear_axes(self.ray(l).1);
                    for a in 0..3 {
                        (k[a][l], s[a][l]) = (kl[a], sl[a]);
                    }
                }
                LaneTests::Watertight { k, s }
            }
        }
    }

    /// The test `tests` of every lane against the triangle `rows` ([`PrimitiveSet::triangle_rows`]
    /// for the same intersector), candidates below `tmax` per lane; `t = inf` marks a miss.
    ///
    /// Measured and dropped: for lanes sharing an origin (a pinhole camera's rays), the
    /// origin's part of Möller–Trumbore (`s`, `q = s × e1`, `t`'s numerator) computed once per
    /// triangle rather than per lane, bit-identical, made 16-lane packets 3–8% slower on the
    /// bunny's 1024² primary rays: these tests wait on loads and the division, not on
    /// arithmetic.
    #[inline(always)]
    pub fn triangle(
        &self,
        rows: [[f32; 3]; 3],
        tests: &LaneTests<N>,
        tmax: &[f32; N],
    ) -> ([f32; N], [f32; N], [f32; N]) {
        let (mut t, mut u, mut v) = ([0.0; N], [0.0; N], [0.0; N]);
        match tests {
            LaneTests::MollerTrumbore => {
                for l in 0..N {
                    let (o, d) = self.ray(l);
                    (t[l], u[l], v[l]) = moller_trumbore(rows, o, d, self.tmin[l], tmax[l]);
                }
            }
            LaneTests::Watertight { k, s } => {
                let mut exact = [false; N];
                let lane = |l: usize| ([k[0][l], k[1][l], k[2][l]], [s[0][l], s[1][l], s[2][l]]);
                for l in 0..N {
                    let (kl, sl) = lane(l);
                    (t[l], u[l], v[l], exact[l]) =
                        watertight_f32(rows, self.ray(l).0, kl, sl, self.tmin[l], tmax[l]);
                }
                for_lanes(lanes_where::<N>(|l| exact[l]), |l| {
                    let ((o, d), (kl, sl)) = (self.ray(l), lane(l));
                    let ray = Ray::new(o.into(), d.into(), self.tmin[l], tmax[l]);
                    (t[l], u[l], v[l]) = watertight(rows, &ray, kl, sl, tmax[l]).unwrap_or((
                        f32::INFINITY,
                        0.0,
                        0.0,
                    ));
                });
            }
        }
        (t, u, v)
    }
}

/// Fewest rays at a leaf for which its triangles are gathered into N-lane blocks once for all of
/// them (a packet's leaf that few of its rays reach; streams test their leaves N rays per
/// triangle). Gathering costs about as much as testing each triangle once, and SAH leaves hold
/// ~3 triangles, so one or two rays take the single-ray leaf test instead, which gathers 4
/// triangles per ray (measured when streams still used it: on the bunny's sets this rule took
/// 8-lane streams from 1.13× to 1.34× the single-ray speed on primary rays; incoherent rays
/// were within noise).
pub const GATHER_MIN_RAYS: usize = 3;

/// Reused buffers for a leaf's primitives prepared once per leaf visit for all the rays that
/// reach it (`gather`), so a traversal allocates nothing per node.
#[derive(Default)]
pub struct LeafPrims<const N: usize> {
    blocks: Vec<TriBlock<N>>,
    others: Vec<u32>,
}

impl<const N: usize> LeafPrims<N> {
    /// The leaf `prims` in whole blocks made by [`TriBlock::from_prims`] (columns built in
    /// registers: these blocks are read at once, by a ray or two), or `None` when it holds
    /// other primitives than triangles.
    #[inline(always)]
    pub fn whole_blocks<'a>(
        &'a mut self,
        set: &PrimitiveSet,
        prims: &[u32],
        intersector: Intersector,
    ) -> Option<PreparedLeaf<'a, N>> {
        if prims.iter().any(|&p| p as usize >= set.triangles.len()) {
            return None;
        }
        self.blocks.clear();
        for group in prims.chunks(N) {
            self.blocks
                .push(TriBlock::from_prims(set, group, intersector));
        }
        Some(PreparedLeaf {
            blocks: &self.blocks,
            others: &[],
            count: prims.len(),
        })
    }
}

/// A leaf prepared by [`LeafPrims::gather`]: triangles in [`TriBlock`]s, the rest as indices for
/// the single-ray leaf test (`traverse::closest_among`).
pub struct PreparedLeaf<'a, const N: usize> {
    pub blocks: &'a [TriBlock<N>],
    pub others: &'a [u32],
    /// Primitive tests one ray costs here (for the statistics).
    pub count: usize,
}

impl<const N: usize> LeafPrims<N> {
    /// Prepares the leaf `prims` for `rays` rays. Gathering costs about one triangle test per
    /// triangle, so for fewer than [`GATHER_MIN_RAYS`] rays every primitive stays an index, read
    /// from the tree's own list (copying it was a library call per leaf visit).
    ///
    /// Lanes are written one by one into the reused blocks rather than built by
    /// [`TriBlock::from_prims`], which suits a block tested at once by one ray: these blocks
    /// are read by several rays well after the stores, and building them through
    /// `from_prims` (after splitting off the other kinds) made 8-ray packets slower.
    #[inline(always)]
    pub fn gather<'a>(
        &'a mut self,
        set: &PrimitiveSet,
        prims: &'a [u32],
        rays: usize,
        intersector: Intersector,
    ) -> PreparedLeaf<'a, N> {
        if rays < GATHER_MIN_RAYS {
            return PreparedLeaf {
                blocks: &[],
                others: prims,
                count: prims.len(),
            };
        }
        self.blocks.clear();
        self.others.clear();
        let mut lane = N;
        for &p in prims {
            if p as usize >= set.triangles.len() {
                self.others.push(p);
                continue;
            }
            if lane == N {
                self.blocks.push(TriBlock::EMPTY);
                lane = 0;
            }
            let b = self.blocks.last_mut().expect("a block was just pushed");
            let rows = set.triangle_rows(p as usize, intersector);
            for (dst, row) in b.rows.iter_mut().zip(&rows) {
                for (d, &x) in dst.iter_mut().zip(row) {
                    d[lane] = x;
                }
            }
            b.prim[lane] = p;
            lane += 1;
        }
        PreparedLeaf {
            blocks: &self.blocks,
            others: &self.others,
            count: prims.len(),
        }
    }
}

/// Columns of rows picked by ray index: lane `l` of column `k` is `rows[ids[l]][columns[k]]`
/// (an index past the end reads the last row: lanes past a list's end hold stale indices).
/// The stream's hot loop picks every ray's origin and reciprocal direction on a node's axis this
/// way, and the leaves their rays. AVX2 and AVX-512 use the CPU's gather instruction (one per
/// column, or per pair of columns at 16 lanes: below); other widths and CPUs take a lane loop.
/// Against that loop, 16-lane streams ran 1.05–1.10× as fast on the bunny's incoherent, primary
/// and diffuse sets and the dragon's incoherent and primary sets, 8-lane streams 0.97–1.08× and
/// packets 0.97–1.03× (Intel Xeon with AVX-512, the loop and the gathers alternating in one
/// process, medians of 11–15 runs; not measured on AMD). At 16 lanes two neighbouring columns (a
/// ray's origin and reciprocal direction on an axis, or two floats of a ray) are gathered as one
/// 8-byte element per lane: half the elements, for two permutes. Against a gather per column,
/// 16-lane packets ran 1.02× as fast on the bunny's 1024² primary rays, 16-lane streams 1.00–1.04×
/// on its 256² primary and incoherent sets and the dragon's 256² primary set (AMD EPYC, medians of
/// 5 alternating runs of two builds, each within ±10% noise).
#[inline(always)]
pub fn gather_columns<const N: usize, const S: usize, const K: usize>(
    _: Isa<N>,
    rows: &[[f32; S]],
    columns: [usize; K],
    ids: &[u32; N],
) -> [[f32; N]; K] {
    assert!(!rows.is_empty() && columns.iter().all(|&c| c < S));
    #[cfg(target_arch = "x86_64")]
    {
        // The instructions' indices are signed 32-bit element offsets.
        let fits = rows.len() * S <= i32::MAX as usize;
        if N == 16 && fits {
            // SAFETY: an `Isa<16>` exists only where the CPU has AVX-512F; the rows are not
            // empty, every column lies in a row and every element offset fits an `i32`.
            return unsafe { x86::gather16(rows, columns, ids) };
        }
        if N == 8 && fits {
            // SAFETY: an `Isa<8>` exists only where the CPU has AVX2; as above.
            return unsafe { x86::gather8(rows, columns, ids) };
        }
    }
    let last = rows.len() - 1;
    let mut out = [[0.0; N]; K];
    for (o, &c) in out.iter_mut().zip(&columns) {
        for (x, &id) in o.iter_mut().zip(ids) {
            *x = rows[(id as usize).min(last)][c];
        }
    }
    out
}

/// Asks the cache for the line holding `x` (a hint: never faults, no effect off x86-64). The
/// stream touches its rays in index order with gaps, which the hardware prefetchers do not follow.
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing the program sees and cannot fault; `x` is a live reference.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((x as *const T).cast());
    }
}

/// The mask of the lanes where `a[l] < b[l]` (false for NaN), from one vector compare: written
/// as a loop over lanes, LLVM stored the lanes of a freshly computed `a` and read them back
/// shifted by one lane, a load the store could not forward to (7% of an 8-ray packet's time).
#[inline(always)]
pub fn lanes_less<const N: usize>(isa: Isa<N>, a: &[f32; N], b: &[f32; N]) -> u32 {
    lanes_compare::<N, LESS>(isa, a, b)
}

/// The mask of the lanes where `a[l] <= b[l]` (false for NaN), as [`lanes_less`].
#[inline(always)]
pub fn lanes_less_eq<const N: usize>(isa: Isa<N>, a: &[f32; N], b: &[f32; N]) -> u32 {
    lanes_compare::<N, LESS_EQ>(isa, a, b)
}

/// The comparisons of [`lanes_compare`], numbered as x86's `_CMP_LT_OQ` and `_CMP_LE_OQ`.
const LESS: i32 = 17;
const LESS_EQ: i32 = 18;

/// The mask of the lanes where `a[l] P b[l]`, `P` one of [`LESS`] and [`LESS_EQ`].
#[inline(always)]
fn lanes_compare<const N: usize, const P: i32>(_: Isa<N>, a: &[f32; N], b: &[f32; N]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        if N == 4 {
            // SAFETY: SSE is part of x86-64; the slices hold 4 lanes.
            return unsafe { x86::compare4::<N, P>(a, b) };
        }
        if N == 8 {
            // SAFETY: an `Isa<8>` exists only where the CPU has AVX2 (so AVX).
            return unsafe { x86::compare8::<N, P>(a, b) };
        }
        if N == 16 {
            // SAFETY: an `Isa<16>` exists only where the CPU has AVX-512F.
            return unsafe { x86::compare16::<N, P>(a, b) };
        }
    }
    if P == LESS {
        lanes_where::<N>(|l| a[l] < b[l])
    } else {
        lanes_where::<N>(|l| a[l] <= b[l])
    }
}

/// Stream compaction (the paper's "compactación" of the near and far lists): writes the lanes of
/// each `src` column whose bit is set in `keep` to the front of the matching `dst` column, in
/// lane order; the rest of `dst[..N]` gets unspecified lanes of `src`. Every `dst` has room for
/// N lanes. AVX2 permutes by a table of the 256 masks, AVX-512 has `vpcompressd` (into a register:
/// its store form is slow on AMD Zen 4); other widths and CPUs take the portable lane loop.
#[inline(always)]
pub fn compress<const N: usize, const K: usize>(
    _: Isa<N>,
    keep: u32,
    src: [&[u32; N]; K],
    dst: [&mut [u32]; K],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if N == 8 {
            // SAFETY: an `Isa<8>` exists only where the CPU has AVX2.
            return unsafe { x86::compress8(keep, src, dst) };
        }
        if N == 16 {
            // SAFETY: an `Isa<16>` exists only where the CPU has AVX-512F.
            return unsafe { x86::compress16(keep, src, dst) };
        }
    }
    for (s, d) in src.into_iter().zip(dst) {
        let d = &mut d[..N];
        let mut w = 0;
        for (l, &x) in s.iter().enumerate() {
            // Branch-free: every lane is written, the position steps by its flag.
            d[w.min(N - 1)] = x;
            w += (keep >> l & 1) as usize;
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    const _: () = assert!(super::LESS == _CMP_LT_OQ && super::LESS_EQ == _CMP_LE_OQ);

    /// For each 8-bit mask, the indices of its set bits in order, one nibble each (lowest first).
    const PERM8: [u32; 256] = {
        let mut t = [0u32; 256];
        let mut m = 0;
        while m < 256 {
            let (mut l, mut w, mut packed) = (0, 0, 0u32);
            while l < 8 {
                if m >> l & 1 == 1 {
                    packed |= (l as u32) << (4 * w);
                    w += 1;
                }
                l += 1;
            }
            t[m] = packed;
            m += 1;
        }
        t
    };

    /// [`super::compress`] for 8 lanes: one table look-up per mask, one permute per column.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn compress8<const N: usize, const K: usize>(
        keep: u32,
        src: [&[u32; N]; K],
        dst: [&mut [u32]; K],
    ) {
        let packed = _mm256_set1_epi32(PERM8[(keep & 0xff) as usize] as i32);
        let idx = _mm256_and_si256(
            _mm256_srlv_epi32(packed, _mm256_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28)),
            _mm256_set1_epi32(15),
        );
        for (s, d) in src.into_iter().zip(dst) {
            assert!(N == 8 && d.len() >= 8);
            let v = _mm256_loadu_si256(s.as_ptr().cast());
            _mm256_storeu_si256(d.as_mut_ptr().cast(), _mm256_permutevar8x32_epi32(v, idx));
        }
    }

    /// [`super::lanes_compare`] for 4 lanes (SSE has no compare taking the predicate).
    #[inline]
    pub(super) unsafe fn compare4<const N: usize, const P: i32>(a: &[f32; N], b: &[f32; N]) -> u32 {
        assert!(N == 4);
        let (a, b) = (_mm_loadu_ps(a.as_ptr()), _mm_loadu_ps(b.as_ptr()));
        let m = if P == _CMP_LT_OQ {
            _mm_cmplt_ps(a, b)
        } else {
            _mm_cmple_ps(a, b)
        };
        _mm_movemask_ps(m) as u32
    }

    /// [`super::lanes_compare`] for 8 lanes.
    #[inline]
    #[target_feature(enable = "avx")]
    pub(super) unsafe fn compare8<const N: usize, const P: i32>(a: &[f32; N], b: &[f32; N]) -> u32 {
        assert!(N == 8);
        let (a, b) = (_mm256_loadu_ps(a.as_ptr()), _mm256_loadu_ps(b.as_ptr()));
        _mm256_movemask_ps(_mm256_cmp_ps::<P>(a, b)) as u32
    }

    /// [`super::lanes_compare`] for 16 lanes.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn compare16<const N: usize, const P: i32>(
        a: &[f32; N],
        b: &[f32; N],
    ) -> u32 {
        assert!(N == 16);
        let (a, b) = (_mm512_loadu_ps(a.as_ptr()), _mm512_loadu_ps(b.as_ptr()));
        u32::from(_mm512_cmp_ps_mask::<P>(a, b))
    }

    /// [`super::gather_columns`] for 8 lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn gather8<const N: usize, const S: usize, const K: usize>(
        rows: &[[f32; S]],
        columns: [usize; K],
        ids: &[u32; N],
    ) -> [[f32; N]; K] {
        assert!(N == 8);
        let last = _mm256_set1_epi32((rows.len() - 1) as i32);
        let row = _mm256_min_epu32(_mm256_loadu_si256(ids.as_ptr().cast()), last);
        let at = _mm256_mullo_epi32(row, _mm256_set1_epi32(S as i32));
        let base = rows.as_ptr().cast::<f32>();
        let mut out = [[0.0; N]; K];
        for (o, &c) in out.iter_mut().zip(&columns) {
            let offsets = _mm256_add_epi32(at, _mm256_set1_epi32(c as i32));
            _mm256_storeu_ps(o.as_mut_ptr(), _mm256_i32gather_ps::<4>(base, offsets));
        }
        out
    }

    /// [`super::gather_columns`] for 16 lanes.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn gather16<const N: usize, const S: usize, const K: usize>(
        rows: &[[f32; S]],
        columns: [usize; K],
        ids: &[u32; N],
    ) -> [[f32; N]; K] {
        assert!(N == 16);
        let last = _mm512_set1_epi32((rows.len() - 1) as i32);
        let row = _mm512_min_epu32(_mm512_loadu_si512(ids.as_ptr().cast()), last);
        let at = _mm512_mullo_epi32(row, _mm512_set1_epi32(S as i32));
        let base = rows.as_ptr().cast::<f32>();
        let mut out = [[0.0; N]; K];
        let mut k = 0;
        while k < K {
            let offsets = _mm512_add_epi32(at, _mm512_set1_epi32(columns[k] as i32));
            if k + 1 < K && columns[k + 1] == columns[k] + 1 {
                // Two neighbouring columns: one 8-byte element per lane (two gathers of 8
                // lanes), split into the columns by two permutes.
                let pairs = base.cast::<i64>();
                let lo = _mm512_i32gather_epi64::<4>(_mm512_castsi512_si256(offsets), pairs);
                let hi =
                    _mm512_i32gather_epi64::<4>(_mm512_extracti64x4_epi64::<1>(offsets), pairs);
                let (lo, hi) = (_mm512_castsi512_ps(lo), _mm512_castsi512_ps(hi));
                let even =
                    _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
                let odd = _mm512_add_epi32(even, _mm512_set1_epi32(1));
                let first = _mm512_permutex2var_ps(lo, even, hi);
                _mm512_storeu_ps(out[k].as_mut_ptr(), first);
                let second = _mm512_permutex2var_ps(lo, odd, hi);
                _mm512_storeu_ps(out[k + 1].as_mut_ptr(), second);
                k += 2;
            } else {
                let column = _mm512_i32gather_ps::<4>(offsets, base);
                _mm512_storeu_ps(out[k].as_mut_ptr(), column);
                k += 1;
            }
        }
        out
    }

    /// [`super::compress`] for 16 lanes.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn compress16<const N: usize, const K: usize>(
        keep: u32,
        src: [&[u32; N]; K],
        dst: [&mut [u32]; K],
    ) {
        for (s, d) in src.into_iter().zip(dst) {
            assert!(N == 16 && d.len() >= 16);
            let v = _mm512_loadu_si512(s.as_ptr().cast());
            _mm512_storeu_si512(
                d.as_mut_ptr().cast(),
                _mm512_maskz_compress_epi32(keep as u16, v),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every mask of every width, through the width's own path (AVX2 / AVX-512 where the CPU has
    /// them, the lane loop otherwise), against the plain filter.
    fn check<const N: usize>() {
        struct Job;
        impl Kernel for Job {
            type Out = ();
            fn run<const M: usize>(self, isa: Isa<M>) {
                let src: [u32; M] = std::array::from_fn(|l| 100 + l as u32);
                let twice = src.map(|x| 2 * x);
                let masks = if M == 16 { 1u32 << 16 } else { 1 << M };
                for keep in 0..masks {
                    let (mut a, mut b) = (vec![0; M + 3], vec![0; M + 3]);
                    compress(isa, keep, [&src, &twice], [&mut a[3..], &mut b[3..]]);
                    let want: Vec<u32> = (0..M)
                        .filter(|l| keep >> l & 1 == 1)
                        .map(|l| src[l])
                        .collect();
                    assert_eq!(&a[3..3 + want.len()], &want[..], "{M} lanes, mask {keep:b}");
                    let twice_want: Vec<u32> = want.iter().map(|x| 2 * x).collect();
                    assert_eq!(&b[3..3 + want.len()], &twice_want[..]);
                }
            }
        }
        let w = match N {
            4 => Width::W4,
            8 => Width::W8,
            _ => Width::W16,
        };
        dispatch(w, Job);
    }

    /// Random coordinates, half of them on a grid of step 1/4, so that many rays pass exactly
    /// through edges and corners and many triangles are degenerate, and the others round, so
    /// that an operation done in another order or fused changes the bits.
    struct Grid(crate::rng::Rng);

    impl Grid {
        fn coord(&mut self) -> f32 {
            let x = 2.0 * self.0.unit() - 1.0;
            if self.0.unit() < 0.5 {
                (x * 4.0).round() / 4.0
            } else {
                x
            }
        }

        fn point(&mut self) -> glam::Vec3 {
            glam::Vec3::new(self.coord(), self.coord(), self.coord())
        }

        fn ray(&mut self) -> Ray {
            let org = self.point() * 3.0;
            let dir = self.point() - org / 3.0;
            let tmax = if self.coord() < 0.0 {
                0.75
            } else {
                f32::INFINITY
            };
            Ray::new(org, dir, 0.0, tmax)
        }

        /// A ray through a corner or an edge's midpoint of one of the triangles `corners` (every
        /// other one), or [`Grid::ray`]: rays on an edge take the watertight test's f64 path.
        fn ray_near(&mut self, corners: &[[glam::Vec3; 3]]) -> Ray {
            let mut ray = self.ray();
            if self.0.unit() < 0.5 {
                let pick = |x: f32, n: usize| ((x * n as f32) as usize).min(n - 1);
                let c = corners[pick(self.0.unit(), corners.len())];
                let (i, j) = (pick(self.0.unit(), 3), pick(self.0.unit(), 3));
                ray.dir = (c[i] + c[j]) * 0.5 - ray.org;
            }
            ray
        }
    }

    /// The scalar test's closest hit among the triangles of `set`, offered in index order.
    fn scalar(set: &PrimitiveSet, ray: &Ray, test: &RayTest) -> Hit {
        let mut hit = Hit::MISS;
        for p in 0..set.triangles.len() {
            set.intersect(p as u32, ray, test, &mut hit);
        }
        hit
    }

    fn same_bits(a: (f32, f32, f32), b: (f32, f32, f32)) -> bool {
        a.0.to_bits() == b.0.to_bits()
            && a.1.to_bits() == b.1.to_bits()
            && a.2.to_bits() == b.2.to_bits()
    }

    /// The ways a lane test can be asked for: Möller–Trumbore, the watertight test with its
    /// corners rebuilt from the edges, and with exact corners kept.
    const WAYS: [(Intersector, bool); 3] = [
        (Intersector::MollerTrumbore, false),
        (Intersector::Watertight, false),
        (Intersector::Watertight, true),
    ];

    /// Both lane orders (1 ray × N triangles, N rays × 1 triangle) against the scalar test, bit
    /// for bit, at every width this CPU runs, in every way of [`WAYS`]; the blocks also with a
    /// primitive excluded. Counts the watertight hits on an edge (an edge function exactly
    /// zero, redone in f64).
    #[test]
    fn lane_tests_match_the_scalar_test_bit_for_bit() {
        struct Job;
        impl Kernel for Job {
            type Out = (usize, usize);
            fn run<const N: usize>(self, isa: Isa<N>) -> (usize, usize) {
                let mut g = Grid(crate::rng::Rng(N as u64));
                let (mut hits, mut on_edge) = (0, 0);
                for round in 0..12000 {
                    let (intersector, exact) = WAYS[round % 3];
                    let corners: Vec<[glam::Vec3; 3]> =
                        (0..N).map(|_| [g.point(), g.point(), g.point()]).collect();
                    let set = PrimitiveSet {
                        triangles: corners
                            .iter()
                            .map(|&[a, b, c]| crate::geometry::Triangle::from_vertices(a, b, c))
                            .collect(),
                        vertices: match exact {
                            true => corners.iter().map(|c| c.map(|v| v.to_array())).collect(),
                            false => Vec::new(),
                        },
                        ..PrimitiveSet::default()
                    };
                    let ray = g.ray_near(&corners);
                    let ids: Vec<u32> = (0..N as u32).collect();
                    let block = TriBlock::<N>::from_prims(&set, &ids, intersector);
                    let plain = RayTest::new(&ray, intersector, INVALID);
                    let want = scalar(&set, &ray, &plain);
                    // Excluding the closest triangle makes the block find the one behind.
                    let excluding = RayTest::new(&ray, intersector, want.prim);
                    for test in [plain, excluding] {
                        let want = scalar(&set, &ray, &test);
                        let mut simd = Hit::MISS;
                        block.intersect(isa, &ray, &test, &mut simd);
                        assert!(
                            simd.prim == want.prim
                                && same_bits((simd.t, simd.u, simd.v), (want.t, want.u, want.v)),
                            "{N} lanes, {intersector:?}, exact corners {exact}, {ray:?}, \
                             excluding {}: block {simd:?}, scalar {want:?}",
                            test.exclude
                        );
                        assert_eq!(block.occluders(isa, &ray, &test) != 0, want.is_hit());
                    }
                    hits += want.is_hit() as usize;

                    let rays: Vec<Ray> = (0..N).map(|_| g.ray_near(&corners[..1])).collect();
                    let lanes =
                        RayLanes::<N>::gather(isa, &rays, &std::array::from_fn(|l| l as u32));
                    let rows = set.triangle_rows(0, intersector);
                    let (t, u, v) = lanes.triangle(rows, &lanes.tests(intersector), &lanes.tmax);
                    for (l, ray) in rays.iter().enumerate() {
                        let mut want = Hit::MISS;
                        set.intersect(0, ray, &RayTest::new(ray, intersector, INVALID), &mut want);
                        let lane = (t[l], u[l], v[l]);
                        if want.is_hit() {
                            assert!(
                                same_bits(lane, (want.t, want.u, want.v)),
                                "{N} lanes, {intersector:?}, exact corners {exact}, {ray:?}: \
                                 lane {lane:?}, scalar {want:?}"
                            );
                            let edge = want.u == 0.0 || want.v == 0.0;
                            on_edge += (intersector == Intersector::Watertight && edge) as usize;
                        } else {
                            assert_eq!(t[l], f32::INFINITY, "{N} lanes, {ray:?}");
                        }
                    }
                }
                (hits, on_edge)
            }
        }
        for w in Width::ALL {
            // Enough rays hit, and enough of them on an edge, for the comparison to mean
            // something.
            let (hits, on_edge) = dispatch(w, Job);
            assert!(
                hits > 1000 && on_edge > 1000,
                "{w:?}: {hits} hits, {on_edge} on an edge"
            );
        }
    }

    #[test]
    fn compress_keeps_the_masked_lanes_in_order() {
        check::<4>();
        check::<8>();
        check::<16>();
    }

    /// Every width's gather (the CPU's gather instruction with AVX2 and AVX-512, in pairs of
    /// columns with AVX-512) against plain indexing, with row indices past the end (which read
    /// the last row) and the largest index.
    #[test]
    fn gathers_read_what_indexing_reads() {
        struct Job;
        impl Kernel for Job {
            type Out = ();
            fn run<const M: usize>(self, isa: Isa<M>) {
                let rows: Vec<[f32; 3]> = (0..37)
                    .map(|r| [r as f32, -(r as f32), 0.5 + r as f32])
                    .collect();
                let mut rng = crate::rng::Rng(M as u64);
                for round in 0..200 {
                    let mut ids = [0u32; M];
                    for id in &mut ids {
                        *id = (rng.next_u64() % 45) as u32;
                    }
                    ids[round % M] = u32::MAX;
                    // Single columns, and neighbouring ones (gathered in pairs at 16 lanes)
                    // from an even and an odd column.
                    let [third, first, second] = gather_columns(isa, &rows, [2, 0, 1], &ids);
                    let [second_again, third_again] = gather_columns(isa, &rows, [1, 2], &ids);
                    for (l, &id) in ids.iter().enumerate() {
                        let row = rows[(id as usize).min(rows.len() - 1)];
                        let got = [
                            third[l],
                            first[l],
                            second[l],
                            second_again[l],
                            third_again[l],
                        ];
                        let want = [row[2], row[0], row[1], row[1], row[2]];
                        assert_eq!(got, want, "{M} lanes, id {id}");
                    }
                }
            }
        }
        for w in [Width::W4, Width::W8, Width::W16] {
            dispatch(w, Job);
        }
    }

    /// Every width's own path against the plain comparisons, with the values a hit mask meets:
    /// equal lanes, infinities, NaN (never less) and signed zeros.
    #[test]
    fn lane_compares_are_the_lane_by_lane_comparisons() {
        struct Job;
        impl Kernel for Job {
            type Out = usize;
            fn run<const N: usize>(self, isa: Isa<N>) -> usize {
                let values = [
                    0.0,
                    -0.0,
                    1.0,
                    -1.0,
                    2.5,
                    f32::INFINITY,
                    f32::NEG_INFINITY,
                    f32::NAN,
                ];
                let mut rng = crate::rng::Rng(7);
                let mut set = 0;
                for _ in 0..2000 {
                    let mut pick =
                        || values[(rng.unit() * values.len() as f32) as usize % values.len()];
                    let a: [f32; N] = std::array::from_fn(|_| pick());
                    let b: [f32; N] = std::array::from_fn(|_| pick());
                    let want = (0..N).filter(|&l| a[l] < b[l]).fold(0, |m, l| m | 1 << l);
                    assert_eq!(lanes_less(isa, &a, &b), want, "{N} lanes: {a:?} < {b:?}");
                    let want_eq = (0..N).filter(|&l| a[l] <= b[l]).fold(0, |m, l| m | 1 << l);
                    assert_eq!(
                        lanes_less_eq(isa, &a, &b),
                        want_eq,
                        "{N} lanes: {a:?} <= {b:?}"
                    );
                    set += want.count_ones() as usize + (want_eq & !want).count_ones() as usize;
                }
                set
            }
        }
        for w in Width::ALL {
            assert!(dispatch(w, Job) > 1000, "{w:?}");
        }
    }
}
