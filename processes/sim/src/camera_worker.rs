//! The downward camera on a thread of its own.
//!
//! A frame is captured at one instant but only needed at its publish time, 10-15 ms of
//! sensor latency later. A lockstep runner submits the view at capture time and collects
//! the image at publish time, so physics and the depth camera proceed on the other core
//! while the frame is drawn. Jobs are rendered one at a time, in order, by the same
//! `DownCamera`, so the images are exactly those of synchronous rendering.

use std::sync::mpsc;
use std::thread::JoinHandle;

use thiserror::Error;

use crate::camera::{BodyMotion, CameraError, DownCamera};
use crate::ground_vehicle::PadState;

/// Why the worker could not render.
#[derive(Debug, Error)]
pub enum WorkerError {
    /// The thread could not be started.
    #[error("camera worker: cannot start its thread: {0}")]
    Spawn(std::io::Error),
    /// The thread is gone (it panicked or was dropped).
    #[error("camera worker: the render thread stopped")]
    Stopped,
    /// `collect` was called with no job in flight.
    #[error("camera worker: nothing to collect")]
    Idle,
    /// Rendering failed.
    #[error(transparent)]
    Camera(#[from] CameraError),
}

struct Job {
    body: BodyMotion,
    pad: Option<PadState>,
    buf: Vec<u8>,
}

type Done = (Vec<u8>, Result<u32, CameraError>);

/// A `DownCamera` rendering on its own thread.
#[derive(Debug)]
pub struct CameraWorker {
    jobs: Option<mpsc::Sender<Job>>,
    done: mpsc::Receiver<Done>,
    thread: Option<JoinHandle<()>>,
    in_flight: usize,
    frame_len: usize,
}

impl CameraWorker {
    /// Moves `camera` onto a new thread.
    pub fn spawn(mut camera: DownCamera) -> Result<Self, WorkerError> {
        let frame_len = camera.frame_len();
        let (job_tx, job_rx) = mpsc::channel::<Job>();
        let (done_tx, done_rx) = mpsc::channel::<Done>();
        let thread = std::thread::Builder::new()
            .name("camera-render".into())
            .spawn(move || {
                for mut job in job_rx {
                    let r = camera.render_into(&job.body, job.pad.as_ref(), &mut job.buf);
                    if done_tx.send((job.buf, r)).is_err() {
                        break;
                    }
                }
            })
            .map_err(WorkerError::Spawn)?;
        Ok(Self {
            jobs: Some(job_tx),
            done: done_rx,
            thread: Some(thread),
            in_flight: 0,
            frame_len,
        })
    }

    /// Bytes of one frame: the size every submitted buffer is given.
    pub fn frame_len(&self) -> usize {
        self.frame_len
    }

    /// Frames submitted and not yet collected.
    pub fn in_flight(&self) -> usize {
        self.in_flight
    }

    /// Starts rendering the view `body` (and `pad`) into `buf`, which is resized to a
    /// frame; returns at once.
    pub fn submit(
        &mut self,
        body: BodyMotion,
        pad: Option<PadState>,
        mut buf: Vec<u8>,
    ) -> Result<(), WorkerError> {
        buf.resize(self.frame_len, 0);
        let jobs = self.jobs.as_ref().ok_or(WorkerError::Stopped)?;
        jobs.send(Job { body, pad, buf })
            .map_err(|_| WorkerError::Stopped)?;
        self.in_flight += 1;
        Ok(())
    }

    /// Waits for the oldest submitted frame; returns its buffer and the sub-exposures
    /// blended.
    pub fn collect(&mut self) -> Result<(Vec<u8>, u32), WorkerError> {
        if self.in_flight == 0 {
            return Err(WorkerError::Idle);
        }
        let (buf, r) = self.done.recv().map_err(|_| WorkerError::Stopped)?;
        self.in_flight -= 1;
        Ok((buf, r?))
    }
}

impl Drop for CameraWorker {
    fn drop(&mut self) {
        // Closing the job channel ends the thread's loop.
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
