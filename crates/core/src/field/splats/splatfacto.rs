//! Splats from a nerfstudio splatfacto run: `config.yml` (the method and its `sh_degree`) and
//! the newest `nerfstudio_models/step-*.ckpt`, whose state dict holds
//! `_model.gauss_params.{means (N,3), scales (N,3) log, quats (N,4) w x y z, features_dc (N,3),
//! features_rest (N,K,3), opacities (N,1) logit}`. With `sh_degree` 0 splatfacto colours a
//! splat by `sigmoid(features_dc)`; otherwise `features_dc` and `features_rest` are SH
//! coefficients (DC first, then each higher coefficient's r g b: already coefficient-major).
//! The splats are in nerfstudio's normalised frame, as `ns-export gaussian-splat` writes them.

use std::path::Path;

use glam::Vec3;

use super::{SplatColor, SplatFormat, Splats};
use crate::error::{Error, Result};
use crate::field::container::Checkpoint;
use crate::field::nerfacto::{latest_checkpoint, scan};

/// The method a run's `config.yml` names (`method_name`), if it can be read.
fn method_name(run: &Path) -> Option<String> {
    let file = run.join("config.yml");
    let text = crate::input::read_text(&file).ok()?;
    scan(&text, "method_name", &file).ok().flatten()
}

/// Whether `run` is a splatfacto run directory (`splatfacto`, `splatfacto-big`, …).
pub(crate) fn is_splatfacto_run(run: &Path) -> bool {
    run.is_dir() && method_name(run).is_some_and(|m| m.starts_with("splatfacto"))
}

/// Reads the splats of the splatfacto run at `run`.
pub(super) fn read(run: &Path) -> Result<Splats> {
    let config = run.join("config.yml");
    let text = crate::input::read_text(&config)?;
    let sh_degree = match scan(&text, "pipeline.model.sh_degree", &config)? {
        None => 3,
        Some(v) => v.parse::<u8>().ok().filter(|d| *d <= 3).ok_or_else(|| {
            Error::format(
                &config,
                "pipeline.model.sh_degree",
                format!("'{v}': expected 0 to 3"),
            )
        })?,
    };
    let (path, _) = latest_checkpoint(&run.join("nerfstudio_models"))?;
    let ckpt = Checkpoint::open(&path)?;
    let tensor = |name: &str, cols: &[usize]| -> Result<(Vec<f32>, usize)> {
        let key = ckpt
            .tensors()
            .keys()
            .find(|k| k.ends_with(&format!("gauss_params.{name}")))
            // Older splatfacto versions kept the parameters directly on the model.
            .or_else(|| {
                ckpt.tensors()
                    .keys()
                    .find(|k| k.ends_with(&format!("_model.{name}")))
            })
            .ok_or_else(|| {
                Error::format(
                    &path,
                    "pipeline",
                    format!("no 'gauss_params.{name}' tensor: not a splatfacto checkpoint"),
                )
            })?;
        let info = &ckpt.tensors()[key];
        let rows = info.shape.first().copied().unwrap_or(0);
        if info.shape.len() != cols.len() + 1 || info.shape[1..] != *cols {
            return Err(Error::format(
                &path,
                key.as_str(),
                format!("shape {:?}; expected [N, {cols:?}]", info.shape),
            ));
        }
        Ok((ckpt.read_f32(key)?, rows))
    };
    let rest_k = (usize::from(sh_degree) + 1).pow(2) - 1;
    let (means, n) = tensor("means", &[3])?;
    let parts = [
        tensor("scales", &[3])?,
        tensor("quats", &[4])?,
        tensor("features_dc", &[3])?,
        tensor("opacities", &[1])?,
        tensor("features_rest", &[rest_k, 3])?,
    ];
    if let Some((_, rows)) = parts.iter().find(|(_, rows)| *rows != n) {
        return Err(Error::format(
            &path,
            "gauss_params",
            format!("{n} means but {rows} rows in another parameter"),
        ));
    }
    let [(scales, _), (quats, _), (dc, _), (opacities, _), (rest, _)] = parts;
    let color = if sh_degree == 0 {
        SplatColor::Sigmoid
    } else {
        SplatColor::Sh { degree: sh_degree }
    };
    let mut splats = Splats::with_capacity(n, color, SplatFormat::Splatfacto);
    splats.source.quantisation = "none: 32-bit floats".into();
    let v3 = |v: &[f32], i: usize| Vec3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    let mut coeffs = Vec::with_capacity(color.coefficients() * 3);
    for i in 0..n {
        coeffs.clear();
        coeffs.extend_from_slice(&dc[3 * i..3 * i + 3]);
        if sh_degree > 0 {
            coeffs.extend_from_slice(&rest[3 * rest_k * i..3 * rest_k * (i + 1)]);
        }
        let q = [0, 1, 2, 3].map(|k| quats[4 * i + k]);
        if !splats.push(v3(&means, i), v3(&scales, i), q, opacities[i], &coeffs) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}
