//! The trained fields — instant-ngp snapshots, nerfacto runs, splatfacto checkpoints — loaded,
//! sampled and rendered against references that share none of their code (NumPy written from
//! the formats' conventions, closed forms, nerfstudio's own renders): one test binary, so the
//! fixture writers are compiled once for all of them.
//!
//! - instant-ngp: [`ingp_snapshot`] (the loader), [`ingp_features`], [`ingp_render`],
//!   [`ingp_marcher`] (instant-ngp's own marcher);
//! - nerfacto: [`nerfacto_run`] (the loader), [`nerfacto_proposal`] (its sampler),
//!   [`nerfacto_far`] (the contracted far field), [`nerfstudio_renders`] (a real run);
//! - [`splatfacto_run`]; [`joint_trained`]: two trained fields occluding each other.

#[path = "../common_fields/mod.rs"]
mod common_fields;
#[path = "../common_ingp/mod.rs"]
#[allow(dead_code)] // the writers of bytes these tests do not use
mod common_ingp;
#[path = "../common_nerfacto/mod.rs"]
mod common_nerfacto;

mod ingp_features;
mod ingp_marcher;
mod ingp_render;
mod ingp_snapshot;
mod joint_trained;
mod nerfacto_far;
mod nerfacto_proposal;
mod nerfacto_run;
mod nerfstudio_renders;
mod splatfacto_run;
