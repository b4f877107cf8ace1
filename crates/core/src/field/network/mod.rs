//! The pieces the trained networks are built of, shared by instant-ngp snapshots and nerfacto
//! runs: the multiresolution hash-grid encoding, the fully fused MLP, and the spherical-harmonics
//! direction encoding (whose basis 3D Gaussian splats use too).

mod density;
mod hashgrid;
mod mlp;
mod sh4;
mod weights;

pub(crate) use density::exp_density;
pub use hashgrid::TableStorage;
pub(crate) use hashgrid::{correctly_rounded, HashGrid, HashGridConfig};
#[doc(hidden)]
pub use mlp::NetworksBench;
pub(crate) use mlp::{LastInputs, Mlp, MlpConfig};
pub(crate) use sh4::{sh4, sh_basis};
pub(crate) use weights::non_finite;
