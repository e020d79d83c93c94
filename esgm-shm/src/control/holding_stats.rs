//! What a process reports of its shared-memory holdings (the admin channel's and the
//! coordinator's figures). Defined here, where the coordinator's protocol reads it,
//! and made by the client (`holdings`, where users find it), so that control needs
//! nothing of the client.

/// What a process holds in shared memory on behalf of its values, and what it had to
/// copy: how to check that images from other processes reach this one without a copy.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct HoldingStats {
    /// Received samples borrowed now, because values in this process read them in
    /// place.
    pub held_now: usize,
    /// Received samples read in place where they arrived, since the start.
    pub held_total: u64,
    /// Received samples with large octets that were copied instead, because their
    /// subscriber's borrow budget was spent (values kept too many older ones).
    pub copied_over_budget: u64,
    #[serde(default)]
    /// Received samples without large octets whose archive was copied onto this
    /// process's heap for the same reason (still read in place there, never decoded;
    /// not an image copy).
    pub copied_small: u64,
    /// Images this process published from loans: pixels written in place by their
    /// producer, never copied ([`esgm_core::OctetsAllocator`]).
    pub sent_in_place: u64,
    /// Images this process published by encoding them: their pixels were copied from
    /// this process's heap into shared memory once.
    pub sent_copied: u64,
}

impl HoldingStats {
    /// Image copies this process made: received images copied onto its heap, and
    /// images it copied into shared memory to send.
    pub fn copies(&self) -> u64 {
        self.copied_over_budget + self.sent_copied
    }
}
