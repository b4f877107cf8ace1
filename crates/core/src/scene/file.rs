//! The scene file: which fields, where, and how they are cropped.
//!
//! ```json
//! { "instances": [
//!     { "name": "environment", "field": { "analytic": { "primitives": [] } } },
//!     { "name": "statue", "field": { "analytic": { "primitives": [] } },
//!       "object": "NeRF",
//!       "crop": { "center": [0, 0, 0], "scale": [2, 2, 2], "rotation": [0, 0, 0] } },
//!     { "name": "garden", "field": { "ingp": { "path": "garden.ingp", "sampler": "ngp" } } },
//!     { "name": "poster", "field": { "nerfacto": { "path": "outputs/poster/nerfacto/run1",
//!                                                "sampler": "proposal" } } },
//!     { "name": "scan", "field": { "splats": { "path": "scan.spz", "axes": "rub",
//!                                              "antialiased": false } } } ] }
//! ```
//! An optional `"colorspace"` (`"acescg"`, …; see [`OutputColorSpace`]) says which colour
//! space the scene's images are written in.
//! An instance is placed by `world_from_field` (row-major 4×4, default identity) or, when
//! `object` is given, by that object's `matrix_world` in the shot, read per frame.
//! A nerfacto instance is sampled by its own proposal networks (`"sampler": "proposal"`, the
//! default: what nerfstudio shows) or marched by nerfx's occupancy estimator
//! (`"occupancy"`, the default for a run whose checkpoint holds no proposal networks). An
//! instant-ngp instance is marched by nerfx's occupancy estimator (`"occupancy"`, the
//! default) or by instant-ngp's own marcher (`"ngp"`: what its viewer shows). Field
//! files named by a relative path are found next to the scene file (the path is made
//! absolute when the scene file is read).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DMat4;
use serde::{Deserialize, Serialize};

use super::instance::FieldHandle;
use super::{CropBox, Instance, NgpInstance, ProposalInstance, Scene, SplatInstance};
use crate::error::{Error, Result};
use crate::field::{Analytic, Axes, IngpField, NerfactoField, Splats};
use crate::image::OutputColorSpace;

/// Where an instance's field comes from.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum FieldSource {
    /// Analytic primitives, inline.
    Analytic(Analytic),
    /// An instant-ngp snapshot (`.ingp` or `.msgpack`), queried in the NeRF world frame of
    /// its training poses.
    Ingp {
        /// The snapshot file (relative paths: from the scene file's folder).
        path: PathBuf,
        /// Where the field is sampled along each ray: `ngp` or `occupancy` (absent: the
        /// occupancy marcher).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        sampler: Option<Sampler>,
    },
    /// A nerfstudio nerfacto run directory (`config.yml`, `dataparser_transforms.json`,
    /// `nerfstudio_models/step-*.ckpt`), queried in nerfstudio's normalised frame.
    Nerfacto {
        /// The run directory (relative paths: from the scene file's folder).
        path: PathBuf,
        /// Where the field is sampled along each ray: `proposal` or `occupancy` (absent: by
        /// its proposal networks when the checkpoint holds them, else by the occupancy
        /// marcher).
        #[serde(default)]
        sampler: Option<Sampler>,
    },
    /// 3D Gaussian splats in the frame of their file: an INRIA or SuperSplat compressed
    /// `.ply`, a `.splat`, an `.spz`, a `.sog` or a SOG folder's `meta.json`, or a splatfacto
    /// run.
    Splats {
        /// The splat file (relative paths: from the scene file's folder).
        path: PathBuf,
        /// Mip-splatting's opacity compensation, for splats trained with it (gsplat's
        /// `antialiased` mode). Absent: what the file says (SPZ's flag, SOG's model, a PLY's
        /// `SplatRenderMode: mip` comment), else off.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        antialiased: Option<bool>,
        /// The frame the file's values are stored in: `stored` (the default: as they are) or
        /// `rub` (right, up, back, as Niantic's tools write SPZ), turned into the PLY frame.
        #[serde(default, skip_serializing_if = "is_stored")]
        axes: Axes,
    },
}

fn is_stored(axes: &Axes) -> bool {
    *axes == Axes::Stored
}

/// How a trained field's instance is sampled along each ray: by its trainer's own
/// estimator, or by nerfx's marcher.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Sampler {
    /// nerfacto's own proposal networks, as nerfstudio's viewer and `ns-render` sample it:
    /// what the artist approved (the main field is trained only where they sample). The
    /// default for a nerfacto run whose checkpoint holds them.
    Proposal,
    /// instant-ngp's own marcher, as its viewer renders a snapshot: its steps, occupancy
    /// cascades and early stop (no quality dial).
    Ngp,
    /// nerfx's occupancy marcher, jointly with the other instances (error-targeted
    /// quality presets; may show density the trainer's sampler never reaches).
    Occupancy,
}

impl Sampler {
    /// The name in scene files.
    fn name(self) -> &'static str {
        match self {
            Sampler::Proposal => "proposal",
            Sampler::Ngp => "ngp",
            Sampler::Occupancy => "occupancy",
        }
    }
}

/// One instance in a scene file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceDesc {
    /// Name, for messages.
    pub name: String,
    /// The field.
    pub field: FieldSource,
    /// Fixed placement, row-major (used when `object` is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) world_from_field: Option<[[f64; 4]; 4]>,
    /// Take the placement per frame from this object of the shot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<String>,
    /// Crop box in field space.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<CropBox>,
}

/// A scene file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneDesc {
    /// The instances, rendered jointly.
    pub instances: Vec<InstanceDesc>,
    /// The colour space images of the scene are written in (absent: linear Rec.709); the
    /// command line's `--colorspace` and a NeRF Render node's Output Colour Space override it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colorspace: Option<OutputColorSpace>,
}

/// A scene file with its fields loaded once, ready to be placed frame after frame.
#[derive(Clone)]
pub struct LoadedScene {
    desc: SceneDesc,
    contents: Vec<Contents>,
}

/// What an instance holds, loaded.
#[derive(Clone)]
enum Contents {
    Field(FieldHandle),
    Splats(Arc<Splats>),
    /// A run and the colour replacing its own, if any (indicator colours).
    Proposal(Arc<NerfactoField>, Option<[f32; 3]>),
    /// A snapshot and the colour replacing its own, if any (indicator colours).
    Ngp(Arc<IngpField>, Option<[f32; 3]>),
}

/// A row-major nested 4×4 as a matrix.
pub(crate) fn mat4_from_rows(rows: &[[f64; 4]; 4]) -> DMat4 {
    DMat4::from_cols_array_2d(rows).transpose()
}

impl SceneDesc {
    /// Reads a scene file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = crate::input::read_text(path)?;
        Self::from_json_str(&text, path)
    }

    /// The scene a path names: a scene file, or one field or splat file on its own (an
    /// instant-ngp `.ingp`/`.msgpack` snapshot, a splat `.ply`, `.splat`, `.spz`, `.sog` or SOG
    /// folder, a nerfstudio run directory),
    /// rendered in its own frame (`world_from_field` the identity).
    pub fn for_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let file = path.to_path_buf();
        let splats = |path: PathBuf| FieldSource::Splats {
            path,
            antialiased: None,
            axes: Axes::Stored,
        };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let field = if crate::field::is_splatfacto_run(path)
            || (path.is_dir() && path.join("meta.json").is_file())
            || name == "meta.json"
        {
            splats(file)
        } else if path.is_dir() {
            FieldSource::Nerfacto {
                path: file,
                sampler: None,
            }
        } else {
            match ext.as_deref() {
                Some("ingp" | "msgpack") => FieldSource::Ingp {
                    path: file,
                    sampler: None,
                },
                Some("ply" | "splat" | "spz" | "sog") => splats(file),
                _ => return Self::read(path),
            }
        };
        let name = path
            .file_stem()
            .map_or_else(|| "field".into(), |s| s.to_string_lossy().into_owned());
        Ok(SceneDesc {
            instances: vec![InstanceDesc {
                name,
                field,
                world_from_field: None,
                object: None,
                crop: None,
            }],
            colorspace: None,
        })
    }

    /// Parses scene JSON; `path` is used in messages, and relative field paths are made
    /// relative to its folder.
    pub fn from_json_str(text: &str, path: &Path) -> Result<Self> {
        let mut desc: SceneDesc =
            crate::json::parse_json(text, path, "a scene: an object {\"instances\": [...]}")?;
        for (i, inst) in desc.instances.iter().enumerate() {
            let at = format!("instances[{i}] ('{}')", inst.name);
            // Names become Cryptomatte ids and layer names: two alike could not be told apart.
            if let Some(j) = desc.instances[..i].iter().position(|o| o.name == inst.name) {
                return Err(Error::format(
                    path,
                    format!("{at}.name"),
                    format!(
                        "'{}' is the name of instances[{j}] too: each instance needs its own \
                         name (it becomes its Cryptomatte id)",
                        inst.name
                    ),
                ));
            }
            match &inst.field {
                FieldSource::Analytic(a) => a
                    .validate()
                    .map_err(|e| Error::format(path, format!("{at}.field"), e.to_string()))?,
                FieldSource::Ingp { path: file, .. } if file.as_os_str().is_empty() => {
                    return Err(Error::format(
                        path,
                        format!("{at}.field.ingp.path"),
                        "is empty",
                    ))
                }
                FieldSource::Nerfacto { path: file, .. } if file.as_os_str().is_empty() => {
                    return Err(Error::format(
                        path,
                        format!("{at}.field.nerfacto.path"),
                        "is empty",
                    ))
                }
                FieldSource::Splats { path: file, .. } if file.as_os_str().is_empty() => {
                    return Err(Error::format(
                        path,
                        format!("{at}.field.splats.path"),
                        "is empty",
                    ))
                }
                FieldSource::Ingp {
                    sampler: Some(sampler @ Sampler::Proposal),
                    ..
                } => {
                    return Err(Error::format(
                        path,
                        format!("{at}.field.ingp.sampler"),
                        format!(
                            "\"{}\" samples nerfacto runs; an instant-ngp snapshot is marched \
                             by \"ngp\" (instant-ngp's own marcher) or \"occupancy\" (nerfx's)",
                            sampler.name()
                        ),
                    ))
                }
                FieldSource::Nerfacto {
                    sampler: Some(sampler @ Sampler::Ngp),
                    ..
                } => {
                    return Err(Error::format(
                        path,
                        format!("{at}.field.nerfacto.sampler"),
                        format!(
                            "\"{}\" is instant-ngp's marcher, for instant-ngp snapshots; a \
                             nerfacto run is sampled by \"proposal\" (its proposal networks) \
                             or \"occupancy\" (nerfx's marcher)",
                            sampler.name()
                        ),
                    ))
                }
                FieldSource::Ingp { .. }
                | FieldSource::Nerfacto { .. }
                | FieldSource::Splats { .. } => {}
            }
            if inst.world_from_field.is_some() && inst.object.is_some() {
                return Err(Error::format(
                    path,
                    at,
                    "give either world_from_field or object, not both",
                ));
            }
        }
        let base = path.parent().unwrap_or(Path::new(""));
        for inst in &mut desc.instances {
            if let FieldSource::Ingp { path: file, .. }
            | FieldSource::Nerfacto { path: file, .. }
            | FieldSource::Splats { path: file, .. } = &mut inst.field
            {
                if file.is_relative() {
                    *file = base.join(&*file);
                }
            }
        }
        Ok(desc)
    }

    /// The files and folders the scene's fields are read from (field and splat files,
    /// nerfacto run folders), in instance order: what a farm must ship with the scene, and
    /// what a frame rendered from it is older or newer than.
    pub fn sources(&self) -> Vec<PathBuf> {
        self.instances
            .iter()
            .filter_map(|inst| match &inst.field {
                FieldSource::Ingp { path, .. }
                | FieldSource::Nerfacto { path, .. }
                | FieldSource::Splats { path, .. } => Some(path.clone()),
                FieldSource::Analytic(_) => None,
            })
            .collect()
    }

    /// Writes the scene as JSON.
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::format(path, "", e.to_string()))?;
        crate::output::write_file(path, text.as_bytes())
    }

    /// Loads every field once.
    pub fn load(self) -> Result<LoadedScene> {
        let contents = self
            .instances
            .iter()
            .map(|inst| {
                let field = |f: Arc<dyn crate::field::Field>| Contents::Field(FieldHandle::new(f));
                Ok(match &inst.field {
                    FieldSource::Analytic(a) => Contents::Field(FieldHandle::analytic(a.clone())),
                    FieldSource::Ingp { path, sampler } => {
                        let snapshot = Arc::new(IngpField::load(path)?);
                        match sampler.unwrap_or(Sampler::Occupancy) {
                            Sampler::Ngp => Contents::Ngp(snapshot, None),
                            // `from_json_str` refuses the proposal sampler here.
                            Sampler::Occupancy | Sampler::Proposal => field(snapshot),
                        }
                    }
                    FieldSource::Nerfacto { path, sampler } => {
                        let run = Arc::new(NerfactoField::load(path)?);
                        let by_default = if run.has_proposal_sampler() {
                            Sampler::Proposal
                        } else {
                            Sampler::Occupancy
                        };
                        match sampler.unwrap_or(by_default) {
                            Sampler::Proposal => Contents::Proposal(run, None),
                            // `from_json_str` refuses instant-ngp's marcher here.
                            Sampler::Occupancy | Sampler::Ngp => field(run),
                        }
                    }
                    FieldSource::Splats { path, axes, .. } => {
                        Contents::Splats(Arc::new(Splats::load(path)?.into_ply_frame(*axes)))
                    }
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(LoadedScene {
            desc: self,
            contents,
        })
    }
}

impl LoadedScene {
    /// The description it was loaded from.
    pub fn desc(&self) -> &SceneDesc {
        &self.desc
    }

    /// The scene with instance `i` coloured `colours[i]` everywhere (each channel 0 or 1),
    /// its densities untouched: a render of it composites in each channel the coverage of
    /// the instances lit in that channel (see `scene::indicator`).
    ///
    /// Errors: [`Error::Invalid`] when the colours are not one per instance.
    pub fn with_indicator_colours(&self, colours: &[glam::Vec3]) -> Result<LoadedScene> {
        if colours.len() != self.contents.len() {
            return Err(Error::invalid(
                "indicator colours",
                format!("{} for {} instances", colours.len(), self.contents.len()),
            ));
        }
        let contents = self
            .contents
            .iter()
            .zip(colours)
            .map(|(contents, &rgb)| match contents {
                Contents::Field(field) => Contents::Field(field.with_indicator_colour(rgb)),
                Contents::Splats(splats) => {
                    Contents::Splats(Arc::new(super::indicator::indicator_splats(splats, rgb)))
                }
                Contents::Proposal(run, _) => Contents::Proposal(run.clone(), Some(rgb.to_array())),
                Contents::Ngp(snapshot, _) => Contents::Ngp(snapshot.clone(), Some(rgb.to_array())),
            })
            .collect();
        Ok(LoadedScene {
            desc: self.desc.clone(),
            contents,
        })
    }

    /// What loading left out that the artist should hear of (splats dropped for non-finite
    /// values), one line each, naming the file.
    pub fn warnings(&self) -> Vec<String> {
        self.desc
            .instances
            .iter()
            .zip(&self.contents)
            .filter_map(|(inst, contents)| match (contents, &inst.field) {
                (Contents::Splats(s), FieldSource::Splats { path, .. }) if s.dropped > 0 => {
                    Some(format!(
                        "{}: {} splats dropped (a value not finite or a zero rotation)",
                        path.display(),
                        s.dropped
                    ))
                }
                _ => None,
            })
            .collect()
    }

    /// The scene with every instance placed: object-bound ones by `object_matrix(name)` (the
    /// shot's object at the frame being rendered), fixed placements as given, carried into the
    /// shot's world by `world_from_scene` ([`ShotFrame::world_from_scene`]).
    ///
    /// [`ShotFrame::world_from_scene`]: crate::camera::ShotFrame::world_from_scene
    pub fn place(
        &self,
        world_from_scene: DMat4,
        object_matrix: &dyn Fn(&str) -> Result<DMat4>,
    ) -> Result<Scene> {
        let mut scene = Scene::default();
        for (inst, contents) in self.desc.instances.iter().zip(&self.contents) {
            let m = match (&inst.object, &inst.world_from_field) {
                (Some(object), _) => object_matrix(object)?,
                (None, Some(rows)) => world_from_scene * mat4_from_rows(rows),
                (None, None) => world_from_scene,
            };
            match contents {
                Contents::Field(field) => scene.push(Instance::new(
                    inst.name.clone(),
                    field.clone(),
                    m,
                    inst.crop,
                )?),
                Contents::Proposal(run, indicator) => scene.push(
                    ProposalInstance::new(inst.name.clone(), run.clone(), m, inst.crop)?
                        .with_indicator(*indicator),
                ),
                Contents::Ngp(snapshot, indicator) => scene.push(
                    NgpInstance::new(inst.name.clone(), snapshot.clone(), m, inst.crop)?
                        .with_indicator(*indicator),
                ),
                Contents::Splats(splats) => {
                    let antialiased = match inst.field {
                        FieldSource::Splats {
                            antialiased: Some(on),
                            ..
                        } => on,
                        _ => splats.source.antialiased,
                    };
                    scene.push(SplatInstance::new(
                        inst.name.clone(),
                        splats.clone(),
                        m,
                        inst.crop,
                        antialiased,
                    )?)
                }
            }
        }
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicate_instance_names_are_refused() {
        let one = r#"{"name": "ball", "field": {"analytic": {"primitives": []}}}"#;
        let text = format!(
            r#"{{"instances": [{one}, {}, {one}]}}"#,
            one.replace("ball", "box")
        );
        let e = SceneDesc::from_json_str(&text, Path::new("s.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.json")
                && e.contains("instances[2] ('ball').name")
                && e.contains("instances[0]"),
            "{e}"
        );
    }

    /// Wrong shapes and values at every level of a scene: each message is in JSON's words,
    /// with one article, no Rust type or path and no number hundreds of digits long.
    #[test]
    fn scene_messages_are_in_the_users_terms() {
        let sphere = r#"{"sphere": {"center": [0, 0, 0], "radius": 1}}"#;
        let gauss = r#"{"gaussian": {"center": [0, 0, 0], "sigma": 1}}"#;
        let scene = |prims: &str| {
            format!(
                r#"{{"instances": [{{"name": "a", "field": {{"analytic": {{"primitives": {prims}}}}}}}]}}"#
            )
        };
        let prim = |shape: &str, density: &str| {
            format!(
                r#"[{{"shape": {shape}, "density": {density}, "color": {{"rgb": [1, 1, 1]}}}}]"#
            )
        };
        let cases = [
            scene("{}"),
            scene("[1]"),
            scene(&prim(r#"{"sphere": []}"#, "1")),
            scene(&prim(r#"{"gaussian": "x"}"#, "1")),
            scene(&prim(r#"{"box": {"min": {}, "max": [1, 1, 1]}}"#, "1")),
            scene(&prim(sphere, "[]")),
            scene(&prim(sphere, "1e308")),
            scene(&prim(
                &sphere.replace("\"radius\": 1", "\"radius\": 1e308"),
                "1",
            )),
            scene(&prim(&gauss.replace("\"sigma\": 1", "\"sigma\": []"), "1")),
            r#"{"instances": {}}"#.to_string(),
            r#"{"instances": [{"name": [], "field": {}}]}"#.to_string(),
        ];
        for text in &cases {
            let e = match SceneDesc::from_json_str(text, Path::new("s.json")).and_then(|d| d.load())
            {
                Ok(_) => panic!("accepted: {text}"),
                Err(e) => e.to_string(),
            };
            for bad in [
                " a a ",
                " a an ",
                "::",
                "Some(",
                "None",
                "f32",
                "f64",
                "00000000000",
            ] {
                assert!(!e.contains(bad), "{bad:?} in: {e}\n(from {text})");
            }
        }
    }

    #[test]
    fn sources_are_the_field_files_from_the_scene_folder() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.json");
        std::fs::write(
            &path,
            r#"{"instances": [
                {"name": "scan", "field": {"splats": {"path": "scan.ply"}}},
                {"name": "box", "field": {"analytic": {"primitives": []}}},
                {"name": "run", "field": {"nerfacto": {"path": "/show/runs/plant"}}}]}"#,
        )
        .unwrap();
        let desc = SceneDesc::read(&path).unwrap();
        assert_eq!(
            desc.sources(),
            [
                dir.path().join("scan.ply"),
                PathBuf::from("/show/runs/plant")
            ]
        );
    }
}
