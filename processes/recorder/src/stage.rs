//! The recorder as a stage: every input into the recording at the time it was handed
//! over, a flush on the stage's clock when inputs stop. It publishes nothing.

use stage::{Counter, Input, Outbox, Stage, StageError};

use crate::writer::{RecordError, Recorder};

/// How often the recorder's clock looks at the flush period when no input comes.
const TICK_NS: u64 = 250_000_000;

/// Records what the driver hands over.
pub struct RecorderStage {
    recorder: Option<Recorder>,
    inputs: u64,
}

impl RecorderStage {
    /// A stage writing into `recorder` (outside the crate: `from_config`).
    pub(crate) fn new(recorder: Recorder) -> Self {
        Self {
            recorder: Some(recorder),
            inputs: 0,
        }
    }

    /// The recording, to add metadata to.
    pub fn recorder(&mut self) -> Option<&mut Recorder> {
        self.recorder.as_mut()
    }

    /// Finishes the file (summary and index); returns the messages written.
    pub fn finish(&mut self) -> Result<u64, RecordError> {
        match self.recorder.take() {
            Some(r) => r.finish(),
            None => Ok(0),
        }
    }
}

fn failed(e: RecordError) -> StageError {
    StageError::Failed(e.to_string())
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
        match &mut self.recorder {
            Some(r) => r.record(input.topic, now_ns, &input.msg).map_err(failed),
            None => Ok(()),
        }
    }

    fn on_tick(&mut self, now_ns: u64, _out: &mut dyn Outbox) -> Result<(), StageError> {
        match &mut self.recorder {
            Some(r) => r.tick(now_ns).map_err(failed),
            None => Ok(()),
        }
    }

    fn counters(&self) -> Vec<Counter> {
        let written = self.recorder.as_ref().map_or(0, |r| r.message_count());
        vec![("inputs", self.inputs), ("written", written)]
    }
}
