//! The recorder as a stage: every input into the recording at the time it was handed
//! over, a flush on the stage's clock when inputs stop. It publishes nothing.
//!
//! The driver's thread only copies each input into a queue; a writer thread of the stage
//! encodes (JPEG, JSON, the chunks' compression) and writes. The subscriber buffers are 4
//! frames or maps deep (133 ms at 30 Hz): a recorder that encoded in the driver's thread
//! fell that far behind on a loaded machine and lost maps (3 in one flight of `make
//! test`, up to 12 beside two other flights), and a replay cannot follow a map it lost. A
//! copy is short, so the reading thread keeps up; the writer catches up from the queue.

use std::borrow::Cow;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use ipc_types::topics;
use stage::{Counter, Input, Outbox, OwnedMessage, Stage, StageError};

use crate::writer::{RecordError, Recorder};

/// How often the recorder's clock looks at the flush period when no input comes.
const TICK_NS: u64 = 250_000_000;

/// Inputs waiting for the writer: about 1.5 s of every topic (30 Hz camera frames,
/// depth frames and maps are ~100 of them, at most ~60 MB at 640 x 480); when full the
/// reading thread waits, as it did before the writer had a thread.
const QUEUE: usize = 512;

/// What the writer thread is given.
enum Job {
    Record {
        /// The stack's own name for it (no allocation); a topic it does not know, copied.
        topic: Cow<'static, str>,
        log_time_ns: u64,
        /// Boxed: a message is up to ~700 bytes besides its pixels, a tick 8.
        msg: Box<OwnedMessage>,
    },
    Tick(u64),
}

/// Records what the driver hands over.
pub struct RecorderStage {
    queue: Option<SyncSender<Job>>,
    writer: Option<JoinHandle<Result<Recorder, RecordError>>>,
    inputs: u64,
    /// Inputs that found the queue full and waited for the writer.
    waited: u64,
}

impl RecorderStage {
    /// A stage writing into `recorder` (outside the crate: `from_config`) from a writer
    /// thread.
    pub(crate) fn new(recorder: Recorder) -> Result<Self, std::io::Error> {
        let (tx, rx) = sync_channel(QUEUE);
        let writer = std::thread::Builder::new()
            .name("recorder-writer".into())
            .spawn(move || write_all(recorder, &rx))?;
        Ok(Self {
            queue: Some(tx),
            writer: Some(writer),
            inputs: 0,
            waited: 0,
        })
    }

    /// Finishes the file (summary and index) once the writer has written everything
    /// queued; returns the messages written.
    pub fn finish(&mut self) -> Result<u64, RecordError> {
        self.queue = None;
        match self.writer.take().map(JoinHandle::join) {
            Some(Ok(r)) => r?.finish(),
            Some(Err(_)) => Err(RecordError::WriterPanicked),
            None => Ok(0),
        }
    }

    /// Hands `job` to the writer; when the writer stopped on an error, that error.
    fn send(&mut self, job: Job) -> Result<(), StageError> {
        let Some(tx) = &self.queue else {
            return Ok(());
        };
        let job = match tx.try_send(job) {
            Ok(()) => return Ok(()),
            Err(TrySendError::Full(job)) => job,
            Err(TrySendError::Disconnected(_)) => return Err(self.writer_error()),
        };
        self.waited += 1;
        match tx.send(job) {
            Ok(()) => Ok(()),
            Err(_) => Err(self.writer_error()),
        }
    }

    /// Why the writer thread ended early.
    fn writer_error(&mut self) -> StageError {
        self.queue = None;
        let e = match self.writer.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => e,
            _ => RecordError::WriterPanicked,
        };
        StageError::Failed(e.to_string())
    }
}

/// The writer thread: every job in order, until the stage drops its end of the queue or
/// a write fails.
fn write_all(mut recorder: Recorder, jobs: &Receiver<Job>) -> Result<Recorder, RecordError> {
    for job in jobs {
        match job {
            Job::Record {
                topic,
                log_time_ns,
                msg,
            } => recorder.record(&topic, log_time_ns, &msg.as_message())?,
            Job::Tick(now_ns) => recorder.tick(now_ns)?,
        }
    }
    Ok(recorder)
}

impl Stage for RecorderStage {
    fn name(&self) -> &'static str {
        "recorder"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(TICK_NS)
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        self.inputs += 1;
        self.send(Job::Record {
            topic: topics::find(input.topic).map_or_else(
                || Cow::Owned(input.topic.to_string()),
                |t| Cow::Borrowed(t.name),
            ),
            log_time_ns: now_ns,
            msg: Box::new(input.msg.to_owned()),
        })
    }

    fn on_tick(&mut self, now_ns: u64, _out: &mut dyn Outbox) -> Result<(), StageError> {
        self.send(Job::Tick(now_ns))
    }

    fn counters(&self) -> Vec<Counter> {
        vec![("inputs", self.inputs), ("waited_for_writer", self.waited)]
    }
}
