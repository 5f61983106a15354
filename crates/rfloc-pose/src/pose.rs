//! Planar rigid-body pose.

use serde::{Deserialize, Serialize};

use crate::angle::wrap_angle;

/// A planar pose: position in metres and heading in radians (wrapped to `(-π, π]`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose2 {
    #[must_use]
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }

    /// Composition `self ⊕ delta`, with `delta` expressed in this pose's frame.
    #[must_use]
    pub fn compose(&self, delta: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            self.x + c * delta.x - s * delta.y,
            self.y + s * delta.x + c * delta.y,
            self.theta + delta.theta,
        )
    }

    /// The relative pose `self ⊖ from`: `from.compose(&self.relative_to(from)) == self`.
    #[must_use]
    pub fn relative_to(&self, from: &Pose2) -> Pose2 {
        let (s, c) = from.theta.sin_cos();
        let dx = self.x - from.x;
        let dy = self.y - from.y;
        Pose2::new(c * dx + s * dy, -s * dx + c * dy, self.theta - from.theta)
    }

    /// Transforms a point given in this pose's frame into the parent frame.
    #[must_use]
    pub fn transform_point(&self, px: f64, py: f64) -> (f64, f64) {
        let (s, c) = self.theta.sin_cos();
        (self.x + c * px - s * py, self.y + s * px + c * py)
    }

    /// Euclidean distance between the positions of two poses.
    #[must_use]
    pub fn distance(&self, other: &Pose2) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    /// True when every component is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_then_relative_round_trips() {
        let a = Pose2::new(1.0, 2.0, 0.7);
        let d = Pose2::new(0.3, -0.4, 2.9);
        let b = a.compose(&d);
        let back = b.relative_to(&a);
        assert!((back.x - d.x).abs() < 1e-12);
        assert!((back.y - d.y).abs() < 1e-12);
        assert!((back.theta - d.theta).abs() < 1e-12);
    }

    #[test]
    fn transform_point_rotates_then_translates() {
        let p = Pose2::new(1.0, 1.0, std::f64::consts::FRAC_PI_2);
        let (x, y) = p.transform_point(1.0, 0.0);
        assert!((x - 1.0).abs() < 1e-12 && (y - 2.0).abs() < 1e-12);
    }
}
