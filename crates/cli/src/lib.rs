//! The `nerfx` command's library: what the command does besides rendering, kept apart from
//! its arguments so the tests can drive it: the frames a command renders and their file
//! names ([`frames`]), and farm jobs for the engines studios run ([`farm`]).
#![deny(missing_docs)]

pub mod farm;
pub mod frames;
