//! The settings of a nerfstudio run that its field needs, from the run's `config.yml`.
//!
//! `config.yml` is PyYAML's dump of nerfstudio's config dataclasses (with `!!python/…`
//! tags). Rather than a YAML parser, a strict line scan reads the plain `key: scalar` lines
//! of block mappings: the indentation gives each key's path (`pipeline.model.max_res`),
//! sequence items (`- …`) and lines that are not `key:` are skipped, and a key found twice
//! at the same path is an error. Keys read (under `pipeline.model`), with nerfstudio's
//! defaults when absent: `num_levels` 16, `features_per_level` 2, `log2_hashmap_size` 19,
//! `base_res` 16, `max_res` 2048, `hidden_dim` 64, `hidden_dim_color` 64,
//! `average_init_density` (1.0: older versions had no such factor; the nerfacto method sets
//! 0.01), `disable_scene_contraction` false, `use_average_appearance_embedding` true (when
//! false, nerfacto renders with a zero appearance), `far_plane` 1000 (nerfacto's own
//! collider reads it, not the base model's `collider_params`; its `near_plane` applies in
//! training only: at inference the collider starts rays at 0); and the top-level
//! `method_name`.

use std::path::Path;

use crate::error::{Error, Result};

/// What the field needs from `config.yml`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct RunSettings {
    pub method_name: String,
    pub num_levels: u32,
    pub features_per_level: u32,
    pub log2_hashmap_size: u32,
    pub base_res: u32,
    pub max_res: u32,
    pub hidden_dim: usize,
    pub hidden_dim_color: usize,
    pub average_init_density: f32,
    pub disable_scene_contraction: bool,
    pub use_average_appearance_embedding: bool,
    pub far_plane: f32,
}

/// The scalar value at the dotted `path`, if present.
pub(crate) fn scan(text: &str, path: &str, file: &Path) -> Result<Option<String>> {
    let mut stack: Vec<(usize, &str)> = Vec::new();
    let mut found = None;
    for (n, line) in text.lines().enumerate() {
        let content = line.trim_start();
        let indent = line.len() - content.len();
        if content.is_empty() || content.starts_with('#') || content.starts_with('-') {
            continue;
        }
        let Some((key, rest)) = content.split_once(':') else {
            continue;
        };
        let is_key = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !is_key || !(rest.is_empty() || rest.starts_with(' ')) {
            continue;
        }
        while stack.last().is_some_and(|&(i, _)| i >= indent) {
            stack.pop();
        }
        stack.push((indent, key));
        let here = stack.iter().map(|(_, k)| *k).collect::<Vec<_>>().join(".");
        if here == path {
            if found.is_some() {
                return Err(Error::format(
                    file,
                    format!("line {}", n + 1),
                    format!("'{path}' is given twice"),
                ));
            }
            let v = rest.trim();
            let v = v
                .strip_prefix('\'')
                .and_then(|v| v.strip_suffix('\''))
                .or_else(|| v.strip_prefix('"').and_then(|v| v.strip_suffix('"')))
                .unwrap_or(v);
            found = Some(v.to_owned());
        }
    }
    Ok(found)
}

fn parsed<T: std::str::FromStr>(text: &str, key: &str, default: T, file: &Path) -> Result<T> {
    let path = format!("pipeline.model.{key}");
    match scan(text, &path, file)? {
        None => Ok(default),
        Some(v) => v.parse().map_err(|_| {
            Error::format(file, &path, format!("'{v}' is not a valid value for {key}"))
        }),
    }
}

impl RunSettings {
    /// Reads `config.yml` at `file`.
    pub(crate) fn read(file: &Path) -> Result<Self> {
        let text = crate::input::read_text(file)?;
        Self::from_text(&text, file)
    }

    /// Parses the text of `config.yml` (`file` names it in messages).
    pub(crate) fn from_text(text: &str, file: &Path) -> Result<Self> {
        let s = RunSettings {
            method_name: scan(text, "method_name", file)?.unwrap_or_default(),
            num_levels: parsed(text, "num_levels", 16, file)?,
            features_per_level: parsed(text, "features_per_level", 2, file)?,
            log2_hashmap_size: parsed(text, "log2_hashmap_size", 19, file)?,
            base_res: parsed(text, "base_res", 16, file)?,
            max_res: parsed(text, "max_res", 2048, file)?,
            hidden_dim: parsed(text, "hidden_dim", 64, file)?,
            hidden_dim_color: parsed(text, "hidden_dim_color", 64, file)?,
            average_init_density: parsed(text, "average_init_density", 1.0, file)?,
            disable_scene_contraction: parsed(text, "disable_scene_contraction", false, file)?,
            use_average_appearance_embedding: parsed(
                text,
                "use_average_appearance_embedding",
                true,
                file,
            )?,
            far_plane: parsed(text, "far_plane", 1000.0, file)?,
        };
        let bad = |key: &str, why: &str| Error::format(file, format!("pipeline.model.{key}"), why);
        if !(1..=32).contains(&s.num_levels) {
            return Err(bad("num_levels", "must be 1 to 32"));
        }
        if ![1, 2, 4, 8].contains(&s.features_per_level) {
            return Err(bad("features_per_level", "must be 1, 2, 4 or 8"));
        }
        if !(1..=30).contains(&s.log2_hashmap_size) {
            return Err(bad("log2_hashmap_size", "must be 1 to 30"));
        }
        if s.base_res == 0 || s.max_res < s.base_res || s.max_res > 1 << 20 {
            return Err(bad(
                "max_res",
                "resolutions must satisfy 0 < base_res <= max_res",
            ));
        }
        if !(1..=1024).contains(&s.hidden_dim) || !(1..=1024).contains(&s.hidden_dim_color) {
            return Err(bad("hidden_dim", "MLP widths must be 1 to 1024"));
        }
        if !(s.average_init_density.is_finite() && s.average_init_density > 0.0) {
            return Err(bad("average_init_density", "must be a positive number"));
        }
        if !(s.far_plane.is_finite() && s.far_plane > 0.0 && s.far_plane <= 1e7) {
            return Err(bad("far_plane", "must be a positive number, at most 1e7"));
        }
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "!!python/object:nerfstudio.engine.trainer.TrainerConfig
_target: !!python/name:nerfstudio.engine.trainer.Trainer ''
data: &id001 !!python/object/apply:pathlib.PosixPath
- data
- poster
method_name: nerfacto
pipeline: !!python/object:nerfstudio.pipelines.base_pipeline.VanillaPipelineConfig
  datamanager: !!python/object:nerfstudio.data.datamanagers.DataManagerConfig
    max_res: 7
  model: !!python/object:nerfstudio.models.nerfacto.NerfactoModelConfig
    average_init_density: 0.01
    collider_params:
      far_plane: 1000.0
    hidden_dim: 32
    log2_hashmap_size: 12
    disable_scene_contraction: false
  num_levels: 3
";

    #[test]
    fn reads_model_keys_by_indentation() {
        let s = RunSettings::from_text(TEXT, Path::new("config.yml")).unwrap();
        assert_eq!(s.method_name, "nerfacto");
        assert_eq!(s.average_init_density, 0.01);
        assert_eq!((s.hidden_dim, s.log2_hashmap_size), (32, 12));
        // `datamanager.max_res` and `pipeline.num_levels` are other paths: defaults stay.
        assert_eq!((s.max_res, s.num_levels), (2048, 16));
        assert!(!s.disable_scene_contraction);
        assert!(s.use_average_appearance_embedding);
        // nerfacto's far plane; `collider_params` belongs to the base model and is not read.
        assert_eq!(s.far_plane, 1000.0);
        let s = RunSettings::from_text(
            &TEXT.replace(
                "    hidden_dim: 32\n",
                "    hidden_dim: 32\n    far_plane: 50.0\n",
            ),
            Path::new("config.yml"),
        )
        .unwrap();
        assert_eq!(s.far_plane, 50.0);
        let t = TEXT.replace(
            "    hidden_dim: 32\n",
            "    hidden_dim: 32\n    use_average_appearance_embedding: false\n",
        );
        let s = RunSettings::from_text(&t, Path::new("config.yml")).unwrap();
        assert!(!s.use_average_appearance_embedding);
    }

    #[test]
    fn bad_and_repeated_values_name_the_key() {
        let t = TEXT.replace("hidden_dim: 32", "hidden_dim: wide");
        let e = RunSettings::from_text(&t, Path::new("config.yml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("config.yml") && e.contains("hidden_dim"), "{e}");
        let t = TEXT.replace(
            "    hidden_dim: 32\n",
            "    hidden_dim: 32\n    hidden_dim: 64\n",
        );
        let e = RunSettings::from_text(&t, Path::new("config.yml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("twice"), "{e}");
        let t = TEXT.replace("0.01", "-1");
        assert!(RunSettings::from_text(&t, Path::new("config.yml")).is_err());
        let t = TEXT.replace(
            "    hidden_dim: 32\n",
            "    hidden_dim: 32\n    far_plane: -1\n",
        );
        let e = RunSettings::from_text(&t, Path::new("config.yml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("far_plane"), "{e}");
    }
}
