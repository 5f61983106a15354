//! The emulated Pioneer's motion hook for a simulated world: each motion substep is clipped
//! where the body would touch a wall or obstacle. The robot may still turn on the spot, which
//! the emulator reports as a wheel stall.

use std::sync::Arc;

use rfloc_aria::emulator::{MotionHook, SonarHook};
use rfloc_aria::SonarDisc;
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

/// A sonar hook for the emulated Pioneer: each disc's range is the distance along its axis to
/// the nearest wall or obstacle of `world`, up to the disc's 5 m reach. A real sonar cone is
/// about 15° wide and misses walls hit at a glancing angle; neither is modelled.
#[must_use]
pub fn sonar_hook(world: Arc<World>) -> SonarHook {
    Box::new(move |truth: &Pose2, disc: &SonarDisc| {
        let at = truth.compose(&disc.pose());
        world
            .ray_cast(&Point::new(at.x, at.y), at.theta)
            .filter(|d| *d < rfloc_aria::NO_ECHO_M)
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

    #[test]
    fn sonar_ranges_are_to_the_wall_along_each_disc() {
        let world = Arc::new(
            World::from_toml_str("[area]\nmin=[0.0,0.0]\nmax=[4.0,4.0]\n", Path::new("w")).unwrap(),
        );
        let mut hook = sonar_hook(world);
        let discs = rfloc_aria::p3dx_discs();
        // Robot at (1, 2) facing +x: disc 0 looks left (+y) from (1.069, 2.136): 1.864 m.
        let robot = Pose2::new(1.0, 2.0, 0.0);
        let left = hook(&robot, &discs[0]).unwrap();
        assert!((left - 1.864).abs() < 1e-6, "{left}");
        // Disc 11 looks back (−170°) from x = 0.745: about 0.757 m to the wall at x = 0.
        let back = hook(&robot, &discs[11]).unwrap();
        assert!(
            (back - 0.745 / 10f64.to_radians().cos()).abs() < 1e-3,
            "{back}"
        );
        // Disc 3 looks 10° left of ahead: the wall at x = 4 is 2.87 m away along it.
        let ahead = hook(&robot, &discs[3]).unwrap();
        assert!(
            (ahead - 2.834 / 10f64.to_radians().cos()).abs() < 1e-3,
            "{ahead}"
        );
        // Beyond the 5 m reach: no echo.
        let far = Pose2::new(-10.0, 2.0, std::f64::consts::PI);
        assert!(hook(&far, &discs[3]).is_none(), "facing away from the area");
    }
}
