//! A [`ShmTrajectoryReader`] on a thread of its own, answering queries from any thread.
//!
//! iceoryx2 ports belong to the thread that made them, so a reader cannot be shared.
//! [`HostedTrajectoryReader`] is the shareable form (`Send + Sync + Clone`, what a
//! trajectory handle needs): its thread owns a node and the reader, takes samples into
//! the history every poll interval and before every query, and runs queries sent to it
//! over a channel. Answers leave the thread, so they are owned [`Sample`]s: decoded,
//! i.e. copied. For zero-copy reads use a [`ShmTrajectoryReader`] on your own thread.
//!
//! The poll interval only bounds how long samples wait in the reader's iceoryx2 queue
//! (a query always sees everything delivered before it): the queue must hold what
//! arrives in one interval. The default, [`DEFAULT_POLL`] = 1 ms, covers 8 kHz with
//! the default queue of 8 and costs about a thousand short wake-ups a second while idle.

use crate::service::ShmService;
use std::sync::Arc;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::Duration;

use esgm_core::{Sample, Time, ValueApproximation};
use iceoryx2::node::NodeCreationFailure;
use iceoryx2::prelude::NodeBuilder;

use crate::reader::{
    CachedSample, HistoryError, ReaderCreateError, ReaderStats, ShmTrajectoryReader,
    ShmTrajectoryReaderBuilder,
};

/// How often [`HostedTrajectoryReader`]'s thread takes samples in when no query comes.
pub const DEFAULT_POLL: Duration = Duration::from_millis(1);

/// A hosted reader could not be started.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HostError {
    /// The operating system refused a thread.
    #[error("cannot start the reader thread: {0}")]
    Spawn(#[source] std::io::Error),
    /// The thread's iceoryx2 node could not be created (see iceoryx2's reason).
    #[error("cannot create the reader thread's iceoryx2 node: {0:?}")]
    Node(NodeCreationFailure),
    /// The reader could not be created.
    #[error(transparent)]
    Create(#[from] ReaderCreateError),
    /// The thread ended before it reported (it panicked); see the log.
    #[error("the reader thread ended before it started")]
    Stopped,
}

type Job = Box<dyn FnOnce(&mut ShmTrajectoryReader) + Send>;

enum Request {
    Run(Job),
    Stop,
}

/// How long a caller waits for the reader's thread to run its job.
const JOB_DEADLINE: std::time::Duration = std::time::Duration::from_secs(30);

#[derive(Debug)]
struct Host {
    trajectory: String,
    requests: Sender<Request>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for Host {
    fn drop(&mut self) {
        let _ = self.requests.send(Request::Stop);
        if let Some(t) = self.thread.take() {
            // A job dropping the last handle runs on the thread itself: no self-join.
            if t.thread().id() != std::thread::current().id() {
                let _ = t.join();
            }
        }
    }
}

/// A trajectory reader with history on a thread of its own (see the module docs). The
/// thread stops when the last clone is dropped.
#[derive(Debug, Clone)]
pub struct HostedTrajectoryReader {
    host: Arc<Host>,
}

impl HostedTrajectoryReader {
    /// Starts a thread with its own iceoryx2 node and the reader `builder` makes, taking
    /// samples in every [`DEFAULT_POLL`].
    pub fn spawn(builder: ShmTrajectoryReaderBuilder) -> Result<Self, HostError> {
        Self::spawn_with_poll(builder, DEFAULT_POLL)
    }

    /// [`Self::spawn`] with another poll interval (see the module docs).
    pub fn spawn_with_poll(
        builder: ShmTrajectoryReaderBuilder,
        poll: Duration,
    ) -> Result<Self, HostError> {
        let trajectory = builder.name().to_owned();
        let (requests, inbox) = mpsc::channel();
        let (ready, started) = mpsc::sync_channel(1);
        let thread = std::thread::Builder::new()
            .name(format!("esgm-reader-{trajectory}"))
            .spawn(move || {
                let node = match NodeBuilder::new().create::<ShmService>() {
                    Ok(node) => node,
                    Err(e) => {
                        let _ = ready.send(Err(HostError::Node(e)));
                        return;
                    }
                };
                match builder.create(&node) {
                    Ok(mut reader) => {
                        let _ = ready.send(Ok(()));
                        serve(&mut reader, &inbox, poll);
                    }
                    Err(e) => {
                        let _ = ready.send(Err(e.into()));
                    }
                }
            })
            .map_err(HostError::Spawn)?;
        let host = Host { trajectory, requests, thread: Some(thread) };
        // The thread reports once, right after creating the reader (or dies trying,
        // which disconnects the channel): no timeout needed.
        started.recv().map_err(|_| HostError::Stopped)??;
        Ok(Self { host: Arc::new(host) })
    }

    /// The trajectory's name.
    pub fn name(&self) -> &str {
        &self.host.trajectory
    }

    /// Runs `f` on the reader's thread, after taking waiting samples in, and returns
    /// its result: any query, including zero-copy ones whose result `f` reduces to an
    /// owned value.
    pub fn with<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut ShmTrajectoryReader) -> R + Send + 'static,
    ) -> Result<R, HistoryError> {
        let stopped = || HistoryError::ReaderStopped { trajectory: self.host.trajectory.clone() };
        if self.host.thread.as_ref().is_some_and(|t| t.thread().id() == std::thread::current().id())
        {
            return Err(HistoryError::Reentrant { trajectory: self.host.trajectory.clone() });
        }
        let (reply, answer) = mpsc::sync_channel(1);
        let job: Job = Box::new(move |reader| {
            let _ = reply.send(f(reader));
        });
        self.host.requests.send(Request::Run(job)).map_err(|_| stopped())?;
        // The thread runs the job or drops it on its way out (disconnecting the reply);
        // a deadline still bounds the wait for a job that never ends.
        answer.recv_timeout(JOB_DEADLINE).map_err(|e| match e {
            mpsc::RecvTimeoutError::Timeout => HistoryError::Timeout {
                trajectory: self.host.trajectory.clone(),
                timeout: JOB_DEADLINE,
            },
            mpsc::RecvTimeoutError::Disconnected => stopped(),
        })
    }

    /// Samples stored.
    pub fn len(&self) -> Result<usize, HistoryError> {
        self.with(|r| r.len())
    }

    /// True if no sample is stored.
    pub fn is_empty(&self) -> Result<bool, HistoryError> {
        self.with(|r| r.is_empty())
    }

    /// The reader's statistics.
    pub fn stats(&self) -> Result<ReaderStats, HistoryError> {
        self.with(|r| r.stats())
    }

    /// [`ShmTrajectoryReader::get_latest`], owned.
    pub fn get_latest(&self) -> Result<Sample, HistoryError> {
        self.with(|r| owned(r, r.get_latest()?))?
    }

    /// [`ShmTrajectoryReader::get_nth_latest`], owned.
    pub fn get_nth_latest(&self, n: usize) -> Result<Sample, HistoryError> {
        self.with(move |r| owned(r, r.get_nth_latest(n)?))?
    }

    /// [`ShmTrajectoryReader::get_between`], owned.
    pub fn get_between(&self, from: Time, to: Time) -> Result<Vec<Sample>, HistoryError> {
        self.with(move |r| r.get_between(from, to).into_iter().map(|s| owned(r, s)).collect())?
    }

    /// [`ShmTrajectoryReader::get_at`], owned.
    pub fn get_at(&self, t: Time) -> Result<Sample, HistoryError> {
        self.with(move |r| owned(r, r.get_at(t)?))?
    }

    /// [`ShmTrajectoryReader::get_closest_at_or_before`], owned.
    pub fn get_closest_at_or_before(&self, t: Time) -> Result<Sample, HistoryError> {
        self.with(move |r| owned(r, r.get_closest_at_or_before(t)?))?
    }

    /// [`ShmTrajectoryReader::get_at_approximating`], owned.
    pub fn get_at_approximating(
        &self,
        t: Time,
        aprx: &ValueApproximation,
    ) -> Result<Sample, HistoryError> {
        let aprx = aprx.clone();
        self.with(move |r| {
            r.get_at_approximating(t, &aprx)?
                .to_sample()
                .map_err(|source| HistoryError::Decode { trajectory: r.name().to_owned(), source })
        })?
    }

    /// [`ShmTrajectoryReader::start_time`].
    pub fn start_time(&self) -> Result<Time, HistoryError> {
        Ok(self.with(|r| r.start_time())??)
    }

    /// [`ShmTrajectoryReader::end_time`].
    pub fn end_time(&self) -> Result<Time, HistoryError> {
        Ok(self.with(|r| r.end_time())??)
    }
}

fn owned(r: &ShmTrajectoryReader, s: CachedSample<'_>) -> Result<Sample, HistoryError> {
    s.to_sample().map_err(|source| HistoryError::Decode { trajectory: r.name().to_owned(), source })
}

/// The thread's loop: take samples in, run queries, until told to stop.
fn serve(reader: &mut ShmTrajectoryReader, inbox: &Receiver<Request>, poll: Duration) {
    let mut failures = 0u64;
    let mut update = |reader: &mut ShmTrajectoryReader| {
        if let Err(e) = reader.update() {
            failures += 1;
            if failures == 1 {
                tracing::warn!(trajectory = %reader.name(), error = %e,
                    "cannot take samples in (later failures are not logged)");
            }
        }
    };
    loop {
        match inbox.recv_timeout(poll) {
            Ok(Request::Run(job)) => {
                update(reader);
                job(reader);
            }
            Ok(Request::Stop) | Err(RecvTimeoutError::Disconnected) => return,
            Err(RecvTimeoutError::Timeout) => update(reader),
        }
    }
}
