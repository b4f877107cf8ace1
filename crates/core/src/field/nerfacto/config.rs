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
    pub(crate) method_name: String,
    pub(crate) num_levels: u32,
    pub(crate) features_per_level: u32,
    pub(crate) log2_hashmap_size: u32,
    pub(crate) base_res: u32,
    pub(crate) max_res: u32,
    pub(crate) hidden_dim: usize,
    pub(crate) hidden_dim_color: usize,
    pub(crate) average_init_density: f32,
    pub(crate) disable_scene_contraction: bool,
    pub(crate) use_average_appearance_embedding: bool,
    pub(crate) far_plane: f32,
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
        too_deep(&stack, n, file)?;
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
            if let Some(name) = v.strip_prefix('*') {
                return Err(Error::format(
                    file,
                    format!("line {}", n + 1),
                    format!(
                        "'{path}' is the YAML alias *{name}: nerfx reads config.yml without \
                         expanding aliases (a file of aliases can expand without bound); \
                         write the value itself"
                    ),
                ));
            }
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

/// The deepest nesting of mappings read: nerfstudio's configs nest about eight deep.
const MAX_NESTING: usize = 64;

/// Refuses a mapping nested deeper than [`MAX_NESTING`] (line `n`, from 0): a file nested
/// that deep is not a nerfstudio config, and each line's key path grows with the depth.
fn too_deep(stack: &[(usize, &str)], n: usize, file: &Path) -> Result<()> {
    if stack.len() > MAX_NESTING {
        return Err(Error::format(
            file,
            format!("line {}", n + 1),
            format!("mappings nested more than {MAX_NESTING} deep: not a nerfstudio config.yml"),
        ));
    }
    Ok(())
}

/// One item of a YAML sequence: its `key: value` pairs.
pub(crate) type Item = Vec<(String, String)>;

/// The items of the sequence at the dotted `path` (PyYAML's block style: `- ` items at the
/// key's indentation or deeper, or an inline `[a, b]`), each as its `key: value` pairs (a
/// scalar item as one pair with an empty key); `None` when the key is absent.
pub(crate) fn scan_items(text: &str, path: &str, file: &Path) -> Result<Option<Vec<Item>>> {
    let Some(inline) = scan(text, path, file)? else {
        return Ok(None);
    };
    let scalar = |v: &str| vec![(String::new(), v.trim().to_owned())];
    if let Some(list) = inline.strip_prefix('[').and_then(|v| v.strip_suffix(']')) {
        return Ok(Some(list.split(',').map(scalar).collect()));
    }
    let mut stack: Vec<(usize, &str)> = Vec::new();
    let mut key_indent = None;
    let mut items: Vec<Item> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let content = line.trim_start();
        let indent = line.len() - content.len();
        if content.is_empty() || content.starts_with('#') {
            continue;
        }
        if let Some(ki) = key_indent {
            let item = content
                .strip_prefix('-')
                .filter(|r| r.is_empty() || r.starts_with(' '));
            match item {
                Some(rest) if indent >= ki => {
                    items.push(Vec::new());
                    let rest = rest.trim();
                    if !rest.is_empty() {
                        push_pair(items.last_mut(), rest);
                    }
                }
                None if indent > ki && !items.is_empty() => push_pair(items.last_mut(), content),
                _ => break,
            }
            continue;
        }
        if content.starts_with('-') {
            continue;
        }
        let Some((key, _)) = content.split_once(':') else {
            continue;
        };
        while stack.last().is_some_and(|&(i, _)| i >= indent) {
            stack.pop();
        }
        stack.push((indent, key));
        too_deep(&stack, n, file)?;
        if stack.iter().map(|(_, k)| *k).collect::<Vec<_>>().join(".") == path {
            key_indent = Some(indent);
        }
    }
    Ok(Some(items))
}

/// Adds `key: value` (or a bare scalar) to a sequence item.
fn push_pair(item: Option<&mut Vec<(String, String)>>, text: &str) {
    let Some(item) = item else { return };
    match text
        .split_once(": ")
        .or_else(|| text.strip_suffix(':').map(|k| (k, "")))
    {
        Some((k, v)) => item.push((k.trim().to_owned(), v.trim().to_owned())),
        None => item.push((String::new(), text.trim().to_owned())),
    }
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
    /// Parses the text of `config.yml` (`file` names it in messages).
    pub(crate) fn from_text(text: &str, file: &Path) -> Result<Self> {
        // Without this, an empty or foreign file reads as all defaults and the checkpoint is
        // blamed for not matching them.
        if text.lines().all(|l| {
            let l = l.trim();
            l.is_empty() || l.starts_with('#')
        }) {
            return Err(Error::format(
                file,
                "",
                "is empty; a nerfstudio run's config.yml (ns-train writes it) holds its \
                 method_name and pipeline.model settings",
            ));
        }
        if scan(text, "method_name", file)?.is_none() && scan(text, "pipeline", file)?.is_none() {
            return Err(Error::format(
                file,
                "",
                "has neither method_name nor pipeline: not a nerfstudio run's config.yml",
            ));
        }
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

/// One proposal density field's shape (an entry of `proposal_net_args_list`, with
/// `HashMLPDensityField`'s defaults for the keys it leaves out).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ProposalNetSettings {
    pub(crate) num_levels: u32,
    pub(crate) features_per_level: u32,
    pub(crate) log2_hashmap_size: u32,
    pub(crate) base_res: u32,
    pub(crate) max_res: u32,
    pub(crate) hidden_dim: usize,
    /// Layers of the MLP counting the output layer (nerfstudio's `num_layers`).
    pub(crate) num_layers: usize,
    pub(crate) use_linear: bool,
}

/// How nerfacto samples a ray at inference (`ProposalNetworkSampler`'s settings).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SamplerSettings {
    /// Samples per ray of each proposal iteration (`num_proposal_samples_per_ray`).
    pub(crate) proposal_samples: Vec<usize>,
    /// Samples per ray of the main field (`num_nerf_samples_per_ray`).
    pub(crate) nerf_samples: usize,
    /// `use_same_proposal_network`.
    pub(crate) same_network: bool,
    /// `proposal_initial_sampler` is `uniform` (else `piecewise`).
    pub(crate) uniform_initial: bool,
    /// The proposal networks' shapes, one per network.
    pub(crate) nets: Vec<ProposalNetSettings>,
}

impl SamplerSettings {
    /// Reads the sampler's keys under `pipeline.model` (nerfacto's defaults when absent).
    pub(crate) fn from_text(text: &str, file: &Path) -> Result<Self> {
        let bad =
            |key: &str, why: String| Error::format(file, format!("pipeline.model.{key}"), why);
        let iterations: usize = parsed(text, "num_proposal_iterations", 2, file)?;
        let same_network = parsed(text, "use_same_proposal_network", false, file)?;
        let key = "pipeline.model.num_proposal_samples_per_ray";
        let proposal_samples = match scan_items(text, key, file)? {
            None => vec![256, 96],
            Some(items) => items
                .iter()
                .map(|item| match &item[..] {
                    [(k, v)] if k.is_empty() => v.parse::<usize>().ok(),
                    _ => None,
                })
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| {
                    bad(
                        "num_proposal_samples_per_ray",
                        "expected a list of counts".into(),
                    )
                })?,
        };
        if !(1..=8).contains(&iterations) || proposal_samples.len() < iterations {
            return Err(bad(
                "num_proposal_iterations",
                format!("{iterations} iterations need 1 to 8 counts in num_proposal_samples_per_ray, found {}", proposal_samples.len()),
            ));
        }
        let nerf_samples: usize = parsed(text, "num_nerf_samples_per_ray", 48, file)?;
        if proposal_samples
            .iter()
            .chain([&nerf_samples])
            .any(|&n| !(1..=4096).contains(&n))
        {
            return Err(bad(
                "num_nerf_samples_per_ray",
                "sample counts must be 1 to 4096".into(),
            ));
        }
        let initial = scan(text, "pipeline.model.proposal_initial_sampler", file)?;
        let uniform_initial = match initial.as_deref() {
            None | Some("piecewise") => false,
            Some("uniform") => true,
            Some(other) => {
                return Err(bad(
                    "proposal_initial_sampler",
                    format!("'{other}' is not piecewise or uniform"),
                ))
            }
        };
        let key = "pipeline.model.proposal_net_args_list";
        let args = scan_items(text, key, file)?.unwrap_or_else(|| {
            [128, 256]
                .map(|r| {
                    [
                        ("hidden_dim", "16"),
                        ("log2_hashmap_size", "17"),
                        ("num_levels", "5"),
                        ("max_res", if r == 128 { "128" } else { "256" }),
                        ("use_linear", "false"),
                    ]
                    .map(|(k, v)| (k.to_owned(), v.to_owned()))
                    .to_vec()
                })
                .to_vec()
        });
        let wanted = if same_network { 1 } else { iterations };
        if args.is_empty() || (same_network && args.len() != 1) {
            return Err(bad(
                "proposal_net_args_list",
                format!("{} entries; the sampler needs {wanted}", args.len()),
            ));
        }
        // nerfacto gives network i the entry min(i, len − 1).
        let nets = (0..wanted)
            .map(|i| net_settings(&args[i.min(args.len() - 1)], i, file))
            .collect::<Result<Vec<_>>>()?;
        Ok(SamplerSettings {
            proposal_samples: proposal_samples[..iterations].to_vec(),
            nerf_samples,
            same_network,
            uniform_initial,
            nets,
        })
    }
}

/// One entry of `proposal_net_args_list`.
fn net_settings(pairs: &[(String, String)], i: usize, file: &Path) -> Result<ProposalNetSettings> {
    let at = format!("pipeline.model.proposal_net_args_list[{i}]");
    let get = |key: &str, default: u64| -> Result<u64> {
        match pairs.iter().find(|(k, _)| k == key) {
            None => Ok(default),
            Some((_, v)) => v.parse().map_err(|_| {
                Error::format(
                    file,
                    format!("{at}.{key}"),
                    format!("'{v}' is not a whole number"),
                )
            }),
        }
    };
    let use_linear = match pairs.iter().find(|(k, _)| k == "use_linear") {
        None => false,
        Some((_, v)) => v.parse().map_err(|_| {
            Error::format(
                file,
                format!("{at}.use_linear"),
                format!("'{v}' is not true or false"),
            )
        })?,
    };
    let s = ProposalNetSettings {
        num_levels: get("num_levels", 8)? as u32,
        features_per_level: get("features_per_level", 2)? as u32,
        log2_hashmap_size: get("log2_hashmap_size", 18)? as u32,
        base_res: get("base_res", 16)? as u32,
        max_res: get("max_res", 1024)? as u32,
        hidden_dim: get("hidden_dim", 64)? as usize,
        num_layers: get("num_layers", 2)? as usize,
        use_linear,
    };
    let ok = (1..=32).contains(&s.num_levels)
        && [1, 2, 4, 8].contains(&s.features_per_level)
        && (1..=30).contains(&s.log2_hashmap_size)
        && s.base_res > 0
        && (s.base_res..=1 << 20).contains(&s.max_res)
        && (1..=1024).contains(&s.hidden_dim)
        && (1..=16).contains(&s.num_layers);
    if !ok {
        return Err(Error::format(file, at, "a size out of range (levels 1-32, features 1/2/4/8, log2 table 1-30, 0 < base_res <= max_res, widths 1-1024)"));
    }
    Ok(s)
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
    fn nesting_and_alias_bombs_are_refused() {
        let file = Path::new("config.yml");
        // 100 000 levels: refused at level 65, not walked (each line's path grows with it).
        let deep: String = (0..100_000)
            .map(|d| format!("{}k{d}:\n", " ".repeat(d)))
            .collect();
        let e = scan(&deep, "pipeline.model.max_res", file)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 65") && e.contains("nested more than 64"),
            "{e}"
        );
        let e = scan_items(&deep, "a.b", file).unwrap_err().to_string();
        assert!(e.contains("nested more than 64"), "{e}");
        // An alias is never expanded: a key nerfx reads given as one is refused.
        let alias = TEXT.replace("hidden_dim: 32", "hidden_dim: *id001");
        let e = scan(&alias, "pipeline.model.hidden_dim", file)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line") && e.contains("alias *id001"), "{e}");
        // Anchors and aliases elsewhere (PyYAML writes them for shared objects) are passed by.
        assert_eq!(
            scan(&alias, "pipeline.model.log2_hashmap_size", file).unwrap(),
            Some("12".to_owned())
        );
    }

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

    #[test]
    fn an_empty_or_foreign_file_is_called_so() {
        for (text, needle) in [
            ("", "config.yml: is empty"),
            ("\n  \n# nothing\n", "config.yml: is empty"),
            (
                "camera_model: OPENCV\nw: 640\n",
                "not a nerfstudio run's config.yml",
            ),
        ] {
            let e = RunSettings::from_text(text, Path::new("config.yml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(needle), "{needle:?} not in {e}");
        }
    }

    #[test]
    fn reads_the_sampler_from_pyyaml_sequences() {
        let t = TEXT.replace(
            "    hidden_dim: 32\n",
            "    hidden_dim: 32
    num_proposal_samples_per_ray: !!python/tuple
    - 128
    - 64
    num_nerf_samples_per_ray: 32
    proposal_net_args_list:
    - hidden_dim: 16
      log2_hashmap_size: 17
      max_res: 128
      num_levels: 5
      use_linear: false
    - hidden_dim: 8
      max_res: 256
      num_levels: 4
      use_linear: true
",
        );
        let s = SamplerSettings::from_text(&t, Path::new("config.yml")).unwrap();
        assert_eq!(
            (s.proposal_samples.clone(), s.nerf_samples),
            (vec![128, 64], 32)
        );
        assert!(!s.same_network && !s.uniform_initial);
        assert_eq!(s.nets.len(), 2);
        assert_eq!((s.nets[0].max_res, s.nets[0].log2_hashmap_size), (128, 17));
        // Keys an entry leaves out take HashMLPDensityField's defaults.
        let n = &s.nets[1];
        assert_eq!(
            (n.num_levels, n.hidden_dim, n.log2_hashmap_size),
            (4, 8, 18)
        );
        assert!(n.use_linear && n.num_layers == 2 && n.base_res == 16);
        // Absent: nerfacto's defaults.
        let d = SamplerSettings::from_text(TEXT, Path::new("config.yml")).unwrap();
        assert_eq!((d.proposal_samples, d.nerf_samples), (vec![256, 96], 48));
        assert_eq!([d.nets[0].max_res, d.nets[1].max_res], [128, 256]);
        // A bad count names the key.
        let bad = t.replace("- 64", "- many");
        let e = SamplerSettings::from_text(&bad, Path::new("config.yml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("num_proposal_samples_per_ray"), "{e}");
    }
}
