//! rfloc robots as VDA 5050 vehicles over a real MQTT broker: each test starts its own
//! mosquitto on a free loopback port, runs the daemon binary on a simulated robot
//! (`config/sim-fleet.toml`, the EKF-SLAM beacon robot, or the HF-grid robot) and plays a fleet
//! manager with an MQTT client that sends orders and instant actions and checks the state
//! transitions. Every message a vehicle publishes is checked against the 2.1.0 JSON schemas.
//! Without mosquitto the tests are skipped (printing why), or fail when
//! `RFLOC_REQUIRE_MOSQUITTO=1` (CI).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::fleet::{action_status, error_types, position, require_mosquitto, Broker, Manager};
use serde_json::{json, Value};

/// The robot's position once it is initialised.
async fn initialised_position(m: &mut Manager, serial: &str) -> (f64, f64) {
    let s = m
        .wait_for(serial, "state", 60.0, |s| {
            s["agvPosition"]["positionInitialized"] == true
        })
        .await
        .expect("no state with an initialised position");
    position(&s).unwrap()
}

/// Waits for a state that passes `pred`; fails with the daemon's log tail otherwise.
async fn state_where(
    m: &mut Manager,
    daemon: common::Daemon,
    serial: &str,
    secs: f64,
    what: &str,
    pred: impl FnMut(&Value) -> bool,
) -> (Value, common::Daemon) {
    match m.wait_for(serial, "state", secs, pred).await {
        Some(s) => (s, daemon),
        None => {
            daemon
                .fail_with_log_tail(&format!("no state: {what}"))
                .await
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fleet_vehicle_drives_an_order_and_refuses_bad_input() {
    let Some(mosquitto) = require_mosquitto("fleet_vehicle_drives_an_order_and_refuses_bad_input")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(&mosquitto, dir.path()).await;
    let mut m = Manager::connect(broker.port, "manager-a").await;
    let serial = "robot-a";
    let path = common::fleet::robot_file(
        dir.path(),
        common::free_port(),
        &broker.address(),
        serial,
        &[("time_scale = 5.0", "time_scale = 10.0")],
    );
    let daemon = common::Daemon::start(&path, "info");

    // ONLINE, the factsheet, and a state with a position.
    let online = m
        .wait_for(serial, "connection", 30.0, |c| {
            c["connectionState"] == "ONLINE"
        })
        .await;
    assert!(online.is_some(), "no ONLINE");
    let (x0, y0) = initialised_position(&mut m, serial).await;
    let factsheet = m.all.iter().find(|x| x.kind() == "factsheet").cloned();
    let factsheet = factsheet.expect("no factsheet").json;
    assert_eq!(
        factsheet["typeSpecification"]["seriesName"],
        "rfloc ekfslam"
    );
    assert_eq!(factsheet["serialNumber"], serial);

    // Bad input: each gets a VDA 5050 error in state.errors; nothing breaks.
    m.send_raw(serial, "order", b"{\"headerId\": 1, not json".to_vec())
        .await;
    let (_, daemon) = state_where(&mut m, daemon, serial, 20.0, "validationError", |s| {
        error_types(s).contains(&"validationError".to_string())
    })
    .await;
    let wrong_version = json!({"headerId": 9, "timestamp": "2027-01-01T00:00:00.000Z",
        "version": "1.1.0", "manufacturer": "rfloc", "serialNumber": serial,
        "actions": []});
    m.send_raw(
        serial,
        "instantActions",
        serde_json::to_vec(&wrong_version).unwrap(),
    )
    .await;
    m.order(serial, "someone-else", "stray", &[(x0, y0)]).await;
    m.instant(serial, "fly", "fly-1", json!([])).await;
    let (s, daemon) = state_where(&mut m, daemon, serial, 20.0, "unsupported action", |s| {
        action_status(s, "fly-1").as_deref() == Some("FAILED")
    })
    .await;
    assert!(
        error_types(&s).contains(&"unsupportedInstantAction".to_string()),
        "{s:#}"
    );
    assert_ne!(
        s["orderId"], "stray",
        "an order for another vehicle was taken"
    );

    // stateRequest and factsheetRequest are answered.
    let factsheets = m.all.iter().filter(|x| x.kind() == "factsheet").count();
    m.instant(serial, "factsheetRequest", "fs-1", json!([]))
        .await;
    m.instant(serial, "stateRequest", "sr-1", json!([])).await;
    let (_, daemon) = state_where(&mut m, daemon, serial, 20.0, "stateRequest", |s| {
        action_status(s, "sr-1").as_deref() == Some("FINISHED")
    })
    .await;
    assert!(
        m.all.iter().filter(|x| x.kind() == "factsheet").count() > factsheets,
        "no factsheet after factsheetRequest"
    );

    // An order: ahead 0.8 m (the robot faces +y), then 0.6 m to the right.
    let nodes = [(x0, y0), (x0, y0 + 0.8), (x0 + 0.6, y0 + 0.8)];
    m.order(serial, serial, "o1", &nodes).await;
    let (s, daemon) = state_where(&mut m, daemon, serial, 20.0, "order o1 accepted", |s| {
        s["orderId"] == "o1"
    })
    .await;
    assert_eq!(s["lastNodeId"], "o1-n0");
    assert!(
        error_types(&s).is_empty(),
        "an accepted order clears the rejections: {s:#}"
    );
    let mut drove = false;
    let mut passed_n1 = false;
    let (s, daemon) = state_where(&mut m, daemon, serial, 120.0, "o1 done", |s| {
        drove |= s["driving"] == true;
        if s["lastNodeId"] == "o1-n1" {
            passed_n1 = true;
            assert_eq!(s["nodeStates"][0]["nodeId"], "o1-n2");
            assert_eq!(s["edgeStates"][0]["edgeId"], "o1-e2");
        }
        s["lastNodeId"] == "o1-n2"
    })
    .await;
    assert!(drove && passed_n1, "driving {drove}, n1 {passed_n1}");
    assert!(s["nodeStates"].as_array().unwrap().is_empty());
    let (x, y) = position(&s).unwrap();
    assert!((x - nodes[2].0).hypot(y - nodes[2].1) <= 0.25, "({x}, {y})");
    let vis = m.all.iter().filter(|x| x.kind() == "visualization").count();
    assert!(vis > 10, "{vis} visualization messages");

    // A long order, cancelled while driving: the robot stops, the cancel finishes.
    let (x1, y1) = (x, y);
    m.order(serial, serial, "o2", &[(x1, y1), (x1 - 3.0, y1)])
        .await;
    let (_, daemon) = state_where(&mut m, daemon, serial, 60.0, "o2 driving", |s| {
        s["orderId"] == "o2" && s["driving"] == true
    })
    .await;
    m.instant(serial, "cancelOrder", "cancel-1", json!([]))
        .await;
    let (s, daemon) = state_where(&mut m, daemon, serial, 30.0, "cancel finished", |s| {
        action_status(s, "cancel-1").as_deref() == Some("FINISHED")
    })
    .await;
    assert!(s["nodeStates"].as_array().unwrap().is_empty(), "{s:#}");
    assert_eq!(s["driving"], false);
    let (xc, yc) = position(&s).unwrap();
    assert!(
        (xc - (x1 - 3.0)).abs() > 1.0,
        "cancelled, not driven to the end"
    );

    // A clean stop: OFFLINE.
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{status:?}");
    let offline = m
        .wait_for(serial, "connection", 10.0, |c| {
            c["connectionState"] == "OFFLINE"
        })
        .await;
    assert!(offline.is_some(), "no OFFLINE; log:\n{log}");
    for needle in [
        "fleet order refused",
        "fleet instantActions refused",
        "instant action type not supported",
        "fleet order accepted",
    ] {
        assert!(log.contains(needle), "no {needle:?} in the log:\n{log}");
    }
    assert!(!log.contains("panicked"), "{log}");
    let _ = (xc, yc);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fleet_vehicle_survives_a_broker_restart_mid_order() {
    let Some(mosquitto) = require_mosquitto("fleet_vehicle_survives_a_broker_restart_mid_order")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut broker = Broker::start(&mosquitto, dir.path()).await;
    let mut m = Manager::connect(broker.port, "manager-b").await;
    let serial = "robot-b";
    let path = common::fleet::robot_file(
        dir.path(),
        common::free_port(),
        &broker.address(),
        serial,
        &[],
    );
    let daemon = common::Daemon::start(&path, "info");
    let (x0, y0) = initialised_position(&mut m, serial).await;
    let nodes = [(x0, y0), (x0, y0 + 1.0), (x0, y0 + 2.0)];
    m.order(serial, serial, "long", &nodes).await;
    let (_, daemon) = state_where(&mut m, daemon, serial, 60.0, "driving the order", |s| {
        s["orderId"] == "long" && s["driving"] == true
    })
    .await;
    // The broker goes away in the middle of the order and comes back.
    broker.kill();
    tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
    broker.restart().await;
    let online = m
        .wait_for(serial, "connection", 30.0, |c| {
            c["connectionState"] == "ONLINE"
        })
        .await;
    if online.is_none() {
        daemon
            .fail_with_log_tail("not ONLINE again after the broker restart")
            .await;
    }
    let (s, daemon) = state_where(&mut m, daemon, serial, 120.0, "the order completed", |s| {
        s["orderId"] == "long" && s["lastNodeId"] == "long-n2"
    })
    .await;
    assert!(s["nodeStates"].as_array().unwrap().is_empty());
    // The process dies without a goodbye: the broker publishes the last will.
    let (_, log) = daemon.terminate_or_collect().await;
    let broken = m
        .wait_for(serial, "connection", 30.0, |c| {
            c["connectionState"] == "CONNECTIONBROKEN"
        })
        .await;
    assert!(broken.is_some(), "no CONNECTIONBROKEN; log:\n{log}");
    assert!(log.contains("fleet broker unreachable"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fleet_hf_robot_refuses_orders_and_turns_for_init_position() {
    let Some(mosquitto) =
        require_mosquitto("fleet_hf_robot_refuses_orders_and_turns_for_init_position")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(&mosquitto, dir.path()).await;
    let mut m = Manager::connect(broker.port, "manager-c").await;
    let serial = "hf-1";
    let fleet = format!(
        "[fleet]\nbroker = \"{}\"\nmanufacturer = \"rfloc\"\nserial_number = \"{serial}\"\n\n[simulation]",
        broker.address()
    );
    // config/sim.toml (it names no scenario file, so it is edited here rather than through
    // `common::sim_robot_file`): the robot stands until a fleet manager turns it.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut text = std::fs::read_to_string(root.join("config/sim.toml")).unwrap();
    for (old, new) in [
        (
            "127.0.0.1:2958",
            format!("127.0.0.1:{}", common::free_port()),
        ),
        (
            "127.0.0.1:8765",
            format!("127.0.0.1:{}", common::free_port()),
        ),
        ("stdout = true", "stdout = false".into()),
        ("[simulation]", fleet),
        ("time_scale = 5.0", "time_scale = 10.0".into()),
        ("duration_s = 40.0", "duration_s = 2000.0".into()),
    ] {
        let edited = text.replace(old, &new);
        assert_ne!(edited, text, "config/sim.toml has no {old:?}");
        text = edited;
    }
    let path = dir.path().join("robot.toml");
    std::fs::write(&path, text).unwrap();
    let daemon = common::Daemon::start(&path, "info");
    let factsheet = m
        .wait_for(serial, "factsheet", 30.0, |_| true)
        .await
        .expect("no factsheet");
    assert_eq!(
        factsheet["typeSpecification"]["localizationTypes"][0],
        "RFID"
    );
    // Standing still, the HF robot has no position yet.
    let (s, daemon) = state_where(&mut m, daemon, serial, 30.0, "a state", |_| true).await;
    assert_ne!(s["agvPosition"]["positionInitialized"], true, "{s:#}");
    m.order(serial, serial, "go", &[(0.2, 0.2), (1.0, 0.2)])
        .await;
    let (s, daemon) = state_where(&mut m, daemon, serial, 20.0, "noRouteError", |s| {
        error_types(s).contains(&"noRouteError".to_string())
    })
    .await;
    assert_ne!(s["orderId"], "go");
    // initPosition: the 360° turn over the tag field finds the pose.
    let params = json!([{"key": "x", "value": 0.2}, {"key": "y", "value": 0.2},
        {"key": "theta", "value": 0.0}, {"key": "mapId", "value": "map"}]);
    m.instant(serial, "initPosition", "init-1", params).await;
    let (s, daemon) = state_where(&mut m, daemon, serial, 60.0, "initPosition done", |s| {
        matches!(
            action_status(s, "init-1").as_deref(),
            Some("FINISHED" | "FAILED")
        )
    })
    .await;
    assert_eq!(
        action_status(&s, "init-1").as_deref(),
        Some("FINISHED"),
        "{s:#}"
    );
    let (s, daemon) = state_where(&mut m, daemon, serial, 30.0, "a position", |s| {
        s["agvPosition"]["positionInitialized"] == true
            && s["agvPosition"]["localizationScore"].is_number()
    })
    .await;
    let (x, y) = position(&s).unwrap();
    assert!((x - 0.2).hypot(y - 0.2) < 0.15, "({x}, {y})");
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{status:?}\n{log}");
    assert!(log.contains("initialisation turn started"), "{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fleet_vehicle_connects_over_tls_with_a_password() {
    let Some(mosquitto) = require_mosquitto("fleet_vehicle_connects_over_tls_with_a_password")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let Some((broker, tls_port, ca)) =
        Broker::start_tls(&mosquitto, dir.path(), "robot-t", "pa55-word").await
    else {
        return;
    };
    let mut m = Manager::connect(broker.port, "manager-t").await;
    let tls = |pw_file: &str| {
        format!(
            "serial_number = \"robot-t\"\ntls = true\nca_file = {:?}\nusername = \"robot-t\"\npassword_file = \"{pw_file}\"",
            ca.display().to_string()
        )
    };
    for (file, text) in [("good-pw", "pa55-word\n"), ("bad-pw", "guess\n")] {
        std::fs::write(dir.path().join(file), text).unwrap();
    }
    let address = format!("127.0.0.1:{tls_port}");
    // The right password: ONLINE over TLS, and the password is in no log line.
    let robot = dir.path().join("good");
    std::fs::create_dir_all(&robot).unwrap();
    std::fs::copy(dir.path().join("good-pw"), robot.join("good-pw")).unwrap();
    let good = tls("good-pw");
    let path = common::fleet::robot_file(
        &robot,
        common::free_port(),
        &address,
        "robot-t",
        &[("serial_number = \"robot-t\"", good.as_str())],
    );
    let daemon = common::Daemon::start(&path, "debug");
    let online = m
        .wait_for("robot-t", "connection", 30.0, |c| {
            c["connectionState"] == "ONLINE"
        })
        .await;
    if online.is_none() {
        daemon.fail_with_log_tail("no ONLINE over TLS").await;
    }
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{status:?}\n{log}");
    assert!(!log.contains("pa55-word"), "the password was logged");
    // A wrong password: refused by the broker, retried, never ONLINE.
    let robot = dir.path().join("bad");
    std::fs::create_dir_all(&robot).unwrap();
    std::fs::copy(dir.path().join("bad-pw"), robot.join("bad-pw")).unwrap();
    let bad = tls("bad-pw");
    let path = common::fleet::robot_file(
        &robot,
        common::free_port(),
        &address,
        "robot-u",
        &[("serial_number = \"robot-u\"", bad.as_str())],
    );
    let daemon = common::Daemon::start(&path, "info");
    let online = m
        .wait_for("robot-u", "connection", 5.0, |c| {
            c["connectionState"] == "ONLINE"
        })
        .await;
    let (_, log) = daemon.terminate().await;
    assert!(online.is_none(), "connected with a wrong password");
    assert!(log.contains("fleet broker unreachable"), "{log}");
    assert!(!log.contains("guess"), "the password was logged");
}
