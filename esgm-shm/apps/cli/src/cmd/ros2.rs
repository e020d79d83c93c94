//! `esgm ros2 …`: esgm beside ROS 2, served by the `esgm-ros2` executable (crate
//! `esgm-ros2`, which holds the DDS stack so this command does not build it).

/// `esgm ros2` options: everything is esgm-ros2's own (`esgm ros2 --help`).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Arguments of `esgm-ros2` (e.g. `--import /camera/image_raw:sensor_msgs/msg/Image
    /// --export driving_direction`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

/// Runs `esgm-ros2 --domain <domain> args…`.
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    crate::external::run("esgm-ros2", "esgm-ros2", domain, &a.args)
}
