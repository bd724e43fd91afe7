//! The order in which packets (and streams, when asked) take a batch's rays. A camera's rays
//! come in scanline order, where N consecutive rays are an N × 1 strip of the image; a tile of
//! the same image (4 × 4 at 16 lanes) holds rays closer together, which share more of their
//! nodes and leaves. On the bunny's 1024² primary rays (one thread, 16 lanes, an Intel Xeon)
//! packets of 4 × 4 tiles ran 1.17× as fast as 16 × 1 strips, 2 × 8 alike, 8 × 2 1.09×.
//! `query` gives streams their rays as given (see there).
//!
//! A batch does not say whether it is an image, nor how wide, so [`detect`] reads that from the
//! rays: along a row a camera's rays move by about one pixel, and from a row's last ray to the
//! next row's first they jump back across the image. Detection only chooses an order: every
//! ray is traced once whatever it finds, with the same hits.

use super::batch::octant;
use crate::geometry::Ray;
use crate::rng::Rng;

/// How a packet or stream batch takes its rays, N at a time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RayOrder {
    /// N consecutive rays at a time.
    #[default]
    AsGiven,
    /// An image in scanline order, rows of this many rays from the batch's first on: taken in
    /// tiles of [`tile`]'s shape (the last row may be partial).
    Rows(usize),
}

/// Most rows of a tile at any lane width: a batch cut into pieces of whole bands of this many
/// rows keeps every tile whole in one piece.
pub const TILE_ROWS: usize = 4;

/// Columns and rows of the tiles of N lanes: as square as a power of two allows (16: 4 × 4,
/// 8: 4 × 2, 4: 2 × 2). 16-lane packets in 8 × 2 and 2 × 8 tiles ran at 0.92× the speed of
/// 4 × 4 (the bunny's 1024² primary rays, one thread).
pub const fn tile<const N: usize>() -> (usize, usize) {
    let rows = 1 << (N.trailing_zeros() / 2);
    (N / rows, rows)
}

/// The largest number of rays of `order`'s batches at most `size` that is a whole number of
/// bands of [`TILE_ROWS`] rows (at least one band), so that a batch cut into pieces of it keeps
/// its tiles whole; `size` itself for rays as given.
pub fn whole_bands(order: RayOrder, size: usize) -> usize {
    match order {
        RayOrder::AsGiven => size,
        RayOrder::Rows(width) => {
            let band = TILE_ROWS * width;
            (size / band).max(1) * band
        }
    }
}

/// The blocks of N rays a batch of `n` rays is taken in, in `order`: each block's ray indices
/// (lanes past the batch's rays hold `n`, which gathers read as the last ray) and the mask of
/// the lanes that hold rays. Every ray is in exactly one block. Rays as given are one row of
/// `n` rays taken in N × 1 tiles, so both orders are one walk over tiles.
pub(crate) struct Blocks<const N: usize> {
    n: usize,
    width: usize,
    columns: usize,
    rows: usize,
    /// The next tile's top-left ray: column and row.
    x: usize,
    y: usize,
}

impl<const N: usize> Blocks<N> {
    pub fn new(n: usize, order: RayOrder) -> Self {
        let ((columns, rows), width) = match order {
            RayOrder::AsGiven => ((N, 1), n),
            RayOrder::Rows(width) => (tile::<N>(), width),
        };
        Blocks {
            n,
            width: width.max(1),
            columns,
            rows,
            x: 0,
            y: 0,
        }
    }
}

impl<const N: usize> Iterator for Blocks<N> {
    type Item = ([u32; N], u32);

    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        // The top-left ray is a tile's first, and every later tile starts after it: none left
        // once it lies past the rays.
        if self.y * self.width + self.x >= self.n {
            return None;
        }
        let mut ids = [self.n as u32; N];
        let mut live = 0;
        // Lane `row * columns + column`: loops rather than a division per lane, as the tile's
        // shape is known only at run time.
        let mut l = 0;
        for y in self.y..self.y + self.rows {
            for x in self.x..self.x + self.columns {
                let i = y * self.width + x;
                if x < self.width && i < self.n {
                    ids[l] = i as u32;
                    live |= 1 << l;
                }
                l += 1;
            }
        }
        self.x += self.columns;
        if self.x >= self.width {
            self.x = 0;
            self.y += self.rows;
        }
        Some((ids, live))
    }
}

/// Fewest rays per row taken for an image: a row must hold a few tiles, and its last step must
/// stand out from the steps before it (a row of w rays jumps back about w steps).
const MIN_WIDTH: usize = 16;

/// Most rays per row looked for (a 16 K-pixel-wide image): the first row is read ray by ray.
const MAX_WIDTH: usize = 16384;

/// How many times the largest step of the first row a step must exceed to end a row, and may
/// not exceed between neighbours: a camera's step varies along and across its image (a
/// pinhole's unit directions by about 2× over a 90° view), a row's last step is about as many
/// steps as the row is long.
const JUMP: f32 = 4.0;

/// Rays whose neighbours [`detect`] checks below the first row.
const SAMPLES: usize = 64;

/// A camera's row crosses each axis plane once at most (twice for a panorama's): a first row
/// whose rays change octant more often than this is no row.
const OCTANT_CHANGES: usize = 4;

/// The order for packets of `rays` (`query` gives streams theirs as given): [`RayOrder::Rows`]
/// when they look like an image of at least two rows in scanline order, else as given. Reads
/// the first row ray by ray, up to half the batch (rays in mixed octants are told after a
/// few), and `SAMPLES` random rays below it with their neighbours: at most about 16,700 rays
/// whatever the batch's size, a few nanoseconds each.
///
/// The rays of a row are consecutive, each a small step (in unit direction and in origin) from
/// the one before; the first ray of each row is a large step from the last of the row above,
/// and a small step from the ray above it. A pinhole camera's rays step in direction, an
/// orthographic camera's in origin.
pub fn detect(rays: &[Ray]) -> RayOrder {
    detect_in(rays.len(), |i| rays[i])
}

/// [`detect`] for `n` rays that `ray` reads on demand (a C caller's rays, converted one at a
/// time).
pub fn detect_in(n: usize, ray: impl Fn(usize) -> Ray) -> RayOrder {
    match first_row(n, &ray) {
        Some((width, largest)) if below_agree(n, &ray, width, largest.times(JUMP)) => {
            RayOrder::Rows(width)
        }
        _ => RayOrder::AsGiven,
    }
}

/// The distance between two rays' unit directions and between their origins.
#[derive(Clone, Copy, Debug, Default)]
struct Step {
    dir: f32,
    org: f32,
}

impl Step {
    fn between(a: &Ray, b: &Ray) -> Self {
        Step {
            dir: a
                .dir
                .normalize_or_zero()
                .distance(b.dir.normalize_or_zero()),
            org: a.org.distance(b.org),
        }
    }

    fn times(self, k: f32) -> Self {
        Step {
            dir: self.dir * k,
            org: self.org * k,
        }
    }

    fn max(self, o: Self) -> Self {
        Step {
            dir: self.dir.max(o.dir),
            org: self.org.max(o.org),
        }
    }

    /// Longer than `limit` in direction or in origin (never with NaN).
    fn exceeds(self, limit: Self) -> bool {
        self.dir > limit.dir || self.org > limit.org
    }

    /// No longer than `limit` in direction and in origin (never with NaN).
    fn within(self, limit: Self) -> bool {
        self.dir <= limit.dir && self.org <= limit.org
    }
}

/// The length of the first row, and its largest step: the first step past [`MIN_WIDTH`] rays
/// that exceeds [`JUMP`] times every step before it ends it. Only rows of at most half the
/// rays count: [`below_agree`] needs two.
fn first_row(n: usize, ray: impl Fn(usize) -> Ray) -> Option<(usize, Step)> {
    let mut largest = Step::default();
    let mut changes = 0;
    if n < 2 {
        return None;
    }
    let mut b = ray(0);
    for i in 0..(n / 2).min(MAX_WIDTH) {
        let a = std::mem::replace(&mut b, ray(i + 1));
        let (a, b) = (&a, &b);
        let step = Step::between(a, b);
        if i + 1 >= MIN_WIDTH && step.exceeds(largest.times(JUMP)) {
            return Some((i + 1, largest));
        }
        changes += usize::from(octant(a) != octant(b));
        if changes > OCTANT_CHANGES {
            return None;
        }
        largest = largest.max(step);
    }
    None
}

/// Whether rows of `width` rays go on below the first: at random rays of the full rows below
/// it, the ray above and the next ray of the row lie within `limit`, and the row above ends
/// with a step beyond it. Needs two full rows.
fn below_agree(n: usize, ray: impl Fn(usize) -> Ray, width: usize, limit: Step) -> bool {
    let rows = n / width;
    if rows < 2 {
        return false;
    }
    let step = |i: usize, j: usize| Step::between(&ray(i), &ray(j));
    let mut rng = Rng(0);
    (0..SAMPLES).all(|_| {
        let (row, x) = (1 + rng.index(rows - 1), rng.index(width));
        let (start, i) = (row * width, row * width + x);
        step(i - width, i).within(limit)
            && step(start - 1, start).exceeds(limit)
            && (x + 1 == width || step(i, i + 1).within(limit))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// The first `rows` rows of a pinhole camera's `w` × `h` image in scanline order, looking
    /// down -z with a vertical field of view of `fov` degrees.
    fn pinhole(w: usize, h: usize, rows: usize, fov: f32) -> Vec<Ray> {
        let scale = (fov.to_radians() / 2.0).tan();
        let aspect = w as f32 / h as f32;
        let org = Vec3::new(0.3, -1.0, 5.0);
        (0..rows)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let u = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * scale * aspect;
                let v = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * scale;
                Ray::new(org, Vec3::new(u, v, -1.0).normalize(), 0.0, f32::INFINITY)
            })
            .collect()
    }

    /// An orthographic camera's rays, `w` × `h`: one direction, origins on a grid.
    fn orthographic(w: usize, h: usize) -> Vec<Ray> {
        let dir = Vec3::new(0.1, 0.2, -1.0);
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let org = Vec3::new(x as f32 * 0.01, -(y as f32) * 0.01, 3.0);
                Ray::new(org, dir, 0.0, f32::INFINITY)
            })
            .collect()
    }

    #[test]
    fn camera_images_are_read_as_rows_of_their_width() {
        // Images `w` × `h`, of which the first `rows` rows are traced (a piece of a batch).
        for (w, h, rows) in [
            (16, 12, 12),
            (64, 4, 4),
            (37, 23, 23),
            (1024, 1024, 8),
            (1376, 768, 20),
            (5000, 3000, 3),
        ] {
            let n = w * rows;
            for fov in [30.0, 60.0, 90.0] {
                let rays = &pinhole(w, h, rows, fov);
                assert_eq!(detect(rays), RayOrder::Rows(w), "pinhole {w}x{h} {fov}°");
                // A last row cut short is still the same image.
                let cut = &rays[..n - w / 2];
                let expected = if rows > 2 {
                    RayOrder::Rows(w)
                } else {
                    RayOrder::AsGiven
                };
                assert_eq!(detect(cut), expected, "{w}x{h} cut");
            }
            let rays = &orthographic(w, rows);
            assert_eq!(detect(rays), RayOrder::Rows(w), "ortho {w}x{h}");
        }
    }

    #[test]
    fn rays_that_are_no_image_of_two_rows_are_taken_as_given() {
        let image = pinhole(64, 16, 16, 60.0);
        let mut rng = Rng(7);
        let random: Vec<Ray> = (0..4096)
            .map(|_| {
                let mut v = || Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0;
                Ray::new(v(), v(), 0.0, f32::INFINITY)
            })
            .collect();
        let mut shuffled = image.clone();
        for i in (1..shuffled.len()).rev() {
            shuffled.swap(i, rng.index(i + 1));
        }
        let cases: [(&str, &[Ray]); 7] = [
            ("empty", &[]),
            ("random", &random),
            ("shuffled image", &shuffled),
            ("one row", &image[..64]),
            ("narrower than MIN_WIDTH", &pinhole(8, 64, 64, 60.0)),
            // Starting mid-row, the first row is short and the rows below disagree with it.
            ("starting mid-row", &image[20..]),
            ("rows of one ray", &pinhole(1, 512, 512, 60.0)),
        ];
        for (what, rays) in cases {
            assert_eq!(detect(rays), RayOrder::AsGiven, "{what}");
        }
        // Degenerate rays (NaN, zero direction) never make steps that agree.
        let mut broken = image.clone();
        for r in broken.iter_mut().step_by(3) {
            r.dir = Vec3::NAN;
        }
        assert_eq!(detect(&broken), RayOrder::AsGiven, "NaN directions");
    }

    /// Every ray index of the batch in exactly one block, each in its lane's place of its tile:
    /// lane `l` at column `l % columns` and row `l / columns` of the tile whose top-left ray
    /// is lane 0's.
    fn check_blocks<const N: usize>(n: usize, order: RayOrder) {
        let mut seen = vec![0u32; n];
        let ((columns, rows), width) = match order {
            RayOrder::AsGiven => ((N, 1), n.max(1)),
            RayOrder::Rows(w) => (tile::<N>(), w),
        };
        for (ids, live) in Blocks::<N>::new(n, order) {
            assert_eq!(
                live & 1,
                1,
                "a block without its top-left ray ({n} rays, {order:?})"
            );
            let (x0, y0) = (ids[0] as usize % width, ids[0] as usize / width);
            for (l, &id) in ids.iter().enumerate() {
                let (x, y) = (x0 + l % columns, y0 + l / columns);
                if live >> l & 1 == 0 {
                    assert_eq!(id as usize, n, "idle lane {l}");
                    assert!(x >= width || y * width + x >= n, "lane {l} left idle");
                    continue;
                }
                seen[id as usize] += 1;
                assert_eq!(id as usize, y * width + x, "lane {l} ({n} rays, {order:?})");
                assert!(x < width && l / columns < rows);
            }
        }
        assert!(seen.iter().all(|&s| s == 1), "{n} rays, {order:?}");
    }

    #[test]
    fn blocks_take_every_ray_once_in_its_tile_place() {
        assert_eq!(tile::<16>(), (4, 4));
        assert_eq!(tile::<8>(), (4, 2));
        assert_eq!(tile::<4>(), (2, 2));
        for n in [0, 1, 15, 16, 17, 100, 1000, 4096] {
            for order in [1, 3, 4, 5, 16, 37, 64, 1000, 5000]
                .map(RayOrder::Rows)
                .into_iter()
                .chain([RayOrder::AsGiven])
            {
                check_blocks::<4>(n, order);
                check_blocks::<8>(n, order);
                check_blocks::<16>(n, order);
            }
        }
    }

    #[test]
    fn pieces_of_whole_bands_keep_tiles_whole() {
        assert_eq!(whole_bands(RayOrder::AsGiven, 4096), 4096);
        assert_eq!(whole_bands(RayOrder::Rows(1024), 4096), 4096);
        assert_eq!(whole_bands(RayOrder::Rows(1376), 4096), 5504);
        assert_eq!(whole_bands(RayOrder::Rows(1376), 32768), 27520);
        assert_eq!(whole_bands(RayOrder::Rows(100), 4096), 4000);
    }
}
