//! Recordings: esgm trajectories in MCAP files (SPEC S1, U1, M1).
#![deny(missing_docs)]

pub mod view;
