//! The robot as an esgm push sensor (tutorial 8.1): a thread that steps [`Kinematics`]
//! at a fixed rate and pushes each new `RobotState` into a primitive trajectory, steering
//! by the latest `DrivingDirection` if it follows one.
//!
//! The publisher only names esgm-core's traits ([`EntityTrajectoryStructure`],
//! [`Clock`](esgm_core::Clock)), so it pushes into the in-process runtime or, later,
//! into shared memory, and it runs on a simulated clock in tests.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use esgm_core::library::{DrivingDirection, RobotState};
use esgm_core::store::QueryError;
use esgm_core::time::millis;
use esgm_core::{AddOutcome, Entity, EntityTrajectoryStructure, SharedClock, Time};

use crate::kinematics::Kinematics;

/// How long the thread sleeps at most before re-checking its stop flag, in real time,
/// so that stopping is prompt even on a simulated clock that does not move.
const STOP_POLL: Duration = Duration::from_millis(20);

/// The default publishing period: 100 ms (10 Hz), the seed's robot thread.
pub const DEFAULT_PERIOD: Time = millis(100);

/// Reads the latest command; `Ok(None)` when there is none yet.
type CommandReader = Box<dyn Fn() -> Result<Option<DrivingDirection>, String> + Send>;

/// A [`RobotPublisher`] could not be started.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RobotPublisherError {
    /// The period is zero or negative: give a positive number of nanoseconds.
    #[error("the publishing period must be positive, got {period} ns")]
    InvalidPeriod {
        /// The period given.
        period: Time,
    },
    /// The operating system refused a thread; free resources and retry.
    #[error("could not start the publisher thread: {0}")]
    Spawn(#[source] std::io::Error),
}

/// What a publisher has done so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PublisherStats {
    /// States the trajectory accepted (added, or held for reordering).
    pub published: u64,
    /// States the trajectory dropped for breaking its policy (also in its stats).
    pub dropped: u64,
    /// States that could not be added at all (e.g. the trajectory was destroyed).
    pub failures: u64,
    /// Latest commands that could not be read as a `DrivingDirection`.
    pub unreadable_commands: u64,
    /// Periods skipped because the thread woke a period or more late.
    pub missed_periods: u64,
}

#[derive(Debug, Default)]
struct Counters {
    published: AtomicU64,
    dropped: AtomicU64,
    failures: AtomicU64,
    unreadable_commands: AtomicU64,
    missed_periods: AtomicU64,
}

impl Counters {
    fn bump(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }

    fn snapshot(&self) -> PublisherStats {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        PublisherStats {
            published: get(&self.published),
            dropped: get(&self.dropped),
            failures: get(&self.failures),
            unreadable_commands: get(&self.unreadable_commands),
            missed_periods: get(&self.missed_periods),
        }
    }
}

/// State shared between the publisher thread and its handle.
#[derive(Debug)]
struct Shared {
    counters: Counters,
    state: parking_lot::Mutex<RobotState>,
    stop: AtomicBool,
}

/// Settings of a [`RobotPublisher`]; start it with [`create`](Self::create).
pub struct RobotPublisherBuilder<T> {
    robot_state: T,
    clock: SharedClock,
    kinematics: Kinematics,
    period: Time,
    entity_name: String,
    commands: Option<CommandReader>,
}

impl<T: std::fmt::Debug> std::fmt::Debug for RobotPublisherBuilder<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotPublisherBuilder")
            .field("robot_state", &self.robot_state)
            .field("kinematics", &self.kinematics)
            .field("period", &self.period)
            .field("entity_name", &self.entity_name)
            .field("follows_commands", &self.commands.is_some())
            .finish_non_exhaustive()
    }
}

impl<T: EntityTrajectoryStructure + 'static> RobotPublisherBuilder<T> {
    /// The simulated robot (default: [`Kinematics::default`], the seed's robot at
    /// (1, 2) heading 3°).
    #[must_use]
    pub fn kinematics(mut self, kinematics: Kinematics) -> Self {
        self.kinematics = kinematics;
        self
    }

    /// Time between states, in ns on the runtime clock (default [`DEFAULT_PERIOD`],
    /// 10 Hz).
    #[must_use]
    pub fn period(mut self, period: Time) -> Self {
        self.period = period;
        self
    }

    /// The name of every structure pushed (default `"robot1"`, the seed's).
    #[must_use]
    pub fn entity_name(mut self, name: impl Into<String>) -> Self {
        self.entity_name = name.into();
        self
    }

    /// Steers by the latest structure of `driving_direction` (any runtime's handle on
    /// a `DrivingDirection` trajectory). Without one, or while it is empty, the robot
    /// holds still and keeps publishing its pose.
    #[must_use]
    pub fn follow<C: EntityTrajectoryStructure + 'static>(mut self, driving_direction: C) -> Self {
        self.commands = Some(Box::new(move || match driving_direction.get_latest() {
            Ok(sample) => DrivingDirection::from_shared(&sample)
                .map(Some)
                .map_err(|e| format!("`{}`: {e}", driving_direction.name())),
            Err(QueryError::ValueNotAvailable { .. }) => Ok(None),
            Err(e) => Err(e.to_string()),
        }));
        self
    }

    /// Starts the thread. The first state is pushed at once, then one every period.
    pub fn create(self) -> Result<RobotPublisher, RobotPublisherError> {
        if self.period <= 0 {
            return Err(RobotPublisherError::InvalidPeriod { period: self.period });
        }
        let shared = Arc::new(Shared {
            counters: Counters::default(),
            state: parking_lot::Mutex::new(self.kinematics.state()),
            stop: AtomicBool::new(false),
        });
        let thread_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name(format!("robot-publisher-{}", self.robot_state.name()))
            .spawn(move || self.run(&thread_shared))
            .map_err(RobotPublisherError::Spawn)?;
        Ok(RobotPublisher { shared, thread: Some(thread) })
    }

    /// The publishing loop: a tick at every multiple of the period after the start, on
    /// the runtime clock.
    fn run(mut self, shared: &Shared) {
        let counters = &shared.counters;
        let trajectory = self.robot_state.name().to_owned();
        let mut next = self.clock.now();
        let mut last_step = next;
        // Failures are logged when they start and when they end, not on every tick.
        let mut publish_failing = false;
        let mut commands_failing = false;
        while !shared.stop.load(Ordering::Relaxed) {
            let now = self.clock.sleep_until(next, STOP_POLL);
            if now < next {
                continue;
            }
            let late = (now - next) / self.period;
            if late > 0 {
                Counters::bump(&counters.missed_periods, late as u64);
                next += late * self.period;
            }
            if shared.stop.load(Ordering::Relaxed) {
                break;
            }

            let command = match self.commands.as_ref().map(|read| read()) {
                Some(Ok(command)) => {
                    commands_failing = false;
                    command
                }
                Some(Err(reason)) => {
                    Counters::bump(&counters.unreadable_commands, 1);
                    if !commands_failing {
                        tracing::warn!(%trajectory, %reason, "cannot read the driving direction; holding still");
                        commands_failing = true;
                    }
                    None
                }
                None => None,
            };
            let state = match command {
                Some(command) => self.kinematics.step(now - last_step, &command),
                None => self.kinematics.state(),
            };
            last_step = now;
            *shared.state.lock() = state;

            match self.robot_state.create_at_now(&self.entity_name, state.to_attributes().into()) {
                Ok(AddOutcome::Added | AddOutcome::Held { .. } | AddOutcome::Forwarded) => {
                    Counters::bump(&counters.published, 1);
                    if publish_failing {
                        tracing::info!(%trajectory, "publishing robot states again");
                        publish_failing = false;
                    }
                }
                // Counted and reported by the trajectory itself.
                Ok(AddOutcome::Dropped(_)) => Counters::bump(&counters.dropped, 1),
                Err(error) => {
                    Counters::bump(&counters.failures, 1);
                    if !publish_failing {
                        tracing::warn!(%trajectory, %error, "cannot publish robot states");
                        publish_failing = true;
                    }
                }
            }
            next += self.period;
        }
    }
}

/// A running robot: a thread pushing its state into a primitive `RobotState`
/// trajectory. Stops on [`stop`](Self::stop) or drop.
///
/// ```
/// use esgm_core::{EntityTrajectoryStructure, Esgm, InProcessEsgm};
/// use robot_publisher::RobotPublisher;
///
/// let esgm = InProcessEsgm::default();
/// let robot_state = esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState")?;
/// let robot = RobotPublisher::builder(robot_state.clone(), esgm.clock().clone()).create()?;
/// // The first state is pushed at once.
/// let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
/// while robot.stats().published == 0 && std::time::Instant::now() < deadline {
///     std::thread::sleep(std::time::Duration::from_millis(1));
/// }
/// robot.stop();
/// assert_eq!(robot_state.get_latest()?.name(), "robot1");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct RobotPublisher {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl RobotPublisher {
    /// Settings for a publisher pushing into `robot_state` (a primitive trajectory of
    /// type `RobotState`), timed by `clock` (the runtime's).
    pub fn builder<T: EntityTrajectoryStructure + 'static>(
        robot_state: T,
        clock: SharedClock,
    ) -> RobotPublisherBuilder<T> {
        RobotPublisherBuilder {
            robot_state,
            clock,
            kinematics: Kinematics::default(),
            period: DEFAULT_PERIOD,
            entity_name: "robot1".to_owned(),
            commands: None,
        }
    }

    /// The last state stepped to (and pushed, unless pushing failed).
    pub fn state(&self) -> RobotState {
        *self.shared.state.lock()
    }

    /// What the publisher has done so far.
    pub fn stats(&self) -> PublisherStats {
        self.shared.counters.snapshot()
    }

    /// Stops the thread and waits for it; no state is pushed after this returns.
    pub fn stop(mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            // The thread never panics on input; if it did, there is nothing left to
            // stop.
            let _ = thread.join();
        }
    }
}

impl Drop for RobotPublisher {
    fn drop(&mut self) {
        self.halt();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    use esgm_core::library::RobotState;
    use esgm_core::{Esgm, InProcessEsgm, InProcessTrajectory, SimClock, secs};

    use crate::KinematicsConfig;

    /// Polls `cond` for up to 10 s of real time; the caller asserts on the result.
    fn wait_for(mut cond: impl FnMut() -> bool) -> bool {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !cond() {
            if Instant::now() > deadline {
                return false;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        true
    }

    fn runtime() -> (Arc<SimClock>, InProcessEsgm, InProcessTrajectory) {
        let clock = SimClock::shared(secs(100));
        let esgm = InProcessEsgm::builder().clock(clock.clone()).create();
        let states =
            esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState").unwrap();
        (clock, esgm, states)
    }

    fn states(t: &InProcessTrajectory) -> Vec<(Time, RobotState)> {
        t.get_between(0, Time::MAX)
            .unwrap()
            .iter()
            .map(|s| (s.valid_time(), RobotState::from_shared(s).unwrap()))
            .collect()
    }

    #[test]
    fn publishes_every_period_and_holds_still_without_commands() {
        let (clock, _esgm, trajectory) = runtime();
        let robot = RobotPublisher::builder(trajectory.clone(), clock.clone()).create().unwrap();
        assert!(wait_for(|| states(&trajectory).len() == 1), "no first state");
        for k in 1..=3 {
            clock.advance(DEFAULT_PERIOD);
            assert!(wait_for(|| states(&trajectory).len() == k + 1), "no state {k}");
        }
        let seed_robot = Kinematics::default().state();
        let expected: Vec<_> =
            (0..4).map(|k| (secs(100) + k * DEFAULT_PERIOD, seed_robot)).collect();
        assert_eq!(states(&trajectory), expected);
        assert_eq!(trajectory.get_latest().unwrap().name(), "robot1");
        robot.stop();
        clock.advance(DEFAULT_PERIOD);
        assert_eq!(states(&trajectory).len(), 4, "published after stop");
    }

    #[test]
    fn steers_by_the_latest_driving_direction() {
        let (clock, esgm, trajectory) = runtime();
        let commands = esgm
            .create_primitive_entity_trajectory_structure("driving_direction", "DrivingDirection")
            .unwrap();
        let start = RobotState { x: 0.0, y: 0.0, dir: 0.0 };
        let robot = RobotPublisher::builder(trajectory.clone(), clock.clone())
            .kinematics(Kinematics::new(start, KinematicsConfig::default()).unwrap())
            .period(millis(50))
            .entity_name("rover")
            .follow(commands.clone())
            .create()
            .unwrap();
        assert!(wait_for(|| states(&trajectory).len() == 1));
        let command = DrivingDirection { dir: 90.0, speed: 0.0 };
        commands.create_at_now("driving_dir", command.to_attributes().into()).unwrap();
        clock.advance(millis(50));
        assert!(wait_for(|| states(&trajectory).len() == 2));
        // 90 °/s for 50 ms.
        let (_, turned) = states(&trajectory)[1];
        assert!((turned.dir - 4.5).abs() < 1e-9, "{turned:?}");
        assert_eq!(robot.state(), turned);
        assert_eq!(trajectory.get_latest().unwrap().name(), "rover");
        assert_eq!(robot.stats().published, 2);
    }

    #[test]
    fn unreadable_commands_hold_the_robot_still() {
        let (clock, esgm, trajectory) = runtime();
        let wrong =
            esgm.create_primitive_entity_trajectory_structure("not_commands", "Blob").unwrap();
        wrong
            .create_at_now(
                "blob",
                esgm_core::library::Blob { x: 1, y: 1, size: 1 }.to_attributes().into(),
            )
            .unwrap();
        let robot = RobotPublisher::builder(trajectory.clone(), clock.clone())
            .follow(wrong)
            .create()
            .unwrap();
        assert!(wait_for(|| robot.stats().published == 1));
        clock.advance(DEFAULT_PERIOD);
        assert!(wait_for(|| robot.stats().published == 2));
        assert_eq!(robot.stats().unreadable_commands, 2);
        assert!(states(&trajectory).iter().all(|(_, s)| *s == Kinematics::default().state()));
    }

    #[test]
    fn a_period_must_be_positive() {
        let (clock, _esgm, trajectory) = runtime();
        let err = RobotPublisher::builder(trajectory, clock).period(0).create().unwrap_err();
        assert!(matches!(err, RobotPublisherError::InvalidPeriod { period: 0 }));
    }
}
