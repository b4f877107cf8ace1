//! Stand-ins: a coloured point cloud of where a field or splat set visibly is, in the frame
//! nerfx renders it in, for an artist to place the NeRF object by in Blender.
//!
//! A field is sampled on a grid over its bounds (at most [`MAX_GRID`] cells per side); a cell
//! is kept when its opacity `1 − exp(−σ·h)` (h the cell's longest side) exceeds the threshold,
//! and its point is jittered deterministically inside the cell. Splats give one point per
//! mean whose opacity exceeds the threshold, coloured by the DC term. Colours are the
//! capture's display colours: sRGB-encoded 8-bit.

use std::path::Path;

use glam::{DMat4, Vec3};

use crate::error::Result;
use crate::field::{Aabb, ColorSpace, Field, SplatColor, Splats};
use crate::scene::Scene;

/// Grid cells per side at most, which bounds time and memory.
pub const MAX_GRID: u32 = 256;

/// A coloured point, in the render frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Position.
    pub position: Vec3,
    /// sRGB-encoded colour.
    pub rgb: [u8; 3],
}

/// Stand-in points for every instance of a scene, mapped by its `world_from_field`, at most
/// `budget` of them (a deterministic stride over the kept points).
pub fn points(scene: &Scene, resolution: u32, threshold: f32, budget: usize) -> Vec<Point> {
    let mut out = Vec::new();
    for inst in scene.field_instances() {
        let m = inst.world_from_field();
        out.extend(
            field_points(inst.field(), resolution, threshold)
                .into_iter()
                .map(|p| transformed(p, m)),
        );
    }
    for inst in scene.splats() {
        let m = inst.world_from_splats();
        out.extend(
            splat_points(inst.splats(), threshold)
                .into_iter()
                .map(|p| transformed(p, m)),
        );
    }
    subsample(out, budget)
}

fn transformed(p: Point, m: DMat4) -> Point {
    Point {
        position: m.transform_point3(p.position.as_dvec3()).as_vec3(),
        rgb: p.rgb,
    }
}

/// Every `len/budget`-th point, deterministically, so the budget holds.
fn subsample(points: Vec<Point>, budget: usize) -> Vec<Point> {
    if points.len() <= budget {
        return points;
    }
    let n = points.len();
    (0..budget).map(|i| points[i * n / budget]).collect()
}

/// A deterministic offset in [0, 1) per cell coordinate (an integer hash).
fn jitter(i: u32, j: u32, k: u32, axis: u32) -> f32 {
    let mut h = i.wrapping_mul(0x9E37_79B1)
        ^ j.wrapping_mul(0x85EB_CA77)
        ^ k.wrapping_mul(0xC2B2_AE3D)
        ^ axis.wrapping_mul(0x27D4_EB2F);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 12;
    (h >> 8) as f32 / (1u32 << 24) as f32
}

/// Where a field's stand-in is sampled: its bounds, or an unbounded field's core (the cube
/// `ns-export` exports by default for nerfacto), not the far-plane cube.
fn detail_bounds(field: &dyn Field) -> Aabb {
    field
        .unbounded()
        .map_or_else(|| field.bounds(), |u| u.core_box())
}

/// Points of a field in its own frame: one per surface cell, a cell whose sample is opaque
/// and which has a transparent (or out-of-grid) neighbour along an axis, so a solid object
/// gives its shell. A surface cell's point lies within two cells of the surface.
pub fn field_points(field: &dyn Field, resolution: u32, threshold: f32) -> Vec<Point> {
    let bounds = detail_bounds(field);
    if bounds.is_empty() {
        return Vec::new();
    }
    let size = bounds.size();
    let h = size.max_element() / resolution.clamp(1, MAX_GRID) as f32;
    let dims = (size / h).ceil().max(Vec3::ONE).as_uvec3();
    let sample = |i: u32, j: u32, k: u32| {
        let cell = Vec3::new(
            i as f32 + jitter(i, j, k, 0),
            j as f32 + jitter(i, j, k, 1),
            k as f32 + jitter(i, j, k, 2),
        );
        bounds.min + cell * h
    };
    let index = |i: u32, j: u32, k: u32| ((k * dims.y + j) * dims.x + i) as usize;
    let mut opaque = vec![false; (dims.x * dims.y * dims.z) as usize];
    let mut positions = Vec::with_capacity(dims.x as usize);
    let mut sigma = Vec::new();
    for k in 0..dims.z {
        for j in 0..dims.y {
            // A row the field's conservative occupancy calls empty stays transparent.
            let row_min = bounds.min + Vec3::new(0.0, j as f32, k as f32) * h;
            let row = Aabb::new(row_min, row_min + Vec3::new(dims.x as f32, 1.0, 1.0) * h);
            if !field.may_be_occupied(&row) {
                continue;
            }
            positions.clear();
            positions.extend((0..dims.x).map(|i| sample(i, j, k)));
            sigma.resize(positions.len(), 0.0);
            field.density(&positions, &mut sigma);
            let start = index(0, j, k);
            for (o, s) in opaque[start..start + sigma.len()].iter_mut().zip(&sigma) {
                *o = 1.0 - (-(s.max(0.0)) * h).exp() > threshold;
            }
        }
    }
    let is_opaque = |i: i64, j: i64, k: i64| {
        let inside = (0..dims.x as i64).contains(&i)
            && (0..dims.y as i64).contains(&j)
            && (0..dims.z as i64).contains(&k);
        inside && opaque[index(i as u32, j as u32, k as u32)]
    };
    let mut kept = Vec::new();
    for k in 0..dims.z {
        for j in 0..dims.y {
            for i in 0..dims.x {
                let (a, b, c) = (i as i64, j as i64, k as i64);
                let surface = is_opaque(a, b, c)
                    && [(1, 0, 0), (0, 1, 0), (0, 0, 1)].iter().any(|&(x, y, z)| {
                        !is_opaque(a + x, b + y, c + z) || !is_opaque(a - x, b - y, c - z)
                    });
                if surface {
                    kept.push(sample(i, j, k));
                }
            }
        }
    }
    let colours = field_colours(field, &kept);
    kept.into_iter()
        .zip(colours)
        .map(|(position, rgb)| Point { position, rgb })
        .collect()
}

/// The field's radiance averaged over the six axis directions, sRGB-encoded.
fn field_colours(field: &dyn Field, positions: &[Vec3]) -> Vec<[u8; 3]> {
    let mut sum = vec![Vec3::ZERO; positions.len()];
    let mut rgb = vec![Vec3::ZERO; positions.len()];
    for d in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
        let dirs = vec![d; positions.len()];
        field.radiance(positions, &dirs, &mut rgb);
        for (s, c) in sum.iter_mut().zip(&rgb) {
            *s += *c / 6.0;
        }
    }
    let linear = field.color_space() == ColorSpace::Linear;
    sum.into_iter()
        .map(|c| {
            let c = if linear {
                Vec3::new(
                    crate::field::linear_to_srgb(c.x),
                    crate::field::linear_to_srgb(c.y),
                    crate::field::linear_to_srgb(c.z),
                )
            } else {
                c
            };
            to_u8(c)
        })
        .collect()
}

fn to_u8(c: Vec3) -> [u8; 3] {
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(c.x), q(c.y), q(c.z)]
}

/// One point per splat mean whose opacity exceeds the threshold, coloured by the DC term.
pub(crate) fn splat_points(splats: &Splats, threshold: f32) -> Vec<Point> {
    /// The degree-0 real spherical harmonic, `1 / (2√π)`.
    const SH_C0: f32 = 0.282_094_8;
    let stride = splats.color.coefficients() * 3;
    (0..splats.len())
        .filter(|&i| splats.opacities[i] > threshold)
        .map(|i| {
            let dc = &splats.coefficients[i * stride..i * stride + 3];
            let dc = Vec3::new(dc[0], dc[1], dc[2]);
            let c = match splats.color {
                SplatColor::Sh { .. } => dc * SH_C0 + 0.5,
                SplatColor::Sigmoid => Vec3::ONE / (Vec3::ONE + (-dc).exp()),
            };
            Point {
                position: splats.means[i],
                rgb: to_u8(c),
            }
        })
        .collect()
}

/// Writes points as a binary little-endian PLY (`x y z` float, `red green blue` uchar).
pub fn write_ply(path: &Path, points: &[Point]) -> Result<()> {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\ncomment nerfx stand-in\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.len()
    )
    .into_bytes();
    bytes.reserve(points.len() * 15);
    for p in points {
        for v in p.position.to_array() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&p.rgb);
    }
    crate::output::write_file(path, &bytes)
}

/// A triangle mesh with vertex colours, in the render frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertices.
    pub vertices: Vec<Point>,
    /// Triangles, as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// The meshes of every field instance of a scene, joined (splats have no density grid).
pub fn mesh(scene: &Scene, resolution: u32, threshold: f32) -> Mesh {
    let mut out = Mesh::default();
    for inst in scene.field_instances() {
        let m = field_mesh(inst.field(), inst.world_from_field(), resolution, threshold);
        let base = out.vertices.len() as u32;
        out.vertices.extend(m.vertices);
        out.triangles
            .extend(m.triangles.into_iter().map(|t| t.map(|i| i + base)));
    }
    out
}

/// The isosurface where a field's opacity over a cell equals `threshold`, by naive surface
/// nets (fast-surface-nets) on a lattice of at most [`MAX_GRID`] cells along the longest side
/// (padded by one transparent cell so the surface closes), mapped by `world_from_field`. A
/// vertex lies in a lattice cube the isosurface crosses, so within √3 cells of it.
pub fn field_mesh(
    field: &dyn Field,
    world_from_field: DMat4,
    resolution: u32,
    threshold: f32,
) -> Mesh {
    use fast_surface_nets::{surface_nets, SurfaceNetsBuffer};
    use ndshape::{RuntimeShape, Shape};
    let bounds = detail_bounds(field);
    if bounds.is_empty() {
        return Mesh::default();
    }
    let size = bounds.size();
    let h = size.max_element() / resolution.clamp(1, MAX_GRID) as f32;
    let cells = (size / h).ceil().max(Vec3::ONE).as_uvec3();
    let dims = cells + glam::UVec3::splat(3);
    let origin = bounds.min - Vec3::splat(h);
    let shape = RuntimeShape::<u32, 3>::new(dims.to_array());
    let mut sdf = vec![threshold; shape.usize()];
    let mut positions = Vec::with_capacity((dims.x * dims.y) as usize);
    let mut sigma = Vec::new();
    for k in 1..dims.z - 1 {
        positions.clear();
        for j in 1..dims.y - 1 {
            for i in 1..dims.x - 1 {
                positions.push(origin + Vec3::new(i as f32, j as f32, k as f32) * h);
            }
        }
        sigma.resize(positions.len(), 0.0);
        field.density(&positions, &mut sigma);
        let mut s = sigma.iter();
        for j in 1..dims.y - 1 {
            for i in 1..dims.x - 1 {
                if let Some(s) = s.next() {
                    let opacity = 1.0 - (-(s.max(0.0)) * h).exp();
                    sdf[shape.linearize([i, j, k]) as usize] = threshold - opacity;
                }
            }
        }
    }
    let mut buffer = SurfaceNetsBuffer::default();
    surface_nets(&sdf, &shape, [0; 3], (dims - 1).to_array(), &mut buffer);
    drop(sdf);
    let local: Vec<Vec3> = buffer
        .positions
        .iter()
        .map(|p| origin + Vec3::from_array(*p) * h)
        .collect();
    let colours = field_colours(field, &local);
    Mesh {
        vertices: local
            .into_iter()
            .zip(colours)
            .map(|(position, rgb)| transformed(Point { position, rgb }, world_from_field))
            .collect(),
        triangles: buffer
            .indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
    }
}

/// Writes a mesh as a binary little-endian PLY: vertices as in [`write_ply`], faces as a
/// `uchar` count and `int` indices.
pub fn write_mesh_ply(path: &Path, mesh: &Mesh) -> Result<()> {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\ncomment nerfx stand-in mesh\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )
    .into_bytes();
    for p in &mesh.vertices {
        for v in p.position.to_array() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&p.rgb);
    }
    for t in &mesh.triangles {
        bytes.push(3);
        for i in t {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
    }
    crate::output::write_file(path, &bytes)
}
