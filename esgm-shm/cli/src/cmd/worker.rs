//! `esgm worker camera|robot|unit`: the processes of the tutorial's system. Each
//! connects under a stable name (a restarted worker takes its place and its
//! trajectories back), registers what it serves, and leaves when the coordinator is
//! gone.

use std::num::NonZeroUsize;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use camera_publisher::{CameraSensor, FrameSource, ImageDirectory, SyntheticScene};
use cu_workers::{BlobDetectionUnit, BlobSelectionUnit, DrivingDirectionUnit, MovingAverageUnit};
use esgm_core::esgm::{CompUnit, CreateError, TrajectorySpec};
use esgm_core::{Esgm, FluentStreamPolicy, millis};
use esgm_shm::ShmEsgm;

use crate::config;
use crate::config::decl::BUILTIN_UNITS;
use crate::policy_args::duration;
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
        /// Frame width in pixels.
        #[arg(long, default_value_t = 640)]
        width: u32,
        /// Frame height in pixels.
        #[arg(long, default_value_t = 480)]
        height: u32,
        /// Serve the PNG/JPEG frames of this directory instead of a synthetic scene.
        #[arg(long)]
        dir: Option<std::path::PathBuf>,
        /// With --dir: how long each frame is shown (`100ms`).
        #[arg(long, default_value = "100ms")]
        frame_period: String,
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
    /// Serve a built-in computational unit: BlobDetection, BlobSelection,
    /// DrivingDirection or MovingAverage.
    Unit {
        /// The unit's name.
        name: String,
        /// Which built-in unit (default: the one called NAME).
        #[arg(long)]
        builtin: Option<String>,
        /// MovingAverage: the type it averages.
        #[arg(long = "type")]
        type_name: Option<String>,
        /// MovingAverage: samples in the window.
        #[arg(long, default_value_t = 5)]
        window: usize,
    },
}

impl Role {
    /// The stable name of this worker in the registry and in logs.
    /// The supervisor names it in `ESGM_WORKER`; by hand, it is named after its role.
    pub fn process_name(&self) -> String {
        if let Ok(name) = std::env::var(esgm_shm::WORKER_ENV) {
            return name;
        }
        match self {
            Role::Camera { name, .. } => config::sensor_process(name),
            Role::Robot { trajectory, .. } => config::robot_process(trajectory),
            Role::Unit { name, .. } => config::unit_process(name),
        }
    }
}

/// Runs the role until the coordinator is gone.
pub fn run(domain: &str, role: &Role) -> anyhow::Result<()> {
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(role.process_name())
        // A gone coordinator is noticed at once (no server); the deadline is only for a
        // slow one, which a loaded machine makes common.
        .timeout(Duration::from_secs(5))
        .connect()
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    let _robot = match role {
        Role::Camera { name, seed, blobs, width, height, dir, frame_period } => {
            match dir {
                Some(dir) => {
                    let period = duration(frame_period).context("--frame-period")?;
                    let frames = ImageDirectory::open(dir, period)?;
                    serve_camera(&esgm, name, frames)?;
                }
                None => {
                    let scene = SyntheticScene::builder()
                        .blobs(*blobs)
                        .seed(*seed)
                        .width(*width)
                        .height(*height)
                        .create()?;
                    serve_camera(&esgm, name, scene)?;
                }
            }
            None
        }
        Role::Unit { name, builtin, type_name, window } => {
            serve_unit(
                &esgm,
                name,
                builtin.as_deref().unwrap_or(name),
                type_name.as_deref(),
                *window,
            )?;
            None
        }
        Role::Robot { trajectory, follow, period_ms } => {
            Some(robot(&esgm, trajectory, follow, *period_ms)?)
        }
    };
    tracing::info!("serving");
    // Leave when the coordinator is gone (for half a second).
    esgm.serve_until_coordinator_gone(Duration::from_millis(500));
    tracing::info!("the coordinator is gone; leaving");
    Ok(())
}

fn serve_camera<S: FrameSource + Send + Sync + 'static>(
    esgm: &ShmEsgm,
    name: &str,
    source: S,
) -> anyhow::Result<()> {
    esgm.add_sensor_interface(
        name,
        CameraSensor::<S>::TYPE_NAME,
        Arc::new(CameraSensor::new(source)),
    )?;
    Ok(())
}

fn serve_unit(
    esgm: &ShmEsgm,
    name: &str,
    builtin: &str,
    type_name: Option<&str>,
    window: usize,
) -> anyhow::Result<()> {
    let (output, inputs, unit): (String, _, Arc<dyn CompUnit>) = match builtin {
        BlobDetectionUnit::NAME => (
            BlobDetectionUnit::OUTPUT_TYPE.into(),
            BlobDetectionUnit::input_types(),
            Arc::new(BlobDetectionUnit::default()),
        ),
        BlobSelectionUnit::NAME => (
            BlobSelectionUnit::OUTPUT_TYPE.into(),
            BlobSelectionUnit::input_types(),
            Arc::new(BlobSelectionUnit),
        ),
        DrivingDirectionUnit::NAME => (
            DrivingDirectionUnit::OUTPUT_TYPE.into(),
            DrivingDirectionUnit::input_types(),
            Arc::new(DrivingDirectionUnit::default()),
        ),
        MovingAverageUnit::BUILTIN => {
            let t = type_name.context("MovingAverage needs --type, the type it averages")?;
            let window = NonZeroUsize::new(window).context("--window must be at least 1")?;
            let unit = MovingAverageUnit::new(window, t);
            (t.to_owned(), unit.input_types(), Arc::new(unit))
        }
        other => bail!("unknown built-in unit `{other}`; built in: {}", BUILTIN_UNITS.join(", ")),
    };
    esgm.add_comp_unit(name, &output, inputs, unit)?;
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
