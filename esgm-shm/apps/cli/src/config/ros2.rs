//! `[[ros2]]`: the system's node on the robot's ROS 2 graph (`esgm-ros2`) as a process
//! the system keeps running:
//!
//! ```toml
//! [[ros2]]
//! import = ["/camera/image_raw:sensor_msgs/msg/Image=images"]   # TOPIC:TYPE[=TRAJECTORY]
//! export = ["driving_direction=/cmd_dir"]                        # TRAJECTORY[=TOPIC]
//! ros_domain_id = 0                                               # else ROS_DOMAIN_ID
//! best_effort = false                                             # imports; depth = 10
//! ```
//!
//! The supervisor runs `esgm-ros2` (next to `esgm`, else on `PATH`) with these settings
//! and restarts it with backoff like any worker. The settings are checked when the file
//! is applied by `esgm-ros2 --check`, the same parser the process uses, so a topic
//! whose type does not map is refused there, with the line, not in a log later.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, bail};
use esgm_shm::control::ProcessSpec;
use serde::Deserialize;

use super::{Serves, Worker};

/// `[[ros2]]`: what this node imports from and exports to ROS 2.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Decl {
    /// Its process name, unique among the system's processes (default `ros2`).
    pub name: Option<String>,
    /// The ROS 2 domain (default: `ROS_DOMAIN_ID` of the coordinator, else 0).
    pub ros_domain_id: Option<u16>,
    /// Its node name (`/esgm/<name>`; default `esgm_<domain>`).
    pub node_name: Option<String>,
    /// Topics to import: `TOPIC:TYPE[=TRAJECTORY]`.
    #[serde(default)]
    pub import: Vec<String>,
    /// Trajectories to export: `TRAJECTORY[=TOPIC]`.
    #[serde(default)]
    pub export: Vec<String>,
    /// Read imported topics best effort.
    #[serde(default)]
    pub best_effort: bool,
    /// Keep-last depth of every topic (default 10).
    pub depth: Option<usize>,
}

/// The node's process: settings as `esgm-ros2` arguments, checked by `program --check`.
pub fn ros2_worker(d: &Ros2Decl, program: &Path) -> anyhow::Result<Worker> {
    if d.import.is_empty() && d.export.is_empty() {
        bail!("a [[ros2]] needs something to carry: import = [...] or export = [...]");
    }
    let mut args: Vec<String> = Vec::new();
    for i in &d.import {
        args.extend(["--import".into(), i.clone()]);
    }
    for e in &d.export {
        args.extend(["--export".into(), e.clone()]);
    }
    if let Some(id) = d.ros_domain_id {
        args.extend(["--ros-domain-id".into(), id.to_string()]);
    }
    if let Some(n) = &d.node_name {
        args.extend(["--node-name".into(), n.clone()]);
    }
    if d.best_effort {
        args.push("--best-effort".into());
    }
    if let Some(depth) = d.depth {
        args.extend(["--depth".into(), depth.to_string()]);
    }
    check(program, &args)?;
    let name = d.name.clone().unwrap_or_else(|| "ros2".to_owned());
    let spec = ProcessSpec {
        name: name.clone(),
        program: program.display().to_string(),
        args,
        env: Vec::new(),
    };
    Ok(Worker { spec, serves: Serves::Bridge(name), program: None })
}

/// Runs `program --check args…`, which parses the settings as the process will and
/// exits; its one-line error is this one's.
fn check(program: &Path, args: &[String]) -> anyhow::Result<()> {
    let out = Command::new(program)
        .arg("--check")
        .args(args)
        .output()
        .with_context(|| format!("cannot run {} to check the settings", program.display()))?;
    if out.status.success() {
        return Ok(());
    }
    let said = String::from_utf8_lossy(&out.stderr);
    let said = said.lines().last().unwrap_or_default().trim_start_matches("esgm-ros2: ");
    bail!("{said}")
}

/// The `esgm-ros2` executable, or why there is none.
pub fn ros2_program() -> anyhow::Result<std::path::PathBuf> {
    crate::external::find("esgm-ros2", "esgm-ros2")
        .context("a [[ros2]] runs the esgm-ros2 executable")
}
