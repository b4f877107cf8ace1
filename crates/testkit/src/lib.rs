//! nerfx-testkit: what nerfx's tests and benchmarks share, and nothing a render needs: the
//! benchmark suite with its scenes, plots and reports ([`bench`]), and references that share
//! no code with the renderer ([`reference`]).
#![deny(missing_docs)]

pub mod bench;
pub mod reference;
