//! Ten simulated robots on one mosquitto broker, each driven by an order of its own from one
//! scripted fleet manager: every robot reaches its order's last node, and the topics stay
//! separate (each robot's messages carry its own serial number and only its own order). The
//! robots are `config/sim-fleet.toml` at time scale 10, sweeping rarely, with 0.6 m orders, so
//! the test stays within about a minute on two cores. Every message is schema-checked.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::collections::{BTreeMap, BTreeSet};

use common::fleet::{position, require_mosquitto, Broker, Manager};

const ROBOTS: usize = 10;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ten_fleet_robots_on_one_broker_each_finish_their_own_order() {
    let Some(mosquitto) =
        require_mosquitto("ten_fleet_robots_on_one_broker_each_finish_their_own_order")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(&mosquitto, dir.path()).await;
    let mut m = Manager::connect(broker.port, "manager-ten").await;
    let serials: Vec<String> = (0..ROBOTS).map(|i| format!("fleet-{i:02}")).collect();
    let mut daemons = Vec::new();
    for serial in &serials {
        let robot_dir = dir.path().join(serial);
        std::fs::create_dir_all(&robot_dir).unwrap();
        let path = common::fleet::robot_file(
            &robot_dir,
            common::free_port(),
            &broker.address(),
            serial,
            &[
                ("time_scale = 5.0", "time_scale = 10.0"),
                ("sweep_every_s = 3.0", "sweep_every_s = 600.0"),
            ],
        );
        daemons.push(common::Daemon::start(&path, "info"));
    }

    // Every robot comes up with a position; then each gets its order.
    let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(90);
    let mut start: BTreeMap<String, (f64, f64)> = BTreeMap::new();
    let mut done: BTreeSet<String> = BTreeSet::new();
    let mut sent = false;
    let mut last_state: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    while done.len() < ROBOTS {
        let Some(msg) = m.next(deadline).await else {
            let mut logs = String::new();
            for (serial, d) in serials.iter().zip(daemons.drain(..)) {
                if !done.contains(serial) {
                    let (_, log) = d.terminate_or_collect().await;
                    let tail: Vec<&str> = log.lines().rev().take(15).collect();
                    logs.push_str(&format!("--- {serial}\n{}\n", tail.join("\n")));
                }
            }
            panic!(
                "robots done: {done:?}; last states: {:#?}\n{logs}",
                last_state
                    .iter()
                    .map(|(k, v)| (k, &v["orderId"], &v["lastNodeId"], &v["agvPosition"]))
                    .collect::<Vec<_>>()
            );
        };
        // Topics stay separate: the topic's serial is the header's.
        assert_eq!(
            msg.json["serialNumber"].as_str(),
            Some(msg.serial()),
            "{}",
            msg.topic
        );
        assert_eq!(msg.json["manufacturer"], "rfloc");
        if msg.kind() != "state" {
            continue;
        }
        let serial = msg.serial().to_string();
        let order = msg.json["orderId"].as_str().unwrap_or("").to_string();
        assert!(
            order.is_empty() || order == format!("to-{serial}"),
            "{serial} took order {order}"
        );
        if msg.json["agvPosition"]["positionInitialized"] == true && !start.contains_key(&serial) {
            start.insert(serial.clone(), position(&msg.json).unwrap());
        }
        if order == format!("to-{serial}") && msg.json["lastNodeId"] == format!("to-{serial}-n1") {
            assert!(msg.json["nodeStates"].as_array().unwrap().is_empty());
            done.insert(serial.clone());
        }
        last_state.insert(serial, msg.json);
        if !sent && start.len() == ROBOTS {
            sent = true;
            for (serial, &(x, y)) in &start {
                m.order(
                    serial,
                    serial,
                    &format!("to-{serial}"),
                    &[(x, y), (x, y + 0.6)],
                )
                .await;
            }
        }
    }
    let mut ok = 0;
    for d in daemons {
        let (status, log) = d.terminate().await;
        assert!(status.success(), "{status:?}\n{log}");
        assert!(!log.contains("panicked"), "{log}");
        ok += 1;
    }
    assert_eq!(ok, ROBOTS);
    // Each robot said ONLINE and, on its way out, OFFLINE on its own connection topic.
    let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(15);
    let offline = |m: &Manager| {
        m.all
            .iter()
            .filter(|x| x.kind() == "connection" && x.json["connectionState"] == "OFFLINE")
            .map(|x| x.serial().to_string())
            .collect::<BTreeSet<String>>()
    };
    while offline(&m).len() < ROBOTS && m.next(deadline).await.is_some() {}
    assert_eq!(offline(&m).len(), ROBOTS, "OFFLINE from {:?}", offline(&m));
    for serial in &serials {
        let states: Vec<&str> = m
            .all
            .iter()
            .filter(|x| x.serial() == serial && x.kind() == "connection")
            .filter_map(|x| x.json["connectionState"].as_str())
            .collect();
        assert!(states.contains(&"ONLINE"), "{serial}: {states:?}");
    }
}
