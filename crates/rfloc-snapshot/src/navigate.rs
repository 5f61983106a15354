//! Goal planning (value iteration over the learned model) and a navigator that avoids the
//! seed's limit cycles.
//!
//! The seed's navigation follows `policy(nearest state)` blindly and reported circling and
//! limit cycling (Table 4.9, runs 10 and 17; section 4.1): localisation that alternates between
//! neighbouring states makes the policy alternate between opposite actions. [`Navigator`] adds
//! two rules on top of the policy:
//! 1. **No reversals**: if the policy asks for the mirror image of the previous action (rotate
//!    left after rotate right, arc left after arc right) from a different state, the best-valued
//!    action that is not that reversal is taken instead.
//! 2. **Revisit escape**: if the current state already occurs `max_visits` times in the last
//!    `window` steps, the next `escape_steps` decisions take the best-valued action not yet tried
//!    from that state within the window, or an exploration action when all were tried.

use std::collections::VecDeque;

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::action::Action;
use crate::database::SnapshotDatabase;
use crate::error::SnapshotError;
use crate::explore::{ExplorationConfig, ExplorationInput, ExplorationPolicy};
use crate::transition::TransitionModel;
use crate::value_iteration::{q_values, value_iteration, ValueIterationConfig};

/// Rewards and solver settings for a navigation goal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlanConfig {
    /// Value iteration settings.
    pub value_iteration: ValueIterationConfig,
    /// Reward for entering the goal state.
    pub goal_reward: f64,
    /// Cost of every step that does not reach the goal.
    pub step_cost: f64,
    /// Penalty for entering the no-tags state (the edge of the tagged area).
    pub no_tags_penalty: f64,
}

impl Default for PlanConfig {
    fn default() -> Self {
        Self {
            value_iteration: ValueIterationConfig::default(),
            goal_reward: 1.0,
            step_cost: 0.01,
            no_tags_penalty: 0.5,
        }
    }
}

/// A solved navigation problem.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Goal state.
    pub goal: usize,
    /// Value of every state.
    pub value: Vec<f64>,
    /// Policy action of every state.
    pub policy: Vec<Action>,
    /// Value iteration sweeps done.
    pub iterations: usize,
    discount: f64,
    model: TransitionModel,
    reward: Vec<Vec<f64>>,
}

impl Plan {
    /// Solves for `goal` on a transition model. Reward of `(s, a)` is the expected reward of the
    /// next state: `goal_reward` for the goal, `−no_tags_penalty` for `no_tags`, `−step_cost`
    /// otherwise; the goal is made absorbing with zero reward.
    ///
    /// # Errors
    /// Out-of-range goal, or what [`value_iteration`] reports.
    pub fn solve(
        model: &TransitionModel,
        goal: usize,
        no_tags: Option<usize>,
        config: &PlanConfig,
    ) -> Result<Plan, SnapshotError> {
        let n = model.states();
        if goal >= n {
            return Err(SnapshotError::StateOutOfRange {
                state: goal,
                states: n,
            });
        }
        let mut model = model.clone();
        model.make_absorbing(goal);
        let r_next: Vec<f64> = (0..n)
            .map(|j| {
                if j == goal {
                    config.goal_reward
                } else if Some(j) == no_tags {
                    -config.no_tags_penalty
                } else {
                    -config.step_cost
                }
            })
            .collect();
        let sum_r: f64 = r_next.iter().sum();
        let reward: Vec<Vec<f64>> = (0..n)
            .map(|s| {
                (0..model.actions())
                    .map(|a| {
                        if s == goal {
                            0.0
                        } else {
                            model
                                .row(a, s)
                                .map_or(0.0, |row| row.expect(&r_next, sum_r))
                        }
                    })
                    .collect()
            })
            .collect();
        let res = value_iteration(&model, &reward, &config.value_iteration)?;
        let policy = res
            .policy
            .iter()
            .map(|&a| Action::from_index(a).unwrap_or(Action::Forward))
            .collect();
        Ok(Plan {
            goal,
            value: res.value,
            policy,
            iterations: res.iterations,
            discount: config.value_iteration.discount,
            model,
            reward,
        })
    }

    /// Q-values of all actions in `state`, in [`Action::index`] order.
    #[must_use]
    pub fn q(&self, state: usize) -> Vec<f64> {
        q_values(&self.model, &self.reward, self.discount, &self.value, state)
    }
}

impl SnapshotDatabase {
    /// Value-iteration plan to `goal` over the learned transitions.
    ///
    /// # Errors
    /// See [`Plan::solve`].
    pub fn plan(&self, goal: usize, config: &PlanConfig) -> Result<Plan, SnapshotError> {
        Plan::solve(&self.transitions, goal, Some(self.no_tags_state()), config)
    }
}

/// Navigator limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NavigatorConfig {
    /// Number of recent decisions remembered.
    pub window: usize,
    /// Visits of one state within the window that count as a cycle.
    pub max_visits: usize,
    /// Decisions taken in escape mode once a cycle is detected.
    pub escape_steps: usize,
}

impl Default for NavigatorConfig {
    fn default() -> Self {
        Self {
            window: 12,
            max_visits: 3,
            escape_steps: 2,
        }
    }
}

/// Why the navigator chose an action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NavReason {
    /// The plan's policy action.
    Policy,
    /// The policy asked for a reversal of the previous action.
    AvoidReversal,
    /// Cycle detected: an untried action from this state.
    CycleEscape,
    /// Cycle detected and every action was tried: exploration action.
    Explore,
    /// No tags visible: turning around (the seed's `'b'` action).
    TurnAround,
}

/// The navigator's decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NavCommand {
    /// The current state is the goal: stop.
    Arrived,
    /// Execute this action.
    Act { action: Action, reason: NavReason },
}

/// Follows a [`Plan`] with limit-cycle avoidance. Pure: decisions depend only on its history,
/// the inputs and the RNG.
#[derive(Debug, Clone)]
pub struct Navigator {
    config: NavigatorConfig,
    history: VecDeque<(usize, Action)>,
    escape_left: usize,
    explorer: ExplorationPolicy,
}

impl Navigator {
    /// A navigator with empty history.
    #[must_use]
    pub fn new(config: NavigatorConfig) -> Self {
        Self {
            config,
            history: VecDeque::new(),
            escape_left: 0,
            explorer: ExplorationPolicy::new(ExplorationConfig::default()),
        }
    }

    /// Decides the next action in `state` (from [`SnapshotDatabase::localise`] or the filter's
    /// most probable state). `no_tags` is the no-tags state index, if any.
    pub fn decide<R: Rng + ?Sized>(
        &mut self,
        plan: &Plan,
        state: usize,
        no_tags: Option<usize>,
        rng: &mut R,
    ) -> NavCommand {
        if state == plan.goal {
            return NavCommand::Arrived;
        }
        if Some(state) == no_tags {
            let action = self.explorer.step(ExplorationInput::default(), rng);
            self.push(state, action);
            return NavCommand::Act {
                action,
                reason: NavReason::TurnAround,
            };
        }
        let visits = self.history.iter().filter(|(s, _)| *s == state).count();
        if visits >= self.config.max_visits && self.escape_left == 0 {
            self.escape_left = self.config.escape_steps.max(1);
            tracing::debug!(state, visits, "navigation cycle detected");
        }
        let q = plan.q(state);
        let ranked = ranked_actions(&q);
        let (action, reason) = if self.escape_left > 0 {
            self.escape_left -= 1;
            let tried: Vec<Action> = self
                .history
                .iter()
                .filter(|(s, _)| *s == state)
                .map(|(_, a)| *a)
                .collect();
            match ranked.iter().find(|a| !tried.contains(a)) {
                Some(a) => (*a, NavReason::CycleEscape),
                None => (
                    self.explorer.step(
                        ExplorationInput {
                            tags_seen: usize::MAX,
                            new_tags: 0,
                        },
                        rng,
                    ),
                    NavReason::Explore,
                ),
            }
        } else {
            let policy = plan.policy.get(state).copied().unwrap_or(Action::Forward);
            match self.history.back() {
                Some(&(prev_state, prev))
                    if prev_state != state && prev.opposite() == Some(policy) =>
                {
                    let alt = ranked
                        .iter()
                        .copied()
                        .find(|a| *a != policy)
                        .unwrap_or(policy);
                    (alt, NavReason::AvoidReversal)
                }
                _ => (policy, NavReason::Policy),
            }
        };
        self.push(state, action);
        NavCommand::Act { action, reason }
    }

    fn push(&mut self, state: usize, action: Action) {
        self.history.push_back((state, action));
        while self.history.len() > self.config.window.max(1) {
            self.history.pop_front();
        }
    }
}

/// Actions sorted by decreasing Q (stable: lower index first on ties).
fn ranked_actions(q: &[f64]) -> Vec<Action> {
    let mut idx: Vec<usize> = (0..q.len().min(Action::COUNT)).collect();
    idx.sort_by(|a, b| {
        let qa = q.get(*a).copied().unwrap_or(f64::NEG_INFINITY);
        let qb = q.get(*b).copied().unwrap_or(f64::NEG_INFINITY);
        qb.total_cmp(&qa)
    });
    idx.into_iter().filter_map(Action::from_index).collect()
}
