//! The robot as a process of an esgm system: its command line ([`RobotArgs`]), starting
//! it on any runtime ([`start`]: its state trajectory, then a [`RobotPublisher`]
//! following the driving direction) and the whole worker ([`run`]: connect, publish,
//! leave with the system).
//!
//! The `robot-publisher` binary and `esgm worker robot` (which the coordinator and
//! `esgm demo` start) are both this code: a robot declared in a configuration file
//! behaves the same whichever of the two runs it.
//!
//! This module is the body of those binaries, so it reports like one: [`anyhow`]
//! errors with the context a user needs, printed as one line by the caller's `main`.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_core::esgm::{CreateError, TrajectorySpec};
use esgm_core::library::RobotState;
use esgm_core::{Entity, Esgm, FluentStreamPolicy, SharedClock, Time, millis};
use esgm_shm::ShmEsgm;
use esgm_shm::attach::serve_while_system_lives;

use crate::publisher::RobotPublisher;

/// How long a stopped system's coordinator may stay gone before a running robot
/// leaves (a slow or crashed coordinator is waited for, publishing on: see
/// [`esgm_shm::attach`]).
pub const COORDINATOR_PATIENCE: Duration = Duration::from_millis(500);

/// How long [`start`] waits for the trajectory it follows to be created (a system
/// being applied creates it after the robot has started).
pub const FOLLOW_WAIT: Duration = Duration::from_secs(60);

/// How often [`start`] looks for the trajectory it follows.
const FOLLOW_POLL: Duration = Duration::from_millis(50);

/// The name of a robot pushing into `trajectory` in the registry and in logs
/// (`robot-<trajectory>`), unless its supervisor names it.
pub fn process_name(trajectory: &str) -> String {
    format!("robot-{trajectory}")
}

/// A robot's settings, as command-line arguments (`robot-publisher …`,
/// `esgm worker robot …`).
#[derive(Debug, Clone, PartialEq, Eq, clap::Parser)]
pub struct RobotArgs {
    /// The primitive `RobotState` trajectory it pushes into (created if missing).
    #[arg(long, default_value = "robot_state")]
    pub trajectory: String,
    /// The `DrivingDirection` trajectory it steers by (waited for up to a minute).
    #[arg(long, default_value = "driving_direction")]
    pub follow: String,
    /// Time between states (`100ms`: 10 Hz, the seed's robot).
    #[arg(long, default_value = "100ms", value_parser = humantime::parse_duration)]
    pub period: Duration,
}

impl RobotArgs {
    /// This process's name in the registry: the supervisor's name for it
    /// ([`esgm_shm::WORKER_ENV`]), or [`process_name`] of the trajectory when run by
    /// hand.
    pub fn process_name(&self) -> String {
        std::env::var(esgm_shm::WORKER_ENV).unwrap_or_else(|_| process_name(&self.trajectory))
    }
}

/// Starts the robot `args` describes on any runtime: creates its state trajectory
/// (or takes it back, after a restart), waits up to [`FOLLOW_WAIT`] for the trajectory
/// it follows, then publishes a state every period on `clock` (the runtime's) until
/// the returned publisher is stopped or dropped.
///
/// ```
/// use clap::Parser;
/// use esgm_core::{EntityTrajectoryStructure, Esgm, InProcessEsgm};
/// use robot_publisher::serve::{RobotArgs, start};
///
/// let args = RobotArgs::parse_from(["robot", "--follow", "commands", "--period", "50ms"]);
/// let esgm = InProcessEsgm::default();
/// esgm.create_primitive_entity_trajectory_structure("commands", "DrivingDirection")?;
/// let robot = start(&esgm, esgm.clock().clone(), &args)?;
/// let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
/// while robot.stats().published == 0 && std::time::Instant::now() < deadline {
///     std::thread::sleep(std::time::Duration::from_millis(1));
/// }
/// robot.stop();
/// assert_eq!(esgm.get_entity_trajectory_structure("robot_state")?.get_latest()?.name(), "robot1");
/// # Ok::<(), anyhow::Error>(())
/// ```
pub fn start<E>(esgm: &E, clock: SharedClock, args: &RobotArgs) -> anyhow::Result<RobotPublisher>
where
    E: Esgm,
    E::Trajectory: 'static,
{
    let period = Time::try_from(args.period.as_nanos()).context("--period is too long")?;
    // The seed's "reasonable" constraints; one producer in order, so no reordering.
    let policy = FluentStreamPolicy::reasonable(millis(50), 600)
        .context("the robot's policy")?
        .reorder(false);
    let spec = TrajectorySpec::primitive(&args.trajectory, RobotState::TYPE_NAME).policy(policy);
    let states = match esgm.create_trajectory(spec) {
        Ok(states) => states,
        Err(CreateError::EntityStructureAlreadyExists { .. }) => {
            esgm.get_entity_trajectory_structure(&args.trajectory)?
        }
        Err(e) => {
            return Err(e).with_context(|| format!("cannot create `{}`", args.trajectory));
        }
    };
    let deadline = Instant::now() + FOLLOW_WAIT;
    let directions = loop {
        if let Ok(directions) = esgm.get_entity_trajectory_structure(&args.follow) {
            break directions;
        }
        if Instant::now() > deadline {
            bail!("`{}` was not created within {FOLLOW_WAIT:?}", args.follow);
        }
        if !esgm.ping() {
            bail!("the system went away before `{}` was created", args.follow);
        }
        std::thread::sleep(FOLLOW_POLL);
    };
    RobotPublisher::builder(states, clock)
        .period(period)
        .follow(directions)
        .create()
        .context("cannot start the robot")
}

/// The robot process: connects to the system of `domain`, publishes, and returns once
/// the system was stopped (its coordinator gone for [`COORDINATOR_PATIENCE`] and its
/// registry no longer kept). A slow or crashed coordinator is waited for.
pub fn run(domain: &str, args: &RobotArgs) -> anyhow::Result<()> {
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(args.process_name())
        .connect()
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    let robot = start(&esgm, esgm.local().clock().clone(), args)?;
    tracing::info!(trajectory = %args.trajectory, follow = %args.follow, "publishing");
    serve_while_system_lives(&esgm, None, COORDINATOR_PATIENCE);
    let stats = robot.stats();
    robot.stop();
    tracing::info!(trajectory = %args.trajectory, ?stats, "the system was stopped; leaving");
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use super::*;
    use clap::Parser;
    use esgm_core::{EntityTrajectoryStructure, InProcessEsgm};
    use esgm_shm::control::{Coordinator, Registry};
    use esgm_shm::control::{Request, Response};

    fn parse(args: &[&str]) -> Result<RobotArgs, clap::Error> {
        RobotArgs::try_parse_from(std::iter::once("robot").chain(args.iter().copied()))
    }

    #[test]
    fn defaults_are_the_tutorials_robot() {
        let args = parse(&[]).unwrap();
        assert_eq!(args.trajectory, "robot_state");
        assert_eq!(args.follow, "driving_direction");
        assert_eq!(args.period, Duration::from_millis(100));
        assert!(parse(&["--period", "fast"]).is_err());
    }

    /// Where the registry says `trajectory` is written: its writer, its generation and
    /// the writer's publisher port.
    fn placement(esgm: &ShmEsgm, trajectory: &str) -> (String, u64, Option<u128>) {
        let Response::Placements(list) = esgm.control(Request::ListPlacements).unwrap() else {
            panic!("the coordinator did not list placements");
        };
        let p = list.into_iter().find(|p| p.name == trajectory).unwrap();
        (p.writer, p.generation, p.port.map(|w| w.publisher))
    }

    /// Waits up to [`DEADLINE`] for `done`, failing the test with `what` after it.
    fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
        let deadline = Instant::now() + DEADLINE;
        while !done() {
            assert!(Instant::now() < deadline, "{what} within {DEADLINE:?}");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    const DEADLINE: Duration = Duration::from_secs(60);

    /// A robot process that restarts (the supervisor starts it again under the same
    /// name) takes its trajectory back: the same generation (not created anew, so its
    /// readers keep it), the registry names the new robot's publisher port as the
    /// writer's, every state it adds is accepted, and a reader that followed the first
    /// robot receives the new one's states.
    #[test]
    fn takes_its_trajectory_back_after_a_restart() {
        let domain = esgm_shm::unique_domain("robot-restart");
        let registry = Registry::new(esgm_core::TypeRegistry::with_library());
        let _coordinator = Coordinator::spawn(&domain, registry).unwrap();
        let args = parse(&["--period", "20ms"]).unwrap();
        let connect = |host: &str| ShmEsgm::builder().domain(&domain).host(host).connect().unwrap();
        let observer = connect("observer");
        observer
            .create_primitive_entity_trajectory_structure("driving_direction", "DrivingDirection")
            .unwrap();

        // The first robot process: publishes, then goes (as a killed process would,
        // without destroying its trajectory).
        let first = connect(&args.process_name());
        let robot = start(&first, first.local().clock().clone(), &args).unwrap();
        wait_until("the first robot published nothing", || robot.stats().published >= 3);
        let states = observer.get_entity_trajectory_structure(&args.trajectory).unwrap();
        wait_until("the observer received none of the first robot's states", || {
            states.get_latest().is_ok()
        });
        let (writer, generation, port) = placement(&observer, &args.trajectory);
        assert_eq!(writer, args.process_name());
        let first_port = port.expect("the first robot registered its publisher port");
        robot.stop();
        drop(first);
        let last_before = states.get_latest().unwrap().structure.valid_time();

        // The restarted robot process, under the same name.
        let second = connect(&args.process_name());
        let robot = start(&second, second.local().clock().clone(), &args).unwrap();
        wait_until("the restarted robot published nothing", || robot.stats().published >= 3);
        let (writer, generation_after, port) = placement(&observer, &args.trajectory);
        assert_eq!(writer, args.process_name());
        assert_eq!(generation_after, generation, "the trajectory was created anew");
        let port = port.expect("the restarted robot registered its publisher port");
        assert_ne!(port, first_port, "the registry still names the first robot's port");
        // Its adds arrive, at the reader that followed the first robot.
        wait_until("the observer received none of the restarted robot's states", || {
            states.get_latest().is_ok_and(|s| s.structure.valid_time() > last_before)
        });
        let stats = robot.stats();
        robot.stop();
        assert_eq!((stats.dropped, stats.failures), (0, 0), "{stats:?}");
    }

    #[test]
    fn a_zero_period_is_refused() {
        let esgm = InProcessEsgm::default();
        esgm.create_primitive_entity_trajectory_structure("driving_direction", "DrivingDirection")
            .unwrap();
        let args = parse(&["--period", "0s"]).unwrap();
        let err = start(&esgm, esgm.clock().clone(), &args).unwrap_err();
        assert!(format!("{err:#}").contains("period must be positive"), "{err:#}");
    }
}
