//! Least squares over a trajectory of 2-D poses: odometry factors between neighbours, unary
//! pose factors, and relative-pose factors between any two poses ("closures": two visits of
//! one place). Levenberg–Marquardt; each step solves the normal equations by conjugate
//! gradients preconditioned with their exact block-tridiagonal part (the chain), so a chain
//! without closures is solved exactly in one iteration and in O(n).
//!
//! Robust weights: unary factors and closures are Huber-weighted; odometry factors are not.
//! The first pose is fixed (it anchors the frame).

use nalgebra::{Matrix3, Vector3};
use rfloc_pose::{angle_diff, Pose2};

/// A pose's Gaussian factor: mean and information.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PoseFactor {
    pub(crate) mean: Pose2,
    pub(crate) info: Matrix3<f64>,
}

/// A measured pose of `b` in `a`'s frame, with its information.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Closure {
    pub(crate) a: usize,
    pub(crate) b: usize,
    pub(crate) z: Pose2,
    pub(crate) info: Matrix3<f64>,
}

/// The problem: `increments[i]` (information `odo_info[i]`) between poses `i` and `i + 1`,
/// optional unary `factors` per pose, `closures`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Graph<'a> {
    pub(crate) increments: &'a [Pose2],
    pub(crate) odo_info: &'a [Matrix3<f64>],
    pub(crate) factors: &'a [Option<PoseFactor>],
    pub(crate) closures: &'a [Closure],
    pub(crate) huber: f64,
}

/// Conjugate-gradient iterations per step at most, and the residual (relative to the
/// gradient) at which they stop.
const CG_ITERATIONS: usize = 300;
const CG_TOLERANCE: f64 = 1e-7;

/// Residual of the relative pose of `b` seen from `a` against a measured `z`, in `a`'s frame.
pub(crate) fn relative_residual(a: &Pose2, b: &Pose2, z: &Pose2) -> Vector3<f64> {
    let (s, c) = a.theta.sin_cos();
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    Vector3::new(
        c * dx + s * dy - z.x,
        -s * dx + c * dy - z.y,
        angle_diff(b.theta - a.theta, z.theta),
    )
}

/// Jacobians of [`relative_residual`] with respect to `a` and `b`.
pub(crate) fn relative_jacobians(a: &Pose2, b: &Pose2) -> (Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = a.theta.sin_cos();
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let ja = Matrix3::new(
        -c,
        -s,
        -s * dx + c * dy,
        s,
        -c,
        -c * dx - s * dy,
        0.0,
        0.0,
        -1.0,
    );
    let jb = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
    (ja, jb)
}

/// Huber weight and cost of a residual `e` of information `info`.
fn huber(e: &Vector3<f64>, info: &Matrix3<f64>, k: f64) -> (f64, f64) {
    let d = (e.transpose() * info * e).x.max(0.0).sqrt();
    if d > k {
        (k / d, k * (2.0 * d - k))
    } else {
        (1.0, d * d)
    }
}

/// Residual of a unary factor (the pose minus the factor's mean).
pub(crate) fn factor_error(p: &Pose2, f: &PoseFactor) -> Vector3<f64> {
    Vector3::new(
        p.x - f.mean.x,
        p.y - f.mean.y,
        angle_diff(p.theta, f.mean.theta),
    )
}

impl Graph<'_> {
    /// The cost: odometry χ² plus the Huber costs of the factors and closures.
    pub(crate) fn cost(&self, poses: &[Pose2]) -> f64 {
        let odo: f64 = poses
            .windows(2)
            .zip(self.increments)
            .zip(self.odo_info)
            .filter_map(|((w, u), info)| {
                let e = relative_residual(w.first()?, w.get(1)?, u);
                Some((e.transpose() * info * e).x)
            })
            .sum();
        let unary: f64 = poses
            .iter()
            .zip(self.factors)
            .skip(1)
            .filter_map(|(p, f)| {
                let f = f.as_ref()?;
                Some(huber(&factor_error(p, f), &f.info, self.huber).1)
            })
            .sum();
        let closures: f64 = self
            .closures
            .iter()
            .filter_map(|c| {
                let e = relative_residual(poses.get(c.a)?, poses.get(c.b)?, &c.z);
                Some(huber(&e, &c.info, self.huber).1)
            })
            .sum();
        odo + unary + closures
    }

    /// Levenberg–Marquardt from `poses` for at most `iterations` steps; a step is taken only
    /// when it lowers the cost. `poses[0]` stays.
    pub(crate) fn optimise(&self, poses: &mut [Pose2], iterations: usize) {
        let m = poses.len();
        if m < 2 {
            return;
        }
        let mut cost = self.cost(poses);
        let mut lambda = 1e-4;
        for _ in 0..iterations.max(1) {
            let normal = self.normal_equations(poses);
            let mut accepted = None;
            for _ in 0..8 {
                let Some(step) = normal.solve(lambda) else {
                    lambda *= 10.0;
                    continue;
                };
                let trial: Vec<Pose2> = poses
                    .iter()
                    .zip(&step)
                    .map(|(p, d)| Pose2::new(p.x - d.x, p.y - d.y, p.theta - d.z))
                    .collect();
                let c = self.cost(&trial);
                if c < cost {
                    let largest = step
                        .iter()
                        .map(|d| d.x.abs().max(d.y.abs()).max(d.z.abs()))
                        .fold(0.0, f64::max);
                    accepted = Some((trial, c, largest));
                    lambda = (lambda * 0.1).max(1e-9);
                    break;
                }
                lambda *= 10.0;
            }
            let Some((trial, c, largest)) = accepted else {
                return;
            };
            poses.copy_from_slice(&trial);
            let relative = (cost - c) / cost.max(1e-12);
            cost = c;
            if largest < 1e-5 || relative < 1e-6 {
                break;
            }
        }
    }

    /// The Gauss–Newton normal equations at `poses` (first pose's row and column dropped).
    fn normal_equations(&self, poses: &[Pose2]) -> NormalEquations {
        let m = poses.len();
        let mut n = NormalEquations {
            diag: vec![Matrix3::zeros(); m],
            off: vec![Matrix3::zeros(); m.saturating_sub(1)],
            cross: Vec::new(),
            grad: vec![Vector3::zeros(); m],
        };
        for i in 0..m.saturating_sub(1) {
            let (Some(a), Some(b), Some(u), Some(info)) = (
                poses.get(i),
                poses.get(i + 1),
                self.increments.get(i),
                self.odo_info.get(i),
            ) else {
                continue;
            };
            let e = relative_residual(a, b, u);
            let (ja, jb) = relative_jacobians(a, b);
            n.add_pair(i, i + 1, &ja, &jb, info, &e);
        }
        for (i, f) in self.factors.iter().enumerate().skip(1) {
            let (Some(f), Some(p)) = (f, poses.get(i)) else {
                continue;
            };
            let e = factor_error(p, f);
            let (w, _) = huber(&e, &f.info, self.huber);
            if let (Some(d), Some(g)) = (n.diag.get_mut(i), n.grad.get_mut(i)) {
                *d += w * f.info;
                *g += w * f.info * e;
            }
        }
        for c in self.closures {
            let (Some(a), Some(b)) = (poses.get(c.a), poses.get(c.b)) else {
                continue;
            };
            let e = relative_residual(a, b, &c.z);
            let (w, _) = huber(&e, &c.info, self.huber);
            let (ja, jb) = relative_jacobians(a, b);
            n.add_pair(c.a, c.b, &ja, &jb, &(w * c.info), &e);
        }
        // The first pose is fixed: its row and column are dropped.
        if let (Some(d), Some(g)) = (n.diag.first_mut(), n.grad.first_mut()) {
            *d = Matrix3::identity();
            *g = Vector3::zeros();
        }
        if let Some(o) = n.off.first_mut() {
            *o = Matrix3::zeros();
        }
        n.cross.retain(|(a, b, _)| *a != 0 && *b != 0);
        n
    }
}

/// Normal equations `H x = g`: `H`'s diagonal blocks, the blocks `H[i][i+1]`, and the other
/// off-diagonal blocks `(a, b, H[a][b])` (each once; `H[b][a]` is its transpose).
struct NormalEquations {
    diag: Vec<Matrix3<f64>>,
    off: Vec<Matrix3<f64>>,
    cross: Vec<(usize, usize, Matrix3<f64>)>,
    grad: Vec<Vector3<f64>>,
}

impl NormalEquations {
    /// Adds a two-pose factor (Jacobians `ja`, `jb`, information `info`, residual `e`).
    fn add_pair(
        &mut self,
        a: usize,
        b: usize,
        ja: &Matrix3<f64>,
        jb: &Matrix3<f64>,
        info: &Matrix3<f64>,
        e: &Vector3<f64>,
    ) {
        let (jai, jbi) = (ja.transpose() * info, jb.transpose() * info);
        if let (Some(d), Some(g)) = (self.diag.get_mut(a), self.grad.get_mut(a)) {
            *d += jai * ja;
            *g += jai * e;
        }
        if let (Some(d), Some(g)) = (self.diag.get_mut(b), self.grad.get_mut(b)) {
            *d += jbi * jb;
            *g += jbi * e;
        }
        let block = jai * jb;
        if b == a + 1 {
            if let Some(o) = self.off.get_mut(a) {
                *o += block;
            }
        } else if a == b + 1 {
            if let Some(o) = self.off.get_mut(b) {
                *o += block.transpose();
            }
        } else if a != b {
            self.cross.push((a, b, block));
        }
    }

    /// The step of damping `lambda` (`H + λ diag(H)`), by preconditioned conjugate gradients.
    fn solve(&self, lambda: f64) -> Option<Vec<Vector3<f64>>> {
        let diag: Vec<Matrix3<f64>> = self
            .diag
            .iter()
            .map(|d| d + Matrix3::from_diagonal(&d.diagonal()) * lambda)
            .collect();
        let chain = BlockTridiagonal::factor(&diag, &self.off)?;
        if self.cross.is_empty() {
            return chain.solve(&self.grad);
        }
        let apply = |x: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
            let mut y: Vec<Vector3<f64>> = diag.iter().zip(x).map(|(d, v)| d * v).collect();
            for (i, o) in self.off.iter().enumerate() {
                let (Some(&xi), Some(&xn)) = (x.get(i), x.get(i + 1)) else {
                    continue;
                };
                if let Some(v) = y.get_mut(i) {
                    *v += o * xn;
                }
                if let Some(v) = y.get_mut(i + 1) {
                    *v += o.transpose() * xi;
                }
            }
            for (a, b, blk) in &self.cross {
                let (Some(&xa), Some(&xb)) = (x.get(*a), x.get(*b)) else {
                    continue;
                };
                if let Some(v) = y.get_mut(*a) {
                    *v += blk * xb;
                }
                if let Some(v) = y.get_mut(*b) {
                    *v += blk.transpose() * xa;
                }
            }
            y
        };
        let dot = |p: &[Vector3<f64>], q: &[Vector3<f64>]| -> f64 {
            p.iter().zip(q).map(|(a, b)| a.dot(b)).sum()
        };
        let mut x = vec![Vector3::zeros(); self.grad.len()];
        let mut r = self.grad.clone();
        let stop = CG_TOLERANCE * CG_TOLERANCE * dot(&r, &r);
        let mut z = chain.solve(&r)?;
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        for _ in 0..CG_ITERATIONS {
            let hp = apply(&p);
            let php = dot(&p, &hp);
            if php <= 0.0 || !php.is_finite() {
                break;
            }
            let alpha = rz / php;
            for ((xi, ri), (pi, hpi)) in x.iter_mut().zip(r.iter_mut()).zip(p.iter().zip(&hp)) {
                *xi += alpha * pi;
                *ri -= alpha * hpi;
            }
            if dot(&r, &r) <= stop {
                break;
            }
            z = chain.solve(&r)?;
            let rz_next = dot(&r, &z);
            let beta = rz_next / rz;
            rz = rz_next;
            for (pi, zi) in p.iter_mut().zip(&z) {
                *pi = zi + beta * *pi;
            }
        }
        x.iter()
            .all(|v| v.iter().all(|c| c.is_finite()))
            .then_some(x)
    }
}

/// A symmetric block-tridiagonal matrix factored by block elimination.
pub(crate) struct BlockTridiagonal<'a> {
    off: &'a [Matrix3<f64>],
    /// Inverses of the Schur complements.
    pivots: Vec<Matrix3<f64>>,
    /// `off[i−1]ᵀ · pivots[i−1]` for `i ≥ 1`.
    lower: Vec<Matrix3<f64>>,
}

impl<'a> BlockTridiagonal<'a> {
    /// Factors the matrix of diagonal blocks `diag` and blocks `off[i] = H[i][i+1]`; `None`
    /// when a pivot block is singular.
    pub(crate) fn factor(diag: &[Matrix3<f64>], off: &'a [Matrix3<f64>]) -> Option<Self> {
        let m = diag.len();
        let mut pivots: Vec<Matrix3<f64>> = Vec::with_capacity(m);
        let mut lower: Vec<Matrix3<f64>> = Vec::with_capacity(m.saturating_sub(1));
        for (i, d) in diag.iter().enumerate() {
            if i == 0 {
                pivots.push(d.try_inverse()?);
                continue;
            }
            let b = off.get(i - 1)?;
            let l = b.transpose() * pivots.get(i - 1)?;
            let schur = d - l * b;
            pivots.push(schur.try_inverse()?);
            lower.push(l);
        }
        Some(Self { off, pivots, lower })
    }

    /// Solves `H x = g`.
    pub(crate) fn solve(&self, g: &[Vector3<f64>]) -> Option<Vec<Vector3<f64>>> {
        let m = self.pivots.len();
        let mut y: Vec<Vector3<f64>> = Vec::with_capacity(m);
        for i in 0..m {
            let gi = g.get(i)?;
            if i == 0 {
                y.push(*gi);
            } else {
                let v = gi - self.lower.get(i - 1)? * y.get(i - 1)?;
                y.push(v);
            }
        }
        let mut x = vec![Vector3::zeros(); m];
        for i in (0..m).rev() {
            let rhs = if i + 1 < m {
                y.get(i)? - self.off.get(i)? * x.get(i + 1)?
            } else {
                *y.get(i)?
            };
            *x.get_mut(i)? = self.pivots.get(i)? * rhs;
        }
        Some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: u32) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            f64::from(s) / 4_294_967_296.0 - 0.5
        }
    }

    /// Random normal equations of `m` poses: symmetric positive definite diagonal blocks
    /// (`ridge` on their diagonal), random chain blocks and gradient, and random blocks between
    /// the pairs `cross`.
    fn random_system(seed: u32, m: usize, ridge: f64, cross: &[(usize, usize)]) -> NormalEquations {
        let mut r = lcg(seed);
        NormalEquations {
            diag: (0..m)
                .map(|_| {
                    let a = Matrix3::from_fn(|_, _| r());
                    a * a.transpose() + Matrix3::identity() * ridge
                })
                .collect(),
            off: (0..m - 1).map(|_| Matrix3::from_fn(|_, _| r())).collect(),
            grad: (0..m).map(|_| Vector3::from_fn(|_, _| r())).collect(),
            cross: cross
                .iter()
                .map(|&(a, b)| (a, b, Matrix3::from_fn(|_, _| r())))
                .collect(),
        }
    }

    /// `n`'s solution by a dense LU decomposition of the whole matrix.
    fn dense_solution(n: &NormalEquations) -> Vec<Vector3<f64>> {
        let m = n.diag.len();
        let mut dense = nalgebra::DMatrix::<f64>::zeros(3 * m, 3 * m);
        for (i, d) in n.diag.iter().enumerate() {
            dense.view_mut((3 * i, 3 * i), (3, 3)).copy_from(d);
        }
        let mut put = |a: usize, b: usize, blk: &Matrix3<f64>| {
            dense.view_mut((3 * a, 3 * b), (3, 3)).copy_from(blk);
            dense
                .view_mut((3 * b, 3 * a), (3, 3))
                .copy_from(&blk.transpose());
        };
        for (i, o) in n.off.iter().enumerate() {
            put(i, i + 1, o);
        }
        for (a, b, blk) in &n.cross {
            put(*a, *b, blk);
        }
        let rhs =
            nalgebra::DVector::from_iterator(3 * m, n.grad.iter().flat_map(|v| v.iter().copied()));
        let x = dense
            .lu()
            .solve(&rhs)
            .unwrap_or_else(|| nalgebra::DVector::zeros(3 * m));
        (0..m)
            .map(|i| Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]))
            .collect()
    }

    fn assert_close(x: &[Vector3<f64>], want: &[Vector3<f64>], tolerance: f64) {
        assert_eq!(x.len(), want.len());
        for (i, (a, b)) in x.iter().zip(want).enumerate() {
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() < tolerance,
                    "{i} {k}: {} vs {}",
                    a[k],
                    b[k]
                );
            }
        }
    }

    #[test]
    fn block_tridiagonal_solve_matches_dense() {
        // A random symmetric positive definite block-tridiagonal system of 4 blocks.
        let n = random_system(7, 4, 5.0, &[]);
        let x = BlockTridiagonal::factor(&n.diag, &n.off)
            .and_then(|f| f.solve(&n.grad))
            .unwrap_or_default();
        assert_close(&x, &dense_solution(&n), 1e-9);
    }

    #[test]
    fn conjugate_gradients_match_a_dense_solve_with_closures() {
        // Normal equations of a chain with three long-range blocks, solved by the
        // preconditioned conjugate gradients and by a dense LU.
        let n = random_system(11, 12, 6.0, &[(1, 7), (2, 11), (4, 9)]);
        let x = n.solve(0.0).unwrap_or_default();
        assert_close(&x, &dense_solution(&n), 1e-6);
    }

    #[test]
    fn a_closure_removes_the_drift_of_a_loop() {
        // A square loop of 40 steps whose odometry turns 1° too much per step: the worst pose
        // strays 0.45 m from the truth. A closure saying the last pose is the first one
        // again spreads the error over the loop.
        let side = 10;
        let mut truth = vec![Pose2::new(0.0, 0.0, 0.0)];
        let mut increments = Vec::new();
        let mut odometry = vec![truth[0]];
        for k in 0..4 * side {
            let turn = if (k + 1) % side == 0 {
                std::f64::consts::FRAC_PI_2
            } else {
                0.0
            };
            let u = Pose2::new(0.1, 0.0, turn);
            let last = *truth.last().unwrap_or(&truth[0]);
            truth.push(last.compose(&u));
            let measured = Pose2::new(0.1, 0.0, turn + 1.0_f64.to_radians());
            let o = *odometry.last().unwrap_or(&truth[0]);
            odometry.push(o.compose(&measured));
            increments.push(measured);
        }
        let info: Vec<Matrix3<f64>> = increments
            .iter()
            .map(|_| Matrix3::from_diagonal(&Vector3::new(1e4, 1e4, 1e4)))
            .collect();
        let last = truth.len() - 1;
        let closures = [Closure {
            a: 0,
            b: last,
            z: truth[last].relative_to(&truth[0]),
            info: Matrix3::from_diagonal(&Vector3::new(1e6, 1e6, 1e6)),
        }];
        let factors = vec![None; truth.len()];
        let worst = |p: &[Pose2]| {
            p.iter()
                .zip(&truth)
                .map(|(a, b)| a.distance(b))
                .fold(0.0, f64::max)
        };
        let before = worst(&odometry);
        let mut poses = odometry.clone();
        Graph {
            increments: &increments,
            odo_info: &info,
            factors: &factors,
            closures: &closures,
            huber: 1e9,
        }
        .optimise(&mut poses, 10);
        let after = worst(&poses);
        assert!(before > 0.3, "{before}");
        assert!(after < 0.1 * before, "before {before}, after {after}");
        assert!(poses[last].distance(&poses[0]) < 0.01);
        assert_eq!(poses[0], odometry[0]);
    }
}
