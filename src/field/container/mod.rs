//! The files trained fields come in, read without their trainers: torch checkpoints (a zip
//! archive holding a pickle and raw tensor storages) and PLY point clouds.

mod checkpoint;
mod ply;
mod zip;

pub(crate) use checkpoint::{Checkpoint, DType};
pub(crate) use ply::{Ply, Property};
