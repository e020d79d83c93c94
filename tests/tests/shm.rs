//! The conformance suite on the shared-memory runtime: the same functions as
//! `in_process.rs`, each against a coordinator of its own in a unique domain, writing
//! through one connection and reading through another (two locations), so every
//! semantic is checked across the process boundary.

esgm_tests::conformance_tests!(shm, esgm_tests::ShmHarness::new);
