//! The files trained fields come in, read without their trainers: torch checkpoints (a zip
//! archive holding a pickle and raw tensor storages), instant-ngp's msgpack snapshots and PLY
//! point clouds.

mod checkpoint;
mod msgpack;
mod ply;
mod zip;

pub(crate) use checkpoint::{Checkpoint, DType};
pub(crate) use msgpack::{read_document, Doc, Payload, PayloadKind, Verdict};
pub(crate) use ply::{Element, Ply, Property, Scalar};
pub(crate) use zip::Zip;
