//! The reasons an operation fails that several layers share: a limit reached, a peer
//! that cannot be reached. A leaf: it imports nothing of esgm, so the store can name
//! them without depending on the API layer ([`crate::esgm`]) that re-exports them,
//! where users find them.

mod limit;
mod unreachable;

pub use limit::{Limit, LimitReached};
pub use unreachable::{Peer, Unreachable};
