//! The end of a domain a scenario made for its peers.
//!
//! A peer process the benchmark kills (a bridge, `esgm-ros2`) stays counted as a user
//! of the futex words it mapped ([`esgm_shm::unstable::WakeWord`]), so their files would stay in
//! `/dev/shm` after the run. A scenario holds a [`DomainEnd`] for each domain it
//! made, declared right after the domain's name, so it is dropped after every process
//! and connection of the domain, and removes the words as `esgm down` would.

/// Removes the futex words of its domain when dropped (see the module docs).
#[derive(Debug)]
pub struct DomainEnd(String);

impl DomainEnd {
    /// Ends `domain` when dropped.
    pub fn new(domain: &str) -> Self {
        DomainEnd(domain.to_owned())
    }
}

impl Drop for DomainEnd {
    fn drop(&mut self) {
        esgm_shm::process::remove_domain_files(&self.0);
    }
}
