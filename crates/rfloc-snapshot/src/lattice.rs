//! Value iteration on a fine `(x, y, θ)` lattice with the five actions' learned motion.
//!
//! The seed plans on its cluster states; its coarse states and sparse transition matrix are the
//! causes it gives for circling and limit cycling (section 4.1). Here the learned part of the MDP
//! is the *motion* of each action (mean odometry increment over the exploration steps that did
//! not stall, [`ActionModel`]), and the states are the cells of a lattice over the explored
//! floor. A step costs 1 on free floor, `edge_cost` near the edge of the explored floor, and
//! `unknown_cost` off it or near a place where the wheels stalled (the seed's edge penalty, but
//! with a gradient: a robot that believes it is in a costly cell is still led out of it); cells
//! within the goal radius have value 0. The Bellman update is semi-Lagrangian:
//! `V(s) = min_a c(s) + V(s ⊕ μ_a)`, with `V` between lattice points interpolated trilinearly,
//! so actions shorter than a cell still count.

use rfloc_pose::{wrap_angle, Pose2};
use serde::{Deserialize, Serialize};

use crate::action::Action;

/// Mean odometry increment of each action (robot frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActionModel {
    /// Mean increment, [`Action::index`] order.
    pub mean: [Pose2; 5],
    /// Samples behind each mean.
    pub samples: [usize; 5],
}

impl ActionModel {
    /// Learns the means from `(before, action, after)` odometry poses; actions with no sample
    /// keep `fallback`'s increment.
    #[must_use]
    pub fn learn<'a>(
        steps: impl IntoIterator<Item = (&'a Pose2, Action, &'a Pose2)>,
        fallback: &[Pose2; 5],
    ) -> Self {
        let mut sum = [(0.0, 0.0, 0.0, 0.0); 5];
        let mut samples = [0usize; 5];
        for (a, action, b) in steps {
            let d = b.relative_to(a);
            if let (Some(s), Some(n)) =
                (sum.get_mut(action.index()), samples.get_mut(action.index()))
            {
                s.0 += d.x;
                s.1 += d.y;
                s.2 += d.theta.sin();
                s.3 += d.theta.cos();
                *n += 1;
            }
        }
        let mut mean = *fallback;
        for ((m, s), n) in mean.iter_mut().zip(&sum).zip(&samples) {
            if *n > 0 {
                let k = *n as f64;
                *m = Pose2::new(s.0 / k, s.1 / k, s.2.atan2(s.3));
            }
        }
        Self { mean, samples }
    }

    /// Mean increment of an action.
    #[must_use]
    pub fn increment(&self, action: Action) -> Pose2 {
        self.mean.get(action.index()).copied().unwrap_or_default()
    }
}

/// Most lattice points (cells × headings) a plan holds, about 200 MB of values and costs; a
/// 0.15 m × 11.25° lattice of this size covers about 75 m × 75 m.
pub const MAX_LATTICE_STATES: f64 = 8.0e6;

/// Lattice and cost settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatticeConfig {
    /// Cell size, metres.
    pub cell: f64,
    /// Heading bins over 2π.
    pub headings: usize,
    /// A cell is known floor when an exploration pose lies within this distance of its centre.
    pub known_radius: f64,
    /// Cells within this distance of a stall place cost `unknown_cost` per step (a wall is
    /// there).
    pub stall_radius: f64,
    /// Cells closer than this to unknown floor cost `edge_cost` per step (except near the
    /// goal), metres.
    pub edge_margin: f64,
    /// Cost of one step from a cell near the edge of the known floor, in steps; a free cell
    /// costs 1.
    pub edge_cost: f64,
    /// Cost of one step from a cell off the known floor or near a stall place.
    pub unknown_cost: f64,
    /// Value outside the lattice and upper bound of every value (steps).
    pub blocked_cost: f64,
    /// Gauss–Seidel sweeps at most.
    pub max_sweeps: usize,
    /// Stop when no value changes by more than this (steps).
    pub tolerance: f64,
}

impl Default for LatticeConfig {
    fn default() -> Self {
        Self {
            cell: 0.15,
            headings: 32,
            known_radius: 0.25,
            stall_radius: 0.2,
            edge_margin: 0.5,
            edge_cost: 6.0,
            unknown_cost: 30.0,
            blocked_cost: 1000.0,
            max_sweeps: 400,
            tolerance: 1e-3,
        }
    }
}

/// Where one action takes a lattice point: the cell below the landing point, relative, its
/// heading bin, and the trilinear weights towards the next cell / bin.
#[derive(Debug, Clone, Copy)]
struct Stencil {
    di: i64,
    dj: i64,
    h: usize,
    w: [f64; 3],
}

/// A solved lattice plan to one goal point.
#[derive(Debug, Clone)]
pub struct LatticePlan {
    config: LatticeConfig,
    model: ActionModel,
    x0: f64,
    y0: f64,
    nx: usize,
    ny: usize,
    value: Vec<f64>,
    step_cost: Vec<f64>,
    goal: Vec<bool>,
    /// Sweeps done.
    pub sweeps: usize,
}

impl LatticePlan {
    /// Plans to within `goal_radius` of `(goal_x, goal_y)` (any heading) over the floor known from
    /// `explored` poses, avoiding `stalls`.
    #[must_use]
    pub fn solve(
        model: ActionModel,
        explored: &[Pose2],
        stalls: &[Pose2],
        goal: (f64, f64),
        goal_radius: f64,
        config: LatticeConfig,
    ) -> Self {
        let mut cell = config.cell.max(0.01);
        let pad = config.known_radius + cell;
        // The box of the explored poses and the goal (points that are not finite left out).
        let (mut xmin, mut ymin, mut xmax, mut ymax) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        let finite = |x: f64, y: f64| x.is_finite() && y.is_finite();
        for (x, y) in explored
            .iter()
            .map(|p| (p.x, p.y))
            .chain(std::iter::once(goal))
            .filter(|&(x, y)| finite(x, y))
        {
            (xmin, ymin) = (xmin.min(x), ymin.min(y));
            (xmax, ymax) = (xmax.max(x), ymax.max(y));
        }
        if xmin > xmax {
            (xmin, ymin, xmax, ymax) = (0.0, 0.0, 0.0, 0.0);
        }
        let x0 = xmin - pad;
        let y0 = ymin - pad;
        let nh = config.headings.clamp(4, 360);
        // A lattice of at most `MAX_LATTICE_STATES` (a goal or a survey pose far beyond the
        // floor would otherwise ask for more memory than the computer has): coarser cells.
        let states = |cell: f64| {
            ((xmax + pad - x0) / cell + 2.0) * ((ymax + pad - y0) / cell + 2.0) * nh as f64
        };
        if states(cell) > MAX_LATTICE_STATES {
            let fine = cell;
            while states(cell) > MAX_LATTICE_STATES {
                cell *= 1.25;
            }
            tracing::warn!(
                width_m = xmax - xmin,
                height_m = ymax - ymin,
                cell_m = cell,
                configured_cell_m = fine,
                "lattice plan over a large floor: cells coarsened to stay within {MAX_LATTICE_STATES} states"
            );
        }
        let nx = (((xmax + pad - x0) / cell).ceil() as usize).max(1) + 1;
        let ny = (((ymax + pad - y0) / cell).ceil() as usize).max(1) + 1;
        let mut known = vec![false; nx * ny];
        let mark = |grid: &mut Vec<bool>, p: &Pose2, r: f64| {
            let r_cells = (r / cell).ceil() as i64;
            let ci = ((p.x - x0) / cell).round() as i64;
            let cj = ((p.y - y0) / cell).round() as i64;
            for i in (ci - r_cells)..=(ci + r_cells) {
                for j in (cj - r_cells)..=(cj + r_cells) {
                    if i < 0 || j < 0 || i >= nx as i64 || j >= ny as i64 {
                        continue;
                    }
                    let cx = x0 + i as f64 * cell;
                    let cy = y0 + j as f64 * cell;
                    if (cx - p.x).hypot(cy - p.y) <= r {
                        if let Some(g) = grid.get_mut(i as usize * ny + j as usize) {
                            *g = true;
                        }
                    }
                }
            }
        };
        for p in explored {
            mark(&mut known, p, config.known_radius);
        }
        let mut stalled = vec![false; nx * ny];
        for p in stalls {
            mark(&mut stalled, p, config.stall_radius);
        }
        // Keep `edge_margin` off the edge of the known floor (the walls the exploration ran
        // into), except around the goal itself.
        let m_cells = (config.edge_margin / cell).ceil() as i64;
        let near_edge = |c: usize| -> bool {
            let (i, j) = ((c / ny) as i64, (c % ny) as i64);
            for di in -m_cells..=m_cells {
                for dj in -m_cells..=m_cells {
                    if ((di * di + dj * dj) as f64).sqrt() * cell > config.edge_margin {
                        continue;
                    }
                    let (a, b) = (i + di, j + dj);
                    let inside = a >= 0 && b >= 0 && a < nx as i64 && b < ny as i64;
                    if !inside
                        || !known
                            .get(a as usize * ny + b as usize)
                            .copied()
                            .unwrap_or(false)
                    {
                        return true;
                    }
                }
            }
            false
        };
        let goal_clear = goal_radius + config.edge_margin + cell;
        let step_cost: Vec<f64> = (0..nx * ny)
            .map(|c| {
                let cx = x0 + (c / ny) as f64 * cell;
                let cy = y0 + (c % ny) as f64 * cell;
                let k = known.get(c).copied().unwrap_or(false);
                let s = stalled.get(c).copied().unwrap_or(false);
                let near_goal = (cx - goal.0).hypot(cy - goal.1) <= goal_clear;
                if !k || (s && !near_goal) {
                    config.unknown_cost
                } else if !near_goal && near_edge(c) {
                    config.edge_cost
                } else {
                    1.0
                }
            })
            .collect();
        let goal_cells: Vec<bool> = (0..nx * ny)
            .map(|c| {
                let cx = x0 + (c / ny) as f64 * cell;
                let cy = y0 + (c % ny) as f64 * cell;
                (cx - goal.0).hypot(cy - goal.1) <= goal_radius
            })
            .collect();
        let mut plan = Self {
            config: LatticeConfig {
                cell,
                headings: nh,
                ..config
            },
            model,
            x0,
            y0,
            nx,
            ny,
            value: vec![config.blocked_cost; nx * ny * nh],
            step_cost,
            goal: goal_cells,
            sweeps: 0,
        };
        for c in 0..nx * ny {
            if plan.goal.get(c).copied().unwrap_or(false) {
                for h in 0..nh {
                    if let Some(v) = plan.value.get_mut(c * nh + h) {
                        *v = 0.0;
                    }
                }
            }
        }
        plan.iterate();
        plan
    }

    fn cell_free(&self, c: usize) -> bool {
        !self.goal.get(c).copied().unwrap_or(false)
    }

    /// For each heading and action: where the action takes a lattice point, as a fixed
    /// trilinear stencil (the cell offset below the landing point and the weights). A lattice
    /// point has integer coordinates, so the stencil does not depend on the cell.
    fn stencils(&self) -> Vec<[Stencil; 5]> {
        let nh = self.config.headings;
        let dh = std::f64::consts::TAU / nh as f64;
        (0..nh)
            .map(|h| {
                let pose = Pose2::new(0.0, 0.0, h as f64 * dh);
                Action::ALL.map(|a| {
                    let to = pose.compose(&self.model.increment(a));
                    let fx = to.x / self.config.cell;
                    let fy = to.y / self.config.cell;
                    let th = wrap_angle(to.theta).rem_euclid(std::f64::consts::TAU);
                    let fh = th / dh;
                    let (i, j, k) = (fx.floor(), fy.floor(), fh.floor());
                    Stencil {
                        di: i as i64,
                        dj: j as i64,
                        h: (k as usize) % nh,
                        w: [fx - i, fy - j, fh - k],
                    }
                })
            })
            .collect()
    }

    fn iterate(&mut self) {
        let nh = self.config.headings;
        let stencils = self.stencils();
        let (nx, ny) = (self.nx as i64, self.ny as i64);
        let blocked = self.config.blocked_cost;
        for sweep in 0..self.config.max_sweeps {
            let mut change = 0.0_f64;
            // Alternate sweep direction (Gauss–Seidel converges faster both ways).
            let cells: Box<dyn Iterator<Item = usize>> = if sweep % 2 == 0 {
                Box::new(0..self.nx * self.ny)
            } else {
                Box::new((0..self.nx * self.ny).rev())
            };
            for c in cells {
                if !self.cell_free(c) {
                    continue;
                }
                let (i, j) = ((c / self.ny) as i64, (c % self.ny) as i64);
                let cost = self.step_cost.get(c).copied().unwrap_or(1.0);
                for (h, per_action) in stencils.iter().enumerate() {
                    let mut best = f64::INFINITY;
                    for st in per_action {
                        let (a, b) = (i + st.di, j + st.dj);
                        let [tx, ty, tt] = st.w;
                        let (h0, h1) = (st.h, (st.h + 1) % nh);
                        let mut v = 0.0;
                        for (di, wx) in [(0, 1.0 - tx), (1, tx)] {
                            for (dj, wy) in [(0, 1.0 - ty), (1, ty)] {
                                let (x, y) = (a + di, b + dj);
                                let w = wx * wy;
                                if w <= 0.0 {
                                    continue;
                                }
                                if x < 0 || y < 0 || x >= nx || y >= ny {
                                    v += w * blocked;
                                    continue;
                                }
                                let base = (x as usize * self.ny + y as usize) * nh;
                                let at =
                                    |k: usize| self.value.get(base + k).copied().unwrap_or(blocked);
                                if 1.0 - tt > 0.0 {
                                    v += w * (1.0 - tt) * at(h0);
                                }
                                if tt > 0.0 {
                                    v += w * tt * at(h1);
                                }
                            }
                        }
                        best = best.min(cost + v);
                    }
                    let best = best.min(blocked);
                    if let Some(v) = self.value.get_mut(c * nh + h) {
                        change = change.max((*v - best).abs());
                        *v = best;
                    }
                }
            }
            self.sweeps = sweep + 1;
            if change < self.config.tolerance {
                break;
            }
        }
    }

    fn lattice_value(&self, i: i64, j: i64, h: usize) -> f64 {
        if i < 0 || j < 0 || i >= self.nx as i64 || j >= self.ny as i64 {
            return self.config.blocked_cost;
        }
        let nh = self.config.headings;
        self.value
            .get((i as usize * self.ny + j as usize) * nh + h % nh)
            .copied()
            .unwrap_or(self.config.blocked_cost)
    }

    /// Steps to the goal from `pose` (trilinear interpolation of the lattice values).
    #[must_use]
    pub fn value_at(&self, pose: &Pose2) -> f64 {
        let nh = self.config.headings;
        let fx = (pose.x - self.x0) / self.config.cell;
        let fy = (pose.y - self.y0) / self.config.cell;
        let th = wrap_angle(pose.theta).rem_euclid(std::f64::consts::TAU);
        let fh = th / (std::f64::consts::TAU / nh as f64);
        let (i, j, h) = (fx.floor(), fy.floor(), fh.floor());
        let (tx, ty, tht) = (fx - i, fy - j, fh - h);
        let (i, j, h) = (i as i64, j as i64, (h as usize) % nh);
        let mut v = 0.0;
        for (di, wx) in [(0, 1.0 - tx), (1, tx)] {
            for (dj, wy) in [(0, 1.0 - ty), (1, ty)] {
                for (dh, wh) in [(0, 1.0 - tht), (1, tht)] {
                    let w = wx * wy * wh;
                    if w > 0.0 {
                        v += w * self.lattice_value(i + di, j + dj, h + dh);
                    }
                }
            }
        }
        v
    }

    /// Actions ranked by expected steps to the goal after taking them from `pose`, best first.
    #[must_use]
    pub fn ranked(&self, pose: &Pose2) -> Vec<(Action, f64)> {
        let mut r: Vec<(Action, f64)> = Action::ALL
            .iter()
            .map(|a| {
                (
                    *a,
                    1.0 + self.value_at(&pose.compose(&self.model.increment(*a))),
                )
            })
            .collect();
        r.sort_by(|a, b| a.1.total_cmp(&b.1));
        r
    }

    /// True when `pose` lies in a goal cell (nearest lattice point).
    #[must_use]
    pub fn in_goal(&self, pose: &Pose2) -> bool {
        let i = ((pose.x - self.x0) / self.config.cell).round() as i64;
        let j = ((pose.y - self.y0) / self.config.cell).round() as i64;
        if i < 0 || j < 0 || i >= self.nx as i64 || j >= self.ny as i64 {
            return false;
        }
        self.goal
            .get(i as usize * self.ny + j as usize)
            .copied()
            .unwrap_or(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> ActionModel {
        let f = [
            Pose2::new(0.25, 0.0, 0.0),
            Pose2::new(0.25, 0.02, 0.157),
            Pose2::new(0.25, -0.02, -0.157),
            Pose2::new(0.02, 0.0, 0.157),
            Pose2::new(0.02, 0.0, -0.157),
        ];
        ActionModel::learn(std::iter::empty(), &f)
    }

    fn floor() -> Vec<Pose2> {
        let mut v = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                v.push(Pose2::new(
                    0.2 + 0.2 * f64::from(i),
                    0.2 + 0.2 * f64::from(j),
                    0.0,
                ));
            }
        }
        v
    }

    /// Follows the plan from `start` with the model's exact motion; returns steps to the goal.
    fn follow(plan: &LatticePlan, m: &ActionModel, mut p: Pose2, limit: usize) -> Option<usize> {
        for k in 0..limit {
            if plan.in_goal(&p) {
                return Some(k);
            }
            let (a, _) = plan.ranked(&p)[0];
            p = p.compose(&m.increment(a));
        }
        None
    }

    #[test]
    fn learns_mean_increments_per_action() {
        let a = Pose2::new(1.0, 1.0, 0.5);
        let b1 = a.compose(&Pose2::new(0.3, 0.0, 0.0));
        let b2 = a.compose(&Pose2::new(0.1, 0.0, 0.0));
        let fallback = [Pose2::default(); 5];
        let m = ActionModel::learn(
            [(&a, Action::Forward, &b1), (&a, Action::Forward, &b2)],
            &fallback,
        );
        assert_eq!(m.samples, [2, 0, 0, 0, 0]);
        assert!((m.increment(Action::Forward).x - 0.2).abs() < 1e-12);
        assert_eq!(m.increment(Action::RotateLeft), Pose2::default());
    }

    /// A goal (or a survey pose) far beyond the floor does not ask for a lattice larger than
    /// the computer: the cells are coarsened to stay within `MAX_LATTICE_STATES`, and points
    /// that are not finite are left out of the box.
    #[test]
    fn a_far_goal_gets_coarser_cells_not_an_enormous_lattice() {
        let m = model();
        let config = LatticeConfig {
            max_sweeps: 2,
            ..LatticeConfig::default()
        };
        let near = LatticePlan::solve(m, &floor(), &[], (3.5, 3.5), 0.2, config);
        assert_eq!(near.config.cell, config.cell);
        let mut explored = floor();
        explored.push(Pose2::new(f64::NAN, 1.0, 0.0));
        let far = LatticePlan::solve(m, &explored, &[], (4.0e6, -3.0), 0.2, config);
        let states = far.nx * far.ny * far.config.headings;
        #[allow(clippy::cast_precision_loss)]
        let within = states as f64 <= MAX_LATTICE_STATES;
        assert!(within, "{states} states");
        assert!(far.config.cell > 10.0, "cell {}", far.config.cell);
        assert!(far.value_at(&Pose2::new(1.0, 1.0, 0.0)).is_finite());
    }

    #[test]
    fn reaches_the_goal_from_every_heading_and_avoids_a_stall_wall() {
        let m = model();
        let plan = LatticePlan::solve(m, &floor(), &[], (3.5, 3.5), 0.2, LatticeConfig::default());
        for h in 0..8 {
            let start = Pose2::new(0.8, 0.8, f64::from(h) * std::f64::consts::FRAC_PI_4);
            let steps = follow(&plan, &m, start, 200).expect("reaches");
            // 3.8 m of diagonal is 16 forward steps; turning adds at most 20 rotations.
            assert!(steps <= 40, "heading {h}: {steps} steps");
        }
        // Values decrease towards the goal.
        assert!(
            plan.value_at(&Pose2::new(3.0, 3.5, 0.0)) < plan.value_at(&Pose2::new(1.0, 3.5, 0.0))
        );
        // The sweeps (precomputed stencils) solved the Bellman equation as `value_at` and
        // `compose` state it, at every lattice point away from the goal.
        let dh = std::f64::consts::TAU / plan.config.headings as f64;
        let mut worst = 0.0_f64;
        for c in 0..plan.nx * plan.ny {
            if !plan.cell_free(c) {
                continue;
            }
            let (cx, cy) = (
                plan.x0 + (c / plan.ny) as f64 * plan.config.cell,
                plan.y0 + (c % plan.ny) as f64 * plan.config.cell,
            );
            for h in 0..plan.config.headings {
                let pose = Pose2::new(cx, cy, h as f64 * dh);
                let bellman = Action::ALL
                    .iter()
                    .map(|a| plan.step_cost[c] + plan.value_at(&pose.compose(&m.increment(*a))))
                    .fold(f64::INFINITY, f64::min)
                    .min(plan.config.blocked_cost);
                worst = worst.max((plan.value[c * plan.config.headings + h] - bellman).abs());
            }
        }
        assert!(worst < 0.01, "Bellman residual {worst}");
        // A wall of stall places across x = 2 from y = 0 to 3.4: the path goes round its end.
        let wall: Vec<Pose2> = (0..=34)
            .map(|j| Pose2::new(2.0, 0.1 * f64::from(j), 0.0))
            .collect();
        let plan = LatticePlan::solve(
            m,
            &floor(),
            &wall,
            (3.5, 1.0),
            0.2,
            LatticeConfig::default(),
        );
        let mut p = Pose2::new(0.8, 1.0, 0.0);
        let mut max_y = p.y;
        let mut reached = false;
        for _ in 0..300 {
            if plan.in_goal(&p) {
                reached = true;
                break;
            }
            let (a, _) = plan.ranked(&p)[0];
            p = p.compose(&m.increment(a));
            max_y = max_y.max(p.y);
            assert!(
                !((p.x - 2.0).abs() < 0.1 && p.y < 3.4),
                "through the wall at {p:?}"
            );
        }
        assert!(reached && max_y > 3.3, "reached {reached}, max y {max_y}");
    }
}
