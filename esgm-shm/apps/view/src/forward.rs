//! One watched trajectory: a thread that subscribes to it while Foxglove does, and logs
//! each structure on the trajectory's channel at its valid time.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use std::collections::HashMap;

use esgm_core::esgm::trace_with;
use esgm_core::store::RecvError;
use esgm_core::{EntityTrajectoryStructure, Esgm, InProcessTrajectory, SubscribeOptions};
use esgm_shm::ShmEsgm;
use foxglove::{PartialMetadata, RawChannel};

use crate::encoding::Encoding;

/// How often a forwarder looks at its stop flag while nothing arrives.
const POLL: Duration = Duration::from_millis(100);

/// What forwarders report to the server: the latest valid time sent (Foxglove's time)
/// and the messages sent, dropped for not fitting the view.
#[derive(Debug, Default)]
pub struct Counters {
    /// The latest valid time forwarded, ns (0 before the first).
    pub latest_valid_time: AtomicU64,
    /// Messages logged.
    pub sent: AtomicU64,
    /// Structures that could not be encoded (logged once per forwarder).
    pub unencodable: AtomicU64,
}

/// What a channel shows of its trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shown {
    /// Its structures, in this encoding (topic `/<trajectory>`).
    Structures(Encoding),
    /// Each structure's trace: the inputs it was made from, hop by hop (topic
    /// `/<trajectory>/trace`, [`crate::trace_view`]).
    Trace,
}

/// A running forwarder; dropping it stops the thread and closes the subscription.
#[derive(Debug)]
pub struct Forwarder {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Forwarder {
    /// Starts forwarding `trajectory` onto `channel`, beginning with its latest sample.
    pub fn start(
        esgm: ShmEsgm,
        trajectory: String,
        shown: Shown,
        channel: Arc<RawChannel>,
        counters: Arc<Counters>,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(format!("esgm-view-{trajectory}"))
            .spawn(move || run(&esgm, &trajectory, shown, &channel, &counters, &flag));
        let thread = match thread {
            Ok(t) => Some(t),
            Err(e) => {
                tracing::error!("cannot start a forwarding thread: {e}");
                None
            }
        };
        Self { stop, thread }
    }
}

impl Forwarder {
    /// Tells the thread to stop: nothing is logged after this returns, even before the
    /// thread has ended (dropping the forwarder waits for that).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }
}

impl Drop for Forwarder {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // The thread only ends its loop; a panic in it was already reported.
        if let Some(t) = self.thread.take()
            && t.join().is_err()
        {
            tracing::error!("a forwarding thread panicked");
        }
    }
}

fn run(
    esgm: &ShmEsgm,
    name: &str,
    shown: Shown,
    channel: &RawChannel,
    counters: &Counters,
    stop: &AtomicBool,
) {
    let span = tracing::info_span!("forward", trajectory = %name);
    let _entered = span.enter();
    let t = match esgm.get_entity_trajectory_structure(name) {
        Ok(t) => t,
        Err(e) => {
            tracing::warn!("not forwarded: {e}");
            return;
        }
    };
    let sub = match t.subscribe(SubscribeOptions::default().last(1)) {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!("not forwarded: {e}");
            return;
        }
    };
    let mut buf = Vec::new();
    // A trace's input trajectories, opened once (their replicas fill as they come).
    let mut handles: HashMap<String, Option<InProcessTrajectory>> =
        HashMap::from([(name.to_owned(), Some(t.clone()))]);
    while !stop.load(Ordering::Acquire) {
        let sample = match sub.recv_timeout(POLL) {
            Ok(s) => s,
            Err(RecvError::Timeout) => continue,
            Err(e) => {
                tracing::info!("subscription ended: {e}");
                return;
            }
        };
        if stop.load(Ordering::Acquire) {
            return;
        }
        buf.clear();
        let es = &sample.structure;
        let encoded = match shown {
            // Foxglove's encodings are made of owned values: an archived structure is
            // converted for them (its pixels stay where they are).
            Shown::Structures(encoding) => {
                encoding.encode(&es.to_arc(), name, &mut buf).map_err(|e| e.to_string())
            }
            Shown::Trace => {
                let open = |input: &str| {
                    handles
                        .entry(input.to_owned())
                        .or_insert_with(|| esgm.get_entity_trajectory_structure(input).ok())
                        .clone()
                };
                let tree = trace_with(open, name, &sample);
                crate::trace_view::encode(&tree, &mut buf).map_err(|e| e.to_string())
            }
        };
        if let Err(e) = encoded {
            if counters.unencodable.fetch_add(1, Ordering::Relaxed) == 0 {
                tracing::warn!("a structure does not fit its Foxglove view (counted): {e}");
            }
            continue;
        }
        // Foxglove's times are unsigned: a valid time before 1970 is shown at 0.
        let valid = u64::try_from(es.valid_time()).unwrap_or(0);
        channel.log_with_meta(&buf, PartialMetadata { log_time: Some(valid) });
        counters.sent.fetch_add(1, Ordering::Relaxed);
        counters.latest_valid_time.fetch_max(valid, Ordering::Relaxed);
    }
}
