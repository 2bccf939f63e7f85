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
        let ab = self.b - self.a;
        let denom = dir.cross(ab);
        if denom.abs() < 1e-12 {
            return None; // parallel
        }
        let ao = self.a - origin;
        let t = ao.cross(ab) / denom;
        let u = ao.cross(dir) / denom;
        (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
    }
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
}

impl Enclosure {
    /// The paper's arena: a right triangle with short walls of `leg` m, the right angle at the origin,
    /// legs along +x and +y.
    pub fn right_triangle(leg: f64) -> Self {
        let o = Vec2::new(0.0, 0.0);
        let a = Vec2::new(leg, 0.0);
        let b = Vec2::new(0.0, leg);
        Enclosure {
            walls: vec![
                Segment { a: o, b: a },
                Segment { a, b },
                Segment { a: b, b: o },
            ],
        }
    }

    pub fn walls(&self) -> &[Segment] {
        &self.walls
    }

    /// Replaces `out` with the contacts of a disc of `radius` at `centre` with every wall closer than
    /// `radius + tolerance`.
    pub fn contacts(&self, centre: Vec2, radius: f64, tolerance: f64, out: &mut Vec<Contact>) {
        out.clear();
        for wall in &self.walls {
            let away = centre - wall.closest_point(centre);
            let dist = away.length();
            if dist < radius + tolerance && dist > 1e-12 {
                out.push(Contact {
                    normal: away * (1.0 / dist),
                    depth: radius - dist,
                });
            }
        }
    }

    /// Distance from `origin` along unit `dir` to the nearest wall, if any wall is hit.
    pub fn ray_distance(&self, origin: Vec2, dir: Vec2) -> Option<f64> {
        self.walls
            .iter()
            .filter_map(|w| w.ray_hit(origin, dir))
            .min_by(f64::total_cmp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
