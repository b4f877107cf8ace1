//! The tiled ray marcher.
