//! The conformance suite on the in-process runtime.

esgm_tests::conformance_tests!(esgm_tests::InProcessHarness::new);
