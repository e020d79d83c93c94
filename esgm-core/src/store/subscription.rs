//! Subscriptions (T3): every structure added after subscribing, in add order.
//!
//! Each subscriber has its own bounded channel. The writer never blocks on a slow
//! subscriber: when a subscriber's buffer is full, its oldest undelivered sample is
//! discarded to make room (a controller wants the freshest data) and the overflow is
//! counted, for the subscriber and in the trajectory's stats.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TryRecvError, TrySendError};

/// Identifies one subscription of one trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SubscriptionId(pub u64);

/// How to subscribe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SubscribeOptions {
    /// Deliver the last `n` stored samples first (a late joiner catching up).
    pub last: usize,
    /// Buffer capacity before the oldest undelivered sample is discarded.
    pub capacity: usize,
}

impl Default for SubscribeOptions {
    fn default() -> Self {
        Self { last: 0, capacity: 1024 }
    }
}

impl SubscribeOptions {
    /// Builder form: replay the last `n` samples first.
    #[must_use]
    pub fn last(mut self, n: usize) -> Self {
        self.last = n;
        self
    }
    /// Builder form: buffer capacity (at least 1).
    #[must_use]
    pub fn capacity(mut self, n: usize) -> Self {
        self.capacity = n.max(1);
        self
    }
}

/// How a store fed from elsewhere — a replica of a trajectory another process writes —
/// lets its subscribers wait for the writer themselves.
///
/// Why: a sample from another process otherwise wakes a thread that feeds the replica,
/// which then wakes the subscriber's thread: two wake-ups, each tens of microseconds.
/// A subscriber that waits on the writer's own wake-up and feeds the replica itself
/// is woken once.
pub trait ReplicaFeed: Send + Sync + std::fmt::Debug + 'static {
    /// A waiter for one subscription; `None` if none can be made now (the subscription
    /// then waits on its channel, fed by the runtime).
    fn waiter(&self) -> Option<Box<dyn FeedWaiter>>;

    /// A waiter for a runtime's worker (a unit's or operator's input loop), which,
    /// unlike a user's subscription, always comes back to wait: the transport may
    /// leave the replica's feeding to it while it waits. The default is
    /// [`ReplicaFeed::waiter`].
    fn worker_waiter(&self) -> Option<Box<dyn FeedWaiter>> {
        self.waiter()
    }
}

/// One subscription's way to wait for a replica's writer (see [`ReplicaFeed`]).
pub trait FeedWaiter: Send + 'static {
    /// Takes into the replica everything its writer published that nobody took yet
    /// (so it reaches every subscriber's channel, this one's included).
    fn feed(&mut self);
    /// Sleeps until the writer publishes again (or did since the last wait), at most
    /// `timeout`, then feeds. Returns false if it could not wait (the caller then
    /// waits on its channel).
    fn wait_and_feed(&mut self, timeout: Duration) -> bool;

    /// This waiter and `others` (the other inputs' waiters of one worker) as one waiter
    /// that sleeps until any of their writers publishes: a unit with several inputs
    /// from other processes waits on all of them itself and is woken once, with no
    /// thread between the writers' wake-ups and its `compute`. `None` where the
    /// transport cannot join them: the worker then waits on its channel, fed by the
    /// runtime.
    fn join(self: Box<Self>, others: Vec<Box<dyn FeedWaiter>>) -> Option<Box<dyn FeedWaiter>>;

    /// This waiter as `Any`, for a transport's [`FeedWaiter::join`] to find its own
    /// among the others.
    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any + Send>;
}

/// The receiving end of a subscription; dropping it unsubscribes.
pub struct Subscription<T> {
    id: SubscriptionId,
    receiver: Receiver<T>,
    overflow: Arc<AtomicU64>,
    /// A replica's subscriber waits for the writer itself (see [`ReplicaFeed`]).
    waiter: Option<std::sync::Mutex<Box<dyn FeedWaiter>>>,
}

impl<T> std::fmt::Debug for Subscription<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Subscription")
            .field("id", &self.id)
            .field("queued", &self.receiver.len())
            .field("overflowed", &self.overflowed())
            .field("feeds_itself", &self.waiter.is_some())
            .finish()
    }
}

/// The error of a timed receive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RecvError {
    /// Nothing arrived in time; try again or give up.
    #[error("nothing arrived before the timeout")]
    Timeout,
    /// The trajectory was destroyed or unsubscribed this subscription.
    #[error("the subscription has ended")]
    Closed,
}

impl<T> Subscription<T> {
    /// This subscription's id, for `unsubscribe`.
    pub fn id(&self) -> SubscriptionId {
        self.id
    }

    /// Makes this subscription wait for a replica's writer itself.
    pub(crate) fn with_waiter(mut self, waiter: Option<Box<dyn FeedWaiter>>) -> Self {
        self.waiter = waiter.map(std::sync::Mutex::new);
        self
    }

    /// Waits up to `timeout` for the next item.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<T, RecvError> {
        let closed = |e| match e {
            RecvTimeoutError::Timeout => RecvError::Timeout,
            RecvTimeoutError::Disconnected => RecvError::Closed,
        };
        let Some(waiter) = &self.waiter else {
            return self.receiver.recv_timeout(timeout).map_err(closed);
        };
        let deadline = std::time::Instant::now() + timeout;
        loop {
            // What is queued here; else what the writer published that nobody fed yet
            // (fed before sleeping, so nothing published before the waiter listened is
            // missed); else sleep on the writer's wake-up.
            match self.receiver.try_recv() {
                Ok(item) => return Ok(item),
                Err(TryRecvError::Disconnected) => return Err(RecvError::Closed),
                Err(TryRecvError::Empty) => {}
            }
            let mut waiter = match waiter.lock() {
                Ok(w) => w,
                // A panic while feeding left nothing half-done that matters here: the
                // replica's lock protects its state; fall back to the channel.
                Err(_) => return self.receiver.recv_timeout(timeout).map_err(closed),
            };
            waiter.feed();
            if let Ok(item) = self.receiver.try_recv() {
                return Ok(item);
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Err(RecvError::Timeout);
            }
            if !waiter.wait_and_feed(left) {
                drop(waiter);
                return self.receiver.recv_timeout(left).map_err(closed);
            }
        }
    }

    /// The next item if one is waiting (for a replica's subscriber: also what its
    /// writer published that was not fed yet).
    pub fn try_recv(&self) -> Option<T> {
        if let Ok(item) = self.receiver.try_recv() {
            return Some(item);
        }
        self.feed();
        // Empty or closed alike: nothing is waiting.
        self.receiver.try_recv().ok()
    }

    /// [`Subscription::try_recv`] that also says when the subscription has ended: the
    /// next item if one is waiting, `None` if none is, [`RecvError::Closed`] once its
    /// trajectory was destroyed or it was unsubscribed. A poll without a clock, for a
    /// reader that spins (the C ABI's receive with a timeout of 0).
    pub fn poll(&self) -> Result<Option<T>, RecvError> {
        match self.receiver.try_recv() {
            Ok(item) => return Ok(Some(item)),
            Err(TryRecvError::Disconnected) => return Err(RecvError::Closed),
            Err(TryRecvError::Empty) => {}
        }
        self.feed();
        match self.receiver.try_recv() {
            Ok(item) => Ok(Some(item)),
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => Err(RecvError::Closed),
        }
    }

    /// Everything waiting now, without blocking.
    pub fn drain(&self) -> Vec<T> {
        self.feed();
        self.receiver.try_iter().collect()
    }

    fn feed(&self) {
        if let Some(Ok(mut w)) = self.waiter.as_ref().map(|w| w.lock()) {
            w.feed();
        }
    }

    /// How many items were discarded because this subscriber fell behind.
    pub fn overflowed(&self) -> u64 {
        self.overflow.load(Ordering::Relaxed)
    }

    /// The underlying channel, to `select!` over several subscriptions.
    pub fn receiver(&self) -> &Receiver<T> {
        &self.receiver
    }
}

impl<T: Send + 'static> Subscription<T> {
    /// Calls `callback` on a thread of its own for every item, until the subscription
    /// ends or the returned handle is dropped (the seed's `SubscriptionProxy`). Fails
    /// when the OS refuses the thread: a callback that would never run is an error the
    /// caller sees, not a log line.
    pub fn spawn_callback<F>(self, mut callback: F) -> Result<CallbackHandle, CallbackError>
    where
        F: FnMut(T) + Send + 'static,
    {
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let stop_thread = Arc::clone(&stop);
        let trajectory = self.id.0;
        let thread = std::thread::Builder::new()
            .name(format!("esgm-callback-{trajectory}"))
            .spawn(move || {
                while !stop_thread.load(Ordering::Relaxed) {
                    match self.recv_timeout(Duration::from_millis(50)) {
                        Ok(item) => callback(item),
                        Err(RecvError::Timeout) => {}
                        Err(RecvError::Closed) => break,
                    }
                }
            })
            .map_err(CallbackError::NoThread)?;
        Ok(CallbackHandle { stop, thread: Some(thread) })
    }
}

/// [`Subscription::spawn_callback`] failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CallbackError {
    /// The OS refused the callback's thread (a process at its thread limit).
    #[error("cannot start the subscription's callback thread: {0}")]
    NoThread(#[source] std::io::Error),
}

/// Keeps a callback subscription alive; dropping it stops the callback thread.
#[derive(Debug)]
pub struct CallbackHandle {
    stop: Arc<std::sync::atomic::AtomicBool>,
    /// Taken when dropped, to join it.
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for CallbackHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            // Do not join from the callback thread itself (a callback dropping its
            // own handle would deadlock).
            if t.thread().id() != std::thread::current().id() {
                // A callback's panic was reported by the panic hook; nothing to add here.
                let _ = t.join();
            }
        }
    }
}

/// Where one subscriber's items go.
#[derive(Debug)]
enum Sink<T> {
    /// Its own channel; the writer keeps a second receiver to discard the oldest.
    Own { sender: Sender<T>, oldest: Receiver<T> },
    /// A channel shared with other trajectories' subscribers (a unit's inputs), each
    /// item tagged with the input's index, so the reader sees every input's items in
    /// the order they were added across all of them.
    Tagged {
        tag: usize,
        sender: Sender<(usize, T)>,
        oldest: Receiver<(usize, T)>,
        /// Dead once the [`FanIn`] is dropped.
        alive: std::sync::Weak<()>,
    },
}

/// The writer's side of one subscription.
#[derive(Debug)]
struct Subscriber<T> {
    id: SubscriptionId,
    sink: Sink<T>,
    overflow: Arc<AtomicU64>,
}

/// One channel fed by several trajectories, each item tagged with its input index (see
/// [`crate::TrajectoryStore::subscribe_tagged`]). Dropping it ends those subscriptions.
pub struct FanIn<T> {
    sender: Sender<(usize, T)>,
    receiver: Receiver<(usize, T)>,
    overflow: Arc<AtomicU64>,
    token: Arc<()>,
    /// A fan-in of one replica waits for its writer itself (see [`ReplicaFeed`]).
    waiter: Option<Box<dyn FeedWaiter>>,
}

impl<T> std::fmt::Debug for FanIn<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FanIn")
            .field("queued", &self.receiver.len())
            .field("overflowed", &self.overflowed())
            .field("feeds_itself", &self.waiter.is_some())
            .finish()
    }
}

impl<T> FanIn<T> {
    /// A fan-in buffering up to `capacity` items before discarding the oldest.
    pub fn new(capacity: usize) -> Self {
        let (sender, receiver) = crossbeam_channel::bounded(capacity.max(1));
        Self {
            sender,
            receiver,
            overflow: Arc::new(AtomicU64::new(0)),
            token: Arc::new(()),
            waiter: None,
        }
    }

    /// Makes its reader wait for the writer of its (one) replica input itself: a
    /// sample from another process then wakes the reader once, not a feeding thread
    /// first.
    pub fn set_waiter(&mut self, waiter: Box<dyn FeedWaiter>) {
        self.waiter = Some(waiter);
    }

    /// The waiter, for the reader's loop.
    pub fn take_waiter(&mut self) -> Option<Box<dyn FeedWaiter>> {
        self.waiter.take()
    }

    /// A sending end of the reader's queue, for what its runtime sends the reader
    /// itself (a flush marker, queued behind everything delivered before it).
    pub fn sender(&self) -> Sender<(usize, T)> {
        self.sender.clone()
    }

    /// The receiving end, to `select!` on.
    pub fn receiver(&self) -> &Receiver<(usize, T)> {
        &self.receiver
    }

    /// Items discarded because the reader fell behind.
    pub fn overflowed(&self) -> u64 {
        self.overflow.load(Ordering::Relaxed)
    }
}

/// The subscribers of one trajectory (or of its violations).
#[derive(Debug)]
pub(crate) struct Subscribers<T> {
    subscribers: Vec<Subscriber<T>>,
    next_id: u64,
}

impl<T> Default for Subscribers<T> {
    fn default() -> Self {
        Self { subscribers: Vec::new(), next_id: 1 }
    }
}

impl<T: Clone> Subscribers<T> {
    /// Adds a subscriber, first filled with `backlog`.
    pub fn subscribe(
        &mut self,
        capacity: usize,
        backlog: impl Iterator<Item = T>,
    ) -> Subscription<T> {
        let (sender, receiver) = crossbeam_channel::bounded(capacity.max(1));
        let id = SubscriptionId(self.next_id);
        self.next_id += 1;
        let overflow = Arc::new(AtomicU64::new(0));
        let sub = Subscriber {
            id,
            sink: Sink::Own { sender, oldest: receiver.clone() },
            overflow: Arc::clone(&overflow),
        };
        for item in backlog {
            Self::deliver(&sub, item);
        }
        self.subscribers.push(sub);
        Subscription { id, receiver, overflow, waiter: None }
    }

    /// Adds a subscriber feeding `fan_in` with items tagged `tag`.
    pub fn subscribe_tagged(&mut self, fan_in: &FanIn<T>, tag: usize) -> SubscriptionId {
        let id = SubscriptionId(self.next_id);
        self.next_id += 1;
        self.subscribers.push(Subscriber {
            id,
            sink: Sink::Tagged {
                tag,
                sender: fan_in.sender.clone(),
                oldest: fan_in.receiver.clone(),
                alive: Arc::downgrade(&fan_in.token),
            },
            overflow: Arc::clone(&fan_in.overflow),
        });
        id
    }

    /// Removes a subscriber; false if there was none with that id.
    pub fn unsubscribe(&mut self, id: SubscriptionId) -> bool {
        let before = self.subscribers.len();
        self.subscribers.retain(|s| s.id != id);
        before != self.subscribers.len()
    }

    /// Sends `item` to every subscriber; returns how many older items had to be
    /// discarded for lack of room. Subscribers whose receiver is gone are removed.
    pub fn publish(&mut self, item: &T) -> u64 {
        let mut overflowed = 0;
        self.subscribers.retain(|s| match Self::deliver(s, item.clone()) {
            Delivery::Sent => true,
            Delivery::Overflowed => {
                overflowed += 1;
                true
            }
            Delivery::Gone => false,
        });
        overflowed
    }

    fn deliver(s: &Subscriber<T>, item: T) -> Delivery {
        // The writer keeps a receiver of its own, so the channel never reports the
        // reader gone: an own subscription is gone when only the writer still holds its
        // overflow counter, a tagged one when its fan-in's token is dropped.
        match &s.sink {
            Sink::Own { sender, oldest } => {
                if Arc::strong_count(&s.overflow) == 1 {
                    return Delivery::Gone;
                }
                push_dropping_oldest(sender, oldest, item, &s.overflow)
            }
            Sink::Tagged { tag, sender, oldest, alive } => {
                if alive.strong_count() == 0 {
                    return Delivery::Gone;
                }
                push_dropping_oldest(sender, oldest, (*tag, item), &s.overflow)
            }
        }
    }

    /// Number of live subscribers. (A receiver dropped since the last publish is
    /// still counted until then.)
    pub fn len(&self) -> usize {
        self.subscribers.len()
    }

    /// Moves every subscriber of `other` here (re-pointing a name keeps subscribers).
    pub fn adopt(&mut self, other: &mut Subscribers<T>) {
        self.next_id = self.next_id.max(other.next_id);
        self.subscribers.append(&mut other.subscribers);
    }
}

/// Sends `item`, discarding the oldest waiting item (counted) while the channel is
/// full; never blocks.
fn push_dropping_oldest<U>(
    sender: &Sender<U>,
    oldest: &Receiver<U>,
    mut item: U,
    overflow: &AtomicU64,
) -> Delivery {
    let mut discarded = false;
    loop {
        match sender.try_send(item) {
            Ok(()) => return if discarded { Delivery::Overflowed } else { Delivery::Sent },
            Err(TrySendError::Disconnected(_)) => return Delivery::Gone,
            Err(TrySendError::Full(back)) => {
                item = back;
                // The reader may have drained the slot meanwhile, which is also fine.
                if oldest.try_recv().is_ok() {
                    overflow.fetch_add(1, Ordering::Relaxed);
                    discarded = true;
                }
            }
        }
    }
}

enum Delivery {
    Sent,
    Overflowed,
    Gone,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delivers_in_order_and_discards_oldest_when_full() {
        let mut subs = Subscribers::<u32>::default();
        let s = subs.subscribe(2, [7].into_iter());
        assert_eq!(subs.publish(&1), 0);
        assert_eq!(subs.publish(&2), 1); // 7 discarded
        assert_eq!(s.drain(), vec![1, 2]);
        assert_eq!(s.overflowed(), 1);
    }

    #[test]
    fn fan_in_keeps_order_across_writers_and_ends_when_dropped() {
        let mut a = Subscribers::<u32>::default();
        let mut b = Subscribers::<u32>::default();
        let fan = FanIn::new(8);
        a.subscribe_tagged(&fan, 0);
        b.subscribe_tagged(&fan, 1);
        a.publish(&10);
        b.publish(&20);
        a.publish(&11);
        let got: Vec<_> = fan.receiver().try_iter().collect();
        assert_eq!(got, vec![(0, 10), (1, 20), (0, 11)]);
        drop(fan);
        a.publish(&12);
        assert_eq!(a.len(), 0, "a dropped fan-in ends its subscriptions");
    }

    #[test]
    fn dropped_receivers_are_pruned_and_unsubscribe_works() {
        let mut subs = Subscribers::<u32>::default();
        let a = subs.subscribe(4, std::iter::empty());
        let b = subs.subscribe(4, std::iter::empty());
        drop(a);
        subs.publish(&1);
        assert_eq!(subs.len(), 1);
        assert!(subs.unsubscribe(b.id()));
        assert!(!subs.unsubscribe(b.id()));
        assert_eq!(b.recv_timeout(Duration::from_millis(1)), Ok(1));
        assert_eq!(b.recv_timeout(Duration::from_millis(1)), Err(RecvError::Closed));
    }
}
