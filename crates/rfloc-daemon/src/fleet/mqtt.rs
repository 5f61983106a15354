//! The fleet task: the [`Agent`] between the estimator thread, the router and an MQTT broker.
//!
//! `rumqttc`'s event loop runs in a task of its own and hands connection changes and incoming
//! messages over a channel; the fleet task publishes with `try_publish` and never waits for the
//! broker. While the broker is away nothing is published, the event loop retries with back-off,
//! and the robot keeps driving the node it was given; on reconnection the vehicle comes back
//! ONLINE with a full state.

use std::sync::Arc;
use std::time::{Duration, SystemTime};

use rumqttc::{AsyncClient, Event, EventLoop, LastWill, MqttOptions, Outgoing, Packet, QoS};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use rfloc_vda5050::messages::ConnectionState;

use super::agent::{timestamp, Agent, Outbox, Publish};
use super::{Control, Note, Sample};
use crate::config::FleetConfig;
use crate::devices::{Backoff, Resources};
use crate::pipeline::Request;

/// Requests `rumqttc` queues for its event loop.
const CLIENT_QUEUE: usize = 512;
/// Largest MQTT packet in either direction (an order with many nodes), bytes.
const MAX_PACKET: usize = 1 << 20;

/// MQTT options for `[fleet]`: broker, client id, keep-alive, last will, credentials, TLS.
pub(super) fn options(
    fleet: &FleetConfig,
    config_dir: Option<&std::path::Path>,
    agent: &mut Agent,
) -> anyhow::Result<MqttOptions> {
    let (host, port) = fleet
        .broker_host_port()
        .ok_or_else(|| anyhow::anyhow!("fleet.broker {:?} is not host:port", fleet.broker))?;
    let mut o = MqttOptions::new(fleet.client_id(), host, port);
    o.set_keep_alive(crate::time::seconds(fleet.keep_alive_s));
    o.set_clean_session(true);
    o.set_max_packet_size(MAX_PACKET, MAX_PACKET);
    // The will is built once; its headerId is the connection topic's first.
    let will = agent
        .connection(
            ConnectionState::Connectionbroken,
            timestamp(SystemTime::now()),
        )
        .ok_or_else(|| anyhow::anyhow!("the last will could not be encoded"))?;
    o.set_last_will(LastWill::new(
        will.topic,
        will.payload,
        QoS::AtLeastOnce,
        true,
    ));
    if let Some(user) = &fleet.username {
        let password = match &fleet.password_file {
            Some(p) => {
                let path = crate::config::resolve_credential(p, config_dir).ok_or_else(|| {
                    anyhow::anyhow!("fleet password file {} not found", p.display())
                })?;
                if let Some(w) = crate::config::secret_file_warning(&path) {
                    tracing::warn!("{w}");
                }
                crate::config::read_password(&path).map_err(anyhow::Error::msg)?
            }
            None => String::new(),
        };
        o.set_credentials(user.clone(), password);
    }
    if fleet.tls {
        let ca = fleet
            .ca_file
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("fleet.tls needs fleet.ca_file"))?;
        let path = config_dir.map_or_else(|| ca.clone(), |d| d.join(ca));
        o.set_transport(rumqttc::Transport::tls_with_config(
            rumqttc::TlsConfiguration::Rustls(Arc::new(tls_config(&path)?)),
        ));
    }
    Ok(o)
}

/// A TLS client configuration (ring, TLS 1.2 and 1.3) that trusts the CAs of a PEM file.
fn tls_config(ca_file: &std::path::Path) -> anyhow::Result<rustls::ClientConfig> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::CertificateDer;
    let mut roots = rustls::RootCertStore::empty();
    let certs = CertificateDer::pem_file_iter(ca_file)
        .map_err(|e| anyhow::anyhow!("fleet CA file {}: {e}", ca_file.display()))?;
    for cert in certs {
        let cert = cert.map_err(|e| anyhow::anyhow!("fleet CA file {}: {e}", ca_file.display()))?;
        roots
            .add(cert)
            .map_err(|e| anyhow::anyhow!("fleet CA file {}: {e}", ca_file.display()))?;
    }
    if roots.is_empty() {
        anyhow::bail!("fleet CA file {} holds no certificate", ca_file.display());
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    Ok(rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()?
        .with_root_certificates(roots)
        .with_no_client_auth())
}

/// What the fleet task reads.
pub(super) struct Inputs {
    pub samples: mpsc::Receiver<Sample>,
    pub notes: mpsc::UnboundedReceiver<Note>,
}

/// Where the fleet task's decisions go.
pub(super) struct Outputs {
    pub controls: std::sync::mpsc::Sender<Control>,
    pub base: Option<mpsc::Sender<Request>>,
    pub resources: Arc<Resources>,
}

/// What the event loop task reports.
enum Net {
    Connected,
    Message {
        topic: String,
        payload: bytes::Bytes,
    },
    Lost(String),
    Closed,
}

/// The fleet task, until `stop`; then OFFLINE and a clean disconnect.
pub(super) async fn run(
    mut agent: Agent,
    options: MqttOptions,
    mut inputs: Inputs,
    outputs: Outputs,
    backoff: Backoff,
    stop: CancellationToken,
) {
    let (client, eventloop) = AsyncClient::new(options, CLIENT_QUEUE);
    let (net_tx, mut net_rx) = mpsc::channel(256);
    let mut poller = tokio::spawn(poll(eventloop, net_tx, backoff));
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut lost_reported = false;
    loop {
        let mut out = Outbox::default();
        let now = || timestamp(SystemTime::now());
        tokio::select! {
            () = stop.cancelled() => break,
            net = net_rx.recv() => match net {
                Some(Net::Connected) => {
                    tracing::info!("fleet broker connected");
                    lost_reported = false;
                    for topic in agent.subscriptions() {
                        if let Err(e) = client.try_subscribe(topic, QoS::AtMostOnce) {
                            tracing::warn!(error = %e, "fleet subscription not sent");
                        }
                    }
                    agent.on_connected(now(), &mut out);
                }
                Some(Net::Message { topic, payload }) => agent.on_message(&topic, &payload, now(), &mut out),
                Some(Net::Lost(why)) => {
                    if agent.is_connected() || !lost_reported {
                        tracing::warn!(reason = %why, "fleet broker unreachable; reconnecting (the order goes on)");
                        lost_reported = true;
                    }
                    agent.on_disconnected();
                }
                Some(Net::Closed) | None => {
                    agent.on_disconnected();
                    break;
                }
            },
            s = inputs.samples.recv() => {
                if let Some(s) = s {
                    agent.on_sample(&s, now(), &mut out);
                }
            }
            n = inputs.notes.recv() => match n {
                Some(Note::Device { name, driver, state, detail }) => {
                    agent.on_device(&name, driver, state, &detail, now(), &mut out);
                }
                Some(Note::Init { action_id, result }) => {
                    agent.on_init_result(&action_id, result, now(), &mut out);
                }
                None => {}
            },
            _ = tick.tick() => {
                if let Some(v) = outputs.resources.battery_v.lock().ok().and_then(|b| *b) {
                    agent.on_battery(v);
                }
                agent.tick(now(), &mut out);
            }
        }
        deliver(out, &client, &outputs);
    }
    // A clean goodbye: OFFLINE (retained), then DISCONNECT, so the broker keeps the will.
    if agent.is_connected() {
        if let Some(offline) =
            agent.connection(ConnectionState::Offline, timestamp(SystemTime::now()))
        {
            publish(&client, offline);
        }
        if let Err(e) = client.try_disconnect() {
            tracing::warn!(error = %e, "fleet disconnect not sent");
        }
        match tokio::time::timeout(Duration::from_secs(3), &mut poller).await {
            Ok(_) => tracing::info!("fleet link closed (OFFLINE)"),
            Err(_) => {
                tracing::warn!("fleet broker did not take the disconnect within 3 s");
                poller.abort();
            }
        }
    } else {
        poller.abort();
    }
    tracing::info!(refused = agent.rejections, "fleet link stopped");
}

fn publish(client: &AsyncClient, p: Publish) {
    let qos = if p.qos >= 1 {
        QoS::AtLeastOnce
    } else {
        QoS::AtMostOnce
    };
    if let Err(e) = client.try_publish(p.topic, qos, p.retain, p.payload) {
        tracing::warn!(error = %e, "fleet message not queued");
    }
}

fn deliver(out: Outbox, client: &AsyncClient, outputs: &Outputs) {
    if out.stop_base {
        if let Some(base) = &outputs.base {
            if base.try_send(Request::Velocity { v: 0.0, w: 0.0 }).is_err() {
                tracing::warn!("base busy: the fleet's stop goes with the pipeline's next request");
            }
        }
    }
    for c in out.controls {
        // The estimator thread ends last; a send fails only at shutdown.
        let _ = outputs.controls.send(c);
    }
    for p in out.publish {
        publish(client, p);
    }
}

/// Runs the event loop: connection changes and messages to the fleet task, reconnection with
/// back-off, until it sent a DISCONNECT or the fleet task is gone.
async fn poll(mut eventloop: EventLoop, tx: mpsc::Sender<Net>, backoff: Backoff) {
    let seed = crate::devices::seed_of("fleet");
    let mut failures = 0u32;
    loop {
        let net = match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                failures = 0;
                Net::Connected
            }
            Ok(Event::Incoming(Packet::Publish(p))) => Net::Message {
                topic: p.topic,
                payload: p.payload,
            },
            Ok(Event::Outgoing(Outgoing::Disconnect)) => {
                let _ = tx.send(Net::Closed).await;
                return;
            }
            Ok(_) => continue,
            Err(e) => {
                if tx.send(Net::Lost(e.to_string())).await.is_err() {
                    return;
                }
                tokio::time::sleep(backoff.delay(failures, seed)).await;
                failures = failures.saturating_add(1);
                continue;
            }
        };
        if tx.send(net).await.is_err() {
            return;
        }
    }
}
