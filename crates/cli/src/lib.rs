//! The `nerfx` command's library: what the command does besides rendering, kept apart from
//! its arguments so the tests can drive it: farm jobs for the engines studios run
//! ([`farm`]).
#![deny(missing_docs)]

pub mod farm;
