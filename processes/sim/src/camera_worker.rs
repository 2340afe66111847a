//! The downward camera on a thread of its own.
//!
//! A frame is captured at one instant but only needed at its publish time, 10-15 ms of
//! sensor latency later. A lockstep runner submits the view at capture time and collects
//! the image at publish time, so physics and the depth camera proceed on the other core
//! while the frame is drawn. Jobs are rendered one at a time, in order, by the same
//! `DownCamera`, so the images are exactly those of synchronous rendering.

use std::collections::VecDeque;
use std::sync::mpsc;
use std::thread::JoinHandle;

use thiserror::Error;

use crate::camera::{BodyMotion, CameraError, DownCamera};
use crate::ground_vehicle::PadState;
use crate::lockstep::{Shot, Simulator, StepReport};

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

/// The downward camera of a lockstep [`Simulator`] on its worker: submits the view when a
/// frame is due and hands the image back at its publish time (capture + sensor latency),
/// in order. This is how a lockstep runner should drive the camera.
#[derive(Debug)]
pub struct CameraPipeline {
    worker: CameraWorker,
    latency_ns: u64,
    pending: VecDeque<Shot>,
    spare: Vec<Vec<u8>>,
}

impl CameraPipeline {
    /// Moves `sim`'s downward camera onto a worker; `None` when it has no camera.
    pub fn from_simulator(sim: &mut Simulator) -> Result<Option<Self>, WorkerError> {
        let Some(camera) = sim.take_down_camera() else {
            return Ok(None);
        };
        let latency_ns = (camera.params().latency_s.max(0.0) * 1e9) as u64;
        Ok(Some(Self {
            worker: CameraWorker::spawn(camera)?,
            latency_ns,
            pending: VecDeque::new(),
            spare: Vec::new(),
        }))
    }

    /// Call after every [`Simulator::step`]: frames whose publish time has come (or that
    /// must go before the next one is drawn) are pushed to `ready`; a due frame is started.
    pub fn on_step(
        &mut self,
        sim: &Simulator,
        report: &StepReport,
        ready: &mut Vec<(Vec<u8>, Shot)>,
    ) -> Result<(), WorkerError> {
        let now = sim.time_ns();
        while let Some(&shot) = self.pending.front() {
            if shot.publish_ns > now && !report.camera_due {
                break;
            }
            self.pending.pop_front();
            let (buf, blur_samples) = self.worker.collect()?;
            ready.push((
                buf,
                Shot {
                    blur_samples,
                    ..shot
                },
            ));
        }
        if report.camera_due {
            let (body, pad) = sim.camera_view();
            self.worker
                .submit(body, pad, self.spare.pop().unwrap_or_default())?;
            self.pending.push_back(Shot {
                capture_ns: now,
                publish_ns: now + self.latency_ns,
                blur_samples: 0,
            });
        }
        Ok(())
    }

    /// Gives a consumed frame's buffer back, so rendering does not allocate.
    pub fn recycle(&mut self, buf: Vec<u8>) {
        self.spare.push(buf);
    }

    /// Waits for every frame still in flight (end of a run).
    pub fn drain(&mut self, ready: &mut Vec<(Vec<u8>, Shot)>) -> Result<(), WorkerError> {
        while let Some(shot) = self.pending.pop_front() {
            let (buf, blur_samples) = self.worker.collect()?;
            ready.push((
                buf,
                Shot {
                    blur_samples,
                    ..shot
                },
            ));
        }
        Ok(())
    }
}
