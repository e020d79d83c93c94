//! `esgm worker camera|robot|unit`: the processes of the tutorial's system. Each
//! connects under a stable name (a restarted worker takes its place and its
//! trajectories back), registers what it serves, and serves while its system lives:
//! through a slow or crashed coordinator, leaving only once the system was stopped
//! (`esgm_shm::attach`).
//!
//! The camera and the robot are their publishers' own code
//! ([`camera_publisher::serve`], [`robot_publisher::serve`]): `esgm worker camera` and
//! the `camera-publisher` binary are one program, and so are `esgm worker robot` and
//! `robot-publisher`.

use std::num::NonZeroUsize;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use camera_publisher::CameraArgs;
use cu_workers::{BlobDetectionUnit, BlobSelectionUnit, DrivingDirectionUnit, MovingAverageUnit};
use esgm_core::Esgm;
use esgm_core::esgm::{CompUnit, InputType, TypedUnitAdapter};
use esgm_shm::ShmEsgm;
use esgm_shm::attach::serve_while_system_lives;
use robot_publisher::RobotArgs;

use crate::config;
use crate::config::decl::BUILTIN_UNITS;

/// The roles.
#[derive(Debug, clap::Subcommand)]
pub enum Role {
    /// Serve a synthetic camera (or a directory of frames) as a pull sensor of
    /// `Image`s: the `camera-publisher` process.
    Camera(CameraArgs),
    /// Push `RobotState`s at a rate, steering by the latest `DrivingDirection`: the
    /// `robot-publisher` process.
    Robot(RobotArgs),
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
        match self {
            Role::Camera(args) => args.process_name(),
            Role::Robot(args) => args.process_name(),
            Role::Unit { name, .. } => {
                std::env::var(esgm_shm::WORKER_ENV).unwrap_or_else(|_| config::unit_process(name))
            }
        }
    }
}

/// Runs the role until the coordinator is gone.
pub fn run(domain: &str, role: &Role) -> anyhow::Result<()> {
    let (name, builtin, type_name, window) = match role {
        Role::Camera(args) => return camera_publisher::serve::run(domain, args),
        Role::Robot(args) => return robot_publisher::serve::run(domain, args),
        Role::Unit { name, builtin, type_name, window } => (name, builtin, type_name, window),
    };
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(role.process_name())
        .connect()
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    serve_unit(&esgm, name, builtin.as_deref().unwrap_or(name), type_name.as_deref(), *window)?;
    tracing::info!(unit = %name, "serving");
    // Leave once the system was stopped (no coordinator for half a second, and no
    // registry kept); a crashed coordinator is waited for.
    serve_while_system_lives(&esgm, None, Duration::from_millis(500));
    tracing::info!(unit = %name, "the system was stopped; leaving");
    Ok(())
}

fn serve_unit(
    esgm: &ShmEsgm,
    name: &str,
    builtin: &str,
    type_name: Option<&str>,
    window: usize,
) -> anyhow::Result<()> {
    let (output, inputs, unit) = builtin_unit(builtin, type_name, window)?;
    esgm.add_comp_unit(name, &output, inputs, unit)?;
    Ok(())
}

/// A built-in unit by name: its output type, input types and implementation (used by
/// the unit worker and by `esgm replay --in-process`).
pub fn builtin_unit(
    builtin: &str,
    type_name: Option<&str>,
    window: usize,
) -> anyhow::Result<(String, Vec<InputType>, Arc<dyn CompUnit>)> {
    Ok(match builtin {
        BlobDetectionUnit::NAME => (
            BlobDetectionUnit::OUTPUT_TYPE.into(),
            BlobDetectionUnit::input_types(),
            Arc::new(TypedUnitAdapter(BlobDetectionUnit::default())),
        ),
        BlobSelectionUnit::NAME => (
            BlobSelectionUnit::OUTPUT_TYPE.into(),
            BlobSelectionUnit::input_types(),
            Arc::new(TypedUnitAdapter(BlobSelectionUnit)),
        ),
        DrivingDirectionUnit::NAME => (
            DrivingDirectionUnit::OUTPUT_TYPE.into(),
            DrivingDirectionUnit::input_types(),
            Arc::new(TypedUnitAdapter(DrivingDirectionUnit::default())),
        ),
        MovingAverageUnit::BUILTIN => {
            let t = type_name.context("MovingAverage needs --type, the type it averages")?;
            let window = NonZeroUsize::new(window).context("--window must be at least 1")?;
            let unit = MovingAverageUnit::new(window, t);
            (t.to_owned(), unit.input_types(), Arc::new(unit))
        }
        other => bail!("unknown built-in unit `{other}`; built in: {}", BUILTIN_UNITS.join(", ")),
    })
}
