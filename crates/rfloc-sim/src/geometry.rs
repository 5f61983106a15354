//! Planar geometry used by the world, collision checks and the range scanner.

use serde::{Deserialize, Serialize};

/// A point (or vector) in the world frame, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
}

impl Point {
    /// A point at `(x, y)`.
    #[must_use]
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// Euclidean distance to `other`.
    #[must_use]
    pub fn distance(&self, other: &Point) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }
}

/// A line segment between two points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub a: Point,
    pub b: Point,
}

fn cross(ax: f64, ay: f64, bx: f64, by: f64) -> f64 {
    ax * by - ay * bx
}

impl Segment {
    /// The segment from `a` to `b`.
    #[must_use]
    pub const fn new(a: Point, b: Point) -> Self {
        Self { a, b }
    }

    /// Shortest distance from `p` to any point of the segment.
    #[must_use]
    pub fn distance_to_point(&self, p: &Point) -> f64 {
        let (dx, dy) = (self.b.x - self.a.x, self.b.y - self.a.y);
        let len2 = dx * dx + dy * dy;
        if len2 <= f64::EPSILON {
            return self.a.distance(p);
        }
        let t = (((p.x - self.a.x) * dx + (p.y - self.a.y) * dy) / len2).clamp(0.0, 1.0);
        Point::new(self.a.x + t * dx, self.a.y + t * dy).distance(p)
    }

    /// Closest point of the segment to `p`.
    #[must_use]
    pub fn closest_point(&self, p: &Point) -> Point {
        let (dx, dy) = (self.b.x - self.a.x, self.b.y - self.a.y);
        let len2 = dx * dx + dy * dy;
        if len2 <= f64::EPSILON {
            return self.a;
        }
        let t = (((p.x - self.a.x) * dx + (p.y - self.a.y) * dy) / len2).clamp(0.0, 1.0);
        Point::new(self.a.x + t * dx, self.a.y + t * dy)
    }

    /// True when the two closed segments share at least one point (collinear overlaps
    /// included).
    #[must_use]
    pub fn intersects(&self, other: &Segment) -> bool {
        let d1 = orient(&other.a, &other.b, &self.a);
        let d2 = orient(&other.a, &other.b, &self.b);
        let d3 = orient(&self.a, &self.b, &other.a);
        let d4 = orient(&self.a, &self.b, &other.b);
        if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
            && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
        {
            return true;
        }
        (d1 == 0.0 && on_segment(&other.a, &other.b, &self.a))
            || (d2 == 0.0 && on_segment(&other.a, &other.b, &self.b))
            || (d3 == 0.0 && on_segment(&self.a, &self.b, &other.a))
            || (d4 == 0.0 && on_segment(&self.a, &self.b, &other.b))
    }

    /// Distance along the ray from `origin` in direction `angle` (radians) to this segment,
    /// or `None` when the ray misses it.
    #[must_use]
    pub fn ray_hit(&self, origin: &Point, angle: f64) -> Option<f64> {
        let (s, c) = angle.sin_cos();
        let (ex, ey) = (self.b.x - self.a.x, self.b.y - self.a.y);
        let denom = cross(c, s, ex, ey);
        if denom.abs() < 1e-12 {
            return None;
        }
        let (wx, wy) = (self.a.x - origin.x, self.a.y - origin.y);
        let t = cross(wx, wy, ex, ey) / denom;
        let u = cross(wx, wy, c, s) / denom;
        if t >= 0.0 && (0.0..=1.0).contains(&u) {
            Some(t)
        } else {
            None
        }
    }
}

fn orient(a: &Point, b: &Point, c: &Point) -> f64 {
    cross(b.x - a.x, b.y - a.y, c.x - a.x, c.y - a.y)
}

fn on_segment(a: &Point, b: &Point, p: &Point) -> bool {
    p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
}

/// A closed polygon given by its vertices (either winding).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Polygon {
    pub vertices: Vec<Point>,
}

impl Polygon {
    /// The polygon's edges, including the closing edge from the last vertex to the first.
    pub fn edges(&self) -> impl Iterator<Item = Segment> + '_ {
        let n = self.vertices.len();
        self.vertices
            .iter()
            .zip(self.vertices.iter().cycle().skip(1))
            .take(if n >= 2 { n } else { 0 })
            .map(|(a, b)| Segment::new(*a, *b))
    }

    /// Even-odd point-in-polygon test.
    #[must_use]
    pub fn contains(&self, p: &Point) -> bool {
        let mut inside = false;
        for e in self.edges() {
            let (a, b) = (e.a, e.b);
            if (a.y > p.y) != (b.y > p.y) {
                let x_cross = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
                if p.x < x_cross {
                    inside = !inside;
                }
            }
        }
        inside
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_segments_intersect_and_parallel_ones_do_not() {
        let s1 = Segment::new(Point::new(0.0, 0.0), Point::new(2.0, 2.0));
        let s2 = Segment::new(Point::new(0.0, 2.0), Point::new(2.0, 0.0));
        let s3 = Segment::new(Point::new(0.0, 1.0), Point::new(2.0, 3.0));
        assert!(s1.intersects(&s2));
        assert!(!s1.intersects(&s3));
    }

    #[test]
    fn ray_hits_wall_at_expected_distance() {
        let wall = Segment::new(Point::new(3.0, -1.0), Point::new(3.0, 1.0));
        let d = wall.ray_hit(&Point::new(0.0, 0.0), 0.0);
        assert!((d.unwrap_or(f64::NAN) - 3.0).abs() < 1e-12);
        assert!(wall
            .ray_hit(&Point::new(0.0, 0.0), std::f64::consts::PI)
            .is_none());
    }

    #[test]
    fn square_contains_centre_not_outside() {
        let sq = Polygon {
            vertices: vec![
                Point::new(0.0, 0.0),
                Point::new(1.0, 0.0),
                Point::new(1.0, 1.0),
                Point::new(0.0, 1.0),
            ],
        };
        assert!(sq.contains(&Point::new(0.5, 0.5)));
        assert!(!sq.contains(&Point::new(1.5, 0.5)));
        assert_eq!(sq.edges().count(), 4);
    }

    #[test]
    fn point_segment_distance() {
        let s = Segment::new(Point::new(0.0, 0.0), Point::new(2.0, 0.0));
        assert!((s.distance_to_point(&Point::new(1.0, 0.5)) - 0.5).abs() < 1e-12);
        assert!((s.distance_to_point(&Point::new(3.0, 0.0)) - 1.0).abs() < 1e-12);
    }
}
