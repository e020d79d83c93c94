//! The conformance suite on the shared-memory runtime: the same functions as
//! `in_process.rs`, each against a coordinator of its own in a unique domain.

esgm_tests::conformance_tests!(esgm_tests::ShmHarness::new);
