//! The client against the emulator over a real pty (`tokio_serial::SerialStream::pair()`).
#![allow(clippy::expect_used)] // test helper outside #[test] fns

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_kts::{
    EmulatorConfig, KtsClient, KtsClientError, KtsCommand, KtsConfig, KtsEmulator, TagEventKind,
    TagEventSource, TagGrid,
};
use rfloc_transport::MonotonicClock;
use tokio::time::timeout;

fn pty() -> (tokio_serial::SerialStream, tokio_serial::SerialStream) {
    tokio_serial::SerialStream::pair().expect("pty pair")
}

#[tokio::test]
async fn identify_scan_and_stop_over_a_pty() {
    let (host, device) = pty();
    // Seed 002 start pose (200, 200) mm, heading 0, antenna 100 mm behind the centre.
    let antenna = Arc::new(Mutex::new((0.1, 0.2)));
    let a = Arc::clone(&antenna);
    let mut cfg = EmulatorConfig::new(
        TagGrid::seed002_test_field(),
        Arc::new(move || *a.lock().unwrap()),
    );
    cfg.time_scale = 5.0; // 20 ms scans
    let emu = KtsEmulator::new(cfg).spawn(device);
    let mut client = KtsClient::spawn(host, KtsConfig::default(), MonotonicClock::shared());

    let ident = client.identify().await.unwrap();
    assert_eq!(ident, ["rfloc KTS RFIDM1356 emulator", "S/N 0000000001"]);
    client.resync().await.unwrap();
    let err = client
        .command(KtsCommand::Raw("AT+Bogus".into()))
        .await
        .unwrap_err();
    assert!(
        matches!(err, KtsClientError::Device { cme: None, .. }),
        "{err:?}"
    );

    client.start_scan().await.unwrap();
    let mut seen = std::collections::BTreeMap::new();
    while seen.len() < 4 {
        let ev = timeout(Duration::from_secs(2), client.next_event())
            .await
            .unwrap()
            .unwrap();
        if let TagEventKind::Seen { rssi: Some(r) } = ev.kind {
            seen.insert(ev.uid.short_id(3).unwrap(), r.main);
        }
    }
    // Antenna over tag …691 at (100, 200) mm: RSSI 7; the tags 10 cm away read 0
    // (seed 002 Table 4: 0 up to 14 cm, 7 below 2.8 cm).
    assert_eq!(seen.get(&0x691), Some(&7));
    for far in [0xBF4, 0x78D, 0x785] {
        assert_eq!(seen.get(&far), Some(&0), "{far:X}");
    }

    // Move the antenna over …ADC at (200, 100) mm: …691 leaves the field (lost event).
    *antenna.lock().unwrap() = (0.2, 0.1);
    let mut lost_691 = false;
    let mut adc_7 = false;
    while !(lost_691 && adc_7) {
        let ev = timeout(Duration::from_secs(2), client.next_event())
            .await
            .unwrap()
            .unwrap();
        match ev.kind {
            TagEventKind::Lost if ev.uid.short_id(3) == Some(0x691) => lost_691 = true,
            TagEventKind::Seen { rssi: Some(r) } if ev.uid.short_id(3) == Some(0xADC) => {
                adc_7 |= r.main == 7;
            }
            _ => {}
        }
    }

    client.stop_scan().await.unwrap();
    let s = client.stats();
    assert_eq!(s.codec.malformed, 0);
    assert!(s.events_sent > 8);
    drop(client);
    emu.abort();
}

#[tokio::test]
async fn silence_while_scanning_triggers_resync() {
    // A device that answers OK to everything but never reports tags: the client must resync
    // with AT and re-send the scan command after the silence timeout.
    let (host, mut device) = pty();
    let config = KtsConfig {
        silence_timeout: Some(Duration::from_millis(150)),
        ..KtsConfig::default()
    };
    let client = KtsClient::spawn(host, config, MonotonicClock::shared());
    let dev = tokio::spawn(async move {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let mut got = Vec::new();
        let mut buf = [0u8; 64];
        while got
            .windows(b"AT+Scan=AC,RSSI\r".len())
            .filter(|w| w == b"AT+Scan=AC,RSSI\r")
            .count()
            < 2
        {
            let n = device.read(&mut buf).await.unwrap();
            got.extend_from_slice(&buf[..n]);
            for _ in buf[..n].iter().filter(|b| **b == b'\r') {
                device.write_all(b"OK\r\n").await.unwrap();
            }
        }
        got
    });
    client.start_scan().await.unwrap();
    let got = timeout(Duration::from_secs(3), dev).await.unwrap().unwrap();
    assert_eq!(
        String::from_utf8(got).unwrap(),
        "AT+Scan=AC,RSSI\rAT\rAT+Scan=AC,RSSI\r"
    );
    assert_eq!(client.stats().resyncs, 1);
}

#[tokio::test]
async fn command_timeout_is_typed() {
    let (host, _device) = pty();
    let config = KtsConfig {
        command_timeout: Duration::from_millis(100),
        ..KtsConfig::default()
    };
    let client = KtsClient::spawn(host, config, MonotonicClock::shared());
    assert_eq!(
        client.resync().await,
        Err(KtsClientError::Timeout("AT".into()))
    );
}

/// Waits until the client has read `target` bytes.
async fn read_all(sink: &rfloc_transport::CaptureSink, target: u64) {
    timeout(Duration::from_secs(5), async {
        while sink.rx_bytes() < target {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    })
    .await
    .expect("the client read everything the emulator wrote");
    assert_eq!(sink.rx_bytes(), target);
}

/// One lock-step session over a pty: scanning on, the antenna moved in 1 cm steps across the
/// field, one scan per step once the emulator has read every byte the client wrote (counted by
/// a capture sink), every event of a scan received before the next. Returns the events.
async fn lock_step_session() -> Vec<String> {
    let (host, device) = pty();
    let antenna = Arc::new(Mutex::new((0.0, 0.1)));
    let a = Arc::clone(&antenna);
    let mut cfg = EmulatorConfig::new(
        TagGrid::seed002_test_field(),
        Arc::new(move || *a.lock().expect("antenna")),
    );
    cfg.seed = 9;
    cfg.miss_probability = 0.2;
    let mut emu = KtsEmulator::new(cfg);
    let control = emu.lock_step();
    let _task = emu.spawn(device);
    let clock = rfloc_transport::ManualClock::new();
    let sink = rfloc_transport::CaptureSink::from_writer(
        Box::new(std::io::sink()),
        &rfloc_capture::Header::new("kts", "pty"),
        clock.clone(),
    )
    .expect("sink");
    let io = rfloc_transport::Recorder::new(host, sink.clone());
    let mut client = KtsClient::spawn(io, KtsConfig::default(), clock.clone());
    let mut events = client.take_events().expect("events");
    client.start_scan().await.expect("scan on");
    // The `OK` is fully read before the first scan.
    let settled = control.settle(sink.tx_bytes()).await.expect("settle");
    assert_eq!(settled.lines, 0);
    read_all(&sink, settled.tx_bytes).await;
    let mut out = Vec::new();
    for k in 0..30u32 {
        *antenna.lock().expect("antenna") = (f64::from(k) * 0.01, 0.1);
        clock.set_ns(u64::from(k) * 100_000_000);
        let step = timeout(Duration::from_secs(5), control.scan(sink.tx_bytes()))
            .await
            .expect("scan in time")
            .expect("emulator serving");
        for _ in 0..step.lines {
            let ev = timeout(Duration::from_secs(5), events.recv())
                .await
                .expect("event in time")
                .expect("event");
            out.push(ev.to_string());
        }
        // The client reads all of it (an event is out at a line's `\r`, its `\n` may come in
        // a later read), and nothing beyond what the scan reported arrives.
        read_all(&sink, step.tx_bytes).await;
        assert!(events.try_recv().is_err());
    }
    client.stop_scan().await.expect("scan off");
    out
}

#[tokio::test]
async fn lock_step_scans_are_reproducible() {
    let a = lock_step_session().await;
    let b = lock_step_session().await;
    assert_eq!(a, b);
    // The antenna crossed the row: tags were seen and lost, each event at its scan's time.
    assert!(a.iter().any(|e| e.contains(" seen ")), "{a:?}");
    assert!(a.iter().any(|e| e.contains(" lost ")), "{a:?}");
    assert!(a.iter().any(|e| e.starts_with("2.900000")), "{a:?}");
}
