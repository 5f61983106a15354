//! The fleet link's message path at the rate the estimator publishes: one pose sample into the
//! VDA 5050 agent (pose report, node check, visualization, steering), and one `state` message
//! built and JSON-encoded, as for a state at 10 Hz, with an order of ten nodes under way, a
//! device error and action states in it.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use rfloc_daemon::config::{EstimatorConfig, FleetConfig};
use rfloc_daemon::events::DeviceState;
use rfloc_daemon::fleet::{Agent, Outbox, Sample};
use rfloc_pose::{EstimateMode, Pose2};
use rfloc_vda5050::Timestamp;
use serde_json::json;

fn t(ms: u64) -> Timestamp {
    Timestamp::from_unix_millis(1_800_000_000_000 + ms).unwrap()
}

fn sample(k: u64) -> Sample {
    #[allow(clippy::cast_precision_loss)]
    let x = 0.01 * k as f64;
    Sample {
        time: 0.1 * x,
        pose: Pose2::new(x.min(0.5), 0.0, 0.0),
        covariance: [[0.01, 0.001, 0.0], [0.001, 0.02, 0.0], [0.0, 0.0, 0.01]],
        mode: EstimateMode::Fix,
        v: 0.3,
        w: 0.01,
    }
}

/// An agent driving an order of ten nodes along x, with a stale device and two instant actions.
fn busy_agent() -> Agent {
    let fleet: FleetConfig = toml::from_str(
        "broker = \"127.0.0.1:1883\"\nmanufacturer = \"rfloc\"\nserial_number = \"bench-1\"\n",
    )
    .unwrap();
    let mut a = Agent::new(&fleet, &EstimatorConfig::Odometry, "map", true).unwrap();
    let mut out = Outbox::default();
    a.on_connected(t(0), &mut out);
    a.on_sample(&sample(0), t(1), &mut out);
    let nodes: Vec<_> = (0..10)
        .map(|i| {
            json!({"nodeId": format!("n{i}"), "sequenceId": 2 * i, "released": true,
            "nodePosition": {"x": f64::from(i), "y": 0.0, "mapId": "map"}, "actions": []})
        })
        .collect();
    let edges: Vec<_> = (1..10)
        .map(|i| {
            json!({"edgeId": format!("e{i}"), "sequenceId": 2 * i - 1, "released": true,
            "startNodeId": format!("n{}", i - 1), "endNodeId": format!("n{i}"), "actions": []})
        })
        .collect();
    let order = json!({"headerId": 1, "timestamp": "2027-01-01T00:00:00.000Z", "version": "2.1.0",
        "manufacturer": "rfloc", "serialNumber": "bench-1", "orderId": "o1", "orderUpdateId": 0,
        "nodes": nodes, "edges": edges});
    a.on_message(
        "uagv/v2/rfloc/bench-1/order",
        &serde_json::to_vec(&order).unwrap(),
        t(2),
        &mut out,
    );
    let ia = json!({"headerId": 2, "timestamp": "2027-01-01T00:00:00.000Z", "version": "2.1.0",
        "manufacturer": "rfloc", "serialNumber": "bench-1", "actions": [
            {"actionType": "stateRequest", "actionId": "s1", "blockingType": "NONE"},
            {"actionType": "factsheetRequest", "actionId": "f1", "blockingType": "NONE"}]});
    a.on_message(
        "uagv/v2/rfloc/bench-1/instantActions",
        &serde_json::to_vec(&ia).unwrap(),
        t(3),
        &mut out,
    );
    a.on_device("xbee", "xbee", DeviceState::Stale, "silent", t(4), &mut out);
    a.on_battery(12.3);
    a
}

fn fleet(c: &mut Criterion) {
    let mut g = c.benchmark_group("fleet");
    let mut a = busy_agent();
    let mut k = 0u64;
    g.bench_function("sample_into_agent", |b| {
        b.iter(|| {
            k += 1;
            let mut out = Outbox::default();
            // 100 ms apart: every sample is also a visualization.
            a.on_sample(black_box(&sample(k % 40)), t(100 * k), &mut out);
            black_box(out.publish.len())
        });
    });
    let mut a = busy_agent();
    let mut k = 0u64;
    g.bench_function("state_build_and_encode", |b| {
        b.iter(|| {
            k += 1;
            let p = a.state_now(t(100 * k)).unwrap();
            black_box(p.payload.len())
        });
    });
    let mut a = busy_agent();
    println!(
        "state message: {} bytes",
        a.state_now(t(0)).unwrap().payload.len()
    );
    g.finish();
}

criterion_group!(benches, fleet);
criterion_main!(benches);
