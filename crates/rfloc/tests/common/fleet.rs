//! A real MQTT broker (mosquitto, started per test on a free loopback port) and a scripted fleet
//! manager (a rumqttc client) for the fleet tests.

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::Duration;

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use serde_json::{json, Value};
use tokio::sync::mpsc;

/// The mosquitto binary: on PATH, or where Debian puts it.
pub fn mosquitto_binary() -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/usr/local/sbin")])
        .map(|d| d.join("mosquitto"))
        .find(|p| p.is_file())
}

/// The broker binary, or `None` after saying why the test is skipped; with
/// `RFLOC_REQUIRE_MOSQUITTO=1` a missing broker fails the test.
pub fn require_mosquitto(test: &str) -> Option<PathBuf> {
    match mosquitto_binary() {
        Some(p) => Some(p),
        None if std::env::var("RFLOC_REQUIRE_MOSQUITTO").as_deref() == Ok("1") => panic!(
            "{test}: the mosquitto MQTT broker is not installed (RFLOC_REQUIRE_MOSQUITTO=1); install it with `apt-get install mosquitto`"
        ),
        None => {
            eprintln!(
                "{test}: SKIPPED: the mosquitto MQTT broker is not installed (apt-get install mosquitto; set RFLOC_REQUIRE_MOSQUITTO=1 to make this a failure)"
            );
            None
        }
    }
}

/// A mosquitto process on `127.0.0.1:port`, killed when dropped.
pub struct Broker {
    binary: PathBuf,
    dir: PathBuf,
    pub port: u16,
    child: Option<Child>,
}

impl Broker {
    /// Starts mosquitto with a minimal configuration in `dir` on a free port and waits until it
    /// takes connections.
    pub async fn start(binary: &Path, dir: &Path) -> Self {
        let port = super::free_port();
        let mut b = Self {
            binary: binary.to_path_buf(),
            dir: dir.to_path_buf(),
            port,
            child: None,
        };
        b.restart().await;
        b
    }

    /// Starts (again) on the same port.
    pub async fn restart(&mut self) {
        let conf = self.dir.join(format!("mosquitto-{}.conf", self.port));
        if !conf.exists() {
            std::fs::write(
                &conf,
                format!(
                    "listener {} 127.0.0.1\nallow_anonymous true\npersistence false\n",
                    self.port
                ),
            )
            .unwrap();
        }
        let log =
            std::fs::File::create(self.dir.join(format!("mosquitto-{}.log", self.port))).unwrap();
        let child = std::process::Command::new(&self.binary)
            .arg("-c")
            .arg(&conf)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap();
        self.child = Some(child);
        for _ in 0..200 {
            if std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok() {
                return;
            }
            tokio::time::sleep(Duration::from_millis(25)).await;
        }
        panic!("mosquitto did not listen on port {}", self.port);
    }

    /// A broker with a plain anonymous listener (`port`, for the manager) and a TLS listener on
    /// `tls_port` that takes only `user`/`password`, its certificate (for 127.0.0.1) signed by
    /// a CA made here; returns the broker, the TLS port and the CA file. `None` (after saying
    /// why) without `openssl` or `mosquitto_passwd`.
    pub async fn start_tls(
        binary: &Path,
        dir: &Path,
        user: &str,
        password: &str,
    ) -> Option<(Self, u16, PathBuf)> {
        let run = |args: &[&str]| {
            std::process::Command::new(args[0])
                .args(&args[1..])
                .current_dir(dir)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        std::fs::write(dir.join("san.ext"), "subjectAltName=IP:127.0.0.1\n").unwrap();
        let ec = [
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
        ];
        let made = run(&[
            &["openssl", "req", "-x509"][..],
            &ec[..],
            &[
                "-keyout",
                "ca.key",
                "-out",
                "ca.pem",
                "-days",
                "2",
                "-subj",
                "/CN=rfloc test CA",
            ][..],
        ]
        .concat())
            && run(&[
                &["openssl", "req"][..],
                &ec[..],
                &[
                    "-keyout",
                    "server.key",
                    "-out",
                    "server.csr",
                    "-subj",
                    "/CN=127.0.0.1",
                ][..],
            ]
            .concat())
            && run(&[
                "openssl",
                "x509",
                "-req",
                "-in",
                "server.csr",
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-out",
                "server.pem",
                "-days",
                "2",
                "-extfile",
                "san.ext",
            ])
            && run(&["mosquitto_passwd", "-b", "-c", "passwd", user, password]);
        if !made {
            eprintln!("SKIPPED: openssl or mosquitto_passwd missing or failing; no TLS broker");
            return None;
        }
        let port = super::free_port();
        let tls_port = super::free_port();
        let d = dir.display();
        std::fs::write(
            dir.join(format!("mosquitto-{port}.conf")),
            format!(
                // `user root`: a broker started as root keeps the rights to read the key
                // files in the test's folder (it has no effect on other users).
                "user root\nper_listener_settings true\npersistence false\n\
                 listener {port} 127.0.0.1\nallow_anonymous true\n\
                 listener {tls_port} 127.0.0.1\nallow_anonymous false\npassword_file {d}/passwd\n\
                 cafile {d}/ca.pem\ncertfile {d}/server.pem\nkeyfile {d}/server.key\n"
            ),
        )
        .unwrap();
        let mut b = Self {
            binary: binary.to_path_buf(),
            dir: dir.to_path_buf(),
            port,
            child: None,
        };
        b.restart().await;
        Some((b, tls_port, dir.join("ca.pem")))
    }

    /// Kills the broker (SIGKILL: no goodbye to its clients).
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// `host:port`.
    pub fn address(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        self.kill();
    }
}

/// One message the manager received.
#[derive(Debug, Clone)]
pub struct Msg {
    pub topic: String,
    pub json: Value,
    pub retained: bool,
}

impl Msg {
    /// The last topic level (`state`, `connection`, …).
    pub fn kind(&self) -> &str {
        self.topic.rsplit('/').next().unwrap_or("")
    }

    /// The serial number level of the topic.
    pub fn serial(&self) -> &str {
        self.topic.split('/').nth(3).unwrap_or("")
    }
}

/// A scripted fleet manager: subscribes to `uagv/v2/rfloc/+/#`, checks every message a vehicle
/// publishes against the VDA 5050 2.1.0 schemas, and sends orders and instant actions.
pub struct Manager {
    client: AsyncClient,
    rx: mpsc::UnboundedReceiver<Result<Msg, String>>,
    task: tokio::task::JoinHandle<()>,
    header: u32,
    /// Messages received and not yet looked at.
    pub backlog: std::collections::VecDeque<Msg>,
    /// Every message received, in order.
    pub all: Vec<Msg>,
}

impl Manager {
    pub async fn connect(port: u16, id: &str) -> Self {
        let mut o = MqttOptions::new(id, "127.0.0.1", port);
        o.set_keep_alive(Duration::from_secs(5));
        o.set_max_packet_size(1 << 20, 1 << 20);
        let (client, mut eventloop) = AsyncClient::new(o, 256);
        let (tx, rx) = mpsc::unbounded_channel();
        let sub = client.clone();
        let task = tokio::spawn(async move {
            loop {
                match eventloop.poll().await {
                    Ok(Event::Incoming(Packet::ConnAck(_))) => {
                        let _ = sub.try_subscribe("uagv/v2/rfloc/+/#", QoS::AtLeastOnce);
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        let kind = p.topic.rsplit('/').next().unwrap_or("").to_string();
                        if kind == "order" || kind == "instantActions" {
                            continue;
                        }
                        let msg = match serde_json::from_slice::<Value>(&p.payload) {
                            Err(e) => Err(format!("{}: not JSON: {e}", p.topic)),
                            Ok(json) => match rfloc_vda5050::schema::topic_of(&p.topic) {
                                None => Err(format!("{}: unknown topic", p.topic)),
                                Some(t) => match rfloc_vda5050::schema::validate(t, &json) {
                                    Ok(()) => Ok(Msg {
                                        topic: p.topic.clone(),
                                        json,
                                        retained: p.retain,
                                    }),
                                    Err(e) => Err(format!("{}: schema: {e:?}\n{json:#}", p.topic)),
                                },
                            },
                        };
                        if tx.send(msg).is_err() {
                            return;
                        }
                    }
                    Ok(_) => {}
                    Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
                }
            }
        });
        Self {
            client,
            rx,
            task,
            header: 0,
            backlog: std::collections::VecDeque::new(),
            all: Vec::new(),
        }
    }

    /// The next message before `deadline` (schema failures fail the test).
    pub async fn next(&mut self, deadline: tokio::time::Instant) -> Option<Msg> {
        if let Some(m) = self.backlog.pop_front() {
            return Some(m);
        }
        match tokio::time::timeout_at(deadline, self.rx.recv()).await {
            Ok(Some(Ok(m))) => {
                self.all.push(m.clone());
                Some(m)
            }
            Ok(Some(Err(e))) => panic!("a vehicle published an invalid message: {e}"),
            _ => None,
        }
    }

    /// Waits up to `secs` for a message of `serial` on `kind` that `pred` accepts; other
    /// messages are looked at and dropped.
    pub async fn wait_for(
        &mut self,
        serial: &str,
        kind: &str,
        secs: f64,
        mut pred: impl FnMut(&Value) -> bool,
    ) -> Option<Value> {
        let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(secs);
        while let Some(m) = self.next(deadline).await {
            if m.serial() == serial && m.kind() == kind && pred(&m.json) {
                return Some(m.json);
            }
        }
        None
    }

    fn header(&mut self, serial: &str) -> Value {
        self.header += 1;
        json!({
            "headerId": self.header,
            "timestamp": "2027-01-01T00:00:00.000Z",
            "version": "2.1.0",
            "manufacturer": "rfloc",
            "serialNumber": serial,
        })
    }

    /// Publishes raw bytes on a vehicle's topic.
    pub async fn send_raw(&self, serial: &str, kind: &str, payload: Vec<u8>) {
        self.client
            .publish(
                format!("uagv/v2/rfloc/{serial}/{kind}"),
                QoS::AtMostOnce,
                false,
                payload,
            )
            .await
            .unwrap();
    }

    /// An order through `points` (node i at points[i], all released) to `serial`, addressed in
    /// its header to `header_serial`.
    pub async fn order(
        &mut self,
        serial: &str,
        header_serial: &str,
        order_id: &str,
        points: &[(f64, f64)],
    ) {
        let mut msg = self.header(header_serial);
        msg["orderId"] = json!(order_id);
        msg["orderUpdateId"] = json!(0);
        msg["nodes"] = json!(points
            .iter()
            .enumerate()
            .map(
                |(i, (x, y))| json!({"nodeId": format!("{order_id}-n{i}"), "sequenceId": 2 * i,
                "released": true, "nodePosition": {"x": x, "y": y, "mapId": "map"}, "actions": []})
            )
            .collect::<Vec<_>>());
        msg["edges"] = json!((1..points.len())
            .map(
                |i| json!({"edgeId": format!("{order_id}-e{i}"), "sequenceId": 2 * i - 1,
                "released": true, "startNodeId": format!("{order_id}-n{}", i - 1),
                "endNodeId": format!("{order_id}-n{i}"), "actions": []})
            )
            .collect::<Vec<_>>());
        self.send_raw(serial, "order", serde_json::to_vec(&msg).unwrap())
            .await;
    }

    /// One instant action.
    pub async fn instant(&mut self, serial: &str, kind: &str, id: &str, params: Value) {
        let mut msg = self.header(serial);
        msg["actions"] = json!([{"actionType": kind, "actionId": id, "blockingType": "NONE",
            "actionParameters": params}]);
        self.send_raw(serial, "instantActions", serde_json::to_vec(&msg).unwrap())
            .await;
    }
}

impl Drop for Manager {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// The error types of a state.
pub fn error_types(state: &Value) -> Vec<String> {
    state["errors"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|e| e["errorType"].as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default()
}

/// The status of action `id` in a state.
pub fn action_status(state: &Value, id: &str) -> Option<String> {
    state["actionStates"]
        .as_array()?
        .iter()
        .find(|a| a["actionId"] == id)
        .and_then(|a| a["actionStatus"].as_str().map(str::to_string))
}

/// `(x, y)` of a state's or visualization's `agvPosition`.
pub fn position(msg: &Value) -> Option<(f64, f64)> {
    let p = &msg["agvPosition"];
    Some((p["x"].as_f64()?, p["y"].as_f64()?))
}

/// `config/sim-fleet.toml` for a test: pose port, broker, serial number and `edits`.
pub fn robot_file(
    dir: &Path,
    pose_port: u16,
    broker: &str,
    serial: &str,
    edits: &[(&str, &str)],
) -> PathBuf {
    let broker_line = format!("broker = \"{broker}\"");
    let serial_line = format!("serial_number = \"{serial}\"");
    let mut all = vec![
        ("broker = \"127.0.0.1:1883\"", broker_line.as_str()),
        ("serial_number = \"sim-fleet-1\"", serial_line.as_str()),
    ];
    all.extend_from_slice(edits);
    super::sim_robot_file(dir, "sim-fleet.toml", "127.0.0.1:2950", pose_port, &all)
}
