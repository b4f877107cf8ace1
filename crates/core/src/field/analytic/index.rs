//! A bounding-volume hierarchy over an analytic field's primitives, for the many
//! "may this box hold density?" questions an occupancy grid's build asks.
//!
//! Each primitive with density contributes the box around its padded support (the volume
//! [`Shape::overlaps`] tests against), grown by a few ulps of its magnitude so that f32
//! rounding of the box never loses a primitive the exact test would find. The tree splits
//! the primitives at the median of their box centres along the axis where those centres
//! spread most, down to a few primitives a leaf: built in O(n log n), and a question costs
//! O(log n) plus the primitives whose boxes the region meets. A question is answered by the
//! same exact test on those primitives, so the answers are the field's own, bit for bit.

use glam::Vec3A;

use super::{padded_box, padded_radius, Primitive, Shape};
use crate::field::{Aabb, RegionQuery};

/// Primitives in a leaf.
const LEAF: usize = 4;

/// A node: its box, and either a range of `order` (a leaf) or two children.
#[derive(Clone, Copy, Debug)]
struct Node {
    /// The box, as SIMD lanes: one comparison per corner.
    min: Vec3A,
    max: Vec3A,
    /// For a leaf, the range `order[start..end]`; for an inner node, its two children's
    /// indices in `nodes`.
    start: u32,
    end: u32,
    leaf: bool,
}

/// The hierarchy over the active primitives of one field.
#[derive(Clone, Debug)]
pub(crate) struct PrimitiveIndex<'a> {
    primitives: &'a [Primitive],
    nodes: Vec<Node>,
    /// Primitive indices, leaf by leaf.
    order: Vec<u32>,
}

/// The box [`Shape::overlaps`] can answer true within, widened against rounding.
fn support_box(shape: &Shape) -> Aabb {
    let ball = |c: glam::Vec3, r: f32| {
        let r = padded_radius(c, r);
        Aabb::new(c, c).grow(r)
    };
    let b = match *shape {
        Shape::Sphere { center, radius } => ball(center, radius),
        Shape::Gaussian {
            center,
            sigma,
            cutoff,
        } => ball(center, cutoff * sigma),
        Shape::Box { min, max } => padded_box(min, max),
    };
    let magnitude = b.min.abs().max(b.max.abs()).max_element();
    b.grow(4.0 * f32::EPSILON * magnitude + f32::MIN_POSITIVE)
}

impl<'a> PrimitiveIndex<'a> {
    /// Indexes the primitives with density (the others never hold any).
    pub(crate) fn new(primitives: &'a [Primitive]) -> Self {
        let boxes: Vec<Aabb> = primitives.iter().map(|p| support_box(&p.shape)).collect();
        let mut order: Vec<u32> = (0..primitives.len() as u32)
            .filter(|&i| primitives[i as usize].density > 0.0)
            .collect();
        let mut nodes = Vec::with_capacity(2 * order.len() / LEAF + 1);
        if !order.is_empty() {
            let n = order.len();
            build(&boxes, &mut order, 0, n, &mut nodes);
        }
        PrimitiveIndex {
            primitives,
            nodes,
            order,
        }
    }

    /// Appends to `out` every primitive with density whose support meets `region`.
    fn collect(&self, region: &Aabb, out: &mut Vec<u32>) {
        let meets = |i: &u32| self.primitives[*i as usize].shape.overlaps(region);
        // A region with a non-finite corner is asked of every primitive, as the field would.
        if !region.min.is_finite() || !region.max.is_finite() {
            out.extend(self.order.iter().copied().filter(meets));
            return;
        }
        if self.nodes.is_empty() {
            return;
        }
        let (lo, hi) = (Vec3A::from(region.min), Vec3A::from(region.max));
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if !node.min.max(lo).cmple(node.max.min(hi)).all() {
                continue;
            }
            if node.leaf {
                let leaf = &self.order[node.start as usize..node.end as usize];
                out.extend(leaf.iter().copied().filter(meets));
            } else {
                stack[top] = node.start;
                stack[top + 1] = node.end;
                top += 2;
            }
        }
    }
}

/// The field's answer, from the primitives the enclosing region met (a region inside another
/// meets only primitives the other meets: the tests are monotone in the region, in f32 too),
/// or from the hierarchy for a region with none around it.
impl RegionQuery for PrimitiveIndex<'_> {
    fn may_be_occupied(&self, region: &Aabb, within: Option<&[u32]>, left: &mut Vec<u32>) -> bool {
        left.clear();
        if region.is_empty() {
            return false;
        }
        match within {
            Some(met) if region.min.is_finite() && region.max.is_finite() => left.extend(
                met.iter()
                    .copied()
                    .filter(|&i| self.primitives[i as usize].shape.overlaps(region)),
            ),
            _ => self.collect(region, left),
        }
        !left.is_empty()
    }
}

/// Builds the subtree over `order[start..end]`, returning its node's index.
fn build(
    boxes: &[Aabb],
    order: &mut [u32],
    start: usize,
    end: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
    let bounds = order[start..end]
        .iter()
        .fold(Aabb::EMPTY, |b, &i| b.union(&boxes[i as usize]));
    let at = nodes.len() as u32;
    let (min, max) = (Vec3A::from(bounds.min), Vec3A::from(bounds.max));
    nodes.push(Node {
        min,
        max,
        start: start as u32,
        end: end as u32,
        leaf: true,
    });
    if end - start <= LEAF {
        return at;
    }
    let centre = |i: u32| {
        let b = boxes[i as usize];
        0.5 * (b.min + b.max)
    };
    let (lo, hi) = order[start..end].iter().fold(
        (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
        |(lo, hi), &i| (lo.min(centre(i)), hi.max(centre(i))),
    );
    let spread = hi - lo;
    let axis = if spread.x >= spread.y && spread.x >= spread.z {
        0
    } else if spread.y >= spread.z {
        1
    } else {
        2
    };
    let mid = (end - start) / 2;
    order[start..end]
        .select_nth_unstable_by(mid, |&a, &b| centre(a)[axis].total_cmp(&centre(b)[axis]));
    let first = build(boxes, order, start, start + mid, nodes);
    let second = build(boxes, order, start + mid, end, nodes);
    nodes[at as usize] = Node {
        min,
        max,
        start: first,
        end: second,
        leaf: false,
    };
    at
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::field::{Analytic, Field, ShColor};

    /// Random spheres, boxes and Gaussians (some without density) against random regions,
    /// small and large, touching and not: the index answers as the field's own scan.
    #[test]
    fn answers_as_the_field_does() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut primitives = Vec::new();
        for i in 0..600 {
            let c = Vec3::new(rnd(), rnd(), rnd()) * 20.0 - 10.0;
            let size = 0.05 + rnd();
            let shape = match i % 3 {
                0 => Shape::Sphere {
                    center: c,
                    radius: size,
                },
                1 => Shape::Box {
                    min: c,
                    max: c + Vec3::new(rnd(), rnd(), rnd()) * size + Vec3::splat(1e-3),
                },
                _ => Shape::Gaussian {
                    center: c,
                    sigma: 0.3 * size,
                    cutoff: 4.0,
                },
            };
            primitives.push(Primitive {
                shape,
                density: if i % 7 == 0 { 0.0 } else { 1.0 + rnd() },
                color: ShColor::constant(Vec3::ONE),
            });
        }
        let field = Analytic { primitives };
        let index = PrimitiveIndex::new(&field.primitives);
        let (mut hits, mut misses) = (0, 0);
        let (mut met, mut around) = (Vec::new(), Vec::new());
        for k in 0..20_000 {
            let a = Vec3::new(rnd(), rnd(), rnd()) * 24.0 - 12.0;
            let s = Vec3::new(rnd(), rnd(), rnd()) * if k % 2 == 0 { 0.05 } else { 2.0 };
            let region = Aabb::new(a, a + s);
            let want = field.may_be_occupied(&region);
            assert_eq!(
                index.may_be_occupied(&region, None, &mut met),
                want,
                "{region:?}"
            );
            // Narrowed through an enclosing region, as an occupancy grid's quadtree asks.
            let outer = region.grow(0.5);
            index.may_be_occupied(&outer, None, &mut around);
            let narrowed = index.may_be_occupied(&region, Some(&around), &mut met);
            assert_eq!(narrowed, want, "{region:?} inside {outer:?}");
            if want {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} {misses}");
        // Empty and non-finite regions.
        for region in [
            Aabb::EMPTY,
            Aabb::new(Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY)),
            Aabb::new(Vec3::splat(f32::NAN), Vec3::ONE),
        ] {
            let want = field.may_be_occupied(&region);
            assert_eq!(index.may_be_occupied(&region, None, &mut met), want);
            assert_eq!(index.may_be_occupied(&region, Some(&[]), &mut met), want);
        }
        let none = PrimitiveIndex::new(&[]);
        assert!(!none.may_be_occupied(&Aabb::new(Vec3::ZERO, Vec3::ONE), None, &mut met));
    }
}
