//! nerfx-core: trained radiance fields and Gaussian splats rendered from Blender cameras.
//!
//! Data flows one way: a **shot** (camera per frame, from Blender) gives [`camera::Camera`]s,
//! cameras give world-space [`camera::Ray`]s, the [`scene::Scene`] carries them into each
//! field's frame, the [`render`] marcher samples the [`field::Field`]s along them and
//! composites the samples into [`image::Planes`], which are written as EXR and PNG.
//!
//! ```
//! use nerfx_core::{demo, render::{render, Outputs, RenderSettings, Quality}};
//! let (scene, camera) = demo::scene_and_camera(64, 36).unwrap();
//! let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
//! let planes = render(&scene, &camera, camera.full_window(), &settings).unwrap();
//! assert_eq!(planes.width, 64);
//! ```
#![deny(missing_docs)]

pub mod camera;
pub mod composite;
pub mod demo;
pub mod error;
pub mod field;
pub mod image;
mod input;
mod json;
mod output;
pub mod render;
mod rng;
pub mod scene;
pub mod shot_render;
pub mod standin;

pub use error::{Error, Result};
pub use input::read_text;
pub use json::parse_json;
pub use output::{remove_stale_temporaries, write_file};
pub use rng::SplitMix64;
