//! The occupancy grid a nerfacto run gets at load (nerfacto has none of its own), and its
//! on-disk cache next to the run.
//!
//! **Grid.** `N³` cells over the *contracted* cube `[−2, 2]³` (nerfacto's L∞ contraction,
//! `c = x` inside `‖x‖∞ < 1`, else `(2 − 1/‖x‖∞)·x/‖x‖∞`), so one grid covers all of space:
//! the unit cube at the grid's resolution and the shell beyond it at the resolution the
//! hash grid has there. A cell is occupied when the largest density sampled at its corners
//! and centre (in contracted coordinates) reaches `opacity / L`, where `L` is the cell's
//! diagonal in *field* units at its outer edge (the contracted diagonal times
//! `max(1, r²)`, `r = 1/(2 − ‖c‖∞)` the field radius there, capped at the far plane), and
//! the occupied set is dilated by one cell (26-neighbourhood). A bit per cell is kept as 3-D
//! prefix sums, so a region's test is eight lookups. A field-space box is tested through
//! the box of its contracted image: `c = x·g(‖x‖∞)` with `g` positive and non-increasing,
//! so over the box `g` lies between its values at the box's largest and smallest `‖x‖∞`,
//! and each `c_a` between the products of the interval bounds.
//!
//! **Cache.** Computing the grid takes `(N + 1)²·2N + N³` density samples (~0.5 M for
//! `N = 64`: about a second), so it is kept: next to the run (`<run>/nerfx_occupancy.bin`)
//! when the run directory can be written, else in the per-user cache directory
//! (`$XDG_CACHE_HOME/nerfx`, else `~/.cache/nerfx`; `occupancy-<hash of the run's
//! path>.bin`), else in memory only. Either file is read only when it is whole and its key
//! matches, so it is never a correctness dependency. The file:
//! `"NERFXOCC"`, format version (u32 LE), key length (u32 LE) and key, `N` (u32 LE), the cells
//! as bits (x fastest, then y, then z; bit `i % 8` of byte `i / 8`), then an FNV-1a 64 hash
//! of everything before it (u64 LE). The key names what the grid depends on: the grid
//! settings, the checkpoint (path, size, modification time and a hash of its first and last
//! 64 KiB) and `config.yml` (size, modification time). A cache that is missing, stale (another
//! key, another run's), truncated or corrupt (hash) is recomputed and rewritten (through a
//! temporary file and a rename, so a reader never sees half a file); one that cannot be
//! written anywhere is not an error, the grid is simply not cached.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use glam::Vec3;
use rayon::prelude::*;

use crate::field::Aabb;

/// The cache file's name inside the run directory.
pub(super) const CACHE_FILE: &str = "nerfx_occupancy.bin";
/// Bumped whenever the grid rule or the file layout changes (2: cells in contracted
/// coordinates).
const CACHE_VERSION: u32 = 2;
const MAGIC: &[u8; 8] = b"NERFXOCC";
/// Bytes hashed at each end of the checkpoint for the key.
const KEY_SAMPLE: u64 = 64 * 1024;

/// Half the side of the contracted cube the grid covers.
const CONTRACTED: f32 = 2.0;

/// How the grid is computed: cells per axis and the opacity rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct GridSettings {
    /// Cells per axis `N`.
    pub(crate) n: usize,
    /// Opacity across a cell above which it is occupied.
    pub opacity: f32,
    /// The field radius `‖x‖∞` beyond which nothing is rendered (the far plane): caps the
    /// outermost cells' extent in the opacity rule.
    pub(crate) far: f32,
}

/// nerfacto's L∞ contraction of a field point (`(x/m)·(2 − 1/m)` beyond the unit cube, in
/// that order, as nerfstudio computes it).
#[inline]
pub(super) fn contract(p: Vec3) -> Vec3 {
    let m = p.abs().max_element();
    if m < 1.0 {
        p
    } else {
        (p / m) * (2.0 - 1.0 / m)
    }
}

/// `g(m)`: the contraction is `c = x·g(‖x‖∞)`; 1 inside the unit cube, `(2 − 1/m)/m` beyond
/// (positive, non-increasing, 0 at infinity).
#[inline]
fn shrink(m: f32) -> f32 {
    if m < 1.0 {
        1.0
    } else if m.is_finite() {
        (2.0 - 1.0 / m) / m
    } else {
        0.0
    }
}

/// A box holding the contracted image of the field-space box `b` (see the module docs), and
/// the least `‖c‖∞` of that image: `‖c‖∞ = h(‖x‖∞)` with `h(m) = m·g(m)` increasing, so the
/// image lies outside the cube of half side `h` of the box's least `‖x‖∞`.
fn contract_box(b: &Aabb) -> (Aabb, f32) {
    let (lo, hi) = (b.min.to_array(), b.max.to_array());
    let (mut near, mut far) = (0.0f32, 0.0f32);
    for a in 0..3 {
        let gap = if lo[a] > 0.0 {
            lo[a]
        } else if hi[a] < 0.0 {
            -hi[a]
        } else {
            0.0
        };
        near = near.max(gap);
        far = far.max(lo[a].abs()).max(hi[a].abs());
    }
    let (g_lo, g_hi) = (shrink(far), shrink(near));
    let axis = |a: usize| {
        let min = lo[a] * if lo[a] >= 0.0 { g_lo } else { g_hi };
        let max = hi[a] * if hi[a] >= 0.0 { g_hi } else { g_lo };
        // A few ulps of room for the f32 rounding of `contract`.
        let pad = 4.0 * f32::EPSILON * CONTRACTED;
        (min - pad, max + pad)
    };
    let [x, y, z] = [0, 1, 2].map(axis);
    let inner = near * shrink(near) - 4.0 * f32::EPSILON * CONTRACTED;
    (
        Aabb::new(Vec3::new(x.0, y.0, z.0), Vec3::new(x.1, y.1, z.1)),
        inner,
    )
}

/// Where a grid came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) enum Source {
    /// Sampled from the field at this load.
    Computed,
    /// Read from this cache file.
    Cached(PathBuf),
}

/// A bit per cell, as prefix sums.
#[derive(Clone, Debug)]
pub(super) struct OccupancyGrid {
    n: usize,
    /// `(n+1)³` prefix counts: `sums[(z·(n+1) + y)·(n+1) + x]` = occupied cells below.
    sums: Vec<u32>,
    source: Source,
}

impl OccupancyGrid {
    /// Every cell occupied (before the grid is computed).
    pub(crate) fn full(settings: &GridSettings) -> Self {
        Self::from_cells(settings, &vec![true; settings.n.pow(3)], Source::Computed)
    }

    /// The grid of `cells` (`n³`, x fastest).
    pub(crate) fn from_cells(settings: &GridSettings, cells: &[bool], source: Source) -> Self {
        let n = settings.n;
        let m = n + 1;
        let mut sums = vec![0u32; m * m * m];
        for z in 1..m {
            for y in 1..m {
                for x in 1..m {
                    let c = u32::from(cells[((z - 1) * n + y - 1) * n + x - 1]);
                    let at = |x: usize, y: usize, z: usize| sums[(z * m + y) * m + x];
                    sums[(z * m + y) * m + x] =
                        c + at(x - 1, y, z) + at(x, y - 1, z) + at(x, y, z - 1)
                            - at(x - 1, y - 1, z)
                            - at(x - 1, y, z - 1)
                            - at(x, y - 1, z - 1)
                            + at(x - 1, y - 1, z - 1);
                }
            }
        }
        OccupancyGrid { n, sums, source }
    }

    /// The grid for a run: read from the first of `caches` (see [`cache_paths`]) that is
    /// current for `key`, otherwise computed from `density` (the field's unmasked density at
    /// *contracted* points) and written to the first of `caches` that can be written; with
    /// no key (the checkpoint could not be examined), computed and not cached.
    pub(crate) fn load_or_build(
        settings: &GridSettings,
        caches: &[PathBuf],
        key: Option<&str>,
        density: impl Fn(&[Vec3], &mut [f32]) + Sync,
    ) -> Self {
        if let Some(k) = key {
            for path in caches {
                if let Some(cells) = read_cache(path, k, settings.n) {
                    return Self::from_cells(settings, &cells, Source::Cached(path.clone()));
                }
            }
        }
        let cells = compute_cells(settings, density);
        if let Some(k) = key {
            let _ = caches
                .iter()
                .find(|path| write_cache(path, k, settings.n, &cells));
        }
        Self::from_cells(settings, &cells, Source::Computed)
    }

    /// Where the grid came from.
    pub fn source(&self) -> &Source {
        &self.source
    }

    /// Cells per axis.
    pub(crate) fn resolution(&self) -> usize {
        self.n
    }

    /// Occupied cells in the index box `lo..hi` (exclusive).
    fn count(&self, lo: [usize; 3], hi: [usize; 3]) -> u32 {
        let m = self.n + 1;
        let s = |x: usize, y: usize, z: usize| i64::from(self.sums[(z * m + y) * m + x]);
        let v = s(hi[0], hi[1], hi[2])
            - s(lo[0], hi[1], hi[2])
            - s(hi[0], lo[1], hi[2])
            - s(hi[0], hi[1], lo[2])
            + s(lo[0], lo[1], hi[2])
            + s(lo[0], hi[1], lo[2])
            + s(hi[0], lo[1], lo[2])
            - s(lo[0], lo[1], lo[2]);
        v as u32
    }

    /// Cell index range covering contracted `[a, b]` along one axis (clamped to the grid).
    fn range(&self, a: f32, b: f32) -> (usize, usize) {
        let (n, h) = (self.n as f32, CONTRACTED);
        let to = |v: f32| ((v + h) / (2.0 * h) * n).clamp(0.0, n);
        let lo = to(a).floor() as usize;
        let hi = (to(b).floor() as usize + 1).min(self.n);
        (lo.min(self.n - 1), hi)
    }

    /// Whether any cell meeting the contracted box `c` is occupied.
    fn contracted_region(&self, c: &Aabb) -> bool {
        let r = [0, 1, 2].map(|a| self.range(c.min[a], c.max[a]));
        self.count([r[0].0, r[1].0, r[2].0], [r[0].1, r[1].1, r[2].1]) > 0
    }

    /// Whether any cell meeting the contracted image of the field-space box `region` is
    /// occupied: the cells of its contracted box (see [`contract_box`]) that lie outside the
    /// cube its image cannot enter, as up to six boxes (one per face of that cube).
    pub(crate) fn region(&self, region: &Aabb) -> bool {
        let (c, inner) = contract_box(region);
        if inner <= 0.0 {
            return self.contracted_region(&c);
        }
        (0..3).any(|a| {
            let (mut above, mut below) = (c, c);
            above.min[a] = above.min[a].max(inner);
            below.max[a] = below.max[a].min(-inner);
            [above, below]
                .iter()
                .any(|b| !b.is_empty() && self.contracted_region(b))
        })
    }

    /// Whether the cell of the field point `p` is occupied.
    pub(crate) fn point(&self, p: Vec3) -> bool {
        let c = contract(p);
        self.contracted_region(&Aabb::new(c, c))
    }

    /// Occupied cells over all cells.
    pub(crate) fn fill_ratio(&self) -> f64 {
        let n = self.n;
        f64::from(self.count([0; 3], [n; 3])) / (n * n * n) as f64
    }
}

/// Samples `density` (at contracted points) and applies the rule of the module docs: the
/// occupied cells (`n³`).
fn compute_cells(s: &GridSettings, density: impl Fn(&[Vec3], &mut [f32]) + Sync) -> Vec<bool> {
    let n = s.n;
    let cell = 2.0 * CONTRACTED / n as f32;
    let at = |i: f32| -CONTRACTED + i * cell;
    // A cell's field-space diagonal at its outer edge: by its contracted radius there.
    let threshold = |x: usize, y: usize, z: usize| {
        let edge = |i: usize| at(i as f32).abs().max(at(i as f32 + 1.0).abs());
        let outer = edge(x).max(edge(y)).max(edge(z));
        let r = if outer < 2.0 {
            (1.0 / (2.0 - outer)).min(s.far)
        } else {
            s.far
        };
        s.opacity / (cell * 3f32.sqrt() * r.max(1.0).powi(2))
    };
    // Per z-slab of cells: the max density over its corners and centres.
    let slabs: Vec<Vec<f32>> = (0..n)
        .into_par_iter()
        .map(|z| {
            let mut pts = Vec::with_capacity(2 * (n + 1) * (n + 1) + n * n);
            for dz in 0..2 {
                for y in 0..=n {
                    for x in 0..=n {
                        pts.push(Vec3::new(at(x as f32), at(y as f32), at((z + dz) as f32)));
                    }
                }
            }
            for y in 0..n {
                for x in 0..n {
                    let c = Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5);
                    pts.push(Vec3::new(at(c.x), at(c.y), at(c.z)));
                }
            }
            let mut sigma = vec![0.0; pts.len()];
            density(&pts, &mut sigma);
            let corner = |x: usize, y: usize, dz: usize| sigma[(dz * (n + 1) + y) * (n + 1) + x];
            let centres = &sigma[2 * (n + 1) * (n + 1)..];
            (0..n * n)
                .map(|i| {
                    let (x, y) = (i % n, i / n);
                    let mut m = centres[i];
                    for k in 0..8 {
                        m = m.max(corner(x + (k & 1), y + (k >> 1 & 1), k >> 2));
                    }
                    m
                })
                .collect()
        })
        .collect();
    let hot: Vec<bool> = slabs
        .concat()
        .iter()
        .enumerate()
        .map(|(i, &m)| m >= threshold(i % n, i / n % n, i / (n * n)))
        .collect();
    let mut cells = vec![false; n * n * n];
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let near = |v: usize| v.saturating_sub(1)..=(v + 1).min(n - 1);
                cells[(z * n + y) * n + x] = near(z)
                    .any(|zz| near(y).any(|yy| near(x).any(|xx| hot[(zz * n + yy) * n + xx])));
            }
        }
    }
    cells
}

/// The cache key of a run: the grid settings, the checkpoint and `config.yml`. `None` when
/// the checkpoint cannot be examined (then nothing is cached).
pub(super) fn cache_key(
    settings: &GridSettings,
    checkpoint: &Path,
    config: &Path,
) -> Option<String> {
    let stamp = |p: &Path| -> Option<(u64, u128)> {
        let meta = std::fs::metadata(p).ok()?;
        let mtime = meta
            .modified()
            .ok()?
            .duration_since(std::time::UNIX_EPOCH)
            .ok()?
            .as_nanos();
        Some((meta.len(), mtime))
    };
    let (size, mtime) = stamp(checkpoint)?;
    let (config_size, config_mtime) = stamp(config)?;
    let mut file = std::fs::File::open(checkpoint).ok()?;
    let mut ends = Vec::new();
    (&mut file).take(KEY_SAMPLE).read_to_end(&mut ends).ok()?;
    if size > KEY_SAMPLE {
        file.seek(SeekFrom::Start(
            size.saturating_sub(KEY_SAMPLE).max(KEY_SAMPLE),
        ))
        .ok()?;
        file.take(KEY_SAMPLE).read_to_end(&mut ends).ok()?;
    }
    let path = std::fs::canonicalize(checkpoint).unwrap_or_else(|_| PathBuf::from(checkpoint));
    Some(format!(
        "grid n={} opacity={:08x} contracted far={:08x} dilation=1; checkpoint {} \
         size={size} mtime={mtime} ends={:016x}; config size={config_size} \
         mtime={config_mtime}",
        settings.n,
        settings.opacity.to_bits(),
        settings.far.to_bits(),
        path.display(),
        fnv1a(&ends),
    ))
}

/// FNV-1a, 64 bits.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The file's bytes for `cells` under `key`.
fn encode(key: &str, n: usize, cells: &[bool]) -> Vec<u8> {
    let mut out = Vec::with_capacity(24 + key.len() + cells.len() / 8 + 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&CACHE_VERSION.to_le_bytes());
    out.extend_from_slice(&(key.len() as u32).to_le_bytes());
    out.extend_from_slice(key.as_bytes());
    out.extend_from_slice(&(n as u32).to_le_bytes());
    let mut bits = vec![0u8; cells.len().div_ceil(8)];
    for (i, _) in cells.iter().enumerate().filter(|(_, &c)| c) {
        bits[i / 8] |= 1 << (i % 8);
    }
    out.extend_from_slice(&bits);
    let hash = fnv1a(&out);
    out.extend_from_slice(&hash.to_le_bytes());
    out
}

/// The cells in `bytes` when they are a whole, intact cache for `key` and `n`.
fn decode(bytes: &[u8], key: &str, n: usize) -> Option<Vec<bool>> {
    let (body, hash) = bytes.split_at_checked(bytes.len().checked_sub(8)?)?;
    if fnv1a(body) != u64::from_le_bytes(hash.try_into().ok()?) {
        return None;
    }
    let mut rest = body.strip_prefix(MAGIC.as_slice())?;
    let mut u32_field = || -> Option<u32> {
        let (v, r) = rest.split_first_chunk::<4>()?;
        rest = r;
        Some(u32::from_le_bytes(*v))
    };
    if u32_field()? != CACHE_VERSION {
        return None;
    }
    let key_len = u32_field()? as usize;
    let (stored_key, r) = rest.split_at_checked(key_len)?;
    rest = r;
    if stored_key != key.as_bytes() {
        return None;
    }
    let (stored_n, bits) = rest.split_first_chunk::<4>()?;
    let count = n.pow(3);
    if u32::from_le_bytes(*stored_n) as usize != n || bits.len() != count.div_ceil(8) {
        return None;
    }
    Some(
        (0..count)
            .map(|i| bits[i / 8] >> (i % 8) & 1 == 1)
            .collect(),
    )
}

/// Where a run's grid may be cached, in order: next to the run, then in the per-user cache
/// directory (`$XDG_CACHE_HOME/nerfx` when that is an absolute path, else
/// `$HOME/.cache/nerfx`) under a name from the run's path.
pub(super) fn cache_paths(run: &Path) -> Vec<PathBuf> {
    let mut paths = vec![run.join(CACHE_FILE)];
    let absolute = |v: std::ffi::OsString| Some(PathBuf::from(v)).filter(|p| p.is_absolute());
    let user = std::env::var_os("XDG_CACHE_HOME")
        .and_then(absolute)
        .or_else(|| {
            std::env::var_os("HOME")
                .and_then(absolute)
                .map(|h| h.join(".cache"))
        });
    if let Some(dir) = user {
        let run = std::fs::canonicalize(run).unwrap_or_else(|_| run.to_path_buf());
        let name = format!(
            "occupancy-{:016x}.bin",
            fnv1a(run.as_os_str().as_encoded_bytes())
        );
        paths.push(dir.join("nerfx").join(name));
    }
    paths
}

fn read_cache(path: &Path, key: &str, n: usize) -> Option<Vec<bool>> {
    // A cache is a few tens of KiB: anything much larger is not one (and is not read).
    let len = std::fs::metadata(path).ok()?.len();
    if len > 1 << 20 {
        return None;
    }
    decode(&std::fs::read(path).ok()?, key, n)
}

/// Writes the cache (creating its directory) as every output is written; whether it was
/// written. Failures leave no file behind.
fn write_cache(path: &Path, key: &str, n: usize, cells: &[bool]) -> bool {
    if let Some(dir) = path.parent() {
        if std::fs::create_dir_all(dir).is_err() {
            return false;
        }
    }
    crate::output::write_file(path, &encode(key, n, cells)).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    const SETTINGS: GridSettings = GridSettings {
        n: 8,
        opacity: 1e-3,
        far: 1000.0,
    };

    #[test]
    fn regions_count_cells() {
        let n = 64;
        let settings = GridSettings { n, ..SETTINGS };
        let mut cells = vec![false; n * n * n];
        // One occupied cell at (10, 20, 30): contracted x ∈ [−2 + 10·h, −2 + 11·h], h = 4/64.
        cells[(30 * n + 20) * n + 10] = true;
        let g = OccupancyGrid::from_cells(&settings, &cells, Source::Computed);
        let h = 4.0 / n as f32;
        let centre = Vec3::new(-2.0 + 10.5 * h, -2.0 + 20.5 * h, -2.0 + 30.5 * h);
        let at = |c: Vec3| g.contracted_region(&Aabb::new(c, c));
        assert!(at(centre));
        assert!(!at(centre + Vec3::new(h, 0.0, 0.0)));
        assert!(g.contracted_region(&Aabb::new(
            centre - Vec3::splat(2.0 * h),
            centre - Vec3::splat(0.4 * h)
        )));
        assert!(!g.contracted_region(&Aabb::new(Vec3::splat(-2.0), Vec3::splat(-1.0))));
        assert!((g.fill_ratio() - 1.0 / (n * n * n) as f64).abs() < 1e-12);
        // The same cell from field space: contracted x = −1.34 is field x = −1/(2 − 1.34)
        // scaled along its ray; the centre's field point lies in it.
        let m = centre.abs().max_element();
        let field_point = centre / m / (2.0 - m);
        assert!((contract(field_point) - centre).length() < 1e-5);
        assert!(g.point(field_point));
        let (p, q) = (field_point, field_point * 1.001);
        assert!(g.region(&Aabb::new(p.min(q), p.max(q))));
        // A cell near the centre is not reached from a box out beyond ‖x‖∞ = 2, whose
        // plain interval bound of the contraction would reach down to it.
        let mut cells = vec![false; n * n * n];
        cells[(32 * n + 32) * n + 40] = true; // contracted x ∈ [0.5, 0.5625], y, z ∈ [0, h]
        let g = OccupancyGrid::from_cells(&settings, &cells, Source::Computed);
        assert!(g.point(Vec3::new(0.53, 0.01, 0.01)));
        let far = Aabb::new(Vec3::new(2.0, -0.5, -0.1), Vec3::new(10.0, 1.5, 0.1));
        assert!(contract_box(&far).0.contains(Vec3::new(0.53, 0.01, 0.01)));
        assert!(!g.region(&far));
        assert!(g.region(&Aabb::new(
            Vec3::new(0.3, -0.5, -0.1),
            Vec3::new(10.0, 1.5, 0.1)
        )));
    }

    #[test]
    fn contracted_boxes_hold_the_contracted_points() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for k in 0..2000 {
            // Boxes from the unit cube out to 500 units, some straddling the axes.
            let scale = [0.5, 3.0, 40.0, 500.0][k % 4];
            let a = Vec3::new(next(), next(), next()) * 2.0 - Vec3::ONE;
            let b = Vec3::new(next(), next(), next()) * 2.0 - Vec3::ONE;
            let (lo, hi) = (a.min(b) * scale, a.max(b) * scale);
            let (c, inner) = contract_box(&Aabb::new(lo, hi));
            for _ in 0..8 {
                let t = Vec3::new(next(), next(), next());
                let p = lo + t * (hi - lo);
                let q = contract(p);
                assert!(
                    c.contains(q) && q.abs().max_element() >= inner,
                    "box {lo}..{hi}: contracted {q} of {p} outside {:?}..{:?} or within {inner}",
                    c.min,
                    c.max
                );
            }
        }
        // Contraction at the formula's landmarks.
        assert_eq!(
            contract(Vec3::new(0.5, -0.25, 0.0)),
            Vec3::new(0.5, -0.25, 0.0)
        );
        assert!(
            (contract(Vec3::new(4.0, 2.0, -1.0)) - Vec3::new(1.75, 0.875, -0.4375)).length() < 1e-6
        );
    }

    #[test]
    fn a_point_of_density_occupies_its_cells_and_their_neighbours() {
        // σ = 1 only within 0.01 of the centre of cell (5, 2, 3) (h = 0.5): sampled at that
        // centre only, so cells 4..=6 × 1..=3 × 2..=4 are occupied after dilation.
        let c = Vec3::new(-2.0 + 5.5 * 0.5, -2.0 + 2.5 * 0.5, -2.0 + 3.5 * 0.5);
        let cells = compute_cells(&SETTINGS, |pts, sigma| {
            for (p, s) in pts.iter().zip(sigma.iter_mut()) {
                *s = if (*p - c).length() < 0.01 { 1.0 } else { 0.0 };
            }
        });
        for z in 0..8 {
            for y in 0..8 {
                for x in 0..8 {
                    let want = (4..=6).contains(&x) && (1..=3).contains(&y) && (2..=4).contains(&z);
                    assert_eq!(cells[(z * 8 + y) * 8 + x], want, "({x}, {y}, {z})");
                }
            }
        }
    }

    fn seeded_cells(n: usize) -> Vec<bool> {
        (0..n * n * n).map(|i| (i * 7 + i / 5) % 3 == 0).collect()
    }

    #[test]
    fn cache_bytes_round_trip_and_refuse_any_change() {
        let cells = seeded_cells(8);
        let bytes = encode("key A", 8, &cells);
        // Layout: magic, version, key length and key, n, 64 bits, hash.
        assert_eq!(&bytes[..8], b"NERFXOCC");
        assert_eq!(bytes.len(), 8 + 4 + 4 + 5 + 4 + 64 + 8);
        assert_eq!(decode(&bytes, "key A", 8), Some(cells));
        assert_eq!(decode(&bytes, "key B", 8), None);
        assert_eq!(decode(&bytes, "key A", 4), None);
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x10;
            assert_eq!(decode(&bad, "key A", 8), None, "flipped byte {i}");
        }
        for cut in 0..bytes.len() {
            assert_eq!(decode(&bytes[..cut], "key A", 8), None, "cut at {cut}");
        }
    }

    #[test]
    fn the_cache_is_used_until_its_key_changes() {
        let dir = std::env::temp_dir().join(format!("nerfx-occ-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let density = |pts: &[Vec3], sigma: &mut [f32]| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            for (p, s) in pts.iter().zip(sigma.iter_mut()) {
                *s = if p.x < 0.0 { 1.0 } else { 0.0 };
            }
        };
        let caches = [dir.join(CACHE_FILE)];
        let a = OccupancyGrid::load_or_build(&SETTINGS, &caches, Some("k1"), density);
        assert_eq!(a.source(), &Source::Computed);
        let computed = calls.load(std::sync::atomic::Ordering::Relaxed);
        assert!(computed > 0);
        let b = OccupancyGrid::load_or_build(&SETTINGS, &caches, Some("k1"), density);
        assert_eq!(b.source(), &Source::Cached(caches[0].clone()));
        assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), computed);
        assert_eq!(a.sums, b.sums);
        // Another key: recomputed (and the cache rewritten for it).
        let c = OccupancyGrid::load_or_build(&SETTINGS, &caches, Some("k2"), density);
        assert_eq!(c.source(), &Source::Computed);
        assert_eq!(a.sums, c.sums);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_cache_that_cannot_be_written_falls_back_and_garbage_is_ignored() {
        let dir = std::env::temp_dir().join(format!("nerfx-occ-fallback-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // The first place is taken by a directory: the grid goes to the second, whose
        // folder is created.
        let caches = [
            dir.join("run").join(CACHE_FILE),
            dir.join("user/nerfx/x.bin"),
        ];
        std::fs::create_dir_all(&caches[0]).unwrap();
        let density = |pts: &[Vec3], sigma: &mut [f32]| {
            for (p, s) in pts.iter().zip(sigma.iter_mut()) {
                *s = if p.y > 0.5 { 1.0 } else { 0.0 };
            }
        };
        let a = OccupancyGrid::load_or_build(&SETTINGS, &caches, Some("k"), density);
        assert_eq!(a.source(), &Source::Computed);
        assert!(caches[1].is_file());
        let b = OccupancyGrid::load_or_build(&SETTINGS, &caches, Some("k"), density);
        assert_eq!(b.source(), &Source::Cached(caches[1].clone()));
        assert_eq!(a.sums, b.sums);
        // Garbage in the first place (now a file) is passed over for the second.
        std::fs::remove_dir(&caches[0]).unwrap();
        std::fs::write(&caches[0], b"NERFXOCC garbage, not a grid").unwrap();
        let c = OccupancyGrid::load_or_build(&SETTINGS, &caches, Some("k"), density);
        assert_eq!(c.source(), &Source::Cached(caches[1].clone()));
        // With nowhere to write, the grid is computed and kept in memory only.
        let nowhere = [dir.join("run").join(CACHE_FILE).join("below-a-file.bin")];
        let d = OccupancyGrid::load_or_build(&SETTINGS, &nowhere, Some("k"), density);
        assert_eq!(d.source(), &Source::Computed);
        assert_eq!(a.sums, d.sums);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
