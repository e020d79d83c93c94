//! One import for a program of a shared-memory system: `use esgm_shm::prelude::*;`
//! brings [`connect`](crate::connect) and [`ShmEsgm`](crate::ShmEsgm) with everything
//! of [`esgm_core::prelude`] — the two interface traits (a trajectory handle's methods),
//! the data model's everyday types and the time helpers — so the same code runs on
//! either runtime with one `use` line changed.

pub use super::{ShmEsgm, connect};
pub use esgm_core::prelude::*;
