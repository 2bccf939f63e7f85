//! Plane geometry for the simulated world: vectors, wall segments, the paper's triangular enclosure,
//! circle-against-wall contacts and ray casts for the infrared proximity sensors.

use std::ops::{Add, Mul, Neg, Sub};

/// A point or direction in the plane, m.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    pub x: f64,
    pub y: f64,
}

impl Vec2 {
    pub const fn new(x: f64, y: f64) -> Self {
        Vec2 { x, y }
    }

    /// The unit vector at `angle` rad from +x, counter-clockwise.
    pub fn from_angle(angle: f64) -> Self {
        let (s, c) = angle.sin_cos();
        Vec2::new(c, s)
    }

    pub fn dot(self, o: Vec2) -> f64 {
        self.x * o.x + self.y * o.y
    }

    /// The z component of the 3-D cross product: positive when `o` is counter-clockwise of `self`.
    pub fn cross(self, o: Vec2) -> f64 {
        self.x * o.y - self.y * o.x
    }

    pub fn length(self) -> f64 {
        self.dot(self).sqrt()
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for Vec2 {
    type Output = Vec2;
    fn mul(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}

impl Neg for Vec2 {
    type Output = Vec2;
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}

/// A straight wall from `a` to `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub a: Vec2,
    pub b: Vec2,
}

impl Segment {
    /// The point of the segment nearest to `p`.
    pub fn closest_point(&self, p: Vec2) -> Vec2 {
        let ab = self.b - self.a;
        let len2 = ab.dot(ab);
        if len2 == 0.0 {
            return self.a;
        }
        let t = ((p - self.a).dot(ab) / len2).clamp(0.0, 1.0);
        self.a + ab * t
    }

    /// Distance along the ray `origin + t·dir` (`dir` a unit vector, `t ≥ 0`) at which it meets the
    /// segment, if it does.
    pub fn ray_hit(&self, origin: Vec2, dir: Vec2) -> Option<f64> {
        ray_hit(self.a, self.b - self.a, origin, dir)
    }
}

/// Distance along the ray `origin + t·dir` at which it meets the segment from `a` to `a + ab`, if it does.
#[inline]
fn ray_hit(a: Vec2, ab: Vec2, origin: Vec2, dir: Vec2) -> Option<f64> {
    let denom = dir.cross(ab);
    if denom.abs() < 1e-12 {
        return None; // parallel
    }
    let ao = a - origin;
    let t = ao.cross(ab) / denom;
    let u = ao.cross(dir) / denom;
    (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
}

/// The robot's body touching a wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Unit vector from the wall toward the body's centre.
    pub normal: Vec2,
    /// How far the body overlaps the wall, m (negative: a gap within the contact tolerance).
    pub depth: f64,
}

/// A closed arena bounded by wall segments.
#[derive(Debug, Clone, PartialEq)]
pub struct Enclosure {
    walls: Vec<Segment>,
    /// One per wall, in the walls' order: the wall as [`Enclosure::contacts`] and
    /// [`Enclosure::ray_distance`] use it, with what they need to skip a wall that is certainly out of
    /// reach.
    reach_filters: Vec<ReachFilter>,
}

/// Relative margin of [`ReachFilter`]: far above the few ulps by which the computed distances can differ
/// from the true ones (rounding of metre-scale coordinates is ~1e-16 of their magnitude).
const REACH_MARGIN: f64 = 1e-9;

/// A lower bound on a point's distance to one wall: its distance to the wall's supporting line. A wall
/// whose line is farther than the reach plus a margin cannot be within reach, so the exact (and
/// dearer) closest-point computation can be skipped for it without changing any result.
///
/// It also keeps the wall's `b − a` and its squared length, computed once as [`Segment::closest_point`]
/// and [`Segment::ray_hit`] compute them on every call (the same operations on the same values, so the
/// same bits).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ReachFilter {
    a: Vec2,
    /// `b − a`.
    ab: Vec2,
    /// `ab · ab`.
    len2: f64,
    /// Unit normal of the wall's line; NaN for a zero-length (or infinite) wall, which makes
    /// `certainly_beyond` false: such a wall is never skipped.
    normal: Vec2,
    /// `1 + |a.x| + |a.y| + |b.x| + |b.y|`: the scale of the coordinates the rounding errors are relative to.
    scale: f64,
}

impl ReachFilter {
    fn new(wall: &Segment) -> Self {
        let ab = wall.b - wall.a;
        let len = ab.length();
        let normal = if len > 0.0 && len.is_finite() {
            Vec2::new(-ab.y, ab.x) * (1.0 / len)
        } else {
            Vec2::new(f64::NAN, f64::NAN)
        };
        ReachFilter {
            a: wall.a,
            ab,
            len2: ab.dot(ab),
            normal,
            scale: 1.0 + wall.a.x.abs() + wall.a.y.abs() + wall.b.x.abs() + wall.b.y.abs(),
        }
    }

    /// True only when `p` is certainly farther than `reach` from the wall: its distance to the wall's
    /// line exceeds `reach` by more than [`REACH_MARGIN`] times the coordinates' scale. `p_scale` is
    /// `|p.x| + |p.y|`. NaN anywhere (a NaN normal included) gives false: the exact computation decides.
    #[inline]
    fn certainly_beyond(&self, p: Vec2, p_scale: f64, reach: f64) -> bool {
        let line_distance = (p - self.a).dot(self.normal).abs();
        line_distance > reach + REACH_MARGIN * (self.scale + p_scale)
    }

    /// [`Segment::closest_point`] of the wall, with its `ab` and `len2` computed once.
    #[inline]
    fn closest_point(&self, p: Vec2) -> Vec2 {
        if self.len2 == 0.0 {
            return self.a;
        }
        let t = ((p - self.a).dot(self.ab) / self.len2).clamp(0.0, 1.0);
        self.a + self.ab * t
    }

    /// [`Segment::ray_hit`] of the wall, with its `ab` computed once.
    #[inline]
    fn ray_hit(&self, origin: Vec2, dir: Vec2) -> Option<f64> {
        ray_hit(self.a, self.ab, origin, dir)
    }
}

impl Enclosure {
    /// The paper's arena: a right triangle with short walls of `leg` m, the right angle at the origin,
    /// legs along +x and +y.
    pub fn right_triangle(leg: f64) -> Self {
        let o = Vec2::new(0.0, 0.0);
        let a = Vec2::new(leg, 0.0);
        let b = Vec2::new(0.0, leg);
        Enclosure::new(vec![
            Segment { a: o, b: a },
            Segment { a, b },
            Segment { a: b, b: o },
        ])
    }

    /// An arena bounded by `walls`.
    pub fn new(walls: Vec<Segment>) -> Self {
        let reach_filters = walls.iter().map(ReachFilter::new).collect();
        Enclosure {
            walls,
            reach_filters,
        }
    }

    pub fn walls(&self) -> &[Segment] {
        &self.walls
    }

    /// Replaces `out` with the contacts of a disc of `radius` at `centre` with every wall closer than
    /// `radius + tolerance`.
    ///
    /// Walls whose line is certainly beyond reach (see `ReachFilter`) are skipped; for the others the
    /// exact test decides, so the contacts are those of testing every wall.
    pub fn contacts(&self, centre: Vec2, radius: f64, tolerance: f64, out: &mut Vec<Contact>) {
        out.clear();
        let reach = radius + tolerance;
        let p_scale = centre.x.abs() + centre.y.abs();
        for wall in &self.reach_filters {
            if wall.certainly_beyond(centre, p_scale, reach) {
                continue;
            }
            let away = centre - wall.closest_point(centre);
            let dist = away.length();
            if dist < reach && dist > 1e-12 {
                out.push(Contact {
                    normal: away * (1.0 / dist),
                    depth: radius - dist,
                });
            }
        }
    }

    /// Distance from `origin` along unit `dir` to the nearest wall, if any wall is hit.
    pub fn ray_distance(&self, origin: Vec2, dir: Vec2) -> Option<f64> {
        // `filter_map(ray_hit).min_by(f64::total_cmp)` written out: the first of the least hits.
        let mut nearest: Option<f64> = None;
        for wall in &self.reach_filters {
            if let Some(t) = wall.ray_hit(origin, dir) {
                nearest = match nearest {
                    Some(n) if t.total_cmp(&n).is_ge() => Some(n),
                    _ => Some(t),
                };
            }
        }
        nearest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slanted quadrilateral with a zero-length wall, and walls not on the axes.
    fn slanted_quad() -> Enclosure {
        let corner = |x, y| Vec2::new(x, y);
        let wall = |a, b| Segment { a, b };
        Enclosure::new(vec![
            wall(corner(-0.3, 0.1), corner(1.7, -0.4)),
            wall(corner(1.7, -0.4), corner(1.7, -0.4)),
            wall(corner(1.7, -0.4), corner(0.9, 1.3)),
            wall(corner(0.9, 1.3), corner(-0.3, 0.1)),
        ])
    }

    #[test]
    fn closest_point_clamps_to_the_ends() {
        let s = Segment {
            a: Vec2::new(0.0, 0.0),
            b: Vec2::new(1.0, 0.0),
        };
        assert_eq!(s.closest_point(Vec2::new(0.5, 2.0)), Vec2::new(0.5, 0.0));
        assert_eq!(s.closest_point(Vec2::new(-3.0, 1.0)), Vec2::new(0.0, 0.0));
        assert_eq!(s.closest_point(Vec2::new(4.0, -1.0)), Vec2::new(1.0, 0.0));
    }

    #[test]
    fn contacts_find_the_touching_walls_only() {
        let e = Enclosure::right_triangle(1.0);
        let mut c = Vec::new();
        e.contacts(Vec2::new(0.5, 0.1), 0.15, 0.001, &mut c);
        assert_eq!(c.len(), 1);
        assert!((c[0].normal.y - 1.0).abs() < 1e-12);
        assert!((c[0].depth - 0.05).abs() < 1e-12);
        e.contacts(Vec2::new(1.0 / 3.0, 1.0 / 3.0), 0.165, 0.001, &mut c);
        assert!(c.is_empty());
        // In the right-angle corner both legs touch.
        e.contacts(Vec2::new(0.16, 0.16), 0.165, 0.001, &mut c);
        assert_eq!(c.len(), 2);
    }

    /// The contacts of testing every wall exactly: [`Enclosure::contacts`] without its prefilter.
    fn contacts_unfiltered(
        e: &Enclosure,
        centre: Vec2,
        radius: f64,
        tolerance: f64,
    ) -> Vec<Contact> {
        let mut out = Vec::new();
        for wall in e.walls() {
            let away = centre - wall.closest_point(centre);
            let dist = away.length();
            if dist < radius + tolerance && dist > 1e-12 {
                out.push(Contact {
                    normal: away * (1.0 / dist),
                    depth: radius - dist,
                });
            }
        }
        out
    }

    fn bits(contacts: &[Contact]) -> Vec<[u64; 3]> {
        contacts
            .iter()
            .map(|c| {
                [
                    c.normal.x.to_bits(),
                    c.normal.y.to_bits(),
                    c.depth.to_bits(),
                ]
            })
            .collect()
    }

    /// Checks the filtered contacts at `p` against the unfiltered ones, bit for bit; returns how many
    /// walls the filter skipped.
    fn agree_at(
        e: &Enclosure,
        p: Vec2,
        radius: f64,
        tolerance: f64,
        out: &mut Vec<Contact>,
    ) -> usize {
        e.contacts(p, radius, tolerance, out);
        let exact = contacts_unfiltered(e, p, radius, tolerance);
        assert_eq!(
            bits(out),
            bits(&exact),
            "at {p:?}, radius {radius}, tolerance {tolerance}"
        );
        let reach = radius + tolerance;
        let p_scale = p.x.abs() + p.y.abs();
        e.reach_filters
            .iter()
            .filter(|f| f.certainly_beyond(p, p_scale, reach))
            .count()
    }

    #[test]
    fn the_reach_prefilter_never_changes_the_contacts() {
        let mut rng = crate::rng::Rng::new(42);
        let mut out = Vec::new();
        let mut skipped = 0;
        let mut near_boundary = 0;
        let arenas = [
            Enclosure::right_triangle(1.0),
            Enclosure::right_triangle(2.5),
            slanted_quad(),
        ];
        for e in &arenas {
            for _ in 0..20_000 {
                let radius = rng.uniform(0.0, 0.4);
                let tolerance = [0.0, 0.001, rng.uniform(0.0, 0.01)][rng.below(3) as usize];
                let reach = radius + tolerance;
                // Anywhere around the arena.
                let p = Vec2::new(rng.uniform(-1.0, 3.5), rng.uniform(-1.0, 3.5));
                skipped += agree_at(e, p, radius, tolerance, &mut out);
                // Exactly at the reach from a wall's line, at the filter's threshold, and a few ulps
                // either side of both.
                let wall = e.walls()[rng.below(e.walls().len() as u64) as usize];
                let f = ReachFilter::new(&wall);
                let n = f.normal;
                if n.x.is_nan() {
                    continue;
                }
                let along = wall.a + (wall.b - wall.a) * rng.uniform(-0.2, 1.2);
                let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
                let threshold = reach + REACH_MARGIN * (f.scale + along.x.abs() + along.y.abs());
                for d in [reach, threshold] {
                    let mut d = d;
                    for _ in 0..4 {
                        d = d.next_down();
                    }
                    for _ in 0..9 {
                        let p = along + n * (side * d);
                        agree_at(e, p, radius, tolerance, &mut out);
                        near_boundary += 1;
                        d = d.next_up();
                    }
                }
            }
        }
        // The filter did skip walls (it is not vacuous) and the boundary points were tried.
        assert!(skipped > 10_000, "skipped {skipped}");
        assert!(near_boundary > 100_000, "{near_boundary}");
    }

    #[test]
    fn the_reach_prefilter_leaves_odd_inputs_to_the_exact_test() {
        let e = Enclosure::right_triangle(1.0);
        let mut out = Vec::new();
        for p in [
            Vec2::new(f64::NAN, 0.5),
            Vec2::new(0.0, 0.0),
            Vec2::new(1e12, -3e11),
            Vec2::new(f64::INFINITY, 0.2),
        ] {
            for (radius, tolerance) in [
                (0.165, 0.001),
                (0.0, 0.0),
                (f64::INFINITY, 0.0),
                (-1.0, 0.0),
            ] {
                agree_at(&e, p, radius, tolerance, &mut out);
            }
        }
    }

    /// [`Enclosure::ray_distance`] is `filter_map(ray_hit).min_by(total_cmp)` over the walls, bit for bit.
    #[test]
    fn ray_distance_is_the_least_hit_of_every_wall() {
        let mut rng = crate::rng::Rng::new(7);
        let quad = slanted_quad();
        let mut hits = 0;
        for e in [Enclosure::right_triangle(1.0), quad] {
            for i in 0..50_000 {
                // Inside and outside, and from a corner (two walls hit at the same distance).
                let origin = if i % 10 == 0 {
                    e.walls()[rng.below(e.walls().len() as u64) as usize].a
                } else {
                    Vec2::new(rng.uniform(-0.5, 2.0), rng.uniform(-0.5, 2.0))
                };
                let dir = Vec2::from_angle(rng.uniform(-4.0, 4.0));
                let expected = e
                    .walls()
                    .iter()
                    .filter_map(|w| w.ray_hit(origin, dir))
                    .min_by(f64::total_cmp);
                let got = e.ray_distance(origin, dir);
                assert_eq!(got.map(f64::to_bits), expected.map(f64::to_bits));
                hits += usize::from(got.is_some());
            }
        }
        assert!(hits > 30_000, "{hits}");
    }

    /// What the world's fused push-out relies on: the contacts within a tolerance ≥ 0 that overlap
    /// (depth > 0) are the overlapping contacts within tolerance 0, bit for bit and in order.
    #[test]
    fn overlapping_contacts_do_not_depend_on_the_tolerance() {
        let mut rng = crate::rng::Rng::new(8);
        let e = Enclosure::right_triangle(1.0);
        let (mut with, mut without) = (Vec::new(), Vec::new());
        let mut overlapping = 0;
        for _ in 0..100_000 {
            let p = Vec2::new(rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0));
            let radius = [0.165, rng.uniform(0.0, 0.4)][rng.below(2) as usize];
            let tolerance = [0.0, 0.001, rng.uniform(0.0, 0.01)][rng.below(3) as usize];
            e.contacts(p, radius, tolerance, &mut with);
            e.contacts(p, radius, 0.0, &mut without);
            with.retain(|c| c.depth > 0.0);
            without.retain(|c| c.depth > 0.0);
            assert_eq!(bits(&with), bits(&without), "at {p:?}");
            overlapping += with.len();
        }
        assert!(overlapping > 10_000, "{overlapping}");
    }

    #[test]
    fn rays_hit_the_nearest_wall() {
        let e = Enclosure::right_triangle(1.0);
        let from = Vec2::new(0.25, 0.25);
        let d = e.ray_distance(from, Vec2::from_angle(std::f64::consts::FRAC_PI_4));
        let expected = (1.0 - 0.5) / 2f64.sqrt();
        assert!((d.unwrap() - expected).abs() < 1e-9);
        let d = e.ray_distance(from, Vec2::new(-1.0, 0.0));
        assert!((d.unwrap() - 0.25).abs() < 1e-12);
        assert!(
            Segment {
                a: Vec2::new(0.0, 1.0),
                b: Vec2::new(1.0, 1.0)
            }
            .ray_hit(from, Vec2::new(0.0, -1.0))
            .is_none()
        );
    }
}
