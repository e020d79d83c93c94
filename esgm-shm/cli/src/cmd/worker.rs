//! `esgm worker camera|robot|unit`: the processes of the tutorial's system. Each
//! connects under a stable name (a restarted worker takes its place and its
//! trajectories back), registers what it serves, and leaves when the coordinator is
//! gone.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use camera_publisher::{CameraSensor, SyntheticScene};
use cu_workers::{BlobDetectionUnit, BlobSelectionUnit, DrivingDirectionUnit};
use esgm_core::esgm::{CreateError, TrajectorySpec};
use esgm_core::{Esgm, FluentStreamPolicy, millis};
use esgm_shm::ShmEsgm;
use robot_publisher::RobotPublisher;

/// The roles.
#[derive(Debug, clap::Subcommand)]
pub enum Role {
    /// Serve a synthetic camera as a pull sensor of `Image`s.
    Camera {
        /// Sensor name.
        #[arg(long, default_value = "camera")]
        name: String,
        /// Scene seed (the same seed gives the same scene everywhere).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Number of moving blobs.
        #[arg(long, default_value_t = 3)]
        blobs: usize,
    },
    /// Push `RobotState`s at a rate, steering by the latest `DrivingDirection`.
    Robot {
        /// The trajectory it pushes into.
        #[arg(long, default_value = "robot_state")]
        trajectory: String,
        /// The trajectory it steers by.
        #[arg(long, default_value = "driving_direction")]
        follow: String,
        /// Milliseconds between states.
        #[arg(long, default_value_t = 100)]
        period_ms: u32,
    },
    /// Serve a built-in computational unit: BlobDetection, BlobSelection or
    /// DrivingDirection.
    Unit {
        /// The unit's name.
        name: String,
    },
}

impl Role {
    /// The stable name of this worker in the registry and in logs.
    pub fn process_name(&self) -> String {
        match self {
            Role::Camera { name, .. } => format!("camera-{name}"),
            Role::Robot { trajectory, .. } => format!("robot-{trajectory}"),
            Role::Unit { name } => format!("unit-{name}"),
        }
    }
}

/// Runs the role until the coordinator is gone.
pub fn run(domain: &str, role: &Role) -> anyhow::Result<()> {
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(role.process_name())
        // Short: a worker notices quickly that its coordinator is gone.
        .timeout(Duration::from_secs(2))
        .connect()
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    let _robot = match role {
        Role::Camera { name, seed, blobs } => {
            let scene = SyntheticScene::builder().blobs(*blobs).seed(*seed).create()?;
            esgm.add_sensor_interface(
                name,
                CameraSensor::<SyntheticScene>::TYPE_NAME,
                Arc::new(CameraSensor::new(scene)),
            )?;
            None
        }
        Role::Unit { name } => {
            let (output, inputs, unit): (_, _, Arc<dyn esgm_core::esgm::CompUnit>) =
                match name.as_str() {
                    BlobDetectionUnit::NAME => (
                        BlobDetectionUnit::OUTPUT_TYPE,
                        BlobDetectionUnit::input_types(),
                        Arc::new(BlobDetectionUnit::default()),
                    ),
                    BlobSelectionUnit::NAME => (
                        BlobSelectionUnit::OUTPUT_TYPE,
                        BlobSelectionUnit::input_types(),
                        Arc::new(BlobSelectionUnit),
                    ),
                    DrivingDirectionUnit::NAME => (
                        DrivingDirectionUnit::OUTPUT_TYPE,
                        DrivingDirectionUnit::input_types(),
                        Arc::new(DrivingDirectionUnit::default()),
                    ),
                    other => bail!(
                        "unknown unit `{other}`; built in: BlobDetection, BlobSelection, \
                         DrivingDirection"
                    ),
                };
            esgm.add_comp_unit(name, output, inputs, unit)?;
            None
        }
        Role::Robot { trajectory, follow, period_ms } => {
            Some(robot(&esgm, trajectory, follow, *period_ms)?)
        }
    };
    tracing::info!("serving");
    // Leave when the coordinator is gone (two failed pings in a row).
    let mut misses = 0;
    while misses < 2 {
        std::thread::sleep(Duration::from_millis(250));
        misses = if esgm.ping() { 0 } else { misses + 1 };
    }
    tracing::info!("the coordinator is gone; leaving");
    Ok(())
}

/// The robot: its state trajectory (created, or taken back after a restart), then,
/// once the direction trajectory exists, a publisher following it.
fn robot(
    esgm: &ShmEsgm,
    trajectory: &str,
    follow: &str,
    period_ms: u32,
) -> anyhow::Result<RobotPublisher> {
    // The seed's "reasonable" constraints; one producer in order, so no reordering.
    let policy = FluentStreamPolicy::reasonable(millis(50), 600)?.reorder(false);
    let spec = TrajectorySpec::primitive(trajectory, "RobotState").policy(policy);
    let states = match esgm.create_trajectory(spec) {
        Ok(t) => t,
        Err(CreateError::EntityStructureAlreadyExists { .. }) => {
            esgm.get_entity_trajectory_structure(trajectory)?
        }
        Err(e) => return Err(e.into()),
    };
    let deadline = Instant::now() + Duration::from_secs(60);
    let directions = loop {
        if let Ok(d) = esgm.get_entity_trajectory_structure(follow) {
            break d;
        }
        if Instant::now() > deadline || !esgm.ping() {
            bail!("`{follow}` was never created");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let clock = esgm.local().clock().clone();
    Ok(RobotPublisher::builder(states, clock)
        .period(millis(i64::from(period_ms)))
        .follow(directions)
        .create()?)
}
