//! Joining Zenoh: peer or client, explicit endpoints, or a Zenoh configuration file.

use std::path::PathBuf;

use zenoh::Wait as _;

/// How the bridge joins Zenoh.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ZenohArgs {
    /// Zenoh mode: `peer` (default) or `client` (through a router).
    #[arg(long, value_parser = ["peer", "client"])]
    pub mode: Option<String>,
    /// Listen on this Zenoh endpoint (e.g. `tcp/10.0.0.1:7447`); repeatable.
    #[arg(long)]
    pub listen: Vec<String>,
    /// Connect to this Zenoh endpoint (e.g. `tcp/10.0.0.2:7447`); repeatable.
    #[arg(long)]
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5). Without one, only the endpoints given here
    /// are used: no multicast scouting, no listening unless `--listen`.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// Zenoh refused a setting or a session (its message says which).
#[derive(Debug, thiserror::Error)]
#[error("zenoh: {0}")]
pub struct ZenohError(pub String);

impl ZenohError {
    /// Wraps any Zenoh error.
    pub fn from(e: impl std::fmt::Display) -> Self {
        ZenohError(e.to_string())
    }
}

fn json_list(items: &[String]) -> String {
    serde_json::Value::from(items.to_vec()).to_string()
}

impl ZenohArgs {
    /// The Zenoh configuration these arguments make.
    pub fn config(&self) -> Result<zenoh::Config, ZenohError> {
        let mut config = match &self.config {
            Some(path) => zenoh::Config::from_file(path).map_err(ZenohError::from)?,
            None => {
                let mut c = zenoh::Config::default();
                // Only the endpoints asked for: no multicast scouting, and no listening
                // on every interface (so gossip has no other address to pass on).
                c.insert_json5("scouting/multicast/enabled", "false").map_err(ZenohError::from)?;
                c.insert_json5("listen/endpoints", "[]").map_err(ZenohError::from)?;
                c
            }
        };
        if let Some(mode) = &self.mode {
            config.insert_json5("mode", &format!("\"{mode}\"")).map_err(ZenohError::from)?;
        }
        if !self.listen.is_empty() {
            config
                .insert_json5("listen/endpoints", &json_list(&self.listen))
                .map_err(ZenohError::from)?;
        }
        if !self.connect.is_empty() {
            config
                .insert_json5("connect/endpoints", &json_list(&self.connect))
                .map_err(ZenohError::from)?;
        }
        Ok(config)
    }

    /// Opens a session. Zenoh's shared-memory segments that a bridge killed before it
    /// could remove them left in `/dev/shm` are removed first (their creator is dead).
    pub fn open(&self) -> Result<zenoh::Session, ZenohError> {
        zenoh::shm::cleanup_orphaned_shm_segments();
        zenoh::open(self.config()?).wait().map_err(ZenohError::from)
    }
}
