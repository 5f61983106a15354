//! Deterministic simulation of the seed's setup (section 3.1–3.2): a square area with randomly
//! placed tags, the exponential RSS model of eq. 3.19/3.22/3.23, a detection threshold, and a
//! robot driven by the seed's actions.
#![allow(dead_code)]

use rand::Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use rfloc_snapshot::{
    integrate, Action, ActionTable, ExplorationConfig, ExplorationInput, ExplorationPolicy,
    Observation, Snapshot, TagId,
};
use std::collections::HashSet;

/// Coefficients of eq. 3.19 (Table 3.2).
const C: [f64; 3] = [2235.0, 17144.0, -12101.0];
/// Attenuation behind the antenna (eq. 3.23).
const A_BEHIND: f64 = 50.0;

/// RSS of a tag at range `d` (m) and bearing `theta` (rad) from the antenna axis.
pub fn rss_model(d: f64, theta: f64) -> f64 {
    let front = theta.cos() >= 0.0;
    let s = if front { d } else { A_BEHIND * d };
    (C[0] * (-s).exp() + C[1] * (-2.0 * s).exp() + C[2] * (-3.0 * s).exp()) * theta.cos().abs()
}

pub struct World {
    pub size: f64,
    pub tags: Vec<(f64, f64)>,
    pub ids: Vec<TagId>,
    pub threshold: f64,
    /// Relative RSS noise (standard deviation as a fraction of the RSS).
    pub rss_noise: f64,
}

pub fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl World {
    /// 5 m × 5 m, 800 tags, threshold 1000 (the seed's simulation).
    pub fn seed_world(seed: u64, rss_noise: f64) -> Self {
        Self::square(seed, 5.0, 32.0, rss_noise)
    }

    /// A square of `size` metres with `per_m2` random tags per square metre (the seed's
    /// density is 32), threshold 1000.
    pub fn square(seed: u64, size: f64, per_m2: f64, rss_noise: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let count = (size * size * per_m2).round() as usize;
        let tags: Vec<(f64, f64)> = (0..count)
            .map(|_| (rng.random::<f64>() * size, rng.random::<f64>() * size))
            .collect();
        let ids = (0..tags.len())
            .map(|i| TagId::new(format!("E2009033{i:08X}").into_bytes()))
            .collect();
        Self {
            size,
            tags,
            ids,
            threshold: 1000.0,
            rss_noise,
        }
    }

    pub fn snapshot(&self, pose: &Pose2, rng: &mut ChaCha8Rng) -> Snapshot {
        let (s, c) = pose.theta.sin_cos();
        let mut snap = Snapshot::new();
        for ((tx, ty), id) in self.tags.iter().zip(&self.ids) {
            let (dx, dy) = (tx - pose.x, ty - pose.y);
            let d2 = dx * dx + dy * dy;
            if d2 > 4.0 {
                continue;
            }
            let (xr, yr) = (c * dx + s * dy, -s * dx + c * dy);
            let rss = rss_model(d2.sqrt(), yr.atan2(xr)) * (1.0 + self.rss_noise * gaussian(rng));
            if rss >= self.threshold {
                snap.insert(id.clone(), rss);
            }
        }
        snap
    }

    pub fn inside(&self, p: &Pose2) -> bool {
        p.x >= 0.0 && p.y >= 0.0 && p.x <= self.size && p.y <= self.size
    }
}

/// A robot run: the exploration policy picks actions, the seed's action table (with `dt`)
/// moves the robot. Poses that would leave the area are clamped by turning in place instead
/// (the walls of the lab).
pub fn explore(world: &World, steps: usize, dt: f64, seed: u64) -> Vec<Observation> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let table = ActionTable::seed_table();
    let mut policy = ExplorationPolicy::new(ExplorationConfig::default());
    let mut pose = Pose2::new(
        world.size / 2.0,
        world.size / 2.0,
        rng.random::<f64>() * std::f64::consts::TAU,
    );
    let mut known: HashSet<TagId> = HashSet::new();
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        let snap = world.snapshot(&pose, &mut rng);
        let new_tags = snap.iter().filter(|(id, _)| !known.contains(*id)).count();
        known.extend(snap.iter().map(|(id, _)| id.clone()));
        let action = policy.step(
            ExplorationInput {
                tags_seen: snap.len(),
                new_tags,
            },
            &mut rng,
        );
        out.push(Observation {
            snapshot: snap,
            pose,
            action: Some(action),
        });
        pose = step(world, &table, pose, action, dt, &mut rng);
    }
    out
}

/// Executes one action with the seed's motion noise; a move that would leave the area becomes
/// a rotation in place by the same command's angle.
pub fn step(
    world: &World,
    table: &ActionTable,
    pose: Pose2,
    action: Action,
    dt: f64,
    rng: &mut ChaCha8Rng,
) -> Pose2 {
    let cmd = table.sample(action, rng);
    let next = integrate(&pose, cmd, dt);
    if world.inside(&next) {
        next
    } else {
        Pose2::new(
            pose.x,
            pose.y,
            pose.theta + if cmd.omega >= 0.0 { 1.0 } else { -1.0 } * std::f64::consts::FRAC_PI_2,
        )
    }
}
