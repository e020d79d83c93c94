//! How many ports and nodes each esgm service is created for: the limits of a domain
//! (P6), as settings.
//!
//! iceoryx2 sizes a service for its ports when the service is created, and refuses a
//! port past that number. So every number here is a setting with a default that fits a
//! robot, and reaching one is [`esgm_core::esgm::LimitReached`] for the process that
//! would exceed it, never a domain that stops serving:
//!
//! | setting | default | sizes | set with |
//! |---|---|---|---|
//! | [`DomainLimits::max_processes`] | [`DEFAULT_MAX_PROCESSES`] | the control and administration services: one client, subscriber and listener per process | `esgm up --max-processes N` |
//! | [`DomainLimits::readers`] | [`DEFAULT_READERS`] | a trajectory's services when it names no `readers` of its own | `esgm up --readers N` |
//! | a trajectory's [`Readers`] | the domain's | its data, wake-up, violations, join and inbox services: one subscriber (or adder) per process, two waiting threads per process | `readers = N` (TOML), `esgm traj create --readers N`, `TrajectorySpec::readers` |
//!
//! Every service also keeps [`TOOL_RESERVE`] ports beyond its limit for short-lived
//! tools (`esgm latest`, `esgm push`, `esgm stats`…, [`crate::ShmEsgmBuilder::tool`]):
//! esgm counts a long-lived process against the limit itself before it opens a port,
//! so when a limit is reached the command that shows it, and every later command,
//! still gets in.
//!
//! What a limit costs (iceoryx2 0.10, measured on this machine; ARCHITECTURE.md has
//! the table): shared memory is mapped for the largest number of samples the ports
//! can hold but committed only as samples are written, so the cost of a limit is
//! mostly private memory in the ports that are sized by it — a notifier keeps about
//! 1.3 KiB per listener it may wake, a subscriber about 3.6 KiB per publisher it may
//! hear.

use esgm_core::esgm::{Limit, LimitReached};

/// Processes a domain admits by default: a Nav2 base runs 30–80, with room to spare.
pub const DEFAULT_MAX_PROCESSES: usize = 128;

/// Reader processes a trajectory admits by default. A `tf`-like stream read by every
/// process sets its own `readers` (up to the domain's processes).
pub const DEFAULT_READERS: usize = 16;

/// Ports every service keeps beyond its limit for short-lived tools (see the module
/// docs).
pub const TOOL_RESERVE: usize = 8;

/// The most a limit may be set to: past it, the ports' own bookkeeping (not the
/// samples) costs megabytes per service.
pub const MAX_LIMIT: usize = 4096;

/// The limits of one domain, set when its coordinator starts (`esgm up`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DomainLimits {
    /// Processes connected at once (each with its connection to the domain).
    pub max_processes: usize,
    /// A trajectory's readers when its declaration names none.
    pub readers: usize,
}

impl Default for DomainLimits {
    fn default() -> Self {
        Self { max_processes: DEFAULT_MAX_PROCESSES, readers: DEFAULT_READERS }
    }
}

/// A limit set to a value it cannot have.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{setting} = {value}: it must be between 1 and {max}")]
pub struct IllegalLimit {
    /// The setting.
    pub setting: &'static str,
    /// The value given.
    pub value: usize,
    /// The largest allowed.
    pub max: usize,
}

/// Checks that `value` is a usable setting of `setting`, at most `max`.
pub fn check_limit(setting: &'static str, value: usize, max: usize) -> Result<(), IllegalLimit> {
    if value == 0 || value > max {
        return Err(IllegalLimit { setting, value, max });
    }
    Ok(())
}

impl DomainLimits {
    /// Checks both settings: between 1 and `MAX_LIMIT`, and readers no more than
    /// processes (a trajectory cannot be read by more processes than the domain has).
    pub fn check(&self) -> Result<(), IllegalLimit> {
        check_limit("max-processes", self.max_processes, MAX_LIMIT)?;
        check_limit("readers", self.readers, self.max_processes)
    }

    /// Ports of a domain-wide service (one per process) with the tools' reserve.
    pub fn process_ports(&self) -> usize {
        self.max_processes + TOOL_RESERVE
    }

    /// Nodes that may open a domain-wide service: a process has up to three (its
    /// connection's, its control client's and its receiver's), and a margin covers
    /// nodes being torn down while new ones join.
    pub fn process_nodes(&self) -> usize {
        3 * self.process_ports() + 16
    }

    /// The readers of a trajectory that asks for `readers` (`None`: the default).
    pub fn readers_of(&self, readers: Option<usize>) -> Result<Readers, IllegalLimit> {
        let n = readers.unwrap_or(self.readers);
        check_limit("readers", n, self.max_processes)?;
        Ok(Readers(n))
    }
}

/// How many processes may read one trajectory at once: the capacity its services are
/// created with, which every process derives from the trajectory's record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Readers(pub usize);

impl Default for Readers {
    fn default() -> Self {
        Self(DEFAULT_READERS)
    }
}

impl Readers {
    /// Subscribers of its data and violations services, and publishers of its inbox
    /// (processes adding to it): one per process, with the tools' reserve.
    pub fn ports(self) -> usize {
        self.0 + TOOL_RESERVE
    }

    /// Nodes that may open its services: a process's connection node and its
    /// receiver's, and a margin for nodes being torn down.
    pub fn nodes(self) -> usize {
        2 * self.ports() + 4
    }

    /// The error for `limit` of `trajectory` reached. Threads waiting on its samples
    /// are two per reader ([`crate::TrajectoryQos::wake_capacity`]).
    pub fn reached(self, limit: Limit, trajectory: &str) -> LimitReached {
        let value = match limit {
            Limit::Waiters => 2 * self.0,
            _ => self.0,
        };
        LimitReached::trajectory(limit, trajectory, value)
    }
}

/// How an event service is sized: its listeners, notifiers and nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EventCapacity {
    /// Listeners (threads woken by it).
    pub listeners: usize,
    /// Notifiers (ports that wake them).
    pub notifiers: usize,
    /// Nodes that may open it.
    pub nodes: usize,
}

/// Notifiers or listeners on the side of an event service that only its writer holds
/// (a bridge or a restarted writer may overlap it briefly).
const WRITER_SIDE: usize = 4;

impl EventCapacity {
    /// A trajectory's violations wake-up: the writer notifies, each reader's receiver
    /// waits.
    pub fn violations(readers: Readers) -> Self {
        Self { listeners: readers.ports(), notifiers: WRITER_SIDE, nodes: readers.nodes() }
    }

    /// A service every reader (or adder) rings and only the writer listens to: a
    /// trajectory's join and inbox wake-ups.
    pub fn to_writer(readers: Readers) -> Self {
        Self { listeners: WRITER_SIDE, notifiers: readers.ports(), nodes: readers.nodes() }
    }

    /// A domain-wide wake-up every process both rings and waits on.
    pub fn domain(limits: &DomainLimits) -> Self {
        Self {
            listeners: limits.process_ports(),
            notifiers: limits.process_ports(),
            nodes: limits.process_nodes(),
        }
    }

    /// A process's own wake-up (its receiver's doorbell).
    pub fn own() -> Self {
        Self { listeners: WRITER_SIDE, notifiers: WRITER_SIDE, nodes: 2 * WRITER_SIDE }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_are_checked() {
        DomainLimits::default().check().unwrap_or_else(|e| unreachable!("{e}"));
        let none = DomainLimits { max_processes: 0, ..DomainLimits::default() };
        assert_eq!(none.check().map_err(|e| e.setting), Err("max-processes"));
        let wide = DomainLimits { max_processes: 8, readers: 16 };
        assert_eq!(wide.check().map_err(|e| e.setting), Err("readers"));
        let limits = DomainLimits { max_processes: 128, readers: 16 };
        assert_eq!(limits.readers_of(None), Ok(Readers(16)));
        assert_eq!(limits.readers_of(Some(128)), Ok(Readers(128)));
        assert!(limits.readers_of(Some(129)).is_err(), "more readers than processes");
        assert!(limits.readers_of(Some(0)).is_err());
    }

    #[test]
    fn every_service_keeps_the_tools_reserve() {
        let r = Readers(64);
        assert_eq!(r.ports(), 64 + TOOL_RESERVE);
        let qos = crate::TrajectoryQos::default().readers(r);
        assert!(qos.wake_capacity().listeners >= 2 * 64, "two waiting threads per reader");
        assert!(EventCapacity::to_writer(r).notifiers > 64);
        let limits = DomainLimits::default();
        assert!(EventCapacity::domain(&limits).notifiers > DEFAULT_MAX_PROCESSES);
        let e = r.reached(Limit::Readers, "tf").to_string();
        assert!(e.contains("readers = 64"), "{e}");
    }
}
