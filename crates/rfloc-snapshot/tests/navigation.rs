//! Planning and limit-cycle avoidance on small learned models whose learned transitions are
//! wrong in the way that produced the seed's limit cycles (Table 4.9 runs 10 and 17).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_snapshot::*;

fn model(n: usize, counts: &[(usize, Action, usize, f64)]) -> TransitionModel {
    let mut c = TransitionCounts::new(n);
    for &(from, a, to, w) in counts {
        c.record_weighted(from, a, to, w).unwrap();
    }
    c.to_model(&TransitionPrior {
        alpha: 0.0,
        self_fraction: 0.0,
    })
}

/// Runs `decide` against a deterministic "true world"; returns the number of steps to arrive.
fn drive(
    plan: &Plan,
    start: usize,
    no_tags: Option<usize>,
    world: impl Fn(usize, Action) -> usize,
    mut decide: impl FnMut(usize) -> NavCommand,
    limit: usize,
) -> Option<usize> {
    let mut s = start;
    for step in 0..limit {
        match decide(s) {
            NavCommand::Arrived => return Some(step),
            NavCommand::Act { action, .. } => s = world(s, action),
        }
        let _ = (plan, no_tags);
    }
    None
}

#[test]
fn reversal_cycle_is_broken() {
    // States A=0, B=1, goal G=2, no-tags 3. The model believes RL from A and RR from B reach
    // the goal; in truth RL takes A to B and RR takes B back to A (the seed's rotate-left /
    // rotate-right limit cycle). Forward truly reaches the goal.
    let m = model(
        4,
        &[
            (0, Action::RotateLeft, 2, 9.0),
            (0, Action::Forward, 2, 5.0),
            (0, Action::Forward, 0, 5.0),
            (1, Action::RotateRight, 2, 9.0),
            (1, Action::Forward, 2, 5.0),
            (1, Action::Forward, 1, 5.0),
        ],
    );
    let plan = Plan::solve(&m, 2, Some(3), &PlanConfig::default()).unwrap();
    assert_eq!(plan.policy[0], Action::RotateLeft);
    assert_eq!(plan.policy[1], Action::RotateRight);
    let world = |s: usize, a: Action| match (s, a) {
        (0, Action::RotateLeft) => 1,
        (1, Action::RotateRight) => 0,
        (0 | 1, Action::Forward) => 2,
        (s, _) => s,
    };
    let blind = drive(
        &plan,
        0,
        Some(3),
        world,
        |s| {
            if s == 2 {
                NavCommand::Arrived
            } else {
                NavCommand::Act {
                    action: plan.policy[s],
                    reason: NavReason::Policy,
                }
            }
        },
        200,
    );
    assert_eq!(blind, None, "following the policy alone must cycle");
    let mut nav = Navigator::new(NavigatorConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut reasons = Vec::new();
    let steps = drive(
        &plan,
        0,
        Some(3),
        world,
        |s| {
            let c = nav.decide(&plan, s, Some(3), &mut rng);
            if let NavCommand::Act { reason, .. } = c {
                reasons.push(reason);
            }
            c
        },
        200,
    );
    assert_eq!(steps, Some(2));
    assert_eq!(reasons, vec![NavReason::Policy, NavReason::AvoidReversal]);
}

#[test]
fn revisit_cycle_is_escaped() {
    // Ring 0 → 1 → 2 → 0 under Forward, goal 3, no-tags 4. The model believes Forward reaches
    // the goal from every ring state; only ArcLeft from state 2 truly does.
    let mut counts = Vec::new();
    for s in 0..3 {
        counts.push((s, Action::Forward, 3, 10.0));
        counts.push((s, Action::ArcLeft, 3, 5.0));
        counts.push((s, Action::ArcLeft, s, 5.0));
    }
    let m = model(5, &counts);
    let plan = Plan::solve(&m, 3, Some(4), &PlanConfig::default()).unwrap();
    assert!(plan.policy[..3].iter().all(|a| *a == Action::Forward));
    let q = plan.q(0);
    assert!(q[Action::Forward.index()] > q[Action::ArcLeft.index()]);
    let world = |s: usize, a: Action| match (s, a) {
        (0..=2, Action::Forward) => (s + 1) % 3,
        (2, Action::ArcLeft) => 3,
        (s, _) => s,
    };
    let blind = drive(
        &plan,
        0,
        Some(4),
        world,
        |s| {
            if s == 3 {
                NavCommand::Arrived
            } else {
                NavCommand::Act {
                    action: plan.policy[s],
                    reason: NavReason::Policy,
                }
            }
        },
        200,
    );
    assert_eq!(blind, None);
    let mut nav = Navigator::new(NavigatorConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut escaped = false;
    let steps = drive(
        &plan,
        0,
        Some(4),
        world,
        |s| {
            let c = nav.decide(&plan, s, Some(4), &mut rng);
            if matches!(
                c,
                NavCommand::Act {
                    reason: NavReason::CycleEscape | NavReason::Explore,
                    ..
                }
            ) {
                escaped = true;
            }
            c
        },
        200,
    );
    assert!(escaped);
    let steps = steps.expect("navigator must reach the goal");
    assert!(steps < 40, "{steps} steps");
}

#[test]
fn no_tags_turns_around_and_goal_stops() {
    let m = model(3, &[(0, Action::Forward, 1, 1.0)]);
    let plan = Plan::solve(&m, 1, Some(2), &PlanConfig::default()).unwrap();
    assert_eq!(plan.policy[0], Action::Forward);
    assert!(plan.value[0] > plan.value[2]);
    let mut nav = Navigator::new(NavigatorConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    match nav.decide(&plan, 2, Some(2), &mut rng) {
        NavCommand::Act { action, reason } => {
            assert_eq!(reason, NavReason::TurnAround);
            assert!(action.is_rotation());
        }
        NavCommand::Arrived => panic!("not at goal"),
    }
    assert_eq!(nav.decide(&plan, 1, Some(2), &mut rng), NavCommand::Arrived);
    assert!(Plan::solve(&m, 7, None, &PlanConfig::default()).is_err());
}
