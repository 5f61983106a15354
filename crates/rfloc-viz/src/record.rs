//! MCAP recordings.

use std::collections::BTreeMap;
use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use crate::hub::{Hub, Sink};
use crate::VizError;

type McapFile = mcap::Writer<BufWriter<File>>;

fn io_error(e: mcap::McapError) -> io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        other => io::Error::other(other),
    }
}

struct State {
    writer: Option<McapFile>,
    /// MCAP channel id of each channel of the table.
    channel_ids: Vec<u16>,
    /// Next sequence number of each channel.
    sequence: Vec<u32>,
    /// The first write error; the recording stops at it and `finish` reports it.
    error: Option<io::Error>,
}

struct McapSink {
    open: AtomicBool,
    state: Mutex<State>,
}

impl Sink for McapSink {
    fn wants(&self, _ch: usize) -> bool {
        self.open.load(Ordering::Relaxed)
    }

    fn write(&self, ch: usize, log_time: u64, data: &[u8]) {
        let mut guard = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let st = &mut *guard;
        let (Some(writer), Some(&channel_id), Some(seq)) = (
            st.writer.as_mut(),
            st.channel_ids.get(ch),
            st.sequence.get_mut(ch),
        ) else {
            return;
        };
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: *seq,
            log_time,
            publish_time: log_time,
        };
        *seq = seq.wrapping_add(1);
        if let Err(e) = writer.write_to_known_channel(&header, data) {
            tracing::warn!("MCAP recording stopped: {e}");
            st.error = Some(io_error(e));
            self.open.store(false, Ordering::Relaxed);
        }
    }
}

/// A running MCAP recording of every channel. [`Recording::finish`] writes the summary
/// (schemas, channels, statistics, indexes) and closes the file; dropping the recording does
/// the same but can only log a failure.
pub struct Recording {
    path: PathBuf,
    hub: Arc<Hub>,
    sink_id: u64,
    sink: Arc<McapSink>,
}

impl fmt::Debug for Recording {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Recording")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

pub(crate) fn start(hub: &Arc<Hub>, path: &Path) -> Result<Recording, VizError> {
    let err = |source| VizError::Record {
        path: path.to_path_buf(),
        source,
    };
    let file = File::create_new(path).map_err(err)?;
    let options = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .library(concat!("rfloc-viz ", env!("CARGO_PKG_VERSION")));
    let mut writer = options
        .create(BufWriter::new(file))
        .map_err(|e| err(io_error(e)))?;
    // Every channel goes into the file up front, so that a recording lists all of them even
    // when some stayed silent.
    let mut channel_ids = Vec::with_capacity(hub.channels.len());
    for c in &hub.channels {
        let schema_id = writer
            .add_schema(&c.schema_name, &c.schema_encoding, &c.schema)
            .map_err(|e| err(io_error(e)))?;
        let id = writer
            .add_channel(schema_id, c.topic, &c.encoding, &BTreeMap::new())
            .map_err(|e| err(io_error(e)))?;
        channel_ids.push(id);
    }
    let sink = Arc::new(McapSink {
        open: AtomicBool::new(true),
        state: Mutex::new(State {
            writer: Some(writer),
            sequence: vec![0; channel_ids.len()],
            channel_ids,
            error: None,
        }),
    });
    let sink_id = hub.add(sink.clone());
    Ok(Recording {
        path: path.to_path_buf(),
        hub: Arc::clone(hub),
        sink_id,
        sink,
    })
}

impl Recording {
    /// The file being written.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Closes the current chunk and writes buffered data to the file, so that the messages so
    /// far survive a crash (a reader then needs to scan the file: the summary comes at the end).
    ///
    /// # Errors
    /// [`VizError::Record`] on a write error, now or earlier.
    pub fn flush(&self) -> Result<(), VizError> {
        let mut st = self
            .sink
            .state
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some(e) = st.error.take() {
            return Err(VizError::Record {
                path: self.path.clone(),
                source: e,
            });
        }
        match st.writer.as_mut().map(McapFile::flush) {
            Some(Err(e)) => Err(VizError::Record {
                path: self.path.clone(),
                source: io_error(e),
            }),
            _ => Ok(()),
        }
    }

    /// Stops recording, writes the MCAP summary and closes the file (synced to disk); returns
    /// its path.
    ///
    /// # Errors
    /// [`VizError::Record`] on a write error, now or earlier.
    pub fn finish(self) -> Result<PathBuf, VizError> {
        self.close()
            .map(|()| self.path.clone())
            .map_err(|source| VizError::Record {
                path: self.path.clone(),
                source,
            })
    }

    fn close(&self) -> io::Result<()> {
        self.hub.remove(self.sink_id);
        self.sink.open.store(false, Ordering::Relaxed);
        let mut st = self
            .sink
            .state
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let Some(mut writer) = st.writer.take() else {
            return Ok(());
        };
        if let Some(e) = st.error.take() {
            return Err(e);
        }
        writer.finish().map_err(io_error)?;
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| e.into_error())?;
        file.sync_all()
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        if let Err(e) = self.close() {
            tracing::warn!(path = %self.path.display(), "MCAP recording not closed cleanly: {e}");
        }
    }
}
