//! The emulated Pioneer's motion hook for a simulated world: each motion substep is clipped
//! where the body would touch a wall or obstacle. The robot may still turn on the spot, which
//! the emulator reports as a wheel stall.

use std::sync::Arc;

use rfloc_aria::emulator::MotionHook;
use rfloc_pose::Pose2;
use rfloc_sim::{Point, World};

/// A motion hook that keeps a disc of `radius` out of the world's walls and obstacles: a
/// substep that would collide keeps the position and takes only the new heading.
#[must_use]
pub fn wall_hook(world: Arc<World>, radius: f64) -> MotionHook {
    Box::new(move |current: &Pose2, proposed: &Pose2| {
        if world.disk_collides(&Point::new(proposed.x, proposed.y), radius) {
            // Blocked: the wheels stall; turning on the spot stays possible.
            Pose2::new(current.x, current.y, proposed.theta)
        } else {
            *proposed
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn hook_stops_at_a_wall_but_lets_the_robot_turn() {
        let world = Arc::new(
            World::from_toml_str("[area]\nmin=[0.0,0.0]\nmax=[2.0,2.0]\n", Path::new("w")).unwrap(),
        );
        let mut hook = wall_hook(world, 0.2);
        let mut pose = Pose2::new(1.0, 1.0, 0.0);
        for _ in 0..20 {
            let proposed = Pose2::new(pose.x + 0.1, pose.y, pose.theta + 0.01);
            pose = hook(&pose, &proposed);
        }
        // Stopped 0.2 m short of the wall at x = 2 but still turned.
        assert!(pose.x <= 1.8 + 1e-9 && pose.x > 1.6, "{pose:?}");
        assert!((pose.theta - 0.2).abs() < 1e-9, "{pose:?}");
    }
}
