//! Fan-out of encoded messages to the attached sinks.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, PoisonError, RwLock};

use foxglove::Encode;

use crate::channels::{table, Ch, ChannelInfo};
use crate::Stamp;

/// Where encoded messages go: a live server or a recording.
pub(crate) trait Sink: Send + Sync {
    /// Whether this sink would take a message on channel `ch` now (so that nothing is encoded
    /// for nobody).
    fn wants(&self, ch: usize) -> bool;
    /// Takes one encoded message. Must not block for long: no waiting on a network peer.
    fn write(&self, ch: usize, log_time: u64, data: &[u8]);
}

pub(crate) struct Hub {
    pub(crate) channels: Vec<ChannelInfo>,
    sinks: RwLock<Vec<(u64, Arc<dyn Sink>)>>,
    next_id: AtomicU64,
}

impl Hub {
    pub(crate) fn new() -> Self {
        Self {
            channels: table(),
            sinks: RwLock::new(Vec::new()),
            next_id: AtomicU64::new(1),
        }
    }

    pub(crate) fn add(&self, sink: Arc<dyn Sink>) -> u64 {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        self.sinks
            .write()
            .unwrap_or_else(PoisonError::into_inner)
            .push((id, sink));
        id
    }

    pub(crate) fn remove(&self, id: u64) {
        self.sinks
            .write()
            .unwrap_or_else(PoisonError::into_inner)
            .retain(|(i, _)| *i != id);
    }

    /// Whether any sink wants channel `ch`.
    pub(crate) fn wants(&self, ch: Ch) -> bool {
        self.sinks
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .any(|(_, s)| s.wants(ch.index()))
    }

    /// Builds the message (only when a sink wants it), encodes it once and hands it to every
    /// sink that wants it, with the measurement time as log time.
    pub(crate) fn deliver<T: Encode>(&self, ch: Ch, stamp: Stamp, make: impl FnOnce() -> T) {
        let sinks = self.sinks.read().unwrap_or_else(PoisonError::into_inner);
        let wanted: Vec<&Arc<dyn Sink>> = sinks
            .iter()
            .map(|(_, s)| s)
            .filter(|s| s.wants(ch.index()))
            .collect();
        if wanted.is_empty() {
            return;
        }
        let msg = make();
        let mut data = Vec::with_capacity(msg.encoded_len().unwrap_or(256));
        if let Err(e) = msg.encode(&mut data) {
            // A Vec grows as needed, so this does not happen; if it did, skip the message.
            tracing::warn!(
                topic = self.channels.get(ch.index()).map(|c| c.topic),
                "encoding failed: {e}"
            );
            return;
        }
        for s in wanted {
            s.write(ch.index(), stamp.unix_nanos(), &data);
        }
    }
}
