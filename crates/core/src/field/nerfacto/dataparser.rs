//! nerfstudio's `dataparser_transforms.json`: how the training data's world (e.g. COLMAP's)
//! maps into the normalised frame the field was trained and renders in.
//!
//! ```json
//! {"transform": [[r00, r01, r02, t0], [r10, r11, r12, t1], [r20, r21, r22, t2]], "scale": 0.25}
//! ```
//!
//! `x_ns = s·(T·x + t)` (docs/src/architecture.md): the 3×4 `[T | t]` is applied first, then the uniform
//! scale `s`. As one matrix, `ns_from_data = diag(s, s, s, 1)·[T t; 0 1]`. A camera from the
//! data's frame (`data_from_camera`) lands in the field's frame as
//! `ns_from_data · data_from_camera`; its rotation then carries the scale `s`, which
//! [`crate::camera::Camera::new`] removes (directions are renormalised, distances follow `s`).

use std::path::Path;

use glam::DMat4;
#[cfg(test)]
use glam::DVec4;
use serde_json::Value;

use crate::error::{Error, Result};
use crate::json::{self, numbers};

/// The dataparser transform of a nerfstudio training run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DataparserTransform {
    /// `[T | t]` as a 4×4 with the row `0 0 0 1`.
    pub transform: DMat4,
    /// The uniform scale `s` (> 0).
    pub scale: f64,
}

impl DataparserTransform {
    /// Reads `dataparser_transforms.json`.
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::input::read_text(path)?;
        Self::from_json_str(&text, path)
    }

    /// Parses the JSON; `path_for_errors` names the source in messages.
    pub(crate) fn from_json_str(text: &str, path_for_errors: impl AsRef<Path>) -> Result<Self> {
        let path = path_for_errors.as_ref();
        let root = json::parse(text, path)?;
        let bad = |loc: &str, msg: String| Error::format(path, loc, msg);
        let rows = match root.get("transform") {
            Some(Value::Array(rows)) if rows.len() == 3 || rows.len() == 4 => rows,
            Some(v) => {
                return Err(bad(
                    "transform",
                    format!("expected 3 rows of 4 numbers, got {v}"),
                ))
            }
            None => return Err(bad("transform", "missing".into())),
        };
        let mut m = [[0.0f64; 4]; 4];
        m[3] = [0.0, 0.0, 0.0, 1.0];
        for (r, row) in rows.iter().enumerate() {
            match numbers(row) {
                Some(c) if c.len() == 4 => m[r].copy_from_slice(&c),
                _ => {
                    return Err(bad(
                        &format!("transform[{r}]"),
                        format!("expected four finite numbers, got {row}"),
                    ))
                }
            }
        }
        if m[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(bad(
                "transform[3]",
                format!("expected [0, 0, 0, 1], got {:?}", m[3]),
            ));
        }
        let scale = match root.get("scale").and_then(Value::as_f64) {
            Some(s) if s.is_finite() && s > 0.0 => s,
            other => {
                return Err(bad(
                    "scale",
                    format!("expected a number > 0, got {other:?}"),
                ))
            }
        };
        let transform = DMat4::from_cols_array_2d(&m).transpose();
        if transform.determinant().abs() <= 1e-300 {
            return Err(bad("transform", "matrix is singular".into()));
        }
        Ok(DataparserTransform { transform, scale })
    }

    /// `ns_from_data = diag(s, s, s, 1)·[T t; 0 1]`: `x_ns = s·(T·x + t)`.
    #[cfg(test)]
    pub(crate) fn ns_from_data(&self) -> DMat4 {
        let s = self.scale;
        DMat4::from_cols(
            DVec4::new(s, 0.0, 0.0, 0.0),
            DVec4::new(0.0, s, 0.0, 0.0),
            DVec4::new(0.0, 0.0, s, 0.0),
            DVec4::W,
        ) * self.transform
    }

    /// `data_from_ns`, the inverse of [`Self::ns_from_data`].
    #[cfg(test)]
    pub(crate) fn data_from_ns(&self) -> DMat4 {
        self.ns_from_data().inverse()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn maps_points_by_scale_after_the_affine_part() {
        // T: 90° about z, t = (1, 2, 3), s = 0.5.
        let json = r#"{"transform": [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3]], "scale": 0.5}"#;
        let d = DataparserTransform::from_json_str(json, "dp.json").unwrap();
        let x = DVec3::new(4.0, 5.0, 6.0);
        // T·x = (−5, 4, 6); + t = (−4, 6, 9); · s = (−2, 3, 4.5).
        let got = d.ns_from_data().transform_point3(x);
        assert!((got - DVec3::new(-2.0, 3.0, 4.5)).length() < 1e-12, "{got}");
        let back = d.data_from_ns().transform_point3(got);
        assert!((back - x).length() < 1e-12);
    }

    #[test]
    fn errors_name_the_field() {
        let e = DataparserTransform::from_json_str(
            r#"{"transform": [[1, 0, 0, 0], [0, 1, 0], [0, 0, 1, 0]], "scale": 1}"#,
            "dp.json",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("dp.json") && e.contains("transform[1]"), "{e}");
        let e = DataparserTransform::from_json_str(
            r#"{"transform": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], "scale": 0}"#,
            "dp.json",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("scale"), "{e}");
    }
}
