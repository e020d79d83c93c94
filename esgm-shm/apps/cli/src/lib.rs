//! The parts of the `esgm` command other programs reuse: the configuration parser
//! ([`config`]) with the policy and time words it reads ([`policy_args`],
//! [`time_arg`]), how external subcommands are found ([`external`]), and the
//! foreground `esgm up` — a domain's coordinator with the supervisor of its workers
//! ([`serve`], [`supervise`]).
//!
//! They are a library so that the fuzzer (`esgm-fuzz`) parses hostile configuration
//! files with the very parser `esgm apply` runs, not a copy, and so that a program
//! that brings up a system of its own (esgm-bench's reference system) serves it as
//! `esgm up --config` does. The `esgm` binary uses them from here; everything else of
//! the command (its subcommands, dashboard and sessions) stays in the binary.

#![deny(missing_docs)]

pub mod config;
pub mod external;
pub mod policy_args;
pub mod serve;
pub mod span_arg;
pub mod stop_args;
pub mod supervise;
pub mod time_arg;
