//! How a trajectory maps to iceoryx2 service names.
//!
//! Every trajectory owns two services in a *domain* (a namespace):
//!
//! | service                         | pattern           | carries                      |
//! |---------------------------------|-------------------|------------------------------|
//! | `esgm/<domain>/traj/<name>`     | publish-subscribe | the samples ([`crate::data_plane::payload`]) |
//! | `esgm/<domain>/wake/<name>`     | event             | "a sample was sent" wake-ups |
//!
//! The domain exists so that independent systems on one host, and tests running in
//! parallel, never meet: give each test its own ([`unique_domain`]). Data and wake-ups
//! live under separate kinds (`traj`, `wake`) rather than as `<name>/wake`, so no
//! trajectory name can collide with another trajectory's event service.
//!
//! Domains and trajectory names are restricted to ASCII letters, digits, `_`, `-`, `.`
//! and `:` — no `/`, so that the mapping stays one-to-one and reversible (a discovery
//! tool can read a trajectory name back from a service name).

use crate::data_plane::service::ShmService;
use std::sync::atomic::{AtomicU64, Ordering};

use iceoryx2::prelude::ServiceName;

/// The domain of the data plane's ports when none is given.
pub const DEFAULT_DOMAIN: &str = "default";

/// The domain of a system when none is given: the `esgm` command's default, so that a
/// program connecting without naming one reaches a system started with `esgm up`.
pub const SYSTEM_DOMAIN: &str = "esgm";

/// Prefix of every esgm service.
pub const SERVICE_PREFIX: &str = "esgm";

/// A domain or trajectory name that cannot become part of a service name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NameError {
    /// The name is empty; give the domain or trajectory a name.
    #[error("the {what} name is empty")]
    Empty {
        /// `"domain"` or `"trajectory"`.
        what: &'static str,
    },
    /// The name holds a character outside `[A-Za-z0-9_.:-]`; rename it.
    #[error(
        "the {what} name `{name}` contains `{character}`; use ASCII letters, digits, `_`, `-`, `.` or `:`"
    )]
    InvalidCharacter {
        /// `"domain"` or `"trajectory"`.
        what: &'static str,
        /// The rejected name.
        name: String,
        /// The first character not allowed.
        character: char,
    },
    /// The service name would exceed iceoryx2's limit; shorten the domain or name.
    #[error("the service name `{service}` is longer than iceoryx2's {max} bytes")]
    TooLong {
        /// The service name that was too long.
        service: String,
        /// iceoryx2's limit.
        max: usize,
    },
}

/// The iceoryx2 service names of one trajectory in one domain.
#[derive(Debug, Clone)]
pub struct TrajectoryServiceNames {
    data: ServiceName,
    wake: ServiceName,
}

impl TrajectoryServiceNames {
    /// The names for `trajectory` in `domain`.
    pub fn new(domain: &str, trajectory: &str) -> Result<Self, NameError> {
        check("domain", domain)?;
        check("trajectory", trajectory)?;
        Ok(Self {
            data: service_name(&data_service_name(domain, trajectory))?,
            wake: service_name(&wake_service_name(domain, trajectory))?,
        })
    }

    /// The publish-subscribe service carrying the samples.
    pub fn data(&self) -> &ServiceName {
        &self.data
    }

    /// The event service carrying wake-ups for blocking readers.
    pub fn wake(&self) -> &ServiceName {
        &self.wake
    }
}

/// `esgm/<domain>/traj/<trajectory>`, unchecked.
pub fn data_service_name(domain: &str, trajectory: &str) -> String {
    format!("{SERVICE_PREFIX}/{domain}/traj/{trajectory}")
}

/// `esgm/<domain>/wake/<trajectory>`, unchecked.
pub fn wake_service_name(domain: &str, trajectory: &str) -> String {
    format!("{SERVICE_PREFIX}/{domain}/wake/{trajectory}")
}

/// The coordinator's control service of `domain`: `esgm/<domain>/control`.
pub fn control_service(domain: &str) -> Result<ServiceName, NameError> {
    check("domain", domain)?;
    service_name(&format!("{SERVICE_PREFIX}/{domain}/control"))
}

/// The coordinator's wake-up of `domain`, `esgm/<domain>/control-wake`: clients notify
/// it after sending a request, so an idle coordinator sleeps instead of polling.
pub fn control_wake_service(domain: &str) -> Result<ServiceName, NameError> {
    check("domain", domain)?;
    service_name(&format!("{SERVICE_PREFIX}/{domain}/control-wake"))
}

/// The doorbell of one connection's receiver thread, `esgm/<domain>/bell/<host>`: an
/// event service its location rings when the set of trajectories it mirrors changes.
pub fn doorbell_service(domain: &str, host: &str) -> Result<ServiceName, NameError> {
    check("domain", domain)?;
    check("host", host)?;
    service_name(&format!("{SERVICE_PREFIX}/{domain}/bell/{host}"))
}

/// A domain no other process or test on this host uses: `<prefix>-<pid>-<n>`, with `n`
/// counting calls in this process. Characters of `prefix` that names may not contain
/// become `_`, so a test can pass its own name (`module::test`).
pub fn unique_domain(prefix: &str) -> String {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let clean: String = prefix.chars().map(|c| if allowed(c) { c } else { '_' }).collect();
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    format!("{clean}-{}-{n}", std::process::id())
}

fn allowed(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | ':')
}

fn check(what: &'static str, name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty { what });
    }
    match name.chars().find(|c| !allowed(*c)) {
        Some(character) => {
            Err(NameError::InvalidCharacter { what, name: name.to_owned(), character })
        }
        None => Ok(()),
    }
}

fn service_name(name: &str) -> Result<ServiceName, NameError> {
    // Only length can fail here: the characters were checked above.
    ServiceName::new(name)
        .map_err(|_| NameError::TooLong { service: name.to_owned(), max: ServiceName::max_len() })
}

/// The name a process's iceoryx2 node carries: `esgm/<domain>/<role>` (at most
/// iceoryx2's 128 characters), so `iox2 node list`, dead-node cleanup and `esgm down`
/// can tell which system a node belonged to.
pub fn node_name(domain: &str, role: &str) -> iceoryx2::prelude::NodeName {
    let mut name = format!("{SERVICE_PREFIX}/{domain}/{role}");
    while name.len() > iceoryx2::prelude::NodeName::max_len() {
        name.pop();
    }
    iceoryx2::prelude::NodeName::new(&name)
        // Cut to iceoryx2's length above; only a byte it refuses would need the fallbacks.
        .or_else(|_| iceoryx2::prelude::NodeName::new(SERVICE_PREFIX))
        .unwrap_or_default()
}

/// The nodes of `domain` on this host, alive or not: `(name, alive)`. After a clean
/// stop (and cleanup of crashed processes) there are none.
///
/// An error means the nodes could not be listed (iceoryx2's node directory is
/// unreadable, say): "none" is never answered for "unknown", so a check that nothing
/// was left behind fails when it cannot look.
pub fn nodes_of(domain: &str) -> Result<Vec<(String, bool)>, iceoryx2::node::NodeListFailure> {
    use iceoryx2::node::{Node, NodeState, NodeView};
    let prefix = format!("{SERVICE_PREFIX}/{domain}/");
    let mut out = Vec::new();
    Node::<ShmService>::list(crate::data_plane::service::iceoryx2_config(), |state| {
        let (details, alive) = match &state {
            NodeState::Alive(v) => (v.details().clone(), true),
            NodeState::Dead(v) => (v.details().clone(), false),
            // A node being created or torn down, or one of another user: no details.
            _ => (None, false),
        };
        if let Some(d) = details {
            if d.name().as_str().starts_with(&prefix) {
                out.push((d.name().as_str().to_owned(), alive));
            }
        }
        iceoryx2::prelude::CallbackProgression::Continue
    })?;
    Ok(out)
}

/// The live processes attached to `domain`: each pid with the names of its nodes
/// there, this process included. What `esgm down` stops after the system it started.
pub fn processes_of(
    domain: &str,
) -> Result<std::collections::BTreeMap<u32, Vec<String>>, iceoryx2::node::NodeListFailure> {
    use iceoryx2::node::{Node, NodeState, NodeView};
    let prefix = format!("{SERVICE_PREFIX}/{domain}/");
    let mut out: std::collections::BTreeMap<u32, Vec<String>> = Default::default();
    Node::<ShmService>::list(crate::data_plane::service::iceoryx2_config(), |state| {
        if let NodeState::Alive(v) = &state {
            let name = v.details().as_ref().map(|d| d.name().as_str().to_owned());
            // A node of the domain without a readable process id is warned about below.
            let pid = v.id().pid::<ShmService>().ok().and_then(|p| u32::try_from(p.value()).ok());
            match (name, pid) {
                (Some(name), Some(pid)) if name.starts_with(&prefix) => {
                    out.entry(pid).or_default().push(name);
                }
                (Some(name), None) if name.starts_with(&prefix) => {
                    tracing::warn!(node = %name,
                        "a node of the domain has no readable process id");
                }
                _ => {}
            }
        }
        iceoryx2::prelude::CallbackProgression::Continue
    })?;
    Ok(out)
}

/// The domain of the services of one generation of a mirrored trajectory:
/// `<domain>.g<generation>`.
///
/// Why per generation: an iceoryx2 service lives while any port of it does, and a
/// value that still reads an image owns a share of its subscriber port (see
/// [`crate::client::holdings`]). A name destroyed and created again — possibly with another
/// cache, so other service settings — must not have to open the former trajectory's
/// services, which may linger for as long as such a value; and the former's chunks
/// are never the new one's.
pub fn generation_domain(domain: &str, generation: u64) -> String {
    format!("{domain}.g{generation}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_map_one_to_one() {
        let n = TrajectoryServiceNames::new("lab", "cam_images").unwrap();
        assert_eq!(n.data().as_str(), "esgm/lab/traj/cam_images");
        assert_eq!(n.wake().as_str(), "esgm/lab/wake/cam_images");
    }

    #[test]
    fn bad_names_are_rejected() {
        assert_eq!(
            TrajectoryServiceNames::new("", "x").unwrap_err(),
            NameError::Empty { what: "domain" }
        );
        assert!(matches!(
            TrajectoryServiceNames::new("d", "a/b"),
            Err(NameError::InvalidCharacter { character: '/', .. })
        ));
        let long = "x".repeat(300);
        assert!(matches!(TrajectoryServiceNames::new("d", &long), Err(NameError::TooLong { .. })));
    }

    #[test]
    fn unique_domains_are_valid_and_distinct() {
        let a = unique_domain("tests::round_trip");
        let b = unique_domain("tests::round_trip");
        assert_ne!(a, b);
        assert!(TrajectoryServiceNames::new(&a, "t").is_ok());
    }
}
