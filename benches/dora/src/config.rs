//! The node's settings, from the environment esgm-bench gives it in the dataflow.

use std::path::PathBuf;

/// What the node does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Sends and measures.
    Ping,
    /// Answers.
    Pong,
}

/// How the node waits for its next event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wait {
    /// Busy-polls the event stream (`try_recv`).
    Spin,
    /// Blocks in `recv_timeout`.
    Block,
}

/// Everything the node is told; see the crate docs for the variables.
#[derive(Debug, Clone)]
pub struct Config {
    /// Ping or pong.
    pub role: Role,
    /// Spin or block.
    pub wait: Wait,
    /// The payload size (ping only).
    pub bytes: usize,
    /// Measured hops (ping only).
    pub samples: u64,
    /// Unmeasured hops first (ping only).
    pub warmup: u64,
    /// Where ping writes its figures.
    pub out: Option<PathBuf>,
    /// The core to run on, if pinned.
    pub core: Option<usize>,
}

fn var(name: &str) -> Result<Option<String>, String> {
    match std::env::var(name) {
        Ok(v) => Ok(Some(v)),
        Err(std::env::VarError::NotPresent) => Ok(None),
        Err(e) => Err(format!("{name}: {e}")),
    }
}

fn number<T: std::str::FromStr>(name: &str) -> Result<Option<T>, String> {
    var(name)?
        .map(|v| v.parse::<T>().map_err(|_| format!("{name} is not a number: {v:?}")))
        .transpose()
}

impl Config {
    /// Reads the `ESGM_DORA_*` variables.
    pub fn from_env() -> Result<Self, String> {
        let role = match var("ESGM_DORA_ROLE")?.as_deref() {
            Some("ping") => Role::Ping,
            Some("pong") => Role::Pong,
            other => return Err(format!("ESGM_DORA_ROLE must be ping or pong, not {other:?}")),
        };
        let wait = match var("ESGM_DORA_WAIT")?.as_deref() {
            Some("spin") => Wait::Spin,
            Some("block") | None => Wait::Block,
            Some(other) => {
                return Err(format!("ESGM_DORA_WAIT must be spin or block, not {other:?}"));
            }
        };
        let config = Self {
            role,
            wait,
            bytes: number("ESGM_DORA_BYTES")?.unwrap_or(0),
            samples: number("ESGM_DORA_SAMPLES")?.unwrap_or(0),
            warmup: number("ESGM_DORA_WARMUP")?.unwrap_or(0),
            out: var("ESGM_DORA_OUT")?.map(PathBuf::from),
            core: number("ESGM_DORA_CORE")?,
        };
        if role == Role::Ping && (config.bytes < crate::message::MIN_BYTES || config.out.is_none())
        {
            return Err(format!(
                "ping needs ESGM_DORA_BYTES >= {} and ESGM_DORA_OUT",
                crate::message::MIN_BYTES
            ));
        }
        Ok(config)
    }

    /// Pins this process to its core, before dora starts any thread in it (they
    /// inherit the mask).
    pub fn pin(&self) -> Result<(), String> {
        let Some(core) = self.core else { return Ok(()) };
        if core >= libc::CPU_SETSIZE as usize {
            return Err(format!("ESGM_DORA_CORE {core} is not a core"));
        }
        // SAFETY: a zeroed cpu_set_t is an empty set; CPU_SET writes inside it (the
        // core is below CPU_SETSIZE); sched_setaffinity reads `size_of` bytes of it.
        let rc = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(core, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if rc != 0 {
            return Err(format!("pinning to core {core}: {}", std::io::Error::last_os_error()));
        }
        Ok(())
    }
}
