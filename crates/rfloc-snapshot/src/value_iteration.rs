//! Value iteration with pymdptoolbox's stopping rule.

use serde::{Deserialize, Serialize};

use crate::error::SnapshotError;
use crate::transition::TransitionModel;

/// Parameters of [`value_iteration`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ValueIterationConfig {
    /// Discount γ in `(0, 1]`.
    pub discount: f64,
    /// ε of the ε-optimal stopping rule.
    pub epsilon: f64,
    /// Hard cap on iterations.
    pub max_iter: usize,
}

impl Default for ValueIterationConfig {
    fn default() -> Self {
        Self {
            discount: 0.95,
            epsilon: 0.01,
            max_iter: 1000,
        }
    }
}

/// Result of value iteration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValueIterationResult {
    /// Value of every state.
    pub value: Vec<f64>,
    /// Greedy action index of every state (ties go to the lowest index).
    pub policy: Vec<usize>,
    /// Bellman sweeps done.
    pub iterations: usize,
    /// Iteration limit used (the computed bound when γ < 1, capped by `max_iter`).
    pub max_iter: usize,
}

/// Solves `V(s) = max_a [R(s,a) + γ Σ_j P(j|s,a) V(j)]` from `V = 0`.
///
/// `reward[s][a]` (states × actions, pymdptoolbox's `(S, A)` layout). Stopping rule as in
/// pymdptoolbox `mdp.ValueIteration`: stop when `span(V_k − V_{k−1}) < ε(1−γ)/γ` (γ < 1) or
/// `< ε` (γ = 1), or when the iteration count reaches the limit. For γ < 1 the limit is
/// Puterman's bound (Theorem 6.6.6), computed before iterating:
/// `ceil(log(ε(1−γ)/γ / span(T V_0 − V_0)) / log(γ·k))` with
/// `k = 1 − Σ_j min_{s,a} P(j|s,a)`; pymdptoolbox replaces `max_iter` by this bound, here the
/// smaller of the two is used (equal when `max_iter` is at least the bound). A non-finite or
/// non-positive bound falls back to `max_iter`.
///
/// # Errors
/// [`SnapshotError::InvalidModel`] on mismatched sizes, [`SnapshotError::InvalidConfig`] on a
/// discount outside `(0, 1]` or a non-positive ε.
pub fn value_iteration(
    model: &TransitionModel,
    reward: &[Vec<f64>],
    config: &ValueIterationConfig,
) -> Result<ValueIterationResult, SnapshotError> {
    let s = model.states();
    let a = model.actions();
    let g = config.discount;
    if g.is_nan() || g <= 0.0 || g > 1.0 {
        return Err(SnapshotError::InvalidConfig(format!(
            "discount {g} not in (0, 1]"
        )));
    }
    if config.epsilon.is_nan() || config.epsilon <= 0.0 {
        return Err(SnapshotError::InvalidConfig(format!(
            "epsilon {} must be > 0",
            config.epsilon
        )));
    }
    if reward.len() != s || reward.iter().any(|r| r.len() != a) {
        return Err(SnapshotError::InvalidModel(format!(
            "reward must be {s} states × {a} actions"
        )));
    }
    if a == 0 {
        return Err(SnapshotError::InvalidModel("no actions".into()));
    }
    let mut v = vec![0.0; s];
    let thresh = if g < 1.0 {
        config.epsilon * (1.0 - g) / g
    } else {
        config.epsilon
    };
    let max_iter = if g < 1.0 {
        let k = 1.0 - column_minima(model).iter().sum::<f64>();
        let (first, _) = bellman(model, reward, g, &v);
        let span = span_of(first.iter().zip(&v).map(|(n, o)| n - o));
        let bound = (thresh / span).ln() / (g * k).ln();
        if bound.is_finite() && bound > 0.0 {
            (bound.ceil() as usize).min(config.max_iter)
        } else {
            config.max_iter
        }
    } else {
        config.max_iter
    };
    let mut policy = vec![0; s];
    let mut iterations = 0;
    loop {
        iterations += 1;
        let (nv, np) = bellman(model, reward, g, &v);
        let variation = span_of(nv.iter().zip(&v).map(|(n, o)| n - o));
        v = nv;
        policy = np;
        if variation < thresh || iterations >= max_iter {
            break;
        }
    }
    Ok(ValueIterationResult {
        value: v,
        policy,
        iterations,
        max_iter,
    })
}

/// `Q(s, a) = R(s, a) + γ Σ_j P(j|s,a) V(j)` for all actions of one state.
#[must_use]
pub fn q_values(
    model: &TransitionModel,
    reward: &[Vec<f64>],
    discount: f64,
    value: &[f64],
    state: usize,
) -> Vec<f64> {
    let sum_v: f64 = value.iter().sum();
    (0..model.actions())
        .map(|a| {
            let r = reward
                .get(state)
                .and_then(|r| r.get(a))
                .copied()
                .unwrap_or(0.0);
            r + discount
                * model
                    .row(a, state)
                    .map_or(0.0, |row| row.expect(value, sum_v))
        })
        .collect()
}

fn bellman(
    model: &TransitionModel,
    reward: &[Vec<f64>],
    g: f64,
    v: &[f64],
) -> (Vec<f64>, Vec<usize>) {
    let sum_v: f64 = v.iter().sum();
    let s = model.states();
    let mut nv = Vec::with_capacity(s);
    let mut np = Vec::with_capacity(s);
    for (i, r) in reward.iter().enumerate().take(s) {
        let mut best = f64::NEG_INFINITY;
        let mut arg = 0;
        for a in 0..model.actions() {
            let q = r.get(a).copied().unwrap_or(0.0)
                + g * model.row(a, i).map_or(0.0, |row| row.expect(v, sum_v));
            if q > best {
                best = q;
                arg = a;
            }
        }
        nv.push(best);
        np.push(arg);
    }
    (nv, np)
}

fn span_of(it: impl Iterator<Item = f64>) -> f64 {
    let (lo, hi) = it.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
        (lo.min(x), hi.max(x))
    });
    if lo.is_finite() && hi.is_finite() {
        hi - lo
    } else {
        0.0
    }
}

/// `h[j] = min over all (s, a) of P(j | s, a)`, computed from the sparse rows.
fn column_minima(model: &TransitionModel) -> Vec<f64> {
    let n = model.states();
    let rows: Vec<_> = (0..model.actions())
        .flat_map(|a| (0..n).filter_map(move |s| model.row(a, s)))
        .collect();
    let mut h = vec![f64::INFINITY; n];
    // Rows that do not list j contribute their uniform part; rows that list j contribute
    // uniform + entry. Count, for every j, in how many rows it is listed.
    let mut listed = vec![0usize; n];
    for row in &rows {
        for &(j, p) in &row.entries {
            if let Some(x) = h.get_mut(j) {
                *x = x.min(row.uniform + p);
            }
            if let Some(c) = listed.get_mut(j) {
                *c += 1;
            }
        }
    }
    let mut by_uniform: Vec<&&crate::transition::TransitionRow> = rows.iter().collect();
    by_uniform.sort_by(|a, b| a.uniform.total_cmp(&b.uniform));
    for (j, hj) in h.iter_mut().enumerate() {
        if listed.get(j).copied().unwrap_or(0) == rows.len() {
            continue;
        }
        // the smallest-uniform row that does not list j
        if let Some(row) = by_uniform
            .iter()
            .find(|r| r.entries.binary_search_by_key(&j, |e| e.0).is_err())
        {
            *hj = hj.min(row.uniform);
        }
    }
    h.iter()
        .map(|x| if x.is_finite() { *x } else { 0.0 })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden values from pymdptoolbox 4.0b3 (`pip install pymdptoolbox` in a scratch venv,
    /// 2026-11-21): `P, R = mdptoolbox.example.forest(); vi = mdptoolbox.mdp.ValueIteration(P, R,
    /// 0.96); vi.run()` printed `V = (5.93215488, 9.38815488, 13.38815488)`, `policy = (0, 0, 0)`,
    /// `iter = 4`, `max_iter = 63`; and `example.small()` with γ = 0.9 printed
    /// `V = (40.048625392716815, 33.65371175967546)`, `policy = (1, 0)`, `iter = 26`, `max_iter = 28`.
    #[test]
    fn forest_matches_pymdptoolbox() {
        let p = vec![
            vec![
                vec![0.1, 0.9, 0.0],
                vec![0.1, 0.0, 0.9],
                vec![0.1, 0.0, 0.9],
            ],
            vec![
                vec![1.0, 0.0, 0.0],
                vec![1.0, 0.0, 0.0],
                vec![1.0, 0.0, 0.0],
            ],
        ];
        let r = vec![vec![0.0, 0.0], vec![0.0, 1.0], vec![4.0, 2.0]];
        let m = TransitionModel::from_dense(&p).unwrap();
        let res = value_iteration(
            &m,
            &r,
            &ValueIterationConfig {
                discount: 0.96,
                epsilon: 0.01,
                max_iter: 1000,
            },
        )
        .unwrap();
        let expected = [5.93215488, 9.38815488, 13.38815488];
        for (v, e) in res.value.iter().zip(expected) {
            assert!((v - e).abs() < 1e-9, "{v} vs {e}");
        }
        assert_eq!(res.policy, vec![0, 0, 0]);
        assert_eq!(res.iterations, 4);
        assert_eq!(res.max_iter, 63);
    }

    #[test]
    fn small_matches_pymdptoolbox() {
        let p = vec![
            vec![vec![0.5, 0.5], vec![0.8, 0.2]],
            vec![vec![0.0, 1.0], vec![0.1, 0.9]],
        ];
        let r = vec![vec![5.0, 10.0], vec![-1.0, 2.0]];
        let m = TransitionModel::from_dense(&p).unwrap();
        let res = value_iteration(
            &m,
            &r,
            &ValueIterationConfig {
                discount: 0.9,
                epsilon: 0.01,
                max_iter: 1000,
            },
        )
        .unwrap();
        assert!((res.value[0] - 40.048625392716815).abs() < 1e-11);
        assert!((res.value[1] - 33.65371175967546).abs() < 1e-11);
        assert_eq!(res.policy, vec![1, 0]);
        assert_eq!(res.iterations, 26);
        assert_eq!(res.max_iter, 28);
        // A smaller user cap wins over the computed bound.
        let capped = value_iteration(
            &m,
            &r,
            &ValueIterationConfig {
                discount: 0.9,
                epsilon: 0.01,
                max_iter: 5,
            },
        )
        .unwrap();
        assert_eq!(capped.iterations, 5);
    }

    /// The sparse-row column minima used by the iteration bound equal a dense brute force,
    /// including rows with a uniform (prior) part.
    #[test]
    fn column_minima_match_dense_brute_force() {
        use crate::action::Action;
        use crate::transition::{TransitionCounts, TransitionPrior};
        let mut c = TransitionCounts::new(6);
        for (k, a) in Action::ALL.iter().enumerate() {
            for s in 0..6 {
                c.record(s, *a, (s + k) % 6).unwrap();
                c.record(s, *a, (s * 2 + 1) % 6).unwrap();
            }
        }
        c.record_weighted(2, Action::Forward, 5, 3.0).unwrap();
        for prior in [
            TransitionPrior {
                alpha: 0.0,
                self_fraction: 0.0,
            },
            TransitionPrior {
                alpha: 1.0,
                self_fraction: 0.5,
            },
            TransitionPrior {
                alpha: 6.0,
                self_fraction: 0.0,
            },
        ] {
            let m = c.to_model(&prior);
            let h = column_minima(&m);
            for (j, hj) in h.iter().enumerate() {
                let brute = (0..m.actions())
                    .flat_map(|a| (0..6).map(move |s| (a, s)))
                    .map(|(a, s)| m.prob(a, s, j))
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    (hj - brute).abs() < 1e-15,
                    "{prior:?} j={j}: {hj} vs {brute}"
                );
            }
        }
    }

    #[test]
    fn rejects_bad_inputs() {
        let m = TransitionModel::from_dense(&[vec![vec![1.0]]]).unwrap();
        let cfg = ValueIterationConfig::default();
        assert!(value_iteration(&m, &[vec![0.0, 1.0]], &cfg).is_err());
        assert!(value_iteration(
            &m,
            &[vec![0.0]],
            &ValueIterationConfig {
                discount: 0.0,
                ..cfg
            }
        )
        .is_err());
        assert!(value_iteration(
            &m,
            &[vec![0.0]],
            &ValueIterationConfig {
                epsilon: 0.0,
                ..cfg
            }
        )
        .is_err());
        assert!(value_iteration(
            &m,
            &[vec![1.0]],
            &ValueIterationConfig {
                discount: 1.0,
                ..cfg
            }
        )
        .is_ok());
    }
}
